"""A Python host's own time per agent-cycle, wall and CPU, with `start()` apart.

    python bench/host_own_time.py --python A:BIN_A [--python B:BIN_B ...] [--agents 16]
        [--cycles 3000] [--rounds 2]

Serves N `vr-agent --policy idle` processes (from folder BIN) over shared memory, sync
mode, one 84x84 rgb8 camera each, through `vrsync.Host` in the interpreter A (with its
own build of the `vrsync` package), doing the loop of `vrsync.bench_host`: per agent
`host.loan(id)`, one byte written through a numpy view of its image, `host.publish`; then
`host.start()` and `host.collect()`. Per measured cycle (after 200 warm-up cycles) it
times the part outside `collect()` — the host's own work — as wall time
(`time.perf_counter_ns`) and as the host thread's CPU time (`time.thread_time_ns`: not
the time other processes took the core meanwhile), with `start()` (the wake-up of every
agent) apart. It prints the medians per agent-cycle. Each `--python` pairs an interpreter
with the folder of the `vr-agent` built from the same tree (say, before and after a
change: the protocol versions must match); they take turns within each round, so a
change of the machine's state hits all alike.

`vr-sim bench`'s `python-host` rows report both too (the ratio lines `python-host own CPU
µs per agent-cycle` and `… own wall …`), with `vr-bench-agent` processes that touch every
image row: on 2 cores those agents, woken by `start()`, take the cores before it returns,
and their work lands in the host's wall time. This script's idle agents and its split of
`start()` separate the host's own cost further.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

# The measuring loop, run by each interpreter (it imports its own `vrsync`).
CHILD = r"""
import statistics, subprocess, sys, time
import vrsync

cfg, n, cycles, bindir = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
WARMUP = 200
with vrsync.Host(cfg) as host:
    procs = [
        subprocess.Popen(
            [f"{bindir}/vr-agent", "--config", cfg, "--id", str(i), "--policy", "idle"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
        for i in range(n)
    ]
    try:
        host.wait_for_agents(60)
        ids = list(host.agent_ids)
        cams = {i: [c.name for c in host.cameras(i)] for i in ids}
        wall, cpu, start_wall, start_cpu = [], [], [], []
        clock, tclock = time.perf_counter_ns, time.thread_time_ns
        for cycle in range(WARMUP + cycles):
            w0, c0 = clock(), tclock()
            for i in ids:
                frame = host.loan(i)
                for name in cams[i]:
                    frame.image(name).reshape(-1)[0] = cycle & 0xFF
                host.publish(frame)
            w1, c1 = clock(), tclock()
            host.start()
            w2, c2 = clock(), tclock()
            report = host.collect()
            if report.timed_out:
                sys.exit(f"cycle {cycle}: agents timed out: {report.timed_out}")
            if cycle >= WARMUP:
                wall.append(w2 - w0)
                cpu.append(c2 - c0)
                start_wall.append(w2 - w1)
                start_cpu.append(c2 - c1)
    finally:
        host.close()
        for p in procs:
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
per = lambda xs: statistics.median(xs) / n / 1000
print(f"{per(wall):.2f} {per(start_wall):.2f} {per(cpu):.2f} {per(start_cpu):.2f}")
"""


def config_text(session: str, agents: int) -> str:
    """A sync-mode shm session of `agents` agents with one 84x84 rgb8 camera each."""
    text = (
        f'session = "{session}"\n[sync]\nsync_mode = true\nstop_timeout = 5.0\n'
        'connect_timeout = 60.0\n[transport]\nkind = "shm"\n'
    )
    for i in range(agents):
        text += (
            f'[[agent]]\nid = {i}\n[[agent.camera]]\nname = "eye"\nwidth = 84\n'
            'height = 84\nformat = "rgb8"\n'
        )
    return text


def python_builds(ap: argparse.ArgumentParser, specs: list[str], program: str) -> list[tuple[str, str]]:
    """The `--python PYTHON:BIN_DIR` pairs, each BIN_DIR checked for `program` (else a usage error)."""
    pairs = []
    for spec in specs:
        python, sep, bindir = spec.partition(":")
        if not sep or not Path(bindir, program).is_file():
            ap.error(f"--python {spec!r}: expected PYTHON:BIN_DIR with BIN_DIR/{program}")
        pairs.append((python, bindir))
    return pairs


def main() -> int:
    """Runs the rounds and prints one line per interpreter and round."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--python",
        action="append",
        required=True,
        metavar="PYTHON:BIN_DIR",
        help="an interpreter with vrsync installed, and the folder of its vr-agent",
    )
    ap.add_argument("--agents", type=int, default=16)
    ap.add_argument("--cycles", type=int, default=3000)
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    pairs = python_builds(ap, args.python, "vr-agent")
    print(
        f"{args.agents} agents, {args.cycles} cycles; µs per agent-cycle outside collect(): "
        "wall (start) / thread CPU (start)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        for rnd in range(args.rounds):
            for k, (python, bindir) in enumerate(pairs):
                session = f"hostown{os.getpid()}r{rnd}k{k}"
                cfg = Path(tmp, f"{session}.toml")
                cfg.write_text(config_text(session, args.agents))
                out = subprocess.run(
                    [python, "-c", CHILD, str(cfg), str(args.agents), str(args.cycles), bindir],
                    capture_output=True,
                    text=True,
                    timeout=600,
                )
                if out.returncode != 0:
                    print(f"{python}: failed: {out.stderr.strip()[-500:]}", file=sys.stderr)
                    return 1
                wall, start_wall, cpu, start_cpu = out.stdout.split()
                print(
                    f"round {rnd} {python}: wall {wall} (start {start_wall}) / "
                    f"CPU {cpu} (start {start_cpu})"
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
