"""`python -m vrsync.bench_vector --warmup N`, as `vr-sim bench`'s python-vec rows start it."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

from conftest import write_config

CAM84 = (("left", 84, "rgb8"),)


def run_bench_vector(tmp_path: Path, start_host, tag: str, frames: int, warmup: int) -> float:
    """Runs the batched bench agent against a host of `frames` cycles; returns its SDK µs
    per agent-step."""
    config, _ = write_config(tmp_path, tag, agents=2, cameras=CAM84)
    host = start_host(config, frames)
    out = subprocess.run(
        [sys.executable, "-m", "vrsync.bench_vector", "--config", str(config), "--warmup", str(warmup)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    summary = host.finish()
    assert summary["frames"] == frames and summary["stop_timeouts"] == 0
    lines = out.stdout.split("\n")
    assert lines[1].startswith("sdk_us_per_agent_step "), out.stdout
    assert lines[2].startswith("allocs_per_cycle "), out.stdout
    allocs = float(lines[2].split()[1])
    # Per agent-step: iceoryx2's one per loan (the motor batch), nothing of ours.
    assert math.isnan(allocs) or allocs <= 1.0, out.stdout
    return float(lines[1].split()[1])


def test_bench_vector_measures_the_sdk_time_after_the_warmup_steps_only(
    tmp_path: Path, start_host
) -> None:
    measured = run_bench_vector(tmp_path, start_host, "bvwarm", frames=30, warmup=5)
    assert math.isfinite(measured) and measured > 0
    # A warm-up longer than the run leaves no step measured: nothing to report.
    assert math.isnan(run_bench_vector(tmp_path, start_host, "bvall", frames=30, warmup=1000))
