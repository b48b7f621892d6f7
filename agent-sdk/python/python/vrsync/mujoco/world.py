"""`MujocoWorld`: an MJCF scene served to vrsync agents, one lock-step cycle at a time.

One cycle (:meth:`MujocoWorld.step_cycle`), in the order of DESIGN §5:

1. *frame 1*: for each agent in id order, ``frame = host.loan(id)``; render each of its
   cameras straight into ``frame.image(name)``; write its vectors into
   ``frame.vector(name)``; set its pose (its body's position and orientation) and its
   reward; ``host.publish(frame)``. Then ``host.start()``.
2. *frame 2*: ``report = host.collect()``; reset the agents that sent a reset (their
   body's joints back to the scene's start, at rest); apply each agent's actions to
   ``data.ctrl`` (an action of ``None``, none sent this cycle, leaves its ``ctrl`` as it was); step
   the physics ``simulation_time_per_frame / model.opt.timestep`` times; fold the new
   state into the trajectory hash.

So cycle 0 shows the agents the scene's initial state, and the actions answering cycle
``f``'s frames act during the step from ``f`` to ``f + 1``, as in vr-sim.

The host is anything with the interface of ``vrsync.Host`` (agent-sdk/python,
``loan``/``publish``/``start``/``collect``); the world only calls those methods (and
``wait_for_agents``, ``stats`` and, when present, ``set_rejected``), reads
``agent_ids`` and ``simulation_time_per_frame``, ``report.timed_out``,
``report.late_batches``, ``report.agents`` and per agent ``agent_id``, ``actions``
(name -> floats, int or ``None``), ``actions_rejected``, ``commands``,
``invalid_commands`` and ``evicted``. Every view of a frame (``frame.image``,
``frame.vector``) is dropped before the frame is published: the host refuses to publish
a frame whose memory is still viewed.
"""

from __future__ import annotations

import hashlib
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol

import mujoco
import numpy as np
import numpy.typing as npt

from .binding import AgentBinding, bind_agent, load_hook
from .config import MujocoConfigError, WorldConfig, load_config
from .render import Renderers

__all__ = ["HostFrameLike", "HostLike", "LocalFrame", "MujocoWorld", "SUMMARY_KEYS"]

log = logging.getLogger("vrsync.mujoco")

#: The keys of ``vr-sim run``'s summary JSON (DESIGN §8) that :meth:`MujocoWorld.summary`
#: always has.
SUMMARY_KEYS = (
    "mode",
    "transport",
    "agents",
    "frames",
    "sim_time_s",
    "wall_s",
    "frames_per_s",
    "stop_timeouts",
    "late_stops",
    "evicted_agents",
    "commands_applied",
    "commands_rejected",
    "trajectory_hash",
)

# How far simulation_time_per_frame may be from a whole number of physics steps.
_STEP_TOLERANCE = 1e-9


class HostFrameLike(Protocol):
    """What the world uses of ``vrsync.HostFrame``."""

    reward: float

    def image(self, name: str) -> npt.NDArray[Any]: ...
    def vector(self, name: str) -> npt.NDArray[np.float32]: ...
    def set_pose(self, position: Sequence[float], rotation: Sequence[float]) -> None: ...


class HostLike(Protocol):
    """What the world uses of ``vrsync.Host``."""

    @property
    def agent_ids(self) -> list[int]: ...
    def loan(self, agent_id: int) -> Any: ...
    def publish(self, frame: Any) -> None: ...
    def start(self) -> None: ...
    def collect(self) -> Any: ...


