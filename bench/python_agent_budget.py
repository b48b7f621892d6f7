"""Where the time of the single Python agent's cycle goes: the `python` case of `vr-sim bench`, longer.

    python bench/python_agent_budget.py [--python PY] [--size 320x240 --size 1920x1080]
        [--cycles 3000] [--warmup 300] [--rounds 3] [--spin-us 50 --spin-us 200]

Runs the `python` case (1 agent, 3 rgb8 cameras of each `--size`, sync mode over shared
memory, the bench config's `wait = "block"`) served by `python -m vrsync.bench_host` (the
bench host's loop in Python), with the agent doing `vrsync.bench_agent`'s work (its
`touch_rows` on every image, one command, stop) and timing each part of its cycle. The
sizes take turns within each round. Per size and round it prints, µs: the host's round
trip (p50 and mean), and the agent's parts (medians): the wait for the frame (`next` of
`Agent.frames`: the SDK's receive, and polling or sleeping until the host's start), the
three numpy views (`frame.images`), the row reads (`touch_rows`), `send` + `stop`.
Each `--spin-us` runs every size once more per round with that `[sync]
spin_before_block_us` (how long host and agent poll before they sleep at least; default
50; each side's window grows to twice its recent waits' mean, up to 500 µs): the cycle's
sensitivity to the agent's time crossing the host's polling window.
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

from vector_budget import host_result, start_host


def config_text(session: str, width: int, height: int, spin_us: int | None) -> str:
    spin = "" if spin_us is None else f"spin_before_block_us = {spin_us}\n"
    head = (
        f'session = "{session}"\n[sync]\nsync_mode = true\nsimulation_time_per_frame = 0.01\n'
        f'stop_timeout = 10.0\nconnect_timeout = 60.0\nwait = "block"\n{spin}[transport]\n'
        'kind = "shm"\nmax_commands_per_cycle = 8\n[[agent]]\nid = 0\n'
    )
    cam = '[[agent.camera]]\nname = "c{}"\nwidth = {}\nheight = {}\nformat = "rgb8"\n'
    return head + "".join(cam.format(c, width, height) for c in range(3))


def agent_main(config: str, warmup: int) -> None:
    """The agent process: bench_agent's loop, timed by part."""
    import vrsync
    from vrsync.bench_agent import touch_rows

    parts: dict[str, list[int]] = {"wait": [], "views": [], "reads": [], "send_stop": []}
    total = steps = 0
    with vrsync.Agent.connect(config, 0) as agent:
        turn = vrsync.Turn(angle_deg=1.0)
        frames = agent.frames(timeout=60)
        try:
            while True:
                t0 = time.perf_counter_ns()
                frame = next(frames)
                t1 = time.perf_counter_ns()
                images = frame.images
                t2 = time.perf_counter_ns()
                total += sum(touch_rows(img) for img in images.values())
                t3 = time.perf_counter_ns()
                del images, frame  # release the sample before the next wait
                agent.send(turn)
                agent.stop()
                t4 = time.perf_counter_ns()
                steps += 1
                if steps > warmup:
                    for key, ns in zip(parts, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                        parts[key].append(ns)
        except (StopIteration, vrsync.HostClosedError):
            pass  # the session ended
    result = {k: statistics.median(v) / 1e3 if v else None for k, v in parts.items()}
    result["checksum"] = total
    print(json.dumps(result), flush=True)


def one(
    python: str, width: int, height: int, spin_us: int | None, warmup: int, cycles: int, tag: str
) -> dict:
    with tempfile.TemporaryDirectory() as d:
        config = Path(d) / "c.toml"
        session = f"agent-budget-{os.getpid()}-{tag}"
        config.write_text(config_text(session, width, height, spin_us))
        out = Path(d) / "host.json"
        host = start_host(python, config, warmup, cycles, out)
        agent = subprocess.run(
            [python, __file__, "--agent", str(config), "--warmup", str(warmup)],
            stdout=subprocess.PIPE, text=True, timeout=600,
        )
        host.wait(timeout=600)
        result = host_result(tag, host, agent, out)
        return json.loads(agent.stdout.strip().splitlines()[-1]) | result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", default=sys.executable)
    parser.add_argument("--size", action="append", default=[])
    parser.add_argument("--cycles", type=int, default=3000)
    parser.add_argument("--warmup", type=int, default=300)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--spin-us", type=int, action="append", default=[])
    parser.add_argument("--agent", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.agent:
        agent_main(args.agent, args.warmup)
        return
    sizes = [tuple(int(x) for x in s.split("x")) for s in args.size or ["320x240", "1920x1080"]]
    keys = ["cycle_p50_us", "cycle_mean_us", "wait", "views", "reads", "send_stop"]
    spins: list[int | None] = args.spin_us or [None]
    print("size spin_us round " + " ".join(keys))
    for r in range(args.rounds):
        for spin in spins:
            for w, h in sizes:
                res = one(args.python, w, h, spin, args.warmup, args.cycles, f"{w}-{spin}-{r}")
                vals = " ".join("-" if res.get(k) is None else f"{res[k]:.1f}" for k in keys)
                label = "default" if spin is None else spin
                print(f"3x{w}x{h} {label} {r} {vals}", flush=True)


if __name__ == "__main__":
    main()
