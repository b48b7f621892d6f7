"""``python -m vrsync.mujoco`` / ``vrsync-mujoco``: run a MuJoCo world, or bench the bridge.

``run`` mirrors ``vr-sim run`` (README "Run a world"): the same config file, the same
``--frames``, ``--session``, ``--spawn-agents`` and ``--summary-json``, the same summary
keys and exit codes (0 success, 1 runtime failure, 2 bad usage or bad config).

``bench`` measures what the bridge adds to the world's cycle: MuJoCo serving N
``channel_agent`` processes through ``vrsync.Host`` against MuJoCo alone, in interleaved
rounds (:func:`vrsync.mujoco.bench.compare`); its rows (``--json``, ``--csv``) have the
keys of :data:`BENCH_COLUMNS`: ``world`` (``mujoco-alone``, ``mujoco-bridge``),
``agents``, ``rounds``, ``frames`` (measured cycles, all rounds), ``width`` and
``height`` (agent 0's first camera), ``p50_us`` (the median of the rounds' median cycle
times), ``mean_us`` and ``s_per_cycle`` (over every measured cycle), ``frames_per_s``,
``bridge_over_alone`` (bridge rows: the p50 ratio; DESIGN §9 target <= 1.10 at 16
agents), ``bridge_over_alone_mean`` (the ratio of the means), ``renders_per_s`` and
``physics_steps_per_s`` (alone rows: MuJoCo's rates on their own); ``null`` (CSV: empty)
where a key does not apply.
"""

from __future__ import annotations

import argparse
import json
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from types import FrameType
from typing import Any

from ..errors import ConfigError
from .bench import (
    Comparison,
    alone_cycle_times,
    compare,
    find_channel_agent,
    physics_rate,
    render_rate,
)
from .config import MujocoConfigError, load_config
from .private_config import agents_config_text
from .world import MujocoWorld

__all__ = ["main"]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2

DEFAULT_AGENT_CMD = (
    "{python} -m vrsync.mujoco.agent --config {config} --id {id} --session {session}"
)


