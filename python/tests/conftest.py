"""Shared fixtures: the repository, the `fairgrasp` binary the suite compares against, and a
trained model."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
# A PPO grasp model trained by `fairgrasp train --config configs/ppo_deploy.toml` (the deploy
# tests' fixture): 100 % held-out success.
TRAINED_MODEL = REPO / "crates" / "deploy" / "tests" / "data" / "deploy_ppo"


def fairgrasp_binary() -> Path:
    """`$FAIRGRASP_BIN`, else the workspace's debug or release build, else `fairgrasp` on PATH."""
    if "FAIRGRASP_BIN" in os.environ:
        return Path(os.environ["FAIRGRASP_BIN"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    for profile in ("debug", "release"):
        candidate = target / profile / "fairgrasp"
        if candidate.is_file():
            return candidate
    found = shutil.which("fairgrasp")
    if found is None:
        raise RuntimeError(
            "no fairgrasp binary: build it (cargo build --bin fairgrasp) or set FAIRGRASP_BIN"
        )
    return Path(found)


@pytest.fixture(scope="session")
def fairgrasp_bin() -> Path:
    return fairgrasp_binary()


@pytest.fixture(scope="session")
def trained_model() -> Path:
    assert (TRAINED_MODEL / "model.json").is_file(), TRAINED_MODEL
    return TRAINED_MODEL


def run_cli(binary: Path, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(binary), *args], cwd=cwd, capture_output=True, text=True, check=True, timeout=600
    )


@pytest.fixture(scope="session")
def camera_model(tmp_path_factory, fairgrasp_bin, trained_model) -> Path:
    """A camera policy distilled from the trained model in a few seconds (24×24 RGB): for the
    plumbing, not for grasping."""
    student = tmp_path_factory.mktemp("camera") / "student"
    settings = ["rounds=2", "steps_per_round=4", "n_envs=2", "batch_size=4", "eval_episodes=1",
                "env.camera.width=24", "env.camera.height=24"]
    args = [a for s in settings for a in ("--set", s)]
    run_cli(fairgrasp_bin, "distill", "--teacher", str(trained_model), "--run-dir", str(student), *args)
    return student
