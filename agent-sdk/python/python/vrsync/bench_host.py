"""The Python benchmark host that ``vr-sim bench`` starts for its ``python-host`` rows.

    python -m vrsync.bench_host --config FILE --warmup W --cycles C --out FILE.json
        [--session NAME] [--timeout S]

Serves the config's agents through :class:`vrsync.Host` and does, per cycle, the work of
``vr-sim bench``'s Rust host loop: for each agent, loan its frame, mark the first byte of
each image with the cycle number (the frame is already in shared memory; nothing is
copied), publish; then ``start`` and ``collect``. It waits up to ``--timeout`` seconds
(default 60) for every agent to connect, runs ``W`` warm-up cycles and ``C`` measured
ones, closes the session (the agents leave) and writes ``--out``, a JSON object:

``agents``, ``warmup``, ``cycles``
    as run;
``round_trip_ns``
    each measured cycle's time from the first loan to the end of ``collect`` (what the
    Rust host's rows measure), ns;
``own_ns``
    each measured cycle's wall time outside ``collect``: loans, marks, publishes,
    ``start``, the check of the report, ns;
``own_cpu_ns``
    the host thread's CPU time in the same parts of each measured cycle
    (``time.thread_time_ns``), ns: the Python host's own cost. The wall time also holds
    whatever ran on the core meanwhile: with more agents than cores, the agents that
    ``start`` wakes take the cores before it returns;
``host_us_per_agent_cycle``, ``host_cpu_us_per_agent_cycle``
    the mean of ``own_ns`` / ``own_cpu_ns`` divided by the agent count, µs (the target,
    DESIGN §9: at most 5 of the host's own CPU time; ``null`` if no cycle was measured);
``host_us_per_agent_cycle_p50``, ``host_cpu_us_per_agent_cycle_p50``
    the same from the medians.

Exits 1 (saying why) if a cycle times out or an agent is missing.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import vrsync

__all__ = ["main", "measure", "result"]


def measure(host: Any, warmup: int, cycles: int) -> tuple[list[int], list[int], list[int]]:
    """Runs ``warmup`` + ``cycles`` cycles on ``host`` (every agent connected) and returns
    the measured cycles' round trips, own wall times and own CPU times (outside
    ``collect``), ns.

    Raises:
        RuntimeError: a cycle timed out.
    """
    ids = list(host.agent_ids)
    # Camera names looked up once, as a simulator knows its cameras.
    cameras = {i: [c.name for c in host.cameras(i)] for i in ids}
    loan, publish, start, collect = host.loan, host.publish, host.start, host.collect
    clock, cpu = time.perf_counter_ns, time.thread_time_ns
    round_trips: list[int] = []
    own: list[int] = []
    own_cpu: list[int] = []
    for cycle in range(warmup + cycles):
        mark = cycle & 0xFF
        c0 = cpu()
        t0 = clock()
        for i in ids:
            frame = loan(i)
            for name in cameras[i]:
                # One write through a view of the frame; the view is gone before publish.
                frame.image(name).reshape(-1)[0] = mark
            publish(frame)
        start()
        t1 = clock()
        c1 = cpu()
        report = collect()
        c2 = cpu()
        t2 = clock()
        if report.timed_out:
            raise RuntimeError(f"cycle {cycle} timed out (agents {ids})")
        t3 = clock()
        c3 = cpu()
        if cycle >= warmup:
            round_trips.append(t3 - t0)
            own.append((t1 - t0) + (t3 - t2))
            own_cpu.append((c1 - c0) + (c3 - c2))
    return round_trips, own, own_cpu


def result(
    agents: int,
    warmup: int,
    round_trips: list[int],
    own: list[int],
    own_cpu: list[int] | None = None,
) -> dict[str, Any]:
    """The ``--out`` object of a run (see the module doc)."""
    n = max(agents, 1)
    cpu = own_cpu if own_cpu is not None else []

    def per_agent(values: list[int], stat: Any) -> float | None:
        # null, not NaN (which JSON has no word for), when nothing was measured.
        return stat(values) / n / 1000.0 if values else None

    return {
        "agents": agents,
        "warmup": warmup,
        "cycles": len(round_trips),
        "round_trip_ns": round_trips,
        "own_ns": own,
        "own_cpu_ns": cpu,
        "host_us_per_agent_cycle": per_agent(own, statistics.fmean),
        "host_us_per_agent_cycle_p50": per_agent(own, statistics.median),
        "host_cpu_us_per_agent_cycle": per_agent(cpu, statistics.fmean),
        "host_cpu_us_per_agent_cycle_p50": per_agent(cpu, statistics.median),
    }


def main(argv: list[str] | None = None) -> int:
    """The command line; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog="python -m vrsync.bench_host", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--config", required=True, type=Path)
    parser.add_argument("--session", help="session name (default: the config's)")
    parser.add_argument("--warmup", type=int, default=20, help="unmeasured cycles first (20)")
    parser.add_argument("--cycles", type=int, default=1000, help="measured cycles (1000)")
    parser.add_argument("--out", required=True, type=Path, help="the JSON result")
    parser.add_argument(
        "--timeout", type=float, default=60.0, help="seconds to wait for the agents (60)"
    )
    args = parser.parse_args(argv)
    if args.warmup < 0 or args.cycles < 1:
        parser.error("--warmup must be >= 0 and --cycles >= 1")
    try:
        with vrsync.Host(args.config, session=args.session) as host:
            host.wait_for_agents(args.timeout)
            round_trips, own, own_cpu = measure(host, args.warmup, args.cycles)
            agents = len(host.agent_ids)
    except (vrsync.VrsyncError, RuntimeError) as e:
        print(f"error: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    # Written after the session is closed: the agents are on their way out.
    report = result(agents, args.warmup, round_trips, own, own_cpu)
    args.out.write_text(json.dumps(report, allow_nan=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
