"""MuJoCo alone and MuJoCo as a vrsync world: the cost the bridge adds to a cycle.

:func:`bench_alone` runs the same scene, the same physics steps and the same renders as
:meth:`MujocoWorld.step_cycle`, into plain numpy arrays (:class:`LocalFrame`) instead
of loaned frames, with no host: the reference the bridge's cycle is compared with
(DESIGN §9: the bridge adds at most 10 % at 16 agents). :func:`bridge_cycle_times`
measures the bridge: the world's own loop (:meth:`MujocoWorld.step_cycle`) serving real
agent processes through ``vrsync.Host``. :func:`compare` interleaves rounds of both, so
a change of the machine's load hits both alike, and makes both step the same scene: a
first, unmeasured bridge run records the controls the agents' actions set in every
cycle, and the alone rounds apply those (``controls``), so both render and step the same
states (their trajectory hashes are equal, and checked). Rendering costs what the
cameras see: with other controls (say, :func:`drive_all`'s) the rovers go elsewhere and
the renders cost more or less, which measured here 25 % of a 16-agent cycle. :func:`render_rate` and
:func:`physics_rate` measure the two parts of a cycle on their own.

The agents of the bridge are ``channel_agent`` (agent-sdk/examples, a Rust agent that
reads its vectors and sends its actions every cycle): :func:`find_channel_agent` looks
for it in the folder of ``vr-sim`` (``target/<profile>``, under ``examples/``).
"""

from __future__ import annotations

import itertools
import os
import statistics
import subprocess
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from .config import WorldConfig, load_config
from .private_config import agents_config_text
from .world import MujocoWorld

__all__ = [
    "Comparison",
    "alone_cycle_times",
    "bench_alone",
    "bridge_cycle_times",
    "compare",
    "drive_all",
    "find_channel_agent",
    "physics_rate",
    "render_rate",
]

#: What :func:`find_channel_agent` looks for, relative to the folder of ``vr-sim``.
CHANNEL_AGENT_PATHS = ("examples/channel_agent", "channel_agent")

_SESSIONS = itertools.count()


def drive_all(world: MujocoWorld) -> None:
    """Sets every actuator's ``ctrl`` to a fixed value inside its range (60 % of the
    upper limit), so that benchmarks step a moving scene the same way every time."""
    model = world.model
    limited = model.actuator_ctrllimited.astype(bool)
    high = np.where(limited, model.actuator_ctrlrange[:, 1], 1.0)
    world.data.ctrl[:] = 0.6 * high


def bench_alone(
    config: str | Path | WorldConfig,
    frames: int,
    *,
    agents: int | None = None,
    warmup: int = 3,
) -> float:
    """Seconds per cycle of the world alone: for each agent, render every camera into a
    numpy array, fill its vectors, pose and reward; then step the physics one cycle.

    ``agents`` resizes the config's agent list as ``--spawn-agents`` does; ``warmup``
    cycles (OpenGL contexts being made, caches) are run first and not counted.

    Raises:
        MujocoConfigError: as :class:`MujocoWorld`.
        ValueError: ``frames`` < 1.
    """
    return statistics.fmean(alone_cycle_times(config, frames, agents=agents, warmup=warmup))


def alone_cycle_times(
    config: str | Path | WorldConfig,
    frames: int,
    *,
    agents: int | None = None,
    warmup: int = 3,
    controls: Sequence[np.ndarray] | None = None,
    hash_out: list[str] | None = None,
) -> list[float]:
    """Each measured cycle's seconds of the world alone (see :func:`bench_alone`).

    ``controls``: the ``ctrl`` of every cycle (``warmup + frames`` of them, as
    :func:`bridge_cycle_times` records them), applied before each cycle's physics;
    without them every actuator is driven as :func:`drive_all` does. ``hash_out`` gets
    the run's trajectory hash appended.

    Raises:
        MujocoConfigError: as :class:`MujocoWorld`.
        ValueError: ``frames`` < 1, or fewer ``controls`` than cycles.
    """
    if frames < 1:
        raise ValueError(f"frames must be at least 1, found {frames}")
    if controls is not None and len(controls) < warmup + frames:
        raise ValueError(f"{len(controls)} recorded controls for {warmup + frames} cycles")
    times: list[float] = []
    with MujocoWorld(config, agents=agents) as world:
        drive_all(world)
        local = world.local_frames()
        ctrl = world.data.ctrl
        clock = time.perf_counter
        for i in range(warmup + frames):
            t0 = clock()
            for b in world.agents:
                world.write_frame(b, local[b.id])
            if controls is not None:
                ctrl[:] = controls[i]
            world.advance()
            if i >= warmup:
                times.append(clock() - t0)
        if hash_out is not None:
            hash_out.append(world.trajectory_hash)
    return times


