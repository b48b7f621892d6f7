"""`python -m vrsync.bench_numpy`: numpy's row reads alone, `vr-sim bench`'s floor-numpy rows."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path


def test_bench_numpy_times_the_bench_agents_reads_of_each_measured_cycle(tmp_path: Path) -> None:
    out = tmp_path / "numpy.json"
    run = subprocess.run(
        [
            sys.executable, "-m", "vrsync.bench_numpy", "--width", "32", "--height", "24",
            "--cameras", "2", "--frames", "3", "--warmup", "2", "--cycles", "5",
            "--out", str(out),
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    report = json.loads(out.read_text())
    assert report["cycles"] == 5
    assert len(report["read_ns"]) == 5 and all(ns > 0 for ns in report["read_ns"])
    # Every byte is 1 but the first of each image, marked with the cycle number (& 0xFF):
    # per image, 24 rows x (first + last byte) = 47 + the mark, over 7 cycles of 2 images.
    marks = sum(c & 0xFF for c in range(7)) * 2
    assert run.stdout.split() == ["checksum", str(7 * 2 * 47 + marks)], run.stdout
    # Nothing left in /dev/shm: the file was never named there (an unlinked temp file).
    assert not any(p.name.startswith("vrsync-bench-numpy-") for p in Path("/dev/shm").iterdir())