def _parser() -> argparse.ArgumentParser:
    script = Path(sys.argv[0]).name == "vrsync-mujoco"
    p = argparse.ArgumentParser(
        prog="vrsync-mujoco" if script else "python -m vrsync.mujoco",
        description="Serve a MuJoCo scene to vrsync agents in lock-step, or bench the bridge. "
        "The config's [world.mujoco] table binds the scene (config/mujoco-rovers.toml "
        "documents every key).",
        epilog="Exit codes: 0 success, 1 runtime failure, 2 bad usage or bad config.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    run = sub.add_parser(
        "run",
        help="serve the world to its agents (like `vr-sim run`)",
        description="Serve the config's MuJoCo scene through a vrsync host. Without "
        "--spawn-agents it waits for the configured agents and says which. Ctrl-C ends "
        "the run and still prints the summary.",
        epilog="Exit codes: 0 success, 1 runtime failure, 2 bad usage or bad config.",
    )
    run.add_argument("--config", required=True, type=Path, help="vrsync config file (TOML)")
    run.add_argument(
        "--frames", type=_positive, default=None, help="cycles to run (default: until Ctrl-C)"
    )
    run.add_argument("--session", default=None, help="session name (default: the config's)")
    run.add_argument(
        "--spawn-agents",
        type=_positive,
        default=None,
        metavar="N",
        help="start N agent processes, ids 0..N, resizing the config's agent list (new "
        "agents copy the last [[agent]] and [[world.mujoco.agent]])",
    )
    run.add_argument(
        "--agent-cmd",
        default=DEFAULT_AGENT_CMD,
        metavar="CMD",
        help="command line of each spawned agent, split like a shell; {config} (a private "
        "copy of the config, resized, with the session), {id}, {session}, {agents} and "
        "{python} are replaced (default: %(default)r, a "
        "wandering agent)",
    )
    run.add_argument(
        "--agent-arg",
        action="append",
        default=[],
        metavar="ARG",
        help="an argument appended to every spawned agent's command line (repeatable)",
    )
    run.add_argument(
        "--summary-json",
        type=Path,
        default=None,
        metavar="FILE",
        help="write the run summary as JSON (vr-sim's keys)",
    )
    run.add_argument("--quiet", action="store_true", help="print only errors")

    bench = sub.add_parser(
        "bench",
        help="the bridge's cost: MuJoCo serving agents against MuJoCo alone",
        description="Seconds per cycle of the world's loop serving N real agent processes "
        "through vrsync.Host over the config's transport (the bridge), against the same "
        "scene, physics and renders into plain numpy arrays with no host (MuJoCo alone), "
        "in interleaved rounds; prints a table with the ratio bridge/alone (DESIGN §9: at "
        "most 1.10 at 16 agents), and MuJoCo's renders/s and physics steps/s. The agents "
        "are channel_agent (a Rust agent that reads its vectors and acts every cycle), "
        "found under --bin-dir. Only ratios from one run count: absolute figures move "
        "with the machine's load. E.g.: python -m vrsync.mujoco bench --config "
        "config/mujoco-rovers-n.toml --agents 4 --agents 16 --bin-dir target/release",
        epilog="Exit codes: 0 success, 1 runtime failure, 2 bad usage or bad config.",
    )
    bench.add_argument("--config", required=True, type=Path, help="vrsync config file (TOML)")
    bench.add_argument(
        "--frames",
        type=_positive,
        default=None,
        help=f"measured cycles per round and kind ({BENCH_FRAMES}; --quick: {QUICK_FRAMES})",
    )
    bench.add_argument(
        "--rounds",
        type=_positive,
        default=None,
        help=f"interleaved rounds of alone and bridge ({BENCH_ROUNDS}; --quick: 1); a "
        "figure is the median of the rounds' median cycle times",
    )
    bench.add_argument(
        "--agents",
        type=_positive,
        action="append",
        default=None,
        metavar="N",
        help="agent count (repeatable; default: the config's)",
    )
    bench.add_argument(
        "--bin-dir",
        type=Path,
        default=None,
        metavar="DIR",
        help="the folder of vr-sim, whose examples/channel_agent the bridge spawns "
        "(default: $VRSYNC_BIN_DIR), e.g. target/release",
    )
    bench.add_argument(
        "--alone",
        action="store_true",
        help="measure MuJoCo alone only (no agents, no bridge rows)",
    )
    bench.add_argument(
        "--quick", action="store_true", help="a few cycles, one round (for tests)"
    )
    bench.add_argument(
        "--json", type=Path, default=None, metavar="FILE", help="write the rows as a JSON array"
    )
    bench.add_argument(
        "--csv", type=Path, default=None, metavar="FILE", help="write the rows as CSV"
    )
    return p


