"""Where the time of a vector-env cycle goes: the `python-vec` case of `vr-sim bench`, longer.

    python bench/vector_budget.py --python A [--python B ...] [--python-stacked C ...]
        [--agents 16] [--cycles 20000] [--rounds 3] [--perf DIR] [--own-host]

Runs the `python-vec` case (N agents, one 84x84 rgb8 camera each, sync mode over shared
memory; the agents in one process through `vrsync.vector.VrsyncVectorEnv` with
`copy_observations=False`, doing `vrsync.bench_vector`'s work: the first and last byte of
every image row, one command, stop) for many more cycles than the bench, served by
`python -m vrsync.bench_host` (the host's loop of the bench in Python) run by the first interpreter
(with `--own-host`, by each interpreter for its own runs). Each `--python` is an interpreter
with its own build of the `vrsync` package (say, before and after a change); they take turns
within each round, so a change of the machine's state hits all alike. Per interpreter and
round it prints, per cycle (µs): the host's round trip (p50), the agent process's step split
into the SDK's Rust code (`AgentGroup.timing`'s SDK time), blocked waiting, the env's Python
code around it, and the row reads; the SDK time per agent-step; and the allocations of the
extension's Rust code per agent-step (if the build counts them). With `--perf DIR` it also
records the agent process with `perf record` over the measured cycles only and prints the
top symbols (the share of the process's samples). A `--python-stacked` interpreter runs the
same case with the host stacking the agents' images (`[transport.shm] stacked_images`), so
that the env views them with no copy; it takes its turn after the `--python` ones.
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


def config_text(session: str, agents: int, stacked: bool = False) -> str:
    head = (
        f'session = "{session}"\n[sync]\nsync_mode = true\nsimulation_time_per_frame = 0.01\n'
        'stop_timeout = 10.0\nconnect_timeout = 60.0\nwait = "block"\n[transport]\n'
        'kind = "shm"\nmax_commands_per_cycle = 8\n'
    )
    if stacked:
        head += "[transport.shm]\nstacked_images = true\n"
    cam = '[[agent.camera]]\nname = "c0"\nwidth = 84\nheight = 84\nformat = "rgb8"\n'
    return head + "".join(f"[[agent]]\nid = {i}\n{cam}" for i in range(agents))


def agent_main(config: str, warmup: int) -> None:
    """The agent process: bench_vector's loop, timed by part."""
    import numpy as np
    import vrsync
    from vrsync import _vrsync
    from vrsync.bench_vector import touch_rows
    from vrsync.vector import VrsyncVectorEnv

    count = getattr(_vrsync, "_allocations", None)
    envs = VrsyncVectorEnv(
        config, None, actions=[vrsync.Turn(angle_deg=1.0)], copy_observations=False,
        step_timeout=60,
    )
    obs, _ = envs.reset()
    actions = np.zeros(envs.num_envs, dtype=np.int64)
    steps, total = 0, 0
    step_ns = touch_ns = 0
    allocs0 = allocs1 = 0
    try:
        while True:
            t0 = time.perf_counter_ns()
            total += sum(touch_rows(a) for k, a in obs.items() if k not in ("position", "rotation"))
            t1 = time.perf_counter_ns()
            obs, *_ = envs.step(actions)
            t2 = time.perf_counter_ns()
            steps += 1
            if steps > warmup:
                touch_ns += t1 - t0
                step_ns += t2 - t1
                allocs1 = count() if count else 0
            if steps == warmup:
                envs.group.reset_timing()
                allocs0 = allocs1 = count() if count else 0
                print("measuring", flush=True)
    except vrsync.HostClosedError:
        pass
    print("done", flush=True)
    calls, sdk_s, wait_s = envs.group.timing
    envs.close()
    n = envs.num_envs
    measured = max(steps - warmup, 1)
    print(json.dumps({
        "steps": measured,
        "sdk_us": sdk_s * 1e6 / max(calls, 1),
        "wait_us": wait_s * 1e6 / max(calls, 1),
        "env_us": step_ns / 1e3 / measured - (sdk_s + wait_s) * 1e6 / max(calls, 1),
        "touch_us": touch_ns / 1e3 / measured,
        "sdk_us_per_agent_step": sdk_s * 1e6 / max(calls * n, 1),
        "allocs_per_agent_step": (allocs1 - allocs0) / (measured * n) if count else None,
        "checksum": total,
    }), flush=True)


PERF_HZ = 4999


