"""A hyperparameter sweep of fairgrasp's native PPO with Ray Tune.

Each trial runs `fairgrasp.train` (the Rust trainer, GIL released) in a Ray worker and reports
every evaluation's success rate to Tune, whose ASHA scheduler stops the trials that trail.

    pip install "./python[ray]"
    python examples/ray_tune_sweep.py --smoke           # 2 trials, a few thousand steps each
    python examples/ray_tune_sweep.py --num-samples 16 --total-timesteps 600000

On a cluster the same script fans the trials out over every node (docs/python.md):

    ray start --head --port=6379                        # on the head node
    ray start --address=HEAD_IP:6379                    # on each other node
    python examples/ray_tune_sweep.py --address auto --num-samples 64 --storage /shared/sweeps

(`--storage` must be a path every node can reach, or a cloud URI such as s3://bucket/sweeps.)
The last line printed is a JSON summary: the best trial's settings and success rate.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import ray
from ray import tune
from ray.tune.schedulers import ASHAScheduler

import fairgrasp


def trainable(config: dict) -> None:
    """One trial: the native trainer with the sampled settings, reporting each evaluation."""
    trial_dir = Path(tune.get_context().get_trial_dir())
    evaluations = 0

    def on_progress(progress: dict) -> None:
        nonlocal evaluations
        if progress["eval_count"] > evaluations:
            evaluations = progress["eval_count"]
            tune.report(
                {
                    "success_rate": progress["last_eval"]["success_rate"],
                    "mean_return": progress["last_eval"]["mean_return"],
                    "timesteps": progress["num_timesteps"],
                    "fps": progress["fps"],
                }
            )

    fairgrasp.train(
        env_id="FaArmGrasp-v0",
        run_dir=trial_dir / "run",
        callback=on_progress,
        total_timesteps=config["total_timesteps"],
        seed=config["seed"],
        n_envs=config["n_envs"],
        threads=config["threads"],
        checkpoint_freq=0,
        eval={"freq": config["eval_freq"], "episodes": config["eval_episodes"], "success_threshold": None},
        ppo={
            "learning_rate": config["learning_rate"],
            "n_steps": config["n_steps"],
            "n_epochs": config["n_epochs"],
            "gamma": config["gamma"],
        },
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--smoke", action="store_true", help="2 trials of a few thousand steps: checks the set-up")
    parser.add_argument("--address", help="a running Ray cluster ('auto' or HOST:PORT); default: start one here")
    parser.add_argument("--num-samples", type=int, default=8)
    parser.add_argument("--total-timesteps", type=int, default=600_000)
    parser.add_argument("--cpus-per-trial", type=int, default=2, help="CPUs (and Rust env threads) per trial")
    parser.add_argument("--storage", type=Path, default=Path("runs") / "ray", help="where Tune keeps the trials")
    parser.add_argument("--name", default="ppo_grasp_sweep")
    args = parser.parse_args()

    if args.smoke:
        args.num_samples, args.total_timesteps, args.cpus_per_trial = 2, 4096, 1
    if args.address:
        ray.init(address=args.address)
    else:
        ray.init(include_dashboard=False, num_cpus=os.cpu_count(), log_to_driver=False)

    space = {
        "total_timesteps": args.total_timesteps,
        "seed": tune.randint(0, 1_000_000),
        "n_envs": 4 if args.smoke else 16,
        "threads": args.cpus_per_trial,
        "eval_freq": 2048 if args.smoke else 50_000,
        "eval_episodes": 4 if args.smoke else 50,
        "n_steps": 256 if args.smoke else 128,
        "n_epochs": 2 if args.smoke else tune.choice([5, 10]),
        "learning_rate": tune.grid_search([1e-4, 3e-4]) if args.smoke else tune.loguniform(5e-5, 1e-3),
        "gamma": 0.95 if args.smoke else tune.choice([0.95, 0.97, 0.99]),
    }
    # ASHA stops the trials that trail at each rung; the smoke run keeps both trials to the end.
    scheduler = None if args.smoke else ASHAScheduler(time_attr="timesteps", max_t=args.total_timesteps, grace_period=100_000)
    tuner = tune.Tuner(
        tune.with_resources(trainable, {"cpu": args.cpus_per_trial}),
        param_space=space,
        tune_config=tune.TuneConfig(
            metric="success_rate",
            mode="max",
            num_samples=1 if args.smoke else args.num_samples,
            scheduler=scheduler,
        ),
        run_config=tune.RunConfig(name=args.name, storage_path=str(args.storage.resolve()), verbose=1),
    )
    results = tuner.fit()
    errors = [str(r.error) for r in results if r.error]
    if errors:
        raise SystemExit(f"{len(errors)} trial(s) failed: {errors[0]}")
    best = results.get_best_result()
    summary = {
        "trials": len(results),
        "best_success_rate": best.metrics["success_rate"],
        "best_config": {k: v for k, v in best.config.items() if k in ("learning_rate", "n_epochs", "gamma", "seed")},
        "best_timesteps": best.metrics["timesteps"],
        "storage": str(args.storage.resolve() / args.name),
    }
    print(json.dumps(summary), flush=True)
    ray.shutdown()


if __name__ == "__main__":
    main()