def _positive(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if n < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, found {n}")
    return n


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; returns the exit code."""
    args = _parser().parse_args(argv)
    try:
        if args.command == "bench":
            return _bench(args)
        return _run(args)
    except (MujocoConfigError, ConfigError) as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as e:  # noqa: BLE001 - the binary's one handler: say it, exit 1
        print(f"error: {type(e).__name__}: {e}", file=sys.stderr)
        return EXIT_FAILURE


#: The bench's rows (``--json``, ``--csv``), in column order.
BENCH_COLUMNS = (
    "world",
    "agents",
    "rounds",
    "frames",
    "width",
    "height",
    "p50_us",
    "mean_us",
    "s_per_cycle",
    "frames_per_s",
    "bridge_over_alone",
    "bridge_over_alone_mean",
    "renders_per_s",
    "physics_steps_per_s",
)
BENCH_FRAMES = 100
BENCH_ROUNDS = 7
QUICK_FRAMES = 3


def _bench(args: argparse.Namespace) -> int:
    frames = args.frames or (QUICK_FRAMES if args.quick else BENCH_FRAMES)
    rounds = args.rounds or (1 if args.quick else BENCH_ROUNDS)
    warmup = 1 if args.quick else 5
    agent = None
    if not args.alone:
        try:
            agent = find_channel_agent(args.bin_dir)
        except FileNotFoundError as e:
            print(f"error: {e} (or bench MuJoCo alone with --alone)", file=sys.stderr)
            return EXIT_USAGE
    rows: list[dict[str, Any]] = []
    print(
        f"vrsync.mujoco bench: {args.config}, {rounds} round(s) of {frames} cycles per kind; "
        "p50 = median of the rounds' median cycle times"
    )
    print(f"{'world':<14} {'agents':>6} {'image':>8} {'p50 ms':>9} {'mean ms':>9} {'ratio':>7}")
    for n in args.agents or [None]:
        cfg = load_config(args.config, agents=n)
        count = len(cfg.agents)
        cam = cfg.agents[0].cameras[0] if cfg.agents[0].cameras else None
        if agent is None:
            result = Comparison(count)
            for _ in range(rounds):
                result.alone.append(alone_cycle_times(args.config, frames, agents=n, warmup=warmup))
        else:
            result = compare(
                args.config, count, frames=frames, rounds=rounds, agent=agent, warmup=warmup
            )
        quick_rates = {"renders": 20, "steps": 200} if args.quick else {}
        alone = bench_row("mujoco-alone", count, result.alone, frames, cam)
        alone["renders_per_s"] = (
            render_rate(args.config, agents=n, renders=quick_rates.get("renders", 200))
            if cam
            else 0.0
        )
        alone["physics_steps_per_s"] = physics_rate(
            args.config, agents=n, steps=quick_rates.get("steps", 5000)
        )
        new = [alone]
        if result.bridge:
            bridge = bench_row("mujoco-bridge", count, result.bridge, frames, cam)
            bridge["bridge_over_alone"] = result.ratio
            bridge["bridge_over_alone_mean"] = result.ratio_mean
            new.append(bridge)
        for row in new:
            ratio = row["bridge_over_alone"]
            print(
                f"{row['world']:<14} {row['agents']:>6} "
                f"{row['width']:>4}x{row['height']:<3} {row['p50_us'] / 1e3:>9.2f} "
                f"{row['mean_us'] / 1e3:>9.2f} {'-' if ratio is None else f'{ratio:.3f}':>7}"
            )
        print(
            f"{'':<14} {count:>6} MuJoCo: {alone['renders_per_s']:.1f} renders/s, "
            f"{alone['physics_steps_per_s']:.0f} physics steps/s"
        )
        rows.extend(new)
    print("\nratios (targets in parentheses):")
    for row in rows:
        if row["bridge_over_alone"] is not None:
            target = "<= 1.10" if row["agents"] == 16 else "report"
            print(
                f"  mujoco bridge / alone, {row['agents']} agents (p50)  "
                f"{row['bridge_over_alone']:.3f}  ({target}); of means "
                f"{row['bridge_over_alone_mean']:.3f}"
            )
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2, allow_nan=False) + "\n")
    if args.csv is not None:
        lines = [",".join(BENCH_COLUMNS)]
        for row in rows:
            lines.append(",".join("" if row[k] is None else str(row[k]) for k in BENCH_COLUMNS))
        args.csv.write_text("\n".join(lines) + "\n")
    return EXIT_OK


def bench_row(
    world: str, agents: int, rounds: list[list[float]], frames: int, cam: Any
) -> dict[str, Any]:
    """One row of the bench (:data:`BENCH_COLUMNS`; the ratio and MuJoCo's rates ``None``
    until filled in) from each round's cycle times (s)."""
    mean = Comparison.mean_s(rounds)
    p50 = Comparison.p50_s(rounds)
    return {
        "world": world,
        "agents": agents,
        "rounds": len(rounds),
        "frames": frames * len(rounds),
        "width": cam.width if cam else 0,
        "height": cam.height if cam else 0,
        "p50_us": p50 * 1e6,
        "mean_us": mean * 1e6,
        "s_per_cycle": mean,
        "frames_per_s": 1.0 / mean,
        "bridge_over_alone": None,
        "bridge_over_alone_mean": None,
        "renders_per_s": None,
        "physics_steps_per_s": None,
    }


class _Agents:
    """Spawned agent processes: started in id order, reaped (killed at the deadline)."""

    def __init__(self) -> None:
        self.procs: dict[int, subprocess.Popen[bytes]] = {}

    def spawn(
        self, template: str, extra: Sequence[str], ids: Sequence[int], fields: dict[str, Any]
    ) -> None:
        for i in ids:
            try:
                argv = [part.format(id=i, **fields) for part in shlex.split(template)]
            except (KeyError, IndexError, ValueError) as e:
                raise MujocoConfigError(f"--agent-cmd {template!r}: {e}") from e
            self.procs[i] = subprocess.Popen([*argv, *extra])

    def finish(self, timeout_s: float) -> dict[int, str]:
        """Waits for every agent up to ``timeout_s`` (kills the rest); what went wrong."""
        deadline = time.monotonic() + timeout_s
        problems = {}
        for i, p in self.procs.items():
            try:
                code = p.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
                problems[i] = f"still running after {timeout_s:.0f} s: killed"
                continue
            if code != 0:
                problems[i] = f"exit code {code}"
        return problems


def _run(args: argparse.Namespace) -> int:
    # SIGTERM ends the run like Ctrl-C: the summary is still written, agents reaped.
    def on_term(_sig: int, _frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, on_term)
    try:
        return _run_world(args)
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run_world(args: argparse.Namespace) -> int:
    config_path = args.config.resolve()
    world = MujocoWorld(config_path, agents=args.spawn_agents)
    import vrsync

    host_cls = getattr(vrsync, "Host", None)
    if host_cls is None:
        world.close()
        print("error: this vrsync build has no vrsync.Host (the Python host API)", file=sys.stderr)
        return EXIT_FAILURE
    session = args.session or world.config.session
    agents = _Agents()
    summary: dict[str, Any] | None = None
    private = tempfile.TemporaryDirectory(prefix="vrsync-mujoco-")
    try:
        with host_cls(config_path, session=session, agents=args.spawn_agents) as host:
            ids = list(host.agent_ids)
            if args.spawn_agents is not None:
                # The agents read their own [[agent]] (resized), the session and the bound
                # TCP address from a private copy of the config, as vr-sim's do.
                agent_config = Path(private.name) / "agents.toml"
                agent_config.write_text(
                    agents_config_text(
                        config_path,
                        agents=args.spawn_agents,
                        session=session,
                        tcp_listen=getattr(host, "tcp_address", None),
                    )
                )
                agents.spawn(
                    args.agent_cmd,
                    args.agent_arg,
                    ids,
                    {
                        "config": str(agent_config),
                        "session": session,
                        "agents": len(ids),
                        "python": sys.executable,
                    },
                )
            elif not args.quiet:
                print(f"waiting for agents {ids} of session {session!r}", file=sys.stderr)
            try:
                summary = world.run(host, args.frames, on_cycle=_progress(args))
            except KeyboardInterrupt:
                # Ctrl-C while waiting for the agents: no cycle ran.
                world.interrupted = True
                summary = world.summary(host)
    except KeyboardInterrupt:
        world.interrupted = True
    finally:
        world.close()
        problems = agents.finish(timeout_s=10.0)
        private.cleanup()
    if summary is None:
        summary = world.summary()
    if args.summary_json is not None:
        args.summary_json.write_text(json.dumps(summary, indent=2) + "\n")
    if not args.quiet:
        _print_summary(summary)
    evicted = set(summary["evicted_agents"])
    unhandled = {i: why for i, why in problems.items() if i not in evicted}
    if unhandled and not summary["interrupted"]:
        print(f"error: spawned agents failed: {unhandled}", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _progress(args: argparse.Namespace) -> Any:
    if args.quiet:
        return None
    every = 100

    def on_cycle(cycle: int, report: Any) -> None:
        if cycle % every == every - 1:
            print(f"cycle {cycle + 1}", file=sys.stderr)

    return on_cycle


def _print_summary(s: dict[str, Any]) -> None:
    rows = [
        ("mode", s["mode"]),
        ("transport", s["transport"]),
        ("agents", s["agents"]),
        ("cycles", s["frames"]),
        ("simulated time", f"{s['sim_time_s']:.2f} s"),
        ("wall time", f"{s['wall_s']:.2f} s"),
        ("cycles per second", f"{s['frames_per_s']:.1f}"),
        ("physics per cycle", f"{s['physics_us']:.0f} us ({s['physics_steps']} steps in all)"),
        ("frames per cycle", f"{s['render_us']:.0f} us (render + vectors + pose + reward)"),
        ("stop timeouts", s["stop_timeouts"]),
        ("late stops", s["late_stops"]),
        ("evicted agents", s["evicted_agents"]),
        ("actions applied", s["commands_applied"]),
        ("rejected", s["commands_rejected"]),
        ("trajectory hash", s["trajectory_hash"][:16]),
    ]
    if s["interrupted"]:
        rows.append(("interrupted", "yes"))
    for k, v in rows:
        print(f"{k:>18}: {v}")