def find_channel_agent(bin_dir: str | Path | None = None) -> Path:
    """The ``channel_agent`` executable in ``bin_dir`` (the folder of ``vr-sim``, e.g.
    ``target/release``; default ``$VRSYNC_BIN_DIR``), under ``examples/`` as cargo puts
    it or beside ``vr-sim``.

    Raises:
        FileNotFoundError: no folder given, or no ``channel_agent`` in it (the message
            says how to build it).
    """
    if bin_dir is None:
        bin_dir = os.environ.get("VRSYNC_BIN_DIR")
    if not bin_dir:
        raise FileNotFoundError(
            "where is channel_agent? give --bin-dir (the folder of vr-sim, e.g. "
            "target/release) or set VRSYNC_BIN_DIR"
        )
    for rel in CHANNEL_AGENT_PATHS:
        path = Path(bin_dir) / rel
        if path.is_file() and os.access(path, os.X_OK):
            return path
    raise FileNotFoundError(
        f"no channel_agent in {bin_dir} (looked for {', '.join(CHANNEL_AGENT_PATHS)}): "
        "build it with `cargo build --release --examples -p vrsync-agent` "
        "(target/release/examples/channel_agent)"
    )


def bridge_cycle_times(
    config: str | Path,
    frames: int,
    agent: str | Path,
    *,
    agents: int | None = None,
    warmup: int = 3,
    session: str | None = None,
    connect_timeout: float = 60.0,
    record: list[np.ndarray] | None = None,
    hash_out: list[str] | None = None,
) -> list[float]:
    """Each measured cycle's seconds of the world serving real agents: ``agents``
    processes of ``agent`` (started as ``agent CONFIG ID``, each reading a private copy
    of the config: resized, with the session) through a ``vrsync.Host``, one
    :meth:`MujocoWorld.step_cycle` per cycle (frames rendered into the loaned samples,
    published, the agents' stops collected, their actions applied, the physics
    stepped), after ``warmup`` cycles. The agents leave when the host closes; any still
    running 30 s later are killed. ``record`` gets every cycle's ``ctrl`` (after the
    agents' actions) appended, ``hash_out`` the run's trajectory hash.

    Raises:
        MujocoConfigError: as :class:`MujocoWorld`.
        ValueError: ``frames`` < 1.
        RuntimeError: a cycle timed out, or an agent failed.
        vrsync.HostWaitTimeout: the agents did not connect within ``connect_timeout`` s.
    """
    import vrsync

    if frames < 1:
        raise ValueError(f"frames must be at least 1, found {frames}")
    config = Path(config).resolve()
    session = session or f"mjbench-{os.getpid()}-{next(_SESSIONS)}"
    times: list[float] = []
    procs: list[subprocess.Popen[bytes]] = []
    failed: list[str] = []
    with MujocoWorld(config, agents=agents) as world, tempfile.TemporaryDirectory(
        prefix="vrsync-mujoco-bench-"
    ) as tmp:
        drive_all(world)
        n = len(world.agents)
        try:
            with vrsync.Host(config, session=session, agents=n) as host:
                world.check_host(host)
                private = Path(tmp) / "agents.toml"
                private.write_text(
                    agents_config_text(
                        config, agents=n, session=session, tcp_listen=host.tcp_address
                    )
                )
                for i in host.agent_ids:
                    procs.append(
                        subprocess.Popen(
                            [str(agent), str(private), str(i)], stdout=subprocess.DEVNULL
                        )
                    )
                host.wait_for_agents(connect_timeout)
                clock = time.perf_counter
                for c in range(warmup + frames):
                    t0 = clock()
                    report = world.step_cycle(host)
                    if c >= warmup:
                        times.append(clock() - t0)
                    if record is not None:
                        record.append(world.data.ctrl.copy())
                    if report.timed_out:
                        raise RuntimeError(f"bridge at {n} agents: cycle {c} timed out")
                if hash_out is not None:
                    hash_out.append(world.trajectory_hash)
        finally:
            # The host is closed: the agents leave on their own.
            deadline = time.monotonic() + 30.0
            for i, p in enumerate(procs):
                try:
                    code = p.wait(timeout=max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    p.kill()
                    p.wait()
                    code = None
                if code != 0:
                    failed.append(f"agent {i}: {'killed' if code is None else f'exit {code}'}")
    if failed:
        raise RuntimeError(f"bridge at {n} agents: {'; '.join(failed)}")
    return times


@dataclass
class Comparison:
    """The rounds of :func:`compare` at one agent count: each round's cycle times, s."""

    agents: int
    alone: list[list[float]] = field(default_factory=list)
    bridge: list[list[float]] = field(default_factory=list)
    #: Every run's trajectory hash: all equal when alone and bridge stepped the same
    #: states (:func:`compare` checks it).
    hashes: list[str] = field(default_factory=list)

    @staticmethod
    def p50_s(rounds: list[list[float]]) -> float:
        """The median of the rounds' medians (one disturbed round cannot move it)."""
        return statistics.median(statistics.median(r) for r in rounds)

    @staticmethod
    def mean_s(rounds: list[list[float]]) -> float:
        """The mean over every cycle of every round."""
        return statistics.fmean(t for r in rounds for t in r)

    @property
    def ratio(self) -> float:
        """Bridge over alone, of :meth:`p50_s` (DESIGN §9: at most 1.10 at 16 agents)."""
        return self.p50_s(self.bridge) / self.p50_s(self.alone)

    @property
    def ratio_mean(self) -> float:
        """Bridge over alone, of :meth:`mean_s`."""
        return self.mean_s(self.bridge) / self.mean_s(self.alone)


def compare(
    config: str | Path,
    agents: int | None,
    *,
    frames: int,
    rounds: int,
    agent: str | Path,
    warmup: int = 3,
    on_round: Callable[[str, int, list[float]], None] | None = None,
) -> Comparison:
    """``rounds`` rounds of :func:`alone_cycle_times` and :func:`bridge_cycle_times` at
    ``agents`` agents (default: the config's count), ``frames`` measured cycles each,
    interleaved (alone first in even rounds, the bridge first in odd ones), so slow
    minutes of a shared machine hit both. First an unmeasured bridge run records the
    controls of every cycle; the alone rounds apply them, so every run steps and
    renders the same states. ``on_round(kind, round, times)`` after each measurement
    (``kind``: ``"alone"`` or ``"bridge"``).

    Raises:
        as :func:`alone_cycle_times` and :func:`bridge_cycle_times`; ValueError:
        ``rounds`` < 1; RuntimeError: the runs did not step the same states (their
        trajectory hashes differ).
    """
    if rounds < 1:
        raise ValueError(f"rounds must be at least 1, found {rounds}")
    n = agents if agents is not None else len(load_config(config).agents)
    result = Comparison(n)
    controls: list[np.ndarray] = []
    bridge_cycle_times(
        config, frames, agent, agents=n, warmup=warmup, record=controls, hash_out=result.hashes
    )
    for r in range(rounds):
        kinds = ("alone", "bridge") if r % 2 == 0 else ("bridge", "alone")
        for kind in kinds:
            if kind == "alone":
                times = alone_cycle_times(
                    config, frames, agents=n, warmup=warmup, controls=controls,
                    hash_out=result.hashes,
                )  # fmt: skip
                result.alone.append(times)
            else:
                times = bridge_cycle_times(
                    config, frames, agent, agents=n, warmup=warmup, hash_out=result.hashes
                )
                result.bridge.append(times)
            if on_round is not None:
                on_round(kind, r, times)
    if len(set(result.hashes)) != 1:
        raise RuntimeError(
            f"at {n} agents the runs stepped different states (trajectory hashes "
            f"{sorted(set(result.hashes))}): the comparison would not be of the same work"
        )
    return result


def render_rate(
    config: str | Path | WorldConfig,
    *,
    renders: int = 200,
    agents: int | None = None,
) -> float:
    """Renders per second of agent 0's first camera, at its configured size."""
    with MujocoWorld(config, agents=agents) as world:
        cam = world.agents[0].cameras[0]
        out = np.zeros((cam.height, cam.width, 3), np.uint8)
        for _ in range(5):
            world.renderers.render(world.data, cam.camera_id, out)
        start = time.perf_counter()
        for _ in range(renders):
            world.renderers.render(world.data, cam.camera_id, out)
        return renders / (time.perf_counter() - start)


def physics_rate(
    config: str | Path | WorldConfig,
    *,
    steps: int = 5000,
    agents: int | None = None,
) -> float:
    """Physics steps per second of the scene (every actuator driven, see
    :func:`drive_all`)."""
    with MujocoWorld(config, agents=agents) as world:
        drive_all(world)
        model, data = world.model, world.data
        start = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(model, data)
        return steps / (time.perf_counter() - start)
