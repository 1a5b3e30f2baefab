"""Smoke runs of the examples: the design's SB3 script on our VecEnv, the Ray Tune sweep, and the camera feed."""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys

from conftest import REPO, run_cli


def run_example(script: str, *args: str, cwd) -> dict:
    done = subprocess.run(
        [sys.executable, str(REPO / "examples" / script), *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_train_sb3_runs_the_design_script_on_eight_native_envs(tmp_path, capsys):
    summary = run_example(
        "train_sb3.py",
        "--total-timesteps", "20000",
        "--n-envs", "8",
        "--eval-freq", "8192",
        "--eval-episodes", "3",
        "--checkpoint-freq", "16384",
        "--out", str(tmp_path / "run"),
        cwd=tmp_path,
    )
    # n_steps 2048 × 8 envs: two rollouts.
    assert summary["steps"] == 32768 and summary["n_envs"] == 8 and summary["fps"] > 0
    assert [e["steps"] for e in summary["evaluations"]] == [8192, 16384, 24576, 32768]
    run = tmp_path / "run"
    assert (run / "models" / "best" / "best_model.zip").is_file()
    assert (run / "models" / "final_model.zip").is_file()
    assert list((run / "models" / "checkpoints").glob("fa_grasp_*_steps.zip"))
    assert list((run / "tb").rglob("events.out.tfevents.*"))
    evaluations = (run / "eval_logs" / "evaluations.npz")
    assert evaluations.is_file()
    with capsys.disabled():
        print(f"\n  SB3 PPO on fairgrasp.make_vec_env(FaArmGrasp-v0, 8): {summary['fps']:.0f} steps/s "
              f"({summary['steps']} steps in {summary['seconds']:.1f} s, updates included)")


def test_ray_tune_sweep_smoke_runs_two_trials(tmp_path):
    summary = run_example("ray_tune_sweep.py", "--smoke", "--storage", str(tmp_path / "ray"), cwd=tmp_path)
    assert summary["trials"] == 2
    assert 0.0 <= summary["best_success_rate"] <= 1.0
    assert summary["best_timesteps"] == 4096
    assert summary["best_config"]["learning_rate"] in (1e-4, 3e-4)


@contextlib.contextmanager
def synthetic_feed(model):
    """The camera feed example serving its test patterns for `model` on a free port: its first
    line (the views it serves) and the port; stopped on leaving."""
    feed = subprocess.Popen(
        [sys.executable, str(REPO / "examples" / "camera_feed.py"), "--model", str(model),
         "--synthetic", "--port", "0", "--seconds", "20"],
        stdout=subprocess.PIPE, text=True,
    )
    try:
        line = feed.stdout.readline()
        assert line.startswith("camera feed on 127.0.0.1:"), line
        yield line, int(line.split(":")[1])
    finally:
        feed.kill()
        feed.wait()
        feed.stdout.close()


def test_the_camera_feed_example_serves_what_fairgrasp_camera_check_reads(fairgrasp_bin, camera_model):
    with synthetic_feed(camera_model) as (_, port):
        out = run_cli(fairgrasp_bin, "camera-check", "--model", str(camera_model),
                      "--camera-tcp", f"127.0.0.1:{port}", "--seconds", "1.5").stdout
    print(out)
    frames = int(out.split("scene_rgb: ")[1].split(" frames")[0])
    assert frames >= 20, out


def two_camera_model(tmp_path):
    """A model.json as a student of the scene and wrist cameras has it (all the example reads)."""
    views = [{"name": n, "height": 24, "width": 24, "channels": 3} for n in ("scene_rgb", "wrist_rgb")]
    (tmp_path / "model.json").write_text(json.dumps({"pixel_actor": {"images": {"views": views}}}))
    return tmp_path


def test_the_camera_feed_example_serves_each_camera_its_own_frames(tmp_path):
    import socket

    with synthetic_feed(two_camera_model(tmp_path)) as (line, port):
        assert "scene_rgb 24x24x3, wrist_rgb 24x24x3" in line, line
        with socket.create_connection(("127.0.0.1", port), timeout=5) as conn:
            reader = conn.makefile("rb")
            frames = {}
            while len(frames) < 2:
                header = json.loads(reader.readline())
                frames[header["camera"]] = reader.read(header["height"] * header["width"] * header["channels"])
    assert set(frames) == {"scene_rgb", "wrist_rgb"}
    assert all(len(p) == 24 * 24 * 3 for p in frames.values())
    assert frames["scene_rgb"] != frames["wrist_rgb"], "the wrist view was sent the scene camera's image"


def test_the_camera_feed_example_asks_for_the_wrist_camera_a_model_reads(tmp_path):
    model = two_camera_model(tmp_path)
    done = subprocess.run(
        [sys.executable, str(REPO / "examples" / "camera_feed.py"), "--model", str(model), "--port", "0",
         "--seconds", "1"],
        capture_output=True, text=True, timeout=60,
    )
    assert done.returncode != 0
    assert "--wrist-device" in done.stderr, done.stderr
