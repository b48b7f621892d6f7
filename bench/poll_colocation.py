"""One agent's cycle with host and agent on one CPU, on two, or where the kernel puts them.

    python bench/poll_colocation.py --python A:BIN_A [--python B:BIN_B ...]
        [--place same --place split --place free] [--size 320x240] [--rounds 2]
        [--cycles 4000] [--agent rust|python]

The `shm` case of `vr-sim bench` at 1 agent (3 rgb8 cameras of `--size`, sync mode over
shared memory, `wait = "block"` with the default `spin_before_block_us`): the host is
`python -m vrsync.bench_host` of interpreter A, the agent `vr-bench-agent --mode sdk` from
folder BIN_A (the same tree's build: the protocol versions must match). Both start
unpinned, so each reads the machine's two CPUs and polls before it sleeps; during the
host's warm-up both are then moved (every thread, `sched_setaffinity`) to CPU 0 (`same`),
the host to CPU 0 and the agent to CPU 1 (`split`), left where they are (`free`), or put on
CPU 0 together for `UNPIN_AFTER_S` and then let run anywhere again (`joined`: whether the
pair leaves a shared CPU on its own). The
host's round trips of the measured cycles are printed: p50, mean and p90, µs.

`same` is what a kernel's wake-up placement can do on its own: the host's *start* and the
agent's *stop* wake a sleeping process, and a kernel may run it on the waker's CPU while
the other CPU is idle. The `--python` builds take turns within each round. With `--agent
python` the agent is `python -m vrsync.bench_agent` of the same interpreter (the `python`
case of `vr-sim bench`: numpy's row reads instead of the Rust agent's).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from host_own_time import python_builds

# Warm-up cycles: enough to outlast the move of the processes (`PIN_AFTER_S`) at a few µs
# per cycle; measured cycles begin after it.
WARMUP = 300_000
PIN_AFTER_S = 1.0
# `joined`: how long host and agent share CPU 0 before both may run anywhere again.
UNPIN_AFTER_S = 0.5


def config_text(session: str, width: int, height: int) -> str:
    cam = '[[agent.camera]]\nname = "c{}"\nwidth = {}\nheight = {}\nformat = "rgb8"\n'
    return (
        f'session = "{session}"\n[sync]\nsync_mode = true\nsimulation_time_per_frame = 0.01\n'
        'stop_timeout = 10.0\nconnect_timeout = 60.0\nwait = "block"\n[transport]\n'
        'kind = "shm"\nmax_commands_per_cycle = 8\n[[agent]]\nid = 0\n'
        + "".join(cam.format(c, width, height) for c in range(3))
    )


def pin(pid: int, cpus: set[int]) -> None:
    """Lets every thread of process `pid` run on `cpus` only."""
    for task in os.listdir(f"/proc/{pid}/task"):
        try:
            os.sched_setaffinity(int(task), cpus)
        except ProcessLookupError:
            pass  # a thread that ended meanwhile


def one(
    python: str, bindir: str, place: str, width: int, height: int, cycles: int, kind: str
) -> dict:
    with tempfile.TemporaryDirectory() as d:
        session = f"coloc-{os.getpid()}-{time.monotonic_ns()}"
        config = Path(d) / "c.toml"
        config.write_text(config_text(session, width, height))
        out = Path(d) / "host.json"
        host = subprocess.Popen(
            [python, "-m", "vrsync.bench_host", "--config", str(config), "--warmup",
             str(WARMUP), "--cycles", str(cycles), "--out", str(out)],
        )
        if kind == "python":
            command = [python, "-m", "vrsync.bench_agent", "--config", str(config), "--id", "0"]
        else:
            command = [f"{bindir}/vr-bench-agent", "--mode", "sdk", "--id", "0", "--config",
                       str(config), "--warmup", "100"]
        agent = subprocess.Popen(command, stdout=subprocess.DEVNULL)
        try:
            time.sleep(PIN_AFTER_S)
            if place == "same":
                pin(host.pid, {0})
                pin(agent.pid, {0})
            elif place == "split":
                pin(host.pid, {0})
                pin(agent.pid, {1})
            elif place == "joined":
                pin(host.pid, {0})
                pin(agent.pid, {0})
                time.sleep(UNPIN_AFTER_S)
                every = set(range(os.cpu_count() or 1))
                pin(host.pid, every)
                pin(agent.pid, every)
            host.wait(timeout=600)
            agent.wait(timeout=60)
        finally:
            for p in (host, agent):
                if p.poll() is None:
                    p.kill()
                    p.wait()
        if host.returncode != 0 or agent.returncode != 0:
            sys.exit(f"{place}: host {host.returncode}, agent {agent.returncode}")
        rt = sorted(json.loads(out.read_text())["round_trip_ns"])
    return {
        "p50": statistics.median(rt) / 1e3,
        "mean": statistics.fmean(rt) / 1e3,
        "p90": rt[int(len(rt) * 0.9)] / 1e3,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", action="append", required=True,
                        help="INTERPRETER:BIN (vrsync installed; BIN holds vr-bench-agent)")
    parser.add_argument("--place", action="append", choices=["same", "split", "free", "joined"])
    parser.add_argument("--size", default="320x240", help="WxH of each of 3 cameras")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--cycles", type=int, default=4000, help="measured cycles per run")
    parser.add_argument("--agent", choices=["rust", "python"], default="rust",
                        help="the bench agent: vr-bench-agent, or vrsync.bench_agent")
    args = parser.parse_args()
    if (os.cpu_count() or 1) < 2:
        sys.exit("needs 2 CPUs")
    width, height = (int(v) for v in args.size.split("x"))
    builds = python_builds(parser, args.python, "vr-bench-agent")
    for r in range(args.rounds):
        for place in args.place or ["same", "split", "free"]:
            for python, bindir in builds:
                m = one(python, bindir, place, width, height, args.cycles, args.agent)
                print(f"round {r} {place:5s} {args.size} {args.agent} {python}: p50 {m['p50']:.1f} "
                      f"mean {m['mean']:.1f} p90 {m['p90']:.1f} µs", flush=True)


if __name__ == "__main__":
    main()
