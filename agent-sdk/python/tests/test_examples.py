"""Every example in agent-sdk/python/examples runs end to end against a real host."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import TRANSPORTS, write_config

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
ALL = sorted(p.name for p in EXAMPLES.glob("*.py"))


def one_thread() -> dict[str, str]:
    """The environment of an example: the host and the example share two cores in CI, so
    torch gets one thread. Built at the call, not at import: it carries what the test's
    fixtures set (`SB3_LOGDIR` in the test's tmp_path, see conftest)."""
    return {**os.environ, "OMP_NUM_THREADS": "1"}


def run_example(name: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=one_thread(),
    )


def test_every_example_has_a_test() -> None:
    assert ALL == [
        "gym_random.py",
        "mujoco_host.py",  # test_mujoco_cli.py
        "pettingzoo_loop.py",
        "python_host.py",  # test_python_host.py
        "seek.py",
        "train_mujoco_ppo.py",
        "train_ppo.py",
        "vector_loop.py",
    ]


def test_seek_finds_the_red_object(tmp_path: Path, start_host) -> None:
    cams = (("left", 128, "rgb8"), ("right", 128, "rgb8"))
    config, _ = write_config(tmp_path, "seek", cameras=cams)
    host = start_host(config)
    out = run_example("seek.py", "--config", str(config), "--cycles", "200")
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.split()[0] == "reached"
    host.kill()


def test_gym_random(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "gymex")
    host = start_host(config)
    out = run_example("gym_random.py", "--config", str(config), "--steps", "120")
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.startswith("steps 120 reward ")
    host.kill()


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_pettingzoo_loop(tmp_path: Path, start_host, transport: str) -> None:
    config, _ = write_config(tmp_path, "pzex", agents=2, transport=transport)
    host = start_host(config)
    out = run_example("pettingzoo_loop.py", "--config", str(config), "--cycles", "60")
    assert out.returncode == 0, out.stdout + out.stderr
    assert out.stdout.strip() == "agents 2 steps 60"
    host.kill()


def test_vector_loop(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "vecex", agents=4, cameras=(("left", 84, "rgb8"),))
    host = start_host(config)
    out = run_example("vector_loop.py", "--config", str(config), "--steps", "100", "--camera", "left")
    assert out.returncode == 0, out.stdout + out.stderr
    words = out.stdout.split()
    assert words[:4] == ["agents", "4", "steps", "100"], out.stdout
    assert float(words[5]) > 0 and float(words[7]) > 0
    host.kill()


def test_train_ppo(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "ppoex", agents=2, cameras=(("left", 84, "rgb8", 84),))
    host = start_host(config)
    model = tmp_path / "ppo.zip"
    out = run_example(
        "train_ppo.py", "--config", str(config), "--camera", "left", "--steps", "512",
        "--n-steps", "64", "--episode", "50", "--save", str(model), timeout=300,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    words = out.stdout.split()
    assert words[:4] == ["agents", "2", "steps", "512"], out.stdout
    assert words[4] == "mean-episode-reward" and words[6] == "agent-steps/s", out.stdout
    assert model.stat().st_size > 0
    host.kill()


@pytest.mark.parametrize("observe", [None, "position,rotation,gyro"])
def test_train_mujoco_ppo(tmp_path: Path, observe: str | None) -> None:
    """The MuJoCo PPO example trains a few updates against its own host process (the
    session is the example's own: ppo-<pid>) and saves the policy; episodes of 40 steps
    end (and reset) within them; with all observations (the camera too) or some."""
    pytest.importorskip("mujoco")
    pytest.importorskip("stable_baselines3")
    model = tmp_path / "rovers.zip"
    extra = ["--observe", observe] if observe else []
    out = run_example(
        "train_mujoco_ppo.py", "--agents", "2", "--timesteps", "256", "--n-steps", "64",
        "--episode-steps", "40", "--save", str(model), *extra, timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stdout + out.stderr
    lines = out.stdout.strip().splitlines()
    assert [line.split()[:2] for line in lines[:2]] == [["rollout", "1"], ["rollout", "2"]], out.stdout
    assert lines[-1].split()[:2] == ["rollouts", "2"], out.stdout
    assert model.stat().st_size > 0
