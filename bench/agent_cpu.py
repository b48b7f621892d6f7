"""CPU time per cycle of the Python bench agent against the Rust one, on one machine.

    python bench/agent_cpu.py [--bin-dir target/release] [--python PYTHON]

Runs `vr-sim run` hosts (3 rgb8 cameras, sync mode) with one agent — `vr-bench-agent`
(Rust SDK) or `python -m vrsync.bench_agent` (Python SDK, the same work: first and last
byte of every image row, one command, stop) — for a short and a long run, and reports the
agent's CPU time per cycle as (CPU(long) − CPU(short)) / (cycles(long) − cycles(short)),
which cancels start-up and connect. CPU time, unlike wall time, hardly depends on what else
the machine runs, so this is the per-cycle overhead of the Python agent.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def config_text(session: str, width: int, height: int) -> str:
    cams = "".join(
        f'[[agent.camera]]\nname = "c{c}"\nwidth = {width}\nheight = {height}\nformat = "rgb8"\n'
        for c in range(3)
    )
    return (
        f'session = "{session}"\n[sync]\nsync_mode = true\nsimulation_time_per_frame = 0.01\n'
        'stop_timeout = 30.0\nconnect_timeout = 60.0\n[transport]\nkind = "shm"\n'
        f"[[agent]]\nid = 0\n{cams}"
    )


def agent_cpu(bin_dir: Path, python: str, kind: str, width: int, height: int, frames: int) -> float:
    """CPU seconds (user + system) of one agent process over a run of `frames` cycles."""
    with tempfile.TemporaryDirectory() as d:
        session = f"agentcpu-{os.getpid()}-{kind}-{width}-{frames}"
        config = Path(d) / "c.toml"
        config.write_text(config_text(session, width, height))
        host = subprocess.Popen(
            [str(bin_dir / "vr-sim"), "run", "--config", str(config), "--frames", str(frames),
             "--quiet", "--render-threads", "1"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        if kind == "rust":
            cmd = [str(bin_dir / "vr-bench-agent"), "--config", str(config), "--id", "0"]
        else:
            cmd = [python, "-m", "vrsync.bench_agent", "--config", str(config), "--id", "0"]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        agent = subprocess.run(cmd, stdout=subprocess.DEVNULL, timeout=1800)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        host.wait(timeout=60)
        if agent.returncode != 0 or host.returncode != 0:
            sys.exit(f"{kind} {width}x{height}: agent {agent.returncode}, host {host.returncode}")
        return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--bin-dir", type=Path, default=ROOT / "target" / "release")
    p.add_argument("--python", default=sys.executable)
    p.add_argument("--short", type=int, default=100)
    p.add_argument("--long", type=int, default=600)
    args = p.parse_args()
    print(f"agent CPU µs per cycle ({args.long} − {args.short} cycles, 3 rgb8 images, shm)")
    results: dict[tuple[str, int], float] = {}
    for width, height in ((320, 240), (1920, 1080)):
        for kind in ("rust", "python"):
            t0 = time.monotonic()
            short = agent_cpu(args.bin_dir, args.python, kind, width, height, args.short)
            long = agent_cpu(args.bin_dir, args.python, kind, width, height, args.long)
            us = (long - short) / (args.long - args.short) * 1e6
            results[(kind, width)] = us
            print(f"  {kind:<7} 3x{width}x{height}: {us:8.1f} µs/cycle  ({time.monotonic() - t0:.0f} s)")
    for width in (320, 1920):
        py, rust = results[("python", width)], results[("rust", width)]
        print(f"  python − rust at width {width}: {py - rust:.1f} µs/cycle (python/rust {py / rust:.1f}×)")


if __name__ == "__main__":
    main()
