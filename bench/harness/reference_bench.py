"""Measurements on the PyBullet + Stable-Baselines3 reference (the side `bench/run` compares
fairgrasp against). Each subcommand prints one JSON object on stdout; `bench/run` collects them.

    python reference_bench.py check    --episodes 20
    python reference_bench.py physics  --seconds 3
    python reference_bench.py env      --seconds 3 --num-envs 4
    python reference_bench.py train    --timesteps 24576 --out DIR [--max-seconds S --eval-freq N]
    python reference_bench.py sac-gradient-steps --seconds 3 --obs-dim 40 --act-dim 5
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "reference"))

import fa_arm_grasp_ref  # noqa: E402
from fa_arm_grasp_ref import FaArmGraspRefEnv, scripted_pick  # noqa: E402

# Seeds as in fairgrasp's training: evaluation during training from 1,000,000, the final
# held-out evaluation from 2,000,000,000.
EVAL_SEED_BASE = 1_000_000
HELD_OUT_SEED_BASE = 2_000_000_000


def emit(result: dict) -> None:
    print(json.dumps(result), flush=True)


def rate(seconds: float, f) -> float:
    """Calls per second of `f` over about `seconds` of wall time (after a short warm-up)."""
    for _ in range(10):
        f()
    start = time.perf_counter()
    calls = 0
    while time.perf_counter() - start < seconds:
        for _ in range(50):
            f()
        calls += 50
    return calls / (time.perf_counter() - start)


# ── check ─────────────────────────────────────────────────────────────────


def cmd_check(args) -> None:
    """Gymnasium's env checker, SB3's env checker, and the scripted pick through `step()`."""
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(fa_arm_grasp_ref.ENV_ID, render_mode="rgb_array")
    with warnings.catch_warnings(record=True) as gym_warnings:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    env.close()
    env = FaArmGraspRefEnv()
    with warnings.catch_warnings(record=True) as sb3_warnings:
        warnings.simplefilter("always")
        sb3_check_env(env)
    successes, steps = 0, []
    start = time.perf_counter()
    for episode in range(args.episodes):
        ok, n = scripted_pick(env, seed=episode)
        successes += ok
        if ok:
            steps.append(n)
    env.close()
    emit(
        {
            "gymnasium_check_env": "passed",
            "gymnasium_warnings": [str(w.message) for w in gym_warnings],
            "sb3_check_env": "passed",
            "sb3_warnings": [str(w.message).split(" cf.")[0] for w in sb3_warnings],
            "scripted_episodes": args.episodes,
            "scripted_successes": successes,
            "scripted_mean_steps": float(np.mean(steps)) if steps else None,
            "scripted_seconds": time.perf_counter() - start,
        }
    )
    if successes < args.episodes:
        sys.exit(f"scripted pick succeeded in only {successes} of {args.episodes} episodes")


# ── physics ───────────────────────────────────────────────────────────────


def cmd_physics(args) -> None:
    """Physics steps/s of the scene (as `fairgrasp bench physics`): arm holding with the cube on
    the table, cube grasped and lifted; resets/s; state restores/s."""
    env = FaArmGraspRefEnv()
    scene = env.scene
    c = scene.client

    def steps_rate(state: int) -> float:
        n = 0

        def step():
            nonlocal n
            n += 1
            if n % 2400 == 0:
                c.restoreState(state)
            c.stepSimulation()

        return rate(args.seconds, step)

    env.reset(seed=0)
    idle = c.saveState()
    idle_rate = steps_rate(idle)

    ok, _ = scripted_pick(env, seed=0)
    if not ok:
        sys.exit("scripted pick failed; cannot measure the grasping state")
    held = c.saveState()
    grasp_rate = steps_rate(held)

    rng = np.random.default_rng(0)
    reset_rate = rate(args.seconds, lambda: scene.reset(rng))
    restore_rate = rate(args.seconds, lambda: c.restoreState(idle))
    env.close()
    emit(
        {
            "physics_hz": round(1 / scene.settings.dt),
            "steps_per_s_idle": idle_rate,
            "steps_per_s_grasping": grasp_rate,
            "resets_per_s": reset_rate,
            "snapshot_restores_per_s": restore_rate,
        }
    )


def cmd_mujoco_physics(args) -> None:
    """Physics steps/s of the same scene in MuJoCo (PyPI's `mujoco`), one thread: arm holding
    with the cube on the table, cube grasped and lifted by a scripted grasp; and whether that
    grasp still holds after the measurement."""
    import mujoco

    from fa_arm_grasp_ref.mujoco_scene import MujocoGraspScene

    scene = MujocoGraspScene()
    m, d = scene.model, scene.data
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    size = mujoco.mj_stateSize(m, spec)

    def snapshot() -> np.ndarray:
        state = np.empty(size)
        mujoco.mj_getState(m, d, state, spec)
        return state

    def steps_rate(state: np.ndarray) -> float:
        # Chunks of 240 steps through one call (the Python loop's overhead stays out of the
        # figure, as in our Rust loop); back to the snapshot every 2,400 steps, like the others.
        chunks = 0

        def chunk():
            nonlocal chunks
            chunks += 1
            if chunks % 10 == 0:
                mujoco.mj_setState(m, d, state, spec)
            mujoco.mj_step(m, d, nstep=240)

        return 240 * rate(args.seconds, chunk)

    scene.reset()
    scene.step(120)
    idle_rate = steps_rate(snapshot())
    if not scene.scripted_grasp():
        sys.exit("MuJoCo: the scripted grasp failed; cannot measure the grasping state")
    held = snapshot()
    grasp_rate = steps_rate(held)
    mujoco.mj_setState(m, d, held, spec)
    scene.step(2400)  # ten seconds of holding
    emit(
        {
            "mujoco": mujoco.__version__,
            "physics_hz": round(1 / m.opt.timestep),
            "solver": "Newton",
            "steps_per_s_idle": idle_rate,
            "steps_per_s_grasping": grasp_rate,
            "grasp_holds_after_10_s": scene.cube_height() > 0.1,
            "cube_height_after_10_s": scene.cube_height(),
        }
    )


# ── env ───────────────────────────────────────────────────────────────────


def make_env(seed: int | None = None):
    def _init():
        env = FaArmGraspRefEnv()
        if seed is not None:
            env.reset(seed=seed)
        return env

    return _init


def random_steps_rate(seconds: float, seed: int = 0) -> float:
    """Env steps/s of one env with random actions, resetting when an episode ends."""
    env = FaArmGraspRefEnv()
    env.reset(seed=seed)
    env.action_space.seed(seed)

    def step():
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()

    result = rate(seconds, step)
    env.close()
    return result


def cmd_env(args) -> None:
    """Env steps/s with random actions: one env in this process; SB3's SubprocVecEnv (one
    process per env, stepped in lockstep: how SB3 trains on several cores); and, as an upper
    bound for Python, independent processes that each step their own env freely."""
    import multiprocessing

    from stable_baselines3.common.vec_env import SubprocVecEnv

    single = random_steps_rate(args.seconds)
    with multiprocessing.get_context("forkserver").Pool(args.processes) as pool:
        free = sum(pool.starmap(random_steps_rate, [(args.seconds, i) for i in range(args.processes)]))

    venv = SubprocVecEnv([make_env() for _ in range(args.num_envs)])
    venv.seed(0)
    venv.reset()
    space = venv.action_space
    space.seed(0)
    vec = rate(
        args.seconds,
        lambda: venv.step(np.stack([space.sample() for _ in range(args.num_envs)])),
    )
    venv.close()
    emit(
        {
            "env_steps_per_s_single": single,
            "env_steps_per_s_subproc": vec * args.num_envs,
            "num_envs": args.num_envs,
            "env_steps_per_s_free_processes": free,
            "processes": args.processes,
        }
    )


# ── train ─────────────────────────────────────────────────────────────────


def evaluate(model, episodes: int, seed_base: int) -> tuple[float, float]:
    """Success rate and mean return of the deterministic policy, one episode per seed."""
    env = FaArmGraspRefEnv()
    successes, returns = 0, []
    for i in range(episodes):
        obs, _ = env.reset(seed=seed_base + i)
        done, ret, info = False, 0.0, {}
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, info = env.step(action)
            ret += reward
            done = terminated or truncated
        successes += bool(info.get("is_success"))
        returns.append(ret)
    env.close()
    return successes / episodes, float(np.mean(returns))


def cmd_train(args) -> None:
    """SB3 PPO with the design document's settings on SubprocVecEnv: throughput, and (with
    `--eval-freq`) the evaluation success against steps and wall time within a budget."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecMonitor

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    class Budget(BaseCallback):
        """Stops at the wall-clock budget; evaluates every `eval_freq` env steps on the seeds
        fairgrasp uses and keeps the best model (by success, then return), like EvalCallback."""

        def __init__(self):
            super().__init__()
            self.start = time.perf_counter()
            self.next_eval = args.eval_freq
            self.curve = []
            self.best = (-1.0, -np.inf)

        def _on_step(self) -> bool:
            if args.eval_freq and self.num_timesteps >= self.next_eval:
                self.next_eval += args.eval_freq
                success, mean_return = evaluate(self.model, args.eval_episodes, EVAL_SEED_BASE)
                elapsed = time.perf_counter() - self.start
                self.curve.append(
                    {"steps": self.num_timesteps, "seconds": elapsed, "success": success}
                )
                print(
                    f"  reference PPO: {self.num_timesteps} steps, {elapsed / 60:.1f} min, "
                    f"eval success {success:.0%}, mean return {mean_return:.2f}",
                    file=sys.stderr,
                    flush=True,
                )
                if (success, mean_return) > self.best:
                    self.best = (success, mean_return)
                    self.model.save(out / "best_model.zip")
            return not (args.max_seconds and time.perf_counter() - self.start > args.max_seconds)

    venv = VecMonitor(SubprocVecEnv([make_env() for _ in range(args.n_envs)]))
    venv.seed(args.seed)
    # The design document's PPO settings (section 4.2).
    model = PPO(
        "MlpPolicy",
        venv,
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
        seed=args.seed,
        device="cpu",
        verbose=0,
    )
    budget = Budget()
    start = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, callback=budget)
    wall = time.perf_counter() - start
    venv.close()
    result = {
        "steps": int(model.num_timesteps),
        "seconds": wall,
        "fps": model.num_timesteps / wall,
        "n_envs": args.n_envs,
        "torch_threads": torch.get_num_threads(),
        "eval_curve": budget.curve,
        "peak_memory_mib": peak_memory_mib(),
    }
    if args.held_out_episodes and (out / "best_model.zip").exists():
        best = PPO.load(out / "best_model.zip", device="cpu")
        success, mean_return = evaluate(best, args.held_out_episodes, HELD_OUT_SEED_BASE)
        result["held_out"] = {
            "episodes": args.held_out_episodes,
            "success": success,
            "mean_return": mean_return,
        }
    emit(result)


