"""`python -m vrsync.bench_host`: the Python host of `vr-sim bench`'s `python-host` rows.

Its bookkeeping against a stand-in host, then the real thing: the module serving the Rust
`vr-bench-agent` processes `vr-sim bench` gives it. Every wait has a deadline; every
process a test starts is killed at its end.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import vrsync
from vrsync import bench_host

from conftest import binary, write_config

DEADLINE = 120.0


def test_result_reports_the_own_time_per_agent_cycle_in_us() -> None:
    r = bench_host.result(
        4, 2, [100_000, 300_000, 200_000], [8_000, 12_000, 10_000], [4_000, 6_000, 8_000]
    )
    assert (r["agents"], r["warmup"], r["cycles"]) == (4, 2, 3)
    assert r["round_trip_ns"] == [100_000, 300_000, 200_000]
    # 10 µs per cycle (mean and median) of wall time over 4 agents.
    assert r["host_us_per_agent_cycle"] == pytest.approx(2.5)
    assert r["host_us_per_agent_cycle_p50"] == pytest.approx(2.5)
    # 6 µs of CPU time per cycle (mean and median) over 4 agents.
    assert r["own_cpu_ns"] == [4_000, 6_000, 8_000]
    assert r["host_cpu_us_per_agent_cycle"] == pytest.approx(1.5)
    assert r["host_cpu_us_per_agent_cycle_p50"] == pytest.approx(1.5)
    # Nothing measured: JSON null, not NaN (which is not JSON).
    empty = bench_host.result(4, 0, [], [], [])
    assert empty["host_us_per_agent_cycle"] is None
    assert empty["host_cpu_us_per_agent_cycle"] is None
    json.loads(json.dumps(empty, allow_nan=False))


class _Report:
    def __init__(self, timed_out: bool) -> None:
        self.timed_out = timed_out


class _Frame:
    def __init__(self, agent: int) -> None:
        self.agent = agent
        self.pixels = np.zeros((3, 4, 3), np.uint8)
        self.views: list[Any] = []

    def image(self, name: str) -> np.ndarray:
        assert name == "c0"
        view = self.pixels[:]
        self.views.append(view)
        return view


class _StandIn:
    """The part of `vrsync.Host` that `measure` uses; records the calls, refuses a
    publish while a view of the frame is alive (as the real host does)."""

    agent_ids = [0, 1]

    def __init__(self, time_out_at: int | None = None) -> None:
        self.calls: list[str] = []
        self.marks: list[int] = []
        self.cycle = 0
        self.time_out_at = time_out_at

    def cameras(self, agent_id: int) -> list[Any]:
        return [type("Camera", (), {"name": "c0"})()]

    def loan(self, agent_id: int) -> _Frame:
        self.calls.append(f"loan {agent_id}")
        return _Frame(agent_id)

    def publish(self, frame: _Frame) -> None:
        alive = [v for v in frame.views if sys.getrefcount(v) > 3]
        assert not alive, "published with a view alive"
        self.marks.append(int(frame.pixels[0, 0, 0]))
        self.calls.append(f"publish {frame.agent}")

    def start(self) -> None:
        self.calls.append("start")

    def collect(self) -> _Report:
        self.calls.append("collect")
        self.cycle += 1
        return _Report(self.cycle - 1 == self.time_out_at)


def test_measure_does_the_rust_hosts_work_per_cycle_and_times_the_measured_ones() -> None:
    host = _StandIn()
    round_trips, own, own_cpu = bench_host.measure(host, warmup=2, cycles=3)
    assert len(round_trips) == len(own) == len(own_cpu) == 3
    assert all(0 < o <= t for o, t in zip(own, round_trips, strict=True))
    assert all(c > 0 for c in own_cpu)
    one_cycle = ["loan 0", "publish 0", "loan 1", "publish 1", "start", "collect"]
    assert host.calls == one_cycle * 5
    # The first byte of each image carries the cycle number.
    assert host.marks == [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    with pytest.raises(RuntimeError, match="cycle 1 timed out"):
        bench_host.measure(_StandIn(time_out_at=1), warmup=0, cycles=3)


def test_bench_host_serves_the_rust_bench_agents(tmp_path: Path) -> None:
    """What `vr-sim bench` does for a `python-host` row, at 4 agents of one 84x84 camera."""
    if not hasattr(vrsync, "Host"):
        pytest.skip("this vrsync build has no vrsync.Host (the Python host API)")
    agent = binary("vr-bench-agent")
    config, _ = write_config(tmp_path, "bhost", agents=4, cameras=(("c0", 84, "rgb8", 84),))
    out = tmp_path / "host.json"
    procs = [
        subprocess.Popen(
            [
                sys.executable, "-m", "vrsync.bench_host", "--config", str(config),
                "--warmup", "3", "--cycles", "25", "--out", str(out), "--timeout", "60",
            ],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )
    ]  # fmt: skip
    try:
        for i in range(4):
            procs.append(
                subprocess.Popen(
                    [
                        str(agent), "--mode", "sdk", "--config", str(config), "--id", str(i),
                        "--warmup", "3",
                    ],
                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                )
            )  # fmt: skip
        outputs = [p.communicate(timeout=DEADLINE) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)
    codes = [p.returncode for p in procs]
    assert codes == [0] * 5, f"{codes}: {[err for _, err in outputs]}"
    r = json.loads(out.read_text())
    assert (r["agents"], r["warmup"], r["cycles"]) == (4, 3, 25)
    assert len(r["round_trip_ns"]) == len(r["own_ns"]) == 25
    assert all(0 < o <= t for o, t in zip(r["own_ns"], r["round_trip_ns"], strict=True))
    assert r["host_us_per_agent_cycle"] > 0
    assert len(r["own_cpu_ns"]) == 25 and all(c > 0 for c in r["own_cpu_ns"])
    assert r["host_cpu_us_per_agent_cycle"] > 0
    # Every agent took part to the end and reported its figures.
    for stdout, _ in outputs[1:]:
        assert "allocs_per_cycle" in stdout


def test_bench_host_exits_1_when_the_agents_do_not_come(tmp_path: Path) -> None:
    if not hasattr(vrsync, "Host"):
        pytest.skip("this vrsync build has no vrsync.Host (the Python host API)")
    config, _ = write_config(tmp_path, "bhost-none", agents=1, cameras=(("c0", 84, "rgb8", 84),))
    out = tmp_path / "host.json"
    r = subprocess.run(
        [
            sys.executable, "-m", "vrsync.bench_host", "--config", str(config),
            "--cycles", "5", "--out", str(out), "--timeout", "0.5",
        ],
        capture_output=True, text=True, timeout=DEADLINE,
    )  # fmt: skip
    assert r.returncode == 1, r.stderr
    assert "error:" in r.stderr and not out.exists()
