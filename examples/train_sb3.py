"""Train the FR5 grasp with Stable-Baselines3's PPO on fairgrasp's native vector env.

The design document's training script (section 4.2: PPO with its hyperparameters, EvalCallback
reporting the success rate, CheckpointCallback, TensorBoard, a progress bar), with fairgrasp's
engine in place of a PyBullet env:

    pip install "./python[sb3]"
    python examples/train_sb3.py                        # the design's settings, 2M steps
    python examples/train_sb3.py --preset native --stop-at-success 0.9
    tensorboard --logdir runs/sb3_design/tb

Presets:
  design  the design's PPO settings (n_steps 2048, batch 256, 10 epochs, lr 3e-4, ent 0.01) on
          4 envs of FaArmGrasp-v0 with its default settings (joint-delta actions);
  native  what `fairgrasp train` runs by default (configs/ppo_grasp.toml): its task settings
          (Cartesian actions, rich observation, staged reward), 16 envs, its PPO settings and
          observation/reward normalisation (SB3's VecNormalize), so SB3 and the native trainer
          learn the same problem with the same algorithm.

The last line printed is a JSON summary (steps, seconds, fps, evaluations).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

import fairgrasp

DESIGN_PPO = dict(
    learning_rate=3e-4,
    n_steps=2048,
    batch_size=256,
    n_epochs=10,
    gamma=0.99,
    gae_lambda=0.95,
    clip_range=0.2,
    ent_coef=0.01,
    vf_coef=0.5,
    max_grad_norm=0.5,
)
# Evaluation seeds: those of `fairgrasp train`'s evaluations (never used for training).
EVAL_SEED = 1_000_000


def native_preset() -> tuple[dict, dict, int, dict]:
    """PPO kwargs, env settings, n_envs and VecNormalize kwargs of `fairgrasp train`'s default."""
    config = tomllib.loads(fairgrasp.default_train_config("FaArmGrasp-v0", "ppo"))
    ppo = config["ppo"]
    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[ppo["activation"]]
    kwargs = dict(
        learning_rate=ppo["learning_rate"],
        n_steps=ppo["n_steps"],
        batch_size=ppo["batch_size"],
        n_epochs=ppo["n_epochs"],
        gamma=ppo["gamma"],
        gae_lambda=ppo["gae_lambda"],
        clip_range=ppo["clip_range"],
        ent_coef=ppo["ent_coef"],
        vf_coef=ppo["vf_coef"],
        max_grad_norm=ppo["max_grad_norm"],
        policy_kwargs=dict(
            net_arch=list(ppo["net_arch"]),
            activation_fn=activation,
            log_std_init=ppo["log_std_init"],
        ),
    )
    norm = config["normalize"]
    normalize = dict(
        norm_obs=norm["norm_obs"],
        norm_reward=norm["norm_reward"],
        clip_obs=norm["clip_obs"],
        clip_reward=norm["clip_reward"],
        gamma=norm["gamma"],
    )
    return kwargs, config.get("env", {}), config["n_envs"], normalize


class SuccessThreshold(BaseCallback):
    """Run after each evaluation: records the success rate and stops at the threshold."""

    def __init__(self, threshold: float | None, started: float) -> None:
        super().__init__()
        self.threshold = threshold
        self.started = started
        self.evaluations: list[dict] = []

    def _on_step(self) -> bool:
        parent = self.parent
        success = float(np.mean(parent._is_success_buffer)) if parent._is_success_buffer else 0.0
        self.evaluations.append(
            {
                "steps": int(self.num_timesteps),
                "seconds": round(time.perf_counter() - self.started, 2),
                "success_rate": success,
                "mean_reward": float(parent.last_mean_reward),
            }
        )
        return self.threshold is None or success < self.threshold