class MujocoWorld:
    """An MJCF scene bound to the agents of a vrsync config.

    Args:
        config: the config file (or a :class:`~vrsync.mujoco.config.WorldConfig`
            loaded already); its ``[world.mujoco]`` table names the scene and binds it.
        agents: resize the agent list to ids ``0..agents`` (as ``--spawn-agents`` does);
            must equal the host's agent count.

    Raises:
        MujocoConfigError: the config or its binding to the scene is wrong (the message
            names the file, agent, channel and what was expected).
    """

    def __init__(self, config: str | Path | WorldConfig, *, agents: int | None = None) -> None:
        if isinstance(config, WorldConfig):
            if agents is not None and agents != len(config.agents):
                config = load_config(config.path, agents=agents)
            self.config = config
        else:
            self.config = load_config(config, agents=agents)
        self.model = _load_model(self.config)
        self.data = mujoco.MjData(self.model)
        self.steps_per_cycle = _steps_per_cycle(self.config, self.model)
        # Body poses and sensors of the initial state, for cycle 0's frames.
        mujoco.mj_forward(self.model, self.data)
        self.agents: tuple[AgentBinding, ...] = tuple(
            bind_agent(self.config, a, self.model, self.data) for a in self.config.agents
        )
        self._by_id = {b.id: b for b in self.agents}
        # Stable views into MjData (its buffers never move): no attribute lookups per cycle.
        self._pose_views = {
            b.id: (self.data.xpos[b.body_id], self.data.xquat[b.body_id]) for b in self.agents
        }
        self._y_up = self.config.pose_axes == "y_up"
        self._ctrl = self.data.ctrl
        self._state = (self.data.qpos, self.data.qvel, self.data.ctrl)
        self.renderers = Renderers(self.model, shadows=self.config.shadows)
        self._hash = hashlib.sha256()
        self.frames = 0
        self.commands_applied = 0
        self.commands_rejected = 0
        self.stop_timeouts = 0
        self.late_stops = 0
        self.evicted_agents: set[int] = set()
        self.render_s = 0.0
        self.physics_s = 0.0
        self.wall_s = 0.0
        self.interrupted = False
        self._warned_copy = False

    # ---- one cycle ---------------------------------------------------------------------

    def step_cycle(self, host: HostLike) -> Any:
        """One lock-step cycle against ``host`` (see the module doc); returns the
        host's report of the cycle."""
        t0 = time.perf_counter()
        for b in self.agents:
            frame = host.loan(b.id)
            self.write_frame(b, frame)
            host.publish(frame)
        self.render_s += time.perf_counter() - t0
        host.start()
        report = host.collect()
        self.apply_report(report, host)
        self.advance()
        return report

    def write_frame(self, agent: AgentBinding, frame: HostFrameLike) -> None:
        """Writes ``agent``'s sensor data of the current state into ``frame``: images
        rendered in place, vectors, pose (position xyz, quaternion xyzw) and reward.

        The pose is in MuJoCo's world frame (z up) by default; with ``pose_axes =
        "y_up"`` in vrsync's (``vrsync.Pose``: y up, heading 0 facing +z): MuJoCo's x, y,
        z become z, x, y, so a body facing MuJoCo's +x has heading 0 and its yaw about
        MuJoCo's z is its heading."""
        data = self.data
        for cam in agent.cameras:
            view = frame.image(cam.name)
            if not self._warned_copy and not view.flags.c_contiguous:
                self._warned_copy = True
                log.warning(
                    "camera %r of agent %d: the frame's image is not C-contiguous; MuJoCo "
                    "renders into a temporary and copies",
                    cam.name,
                    agent.id,
                )
            self.renderers.render(data, cam.camera_id, view)
        for vec in agent.vectors:
            vec.fill(frame.vector(vec.name))
        pos, quat = self._pose_views[agent.id]
        w, x, y, z = quat.tolist()
        if self._y_up:
            # MuJoCo x, y, z -> vrsync z, x, y (a proper rotation: 240 degrees about
            # (1, 1, 1)), for positions and quaternion vector parts alike.
            px, py, pz = pos.tolist()
            frame.set_pose((py, pz, px), (y, z, x, w))
        else:
            frame.set_pose(pos.tolist(), (x, y, z, w))
        if agent.reward is not None:
            frame.reward = float(agent.reward(self.model, data, agent.id))

    def apply_report(self, report: Any, host: Any | None = None) -> None:
        """Counts what ``report`` says and applies every agent's actions to ``ctrl``.

        A reset (``TrialReset`` or ``EnvironmentReset``: what the Gymnasium, vector,
        SB3 and PettingZoo envs send at ``reset``) puts that agent's body back where the
        scene starts it, at rest (:class:`~vrsync.mujoco.binding.ResetBinding`: the
        joints of its subtree to ``qpos0``, their velocities and its actuators' controls
        to 0), before the cycle's actions, so an action sent with the reset acts from the
        start pose. The scene is shared: an environment reset, too, resets only the
        agent that sent it. The other commands of the catalogue (``Move``, ``Turn``, ...)
        mean nothing to a MuJoCo scene: they are rejected, counted, and reported back to
        the agent through ``host.set_rejected`` (when the host has it), as are actions
        the world does not bind. Actions the bridge refused (``actions_rejected``) and
        undecodable commands (``invalid_commands``) are counted too."""
        if report.timed_out:
            self.stop_timeouts += 1
        self.late_stops += int(getattr(report, "late_batches", 0))
        set_rejected = getattr(host, "set_rejected", None)
        ctrl = self._ctrl
        for ar in report.agents:
            aid = int(ar.agent_id)
            if getattr(ar, "evicted", False):
                self.evicted_agents.add(aid)
            self.commands_rejected += int(getattr(ar, "actions_rejected", 0))
            self.commands_rejected += int(getattr(ar, "invalid_commands", 0))
            commands = getattr(ar, "commands", ())
            binding = self._by_id.get(aid)
            resets = sum(1 for c in commands if _is_reset(c)) if binding is not None else 0
            rejected = len(commands) - resets
            if resets:
                binding.reset.apply(self.model, self.data)  # type: ignore[union-attr]
                self.commands_applied += resets
            if binding is not None:
                for name, value in getattr(ar, "actions", {}).items():
                    if value is None:
                        continue
                    action = binding.actions.get(name)
                    if action is None:
                        rejected += 1
                        continue
                    action.apply(ctrl, value)
                    self.commands_applied += 1
            if rejected:
                self.commands_rejected += rejected
                if set_rejected is not None:
                    set_rejected(aid, rejected)

    def advance(self) -> None:
        """Steps the physics by one cycle and folds the new state into the hash."""
        t0 = time.perf_counter()
        model, data = self.model, self.data
        for _ in range(self.steps_per_cycle):
            mujoco.mj_step(model, data)
        self.physics_s += time.perf_counter() - t0
        for array in self._state:
            self._hash.update(memoryview(array))
        self.frames += 1

    # ---- a whole run -------------------------------------------------------------------

    def run(
        self,
        host: HostLike,
        frames: int | None = None,
        *,
        wait: bool = True,
        on_cycle: Callable[[int, Any], None] | None = None,
    ) -> dict[str, Any]:
        """Runs ``frames`` cycles (``None``: until Ctrl-C) and returns :meth:`summary`.

        ``wait``: first wait for every agent to connect (``host.wait_for_agents()``).
        ``on_cycle(cycle, report)`` is called after each cycle. Ctrl-C
        (``KeyboardInterrupt``) ends the run after the cycle in progress is abandoned;
        the summary then says ``interrupted``. When no agent is connected any more (all
        left or were evicted), the run pauses, as ``vr-sim run`` does: no cycle, the world
        does not advance, and the host waits for every agent again (``[sync]
        connect_timeout`` at most).

        Raises:
            MujocoConfigError: the host serves other agents than the world binds.
            vrsync.HostWaitTimeout: the agents did not come back within the connect
                timeout.
        """
        self.check_host(host)
        if wait:
            host.wait_for_agents()  # type: ignore[attr-defined]
        connected = getattr(host, "is_connected", None)
        ids = [b.id for b in self.agents]
        start = time.perf_counter()
        try:
            while frames is None or self.frames < frames:
                report = self.step_cycle(host)
                if on_cycle is not None:
                    on_cycle(self.frames - 1, report)
                if connected is not None and not any(connected(i) for i in ids):
                    host.wait_for_agents()  # type: ignore[attr-defined]
        except KeyboardInterrupt:
            self.interrupted = True
        finally:
            self.wall_s += time.perf_counter() - start
        return self.summary(host)

    def check_host(self, host: HostLike) -> None:
        """Checks that ``host`` serves exactly the world's agents, with the same cycle.

        Raises:
            MujocoConfigError: the agent ids or the cycle length differ.
        """
        ids = sorted(int(i) for i in host.agent_ids)
        mine = [b.id for b in self.agents]
        if ids != mine:
            raise MujocoConfigError(
                f"{self.config.path}: the host serves agents {ids} but the world binds {mine} "
                "(build both with the same agent count)"
            )
        dt = getattr(host, "simulation_time_per_frame", None)
        if dt is not None and abs(float(dt) - self.config.simulation_time_per_frame) > 1e-9:
            raise MujocoConfigError(
                f"{self.config.path}: the host's simulation_time_per_frame is {dt} s, the "
                f"world's {self.config.simulation_time_per_frame} s"
            )

    @property
    def trajectory_hash(self) -> str:
        """sha256 (hex) over ``qpos``, ``qvel`` and ``ctrl`` (float64, native byte order)
        after every cycle so far."""
        return self._hash.copy().hexdigest()

    def summary(self, host: Any | None = None) -> dict[str, Any]:
        """The run's summary: ``vr-sim run``'s keys (:data:`SUMMARY_KEYS`) plus
        ``world`` (``"mujoco"``), ``physics_steps``, ``physics_us`` and ``render_us``
        (per cycle), ``interrupted``, and ``host_stats`` (``host.stats()``, when a host
        is given). The host's own ``stop_timeouts``/``late_batches`` counters win over
        the ones counted from reports."""
        stats: Mapping[str, Any] = {}
        if host is not None and hasattr(host, "stats"):
            stats = dict(host.stats())
        frames = self.frames
        per = 1e6 / frames if frames else 0.0
        return {
            "mode": "sync" if self.config.sync_mode else "async",
            "transport": self.config.transport,
            "agents": len(self.agents),
            "frames": frames,
            "sim_time_s": frames * self.config.simulation_time_per_frame,
            "wall_s": self.wall_s,
            "frames_per_s": frames / self.wall_s if self.wall_s > 0 else 0.0,
            "stop_timeouts": int(stats.get("stop_timeouts", self.stop_timeouts)),
            "late_stops": int(stats.get("late_batches", self.late_stops)),
            "evicted_agents": sorted(self.evicted_agents),
            "commands_applied": self.commands_applied,
            "commands_rejected": self.commands_rejected,
            "trajectory_hash": self.trajectory_hash,
            "world": "mujoco",
            "physics_steps": frames * self.steps_per_cycle,
            "physics_us": self.physics_s * per,
            "render_us": self.render_s * per,
            "interrupted": self.interrupted,
            "host_stats": dict(stats),
        }

    # ---- without a host ----------------------------------------------------------------

    def local_frames(self) -> dict[int, LocalFrame]:
        """One :class:`LocalFrame` per agent: plain numpy buffers shaped like its
        camera images and vectors (for :func:`~vrsync.mujoco.bench_alone` and tests)."""
        return {b.id: LocalFrame.for_agent(b) for b in self.agents}

    def close(self) -> None:
        """Frees the renderers' OpenGL contexts (idempotent)."""
        self.renderers.close()

    def __enter__(self) -> MujocoWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class LocalFrame:
    """A host frame over plain numpy arrays: what :meth:`MujocoWorld.write_frame`
    writes into when there is no bridge."""

    def __init__(
        self,
        images: Mapping[str, npt.NDArray[Any]],
        vectors: Mapping[str, npt.NDArray[np.float32]],
    ) -> None:
        self.images = dict(images)
        self.vectors = dict(vectors)
        self.position: Sequence[float] = (0.0, 0.0, 0.0)
        self.rotation: Sequence[float] = (0.0, 0.0, 0.0, 1.0)
        self.reward = 0.0

    @classmethod
    def for_agent(cls, agent: AgentBinding) -> LocalFrame:
        """Zeroed buffers for ``agent``'s cameras (rgb8) and vectors."""
        return cls(
            {c.name: np.zeros((c.height, c.width, 3), np.uint8) for c in agent.cameras},
            {v.name: np.zeros(v.len, np.float32) for v in agent.vectors},
        )

    def image(self, name: str) -> npt.NDArray[Any]:
        """The image buffer of camera ``name``."""
        return self.images[name]

    def vector(self, name: str) -> npt.NDArray[np.float32]:
        """The buffer of vector ``name``."""
        return self.vectors[name]

    def set_pose(self, position: Sequence[float], rotation: Sequence[float]) -> None:
        """Records the pose (position xyz, quaternion xyzw)."""
        self.position = position
        self.rotation = rotation