# ── sac-gradient-steps ────────────────────────────────────────────────────


def cmd_sac_gradient_steps(args) -> None:
    """SB3 SAC gradient steps per second: `model.train()` on a replay buffer of random
    transitions, with `fairgrasp bench sac`'s sizes (the networks of configs/sac_grasp.toml)."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import SAC
    from stable_baselines3.common.logger import configure

    class Boxes(gym.Env):
        """Only the spaces: SAC needs an env to size its networks, never steps it here."""

        observation_space = gym.spaces.Box(-np.inf, np.inf, (args.obs_dim,), np.float32)
        action_space = gym.spaces.Box(-1.0, 1.0, (args.act_dim,), np.float32)

    net_arch = [int(w) for w in args.net_arch.split(",")]
    model = SAC(
        "MlpPolicy",
        Boxes(),
        buffer_size=args.transitions,
        batch_size=args.batch_size,
        gamma=0.95,
        policy_kwargs={"net_arch": net_arch},
        seed=0,
        device="cpu",
    )
    model.set_logger(configure(None, []))
    rng = np.random.default_rng(0)
    n = args.transitions
    rb = model.replay_buffer
    rb.observations[:n] = rng.standard_normal((n, 1, args.obs_dim), dtype=np.float32)
    rb.next_observations[:n] = rng.standard_normal((n, 1, args.obs_dim), dtype=np.float32)
    rb.actions[:n] = rng.uniform(-1, 1, (n, 1, args.act_dim)).astype(np.float32)
    rb.rewards[:n] = rng.random((n, 1), dtype=np.float32)
    rb.full = True
    # Calls of 5 steps until the time is up (`rate`'s chunks of 50 calls would run for minutes
    # where torch's threads compete with other work).
    per_call = 5
    model.train(gradient_steps=per_call, batch_size=args.batch_size)
    start, cpu_start = time.perf_counter(), time.process_time()
    steps = 0
    while time.perf_counter() - start < args.seconds:
        model.train(gradient_steps=per_call, batch_size=args.batch_size)
        steps += per_call
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    emit(
        {
            "gradient_steps_per_s": steps / wall,
            # All of torch's threads' CPU time (its idle threads spin).
            "gradient_steps_per_cpu_s": steps / cpu if cpu > 0 else None,
            "batch_size": args.batch_size,
            "net_arch": net_arch,
            "obs_dim": args.obs_dim,
            "act_dim": args.act_dim,
            "torch": torch.__version__,
            "torch_threads": torch.get_num_threads(),
        }
    )


def peak_memory_mib() -> float | None:
    """Peak resident memory of this process plus that of its largest finished child (MiB)."""
    try:
        import resource

        own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
        children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        return (own + children) / 1024
    except (ImportError, OSError):
        return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("check", help=cmd_check.__doc__)
    p.add_argument("--episodes", type=int, default=20)
    p = sub.add_parser("physics", help=cmd_physics.__doc__)
    p.add_argument("--seconds", type=float, default=3.0)
    p = sub.add_parser("mujoco-physics", help=cmd_mujoco_physics.__doc__)
    p.add_argument("--seconds", type=float, default=3.0)
    p = sub.add_parser("env", help=cmd_env.__doc__)
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--num-envs", type=int, default=4)
    p.add_argument("--processes", type=int, default=2)
    p = sub.add_parser("train", help=cmd_train.__doc__)
    p.add_argument("--timesteps", type=int, required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--n-envs", type=int, default=4)
    p.add_argument("--seed", type=int, default=42)
    p.add_argument("--max-seconds", type=float, default=0.0)
    p.add_argument("--eval-freq", type=int, default=0)
    p.add_argument("--eval-episodes", type=int, default=50)
    p.add_argument("--held-out-episodes", type=int, default=0)
    p = sub.add_parser("sac-gradient-steps", help=cmd_sac_gradient_steps.__doc__)
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--obs-dim", type=int, required=True)
    p.add_argument("--act-dim", type=int, required=True)
    p.add_argument("--net-arch", default="256,256")
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--transitions", type=int, default=10_000)
    args = parser.parse_args()
    {
        "check": cmd_check,
        "physics": cmd_physics,
        "mujoco-physics": cmd_mujoco_physics,
        "env": cmd_env,
        "train": cmd_train,
        "sac-gradient-steps": cmd_sac_gradient_steps,
    }[args.command](args)


if __name__ == "__main__":
    main()