class TimeBudget(BaseCallback):
    """Stops training once the wall-time budget is spent."""

    def __init__(self, max_seconds: float | None, started: float) -> None:
        super().__init__()
        self.max_seconds = max_seconds
        self.started = started

    def _on_step(self) -> bool:
        return self.max_seconds is None or time.perf_counter() - self.started < self.max_seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", choices=["design", "native"], default="design")
    parser.add_argument("--total-timesteps", type=int, default=2_000_000)
    parser.add_argument("--n-envs", type=int, help="parallel envs (default: the preset's)")
    parser.add_argument("--threads", type=int, default=0, help="Rust threads stepping them (0: one per CPU)")
    parser.add_argument("--seed", type=int, default=42)
    parser.add_argument("--eval-freq", type=int, default=40_000, help="evaluate every this many env steps")
    parser.add_argument("--eval-episodes", type=int, default=10)
    parser.add_argument("--checkpoint-freq", type=int, default=200_000, help="env steps between checkpoints")
    parser.add_argument("--stop-at-success", type=float, help="stop once an evaluation reaches this success rate")
    parser.add_argument("--out", type=Path, help="run directory (default: runs/sb3_<preset>)")
    parser.add_argument("--max-seconds", type=float, help="stop after this much wall time")
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE",
        help="an env setting by its TOML key, e.g. --set control.action_mode=cartesian (value in TOML syntax)",
    )
    parser.add_argument("--no-progress-bar", action="store_true")
    args = parser.parse_args()

    out = args.out or Path("runs") / f"sb3_{args.preset}"
    if args.preset == "design":
        ppo_kwargs, env_settings, n_envs, normalize = DESIGN_PPO, {}, 4, None
    else:
        ppo_kwargs, env_settings, n_envs, normalize = native_preset()
    n_envs = args.n_envs or n_envs
    for item in args.set:
        key, _, value = item.partition("=")
        try:
            parsed = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            parsed = value  # a bare word: a string
        env_settings = {**env_settings, key.strip(): parsed}

    venv = VecMonitor(
        fairgrasp.make_vec_env("FaArmGrasp-v0", n_envs, threads=args.threads, seed=args.seed, **env_settings)
    )
    eval_env = VecMonitor(fairgrasp.make_vec_env("FaArmGrasp-v0", 1, threads=1, seed=EVAL_SEED, **env_settings))
    if normalize is not None:
        venv = VecNormalize(venv, **normalize)
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False, clip_obs=normalize["clip_obs"])

    started = time.perf_counter()
    threshold = SuccessThreshold(args.stop_at_success, started)
    callbacks: list[BaseCallback] = [TimeBudget(args.max_seconds, started)]
    if args.eval_freq > 0:
        callbacks.append(
            EvalCallback(
                eval_env,
                best_model_save_path=str(out / "models" / "best"),
                log_path=str(out / "eval_logs"),
                eval_freq=max(args.eval_freq // n_envs, 1),
                n_eval_episodes=args.eval_episodes,
                deterministic=True,
                callback_after_eval=threshold,
            )
        )
    if args.checkpoint_freq > 0:
        callbacks.append(
            CheckpointCallback(
                save_freq=max(args.checkpoint_freq // n_envs, 1),
                save_path=str(out / "models" / "checkpoints"),
                name_prefix="fa_grasp",
                save_vecnormalize=normalize is not None,
            )
        )
    model = PPO(
        "MlpPolicy",
        venv,
        seed=args.seed,
        device="cpu",
        verbose=0,
        tensorboard_log=str(out / "tb"),
        **ppo_kwargs,
    )
    model.learn(
        total_timesteps=args.total_timesteps,
        callback=callbacks,
        progress_bar=not args.no_progress_bar,
    )
    seconds = time.perf_counter() - started
    model.save(out / "models" / "final_model.zip")
    if normalize is not None:
        venv.save(str(out / "models" / "vecnormalize.pkl"))
    summary = {
        "preset": args.preset,
        "n_envs": n_envs,
        "rust_threads": venv.unwrapped.threads,
        "steps": int(model.num_timesteps),
        "seconds": round(seconds, 2),
        "fps": round(model.num_timesteps / seconds, 1),
        "evaluations": threshold.evaluations,
        "out": str(out),
    }
    print(json.dumps(summary), flush=True)


if __name__ == "__main__":
    sys.exit(main())