def _is_reset(command: Any) -> bool:
    """Whether ``command`` is a ``TrialReset`` or an ``EnvironmentReset`` (by class
    name, so the world's tests can report plain stand-ins)."""
    name = command if isinstance(command, str) else type(command).__name__
    return name in ("TrialReset", "EnvironmentReset")


def _load_model(config: WorldConfig) -> mujoco.MjModel:
    """The scene: the MJCF file, or the generator's text for this many agents."""
    if config.scene is not None:
        if not config.scene.is_file():
            raise MujocoConfigError(
                f"{config.path}: `world.mujoco.scene`: no such file {config.scene}"
            )
        try:
            return mujoco.MjModel.from_xml_path(str(config.scene))
        except ValueError as e:
            raise MujocoConfigError(f"{config.path}: scene {config.scene}: {e}") from e
    assert config.generator is not None
    generate = load_hook(config.generator, config.path)
    xml = generate(len(config.agents))
    if not isinstance(xml, str):
        raise MujocoConfigError(
            f"{config.path}: generator {config.generator!r} returned {type(xml).__name__}, "
            "not MJCF text"
        )
    try:
        return mujoco.MjModel.from_xml_string(xml)
    except ValueError as e:
        raise MujocoConfigError(
            f"{config.path}: the MJCF of generator {config.generator!r}: {e}"
        ) from e


def _steps_per_cycle(config: WorldConfig, model: mujoco.MjModel) -> int:
    """``simulation_time_per_frame / timestep``, which must be a whole number >= 1."""
    dt = config.simulation_time_per_frame
    ts = float(model.opt.timestep)
    n = round(dt / ts)
    if n < 1 or abs(n * ts - dt) > _STEP_TOLERANCE:
        raise MujocoConfigError(
            f"{config.path}: sync.simulation_time_per_frame = {dt} s is not a whole number of "
            f'the scene\'s physics steps (<option timestep="{ts}"/>: {dt / ts:.6f} steps)'
        )
    return n