def perf_top(data: Path, steps: int, limit: int = 25) -> str:
    """The agent process's CPU time per step by library, then its top symbols."""
    def report(sort: str) -> list[str]:
        out = subprocess.run(
            ["perf", "report", "-i", str(data), "--no-children", "-g", "none", "--sort", sort,
             "--stdio", "--percent-limit", "0.5"],
            capture_output=True, text=True,
        ).stdout
        return out.splitlines()
    lines = report("dso")
    samples = next((int(ln.split()[2].rstrip("K")) * (1000 if "K" in ln.split()[2] else 1)
                    for ln in lines if ln.startswith("# Samples:")), 0)
    cpu_us = samples / PERF_HZ * 1e6 / max(steps, 1)
    text = [f"CPU per step ~{cpu_us:.0f} us ({samples} samples at {PERF_HZ} Hz, {steps} steps):"]
    for ln in lines:
        if ln.strip() and not ln.startswith("#"):
            share = float(ln.split("%")[0])
            text.append(f"  {share * cpu_us / 100:7.1f} us  {ln.strip()}")
    text += [ln for ln in report("dso,sym") if ln.strip() and not ln.startswith("#")][:limit]
    return "\n".join(text)


def start_host(python: str, config: Path, warmup: int, cycles: int, out: Path) -> subprocess.Popen:
    """`python -m vrsync.bench_host` serving `config`, its report to `out`."""
    return subprocess.Popen(
        [python, "-m", "vrsync.bench_host", "--config", str(config), "--warmup",
         str(warmup), "--cycles", str(cycles), "--out", str(out)],
    )


def host_result(tag: str, host: subprocess.Popen, agent: subprocess.Popen | subprocess.CompletedProcess,
                out: Path) -> dict:
    """Exits if the host or the agent failed; else the host's round trip, p50 and mean, µs."""
    if host.returncode != 0 or agent.returncode != 0:
        sys.exit(f"{tag}: host {host.returncode}, agent {agent.returncode}")
    rt = json.loads(out.read_text())["round_trip_ns"]
    return {"cycle_p50_us": statistics.median(rt) / 1e3, "cycle_mean_us": statistics.fmean(rt) / 1e3}


def one(python: str, host_python: str, agents: int, warmup: int, cycles: int,
        perf: Path | None, tag: str, stacked: bool) -> dict:
    with tempfile.TemporaryDirectory() as d:
        session = f"budget-{os.getpid()}-{tag}"
        config = Path(d) / "c.toml"
        config.write_text(config_text(session, agents, stacked))
        out = Path(d) / "host.json"
        host = start_host(host_python, config, warmup, cycles, out)
        agent = subprocess.Popen(
            [python, __file__, "--agent", str(config), "--warmup", str(warmup)],
            stdout=subprocess.PIPE, text=True,
        )
        recorder = None
        result: dict = {}
        assert agent.stdout is not None
        for line in agent.stdout:
            line = line.strip()
            if line == "measuring" and perf is not None:
                recorder = subprocess.Popen(
                    ["perf", "record", "-F", str(PERF_HZ), "-g", "-p", str(agent.pid), "-o",
                     str(perf / f"{tag}.data")],
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                )
            elif line == "done" and recorder is not None:
                recorder.send_signal(2)
                recorder.wait()
            elif line.startswith("{"):
                result = json.loads(line)
        agent.wait()
        host.wait()
        return result | host_result(tag, host, agent, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", action="append", default=[])
    parser.add_argument("--python-stacked", action="append", default=[],
                        help="an interpreter whose runs use a config with stacked images")
    parser.add_argument("--agents", type=int, default=16)
    parser.add_argument("--cycles", type=int, default=20000)
    parser.add_argument("--warmup", type=int, default=500)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--perf", type=Path)
    parser.add_argument("--own-host", action="store_true",
                        help="each interpreter's own bench_host serves its agents (the host's "
                        "side of a build is part of the comparison)")
    parser.add_argument("--agent", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.agent:
        agent_main(args.agent, args.warmup)
        return
    runs = [(p, False) for p in args.python or ([] if args.python_stacked else [sys.executable])]
    runs += [(p, True) for p in args.python_stacked]
    pythons = [p for p, _ in runs]
    if args.perf:
        args.perf.mkdir(parents=True, exist_ok=True)
    steps: dict[int, int] = {}
    keys = ["cycle_p50_us", "cycle_mean_us", "sdk_us", "wait_us", "env_us", "touch_us", "sdk_us_per_agent_step",
            "allocs_per_agent_step"]
    print("python round " + " ".join(keys))
    for r in range(args.rounds):
        for i, (python, stacked) in enumerate(runs):
            tag = f"p{i}-r{r}"
            host_python = python if args.own_host else pythons[0]
            res = one(python, host_python, args.agents, args.warmup, args.cycles,
                      args.perf if r == 0 else None, tag, stacked)
            steps[i] = steps.get(i, res.get("steps", 0)) if r == 0 else steps.get(i, 0)
            vals = " ".join(
                "-" if res.get(k) is None else f"{res[k]:.2f}" for k in keys
            )
            print(f"{i} {r} {vals}", flush=True)
    if args.perf:
        for i, _ in enumerate(pythons):
            data = args.perf / f"p{i}-r0.data"
            if data.exists():
                print(f"--- perf, python {i} (agent process, measured cycles) ---")
                print(perf_top(data, steps.get(i, 0)))


if __name__ == "__main__":
    main()
