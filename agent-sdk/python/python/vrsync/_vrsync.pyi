"""Type stubs of the extension module `vrsync._vrsync` (built from Rust with PyO3)."""

from collections.abc import Iterator, Sequence
from os import PathLike
from typing import Any, final

import numpy as np
import numpy.typing as npt

PROTOCOL_VERSION: int
MAX_FRAMES_HELD: int
"""Frames an agent may hold at once (2): the one it reads and one more."""
__version__: str

def config_agent_ids(config: str | PathLike[str]) -> list[int]:
    """The agent ids of the config file (its ``[[agent]]`` entries), sorted."""

@final
class Pose:
    """Body pose: ``position`` (x, y, z metres, y up), ``rotation`` quaternion (x, y, z, w)."""

    @property
    def position(self) -> tuple[float, float, float]: ...
    @property
    def rotation(self) -> tuple[float, float, float, float]: ...
    @property
    def heading_deg(self) -> float:
        """Yaw about +y in degrees, 0 ≤ h < 360 (0 faces +z): ``Move.heading_deg``'s convention."""

@final
class GridPosition:
    """Grid position sensor: position (metres) and Euler rotation (degrees)."""

    @property
    def position(self) -> tuple[float, float, float]: ...
    @property
    def rotation_deg(self) -> tuple[float, float, float]: ...

@final
class HeadMotion:
    """Head motion sensor (each x, y, z)."""

    @property
    def velocity(self) -> tuple[float, float, float]: ...
    @property
    def acceleration(self) -> tuple[float, float, float]: ...
    @property
    def angular_velocity_deg(self) -> tuple[float, float, float]: ...
    @property
    def angular_acceleration_deg(self) -> tuple[float, float, float]: ...

@final
class EyePosition:
    """Eye position sensor: rotation (pan left, pan right, tilt) and its change per cycle."""

    @property
    def rotation_deg(self) -> tuple[float, float, float]: ...
    @property
    def rotation_velocity_deg(self) -> tuple[float, float, float]: ...

@final
class ActionState:
    """Execution state of an action (values of the original protocol)."""

    InExecution: ActionState
    Finished: ActionState
    Aborted: ActionState
    Walking: ActionState
    Rotating: ActionState
    WalkingRotating: ActionState
    @property
    def done(self) -> bool:
        """``Finished`` or ``Aborted``."""
    def __int__(self) -> int: ...

@final
class ActionStatus:
    """An action's state as reported in a frame."""

    @property
    def action_id(self) -> int: ...
    @property
    def state(self) -> ActionState: ...

@final
class Collision:
    """A collision: the running action and what was hit."""

    @property
    def action_id(self) -> int: ...
    @property
    def collider_id(self) -> int: ...

@final
class Camera:
    """One configured camera of an agent."""

    @property
    def name(self) -> str: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def format(self) -> str:
        """``"rgb8"``, ``"rgba8"``, ``"gray8"`` or ``"depth32f"``."""
    @property
    def fov_horizontal_deg(self) -> float: ...
    @property
    def fov_vertical_deg(self) -> float: ...
    @property
    def shape(self) -> list[int]:
        """The numpy shape of its images: (H, W, 3), (H, W, 4) or (H, W)."""
    @property
    def dtype(self) -> str:
        """``"uint8"`` or ``"float32"``."""

class Vector:
    """A float32 vector the host writes into every frame (``[[agent.vector]]``)."""

    @property
    def name(self) -> str: ...
    @property
    def len(self) -> int: ...
    @property
    def low(self) -> list[float]:
        """Lower bound per value (``-inf`` when not configured)."""
    @property
    def high(self) -> list[float]:
        """Upper bound per value (``inf`` when not configured)."""

class Action:
    """What the agent sends back each cycle (``[[agent.action]]``)."""

    @property
    def name(self) -> str: ...
    @property
    def kind(self) -> str:
        """``"box"`` (continuous, within ``low``/``high``) or ``"discrete"`` (0..n)."""
    @property
    def len(self) -> int:
        """Number of values (1 for a discrete action)."""
    @property
    def n(self) -> int | None:
        """Number of choices of a discrete action, else ``None``."""
    @property
    def low(self) -> list[float]: ...
    @property
    def high(self) -> list[float]: ...

@final
class Frame:
    """One sensor frame. Image arrays are read-only views of its memory and keep it alive;
    copy what you keep beyond the cycle (an agent can hold only a few frames)."""

    @property
    def cycle(self) -> int: ...
    @property
    def sim_time(self) -> float:
        """Simulated seconds at the start of this cycle."""
    @property
    def sim_time_ns(self) -> int: ...
    @property
    def agent_id(self) -> int: ...
    @property
    def sync_mode(self) -> bool: ...
    @property
    def pose(self) -> Pose: ...
    @property
    def grid(self) -> GridPosition: ...
    @property
    def head_motion(self) -> HeadMotion: ...
    @property
    def eye(self) -> EyePosition: ...
    @property
    def reward(self) -> float: ...
    @property
    def statuses(self) -> list[ActionStatus]:
        """The statuses this frame brings: each exactly once, also those of skipped frames."""
    @property
    def action_states(self) -> dict[int, ActionState]:
        """The newest state per action id this frame brings."""
    @property
    def collisions(self) -> list[Collision]:
        """The collisions this frame brings: each exactly once."""
    @property
    def previous_outcome(self) -> str:
        """``"stopped"``, ``"timed_out"`` or ``"none"``."""
    @property
    def previous_rejected(self) -> int: ...
    @property
    def frames_skipped(self) -> int: ...
    @property
    def camera_names(self) -> list[str]: ...
    def image(self, name: str) -> npt.NDArray[Any]:
        """Camera ``name`` as a read-only view: H×W×3/H×W×4/H×W uint8 or H×W float32.

        Raises ``KeyError`` for an unknown camera."""
    @property
    def images(self) -> dict[str, npt.NDArray[Any]]:
        """Every image by camera name, in camera order."""
    @property
    def vector_names(self) -> list[str]: ...
    def vector(self, name: str) -> npt.NDArray[np.float32]:
        """Vector ``name`` (``[[agent.vector]]``) as a read-only 1-d float32 view.

        Raises ``KeyError`` for an unknown vector."""
    @property
    def vectors(self) -> dict[str, npt.NDArray[np.float32]]:
        """Every vector by name, in payload order."""
    @property
    def memory_range(self) -> tuple[int, int]:
        """Address range of this frame's images (to check that arrays are views)."""

class Command:
    """Base class of every command; send one with ``Agent.send``."""

    @property
    def name(self) -> str: ...

@final
class Move(Command):
    """Walk towards ``heading_deg`` (world frame) for ``distance_m`` metres."""

    def __init__(self, heading_deg: float, distance_m: float) -> None: ...
    @property
    def heading_deg(self) -> float: ...
    @property
    def distance_m(self) -> float: ...

@final
class Turn(Command):
    """Turn in place by ``angle_deg`` (positive = clockwise seen from above)."""

    def __init__(self, angle_deg: float) -> None: ...
    @property
    def angle_deg(self) -> float: ...

@final
class MoveTo(Command):
    """Walk straight to the world position (x, y, z)."""

    def __init__(self, x: float, y: float, z: float) -> None: ...
    @property
    def x(self) -> float: ...
    @property
    def y(self) -> float: ...
    @property
    def z(self) -> float: ...

@final
class CancelMove(Command):
    """Cancel the running movement."""

    def __init__(self) -> None: ...

@final
class EyeMovement(Command):
    """Move the eyes (degrees, each within ±180)."""

    def __init__(self, pan_left_deg: float, pan_right_deg: float, tilt_deg: float = 0.0) -> None: ...
    @property
    def pan_left_deg(self) -> float: ...
    @property
    def pan_right_deg(self) -> float: ...
    @property
    def tilt_deg(self) -> float: ...

@final
class EyeFixation(Command):
    """Fixate the world point (x, y, z) with both eyes."""

    def __init__(self, x: float, y: float, z: float) -> None: ...
    @property
    def x(self) -> float: ...
    @property
    def y(self) -> float: ...
    @property
    def z(self) -> float: ...

@final
class GraspId(Command):
    """Grasp the object ``object_id``."""

    def __init__(self, object_id: int) -> None: ...
    @property
    def object_id(self) -> int: ...

@final
class PointId(Command):
    """Point at the object ``object_id``."""

    def __init__(self, object_id: int) -> None: ...
    @property
    def object_id(self) -> int: ...

@final
class InteractId(Command):
    """Interact with the object ``object_id``."""

    def __init__(self, object_id: int) -> None: ...
    @property
    def object_id(self) -> int: ...

@final
class GraspPos(Command):
    """Grasp what is seen at left-image pixel (x_px, y_px)."""

    def __init__(self, x_px: float, y_px: float) -> None: ...
    @property
    def x_px(self) -> float: ...
    @property
    def y_px(self) -> float: ...

@final
class PointPos(Command):
    """Point at what is seen at left-image pixel (x_px, y_px)."""

    def __init__(self, x_px: float, y_px: float) -> None: ...
    @property
    def x_px(self) -> float: ...
    @property
    def y_px(self) -> float: ...

@final
class InteractPos(Command):
    """Interact with what is seen at left-image pixel (x_px, y_px)."""

    def __init__(self, x_px: float, y_px: float) -> None: ...
    @property
    def x_px(self) -> float: ...
    @property
    def y_px(self) -> float: ...

@final
class GraspRelease(Command):
    """Release the grasped object."""

    def __init__(self) -> None: ...

@final
class EnvironmentReset(Command):
    """Reset the environment."""

    def __init__(self, reset_type: int = 0) -> None: ...
    @property
    def reset_type(self) -> int: ...

@final
class TrialReset(Command):
    """Reset the trial."""

    def __init__(self, reset_type: int = 0) -> None: ...
    @property
    def reset_type(self) -> int: ...

@final
class FrameIter(Iterator[Frame]):
    """Iterator of ``Agent.frames()``; ends when the host closes the session."""

    def __iter__(self) -> FrameIter: ...
    def __next__(self) -> Frame: ...

@final
class Agent:
    """An agent connected to a vrsync host."""

    @staticmethod
    def connect(
        config: str | PathLike[str],
        agent_id: int,
        *,
        session: str | None = None,
        connect_timeout: float | None = None,
    ) -> Agent:
        """Connects agent ``agent_id`` to the host of ``config``'s session."""
    def wait(self, timeout: float | None = None) -> Frame:
        """Waits for the next frame (raises ``HostClosedError`` at the end of the session)."""
    def frames(self, timeout: float | None = None) -> FrameIter:
        """Frames until the host closes the session."""
    def send(self, command: Command) -> int:
        """Queues ``command``; returns its action id."""
    def send_with_id(self, action_id: int, command: Command) -> None:
        """Queues ``command`` with an action id of your choice."""
    def act(self, name: str, value: Sequence[float] | npt.NDArray[Any] | int) -> None:
        """Queues the value of action ``name`` (floats, or an int for a discrete action);
        raises ``ActionError`` naming the action when it does not fit."""
    def stop(self) -> None:
        """Sends the queued commands with the stop for this cycle."""
    def close(self) -> None:
        """Disconnects (idempotent). Returns within about a second even when the host does
        not answer (a frozen process, a lost link)."""
    def __enter__(self) -> Agent: ...
    def __exit__(self, *args: object) -> bool: ...
    @property
    def id(self) -> int: ...
    @property
    def session(self) -> str: ...
    @property
    def config_path(self) -> str: ...
    @property
    def transport(self) -> str: ...
    @property
    def sync_mode(self) -> bool: ...
    @property
    def stop_timeout(self) -> float: ...
    @property
    def wait_for_stop(self) -> str: ...
    @property
    def frame_wait(self) -> float | None: ...
    @property
    def simulation_time_per_frame(self) -> float: ...
    @property
    def max_commands_per_cycle(self) -> int: ...
    @property
    def cameras(self) -> list[Camera]: ...
    @property
    def vector_specs(self) -> list[Vector]:
        """The agent's ``[[agent.vector]]`` entries (``Frame.vector`` reads them)."""
    @property
    def action_specs(self) -> list[Action]:
        """The agent's ``[[agent.action]]`` entries (``act`` sends them)."""
    @property
    def last_cycle(self) -> int | None: ...
    @property
    def frames_skipped(self) -> int: ...
    @property
    def frames_held(self) -> int:
        """Frames of this agent alive now (a wait fails at ``MAX_FRAMES_HELD``)."""
    @property
    def closed(self) -> bool: ...

@final
class MoveAhead:
    """An action-table entry: walk ``distance_m`` towards the body's current heading plus
    ``heading_offset_deg`` (resolved per agent and cycle into a ``Move``)."""

    def __init__(self, distance_m: float, heading_offset_deg: float = 0.0) -> None: ...
    def __call__(self, frame: Frame) -> Move:
        """The ``Move`` this entry means for ``frame``."""
    @property
    def distance_m(self) -> float: ...
    @property
    def heading_offset_deg(self) -> float: ...

@final
class StackedSample:
    """The shared memory of a group's zero-copy images (their ``base``): one sample with
    every stacked agent's payload of one cycle."""

    @property
    def cycle(self) -> int: ...

_Entry = Command | MoveAhead | Sequence[Command | MoveAhead] | None

@final
class AgentGroup:
    """N agents of one session, stepped together with one call into Rust per cycle; their
    frames are written into stacked numpy arrays (row ``k`` = ``ids[k]``), overwritten
    in place by every ``reset``/``step`` (with ``zero_copy`` the images are views of the
    host's stacked sample instead)."""

    @staticmethod
    def connect(
        config: str | PathLike[str],
        agent_ids: Sequence[int] | None = None,
        *,
        session: str | None = None,
        connect_timeout: float | None = None,
        step_timeout: float | None = None,
    ) -> AgentGroup:
        """Connects the agents (default: every ``[[agent]]``); they need equal cameras."""
    def set_action_table(self, table: Sequence[_Entry]) -> None:
        """The discrete actions ``step`` indexes."""
    @property
    def num_actions(self) -> int: ...
    def reset(self, kind: str = "trial") -> None:
        """Every agent's reset (``"trial"``/``"environment"``) and next frame."""
    def step(
        self,
        actions: npt.ArrayLike,
        *,
        reset: npt.ArrayLike | None = None,
        reset_kind: str = "trial",
    ) -> None:
        """One cycle: table entry ``actions[k]`` for agent ``k`` (a reset where
        ``reset[k]``), then every agent's next frame."""
    def step_commands(self, commands: Sequence[_Entry]) -> None:
        """One cycle with explicit commands per agent."""
    @property
    def images(self) -> dict[str, npt.NDArray[Any]]:
        """Camera name → (N, H, W[, C]) array."""
    def image(self, name: str) -> npt.NDArray[Any]: ...
    @property
    def fresh_images(self) -> bool:
        """Whether every step writes the images into new arrays (default False: the
        same arrays, overwritten in place); the arrays of earlier steps keep their
        contents."""
    @fresh_images.setter
    def fresh_images(self, fresh: bool) -> None: ...
    @property
    def stacked(self) -> bool:
        """Whether the agents' payloads are stacked (``[transport.shm] stacked_images``,
        the group's ids the config's shared-memory agents in id order): ``zero_copy``
        can be turned on."""
    @property
    def zero_copy(self) -> bool:
        """Whether ``images`` are read-only views of the shared memory the host wrote
        (no copy): new arrays each step, valid while held; at most 2 steps' images held
        at once, else the next step raises ``TooManyFramesHeldError``."""
    @zero_copy.setter
    def zero_copy(self, on: bool) -> None: ...
    def step_actions(
        self,
        values: dict[str, npt.ArrayLike],
        *,
        reset: Sequence[bool] | npt.NDArray[np.bool_] | None = None,
        reset_kind: str = "trial",
        active: Sequence[bool] | npt.NDArray[np.bool_] | None = None,
    ) -> None:
        """One cycle with channel actions: ``{name: (N, len) floats or (N,) ints}``;
        agents with ``active[k]`` false only stop."""
    @property
    def vectors(self) -> dict[str, npt.NDArray[np.float32]]:
        """Stacked vectors ``{name: (N, len) float32}``, overwritten by every step."""
    def vector(self, name: str) -> npt.NDArray[np.float32]: ...
    @property
    def vector_specs(self) -> list[Vector]: ...
    @property
    def action_specs(self) -> list[Action]: ...
    @property
    def positions(self) -> npt.NDArray[Any]:
        """(N, 3) float32."""
    @property
    def rotations(self) -> npt.NDArray[Any]:
        """(N, 4) float32 quaternions (x, y, z, w)."""
    @property
    def rewards(self) -> npt.NDArray[Any]:
        """(N,) float32."""
    @property
    def sim_time_ns(self) -> npt.NDArray[Any]:
        """(N,) uint64."""
    @property
    def cycles(self) -> npt.NDArray[Any]:
        """(N,) uint64."""
    @property
    def collisions(self) -> npt.NDArray[Any]:
        """(N,) uint32: collisions each frame brings."""
    @property
    def previous_outcome(self) -> npt.NDArray[Any]:
        """(N,) uint8: 0 none, 1 stopped, 2 timed out."""
    @property
    def previous_rejected(self) -> npt.NDArray[Any]:
        """(N,) uint32."""
    @property
    def frames_skipped(self) -> npt.NDArray[Any]:
        """(N,) uint64, since connect."""
    @property
    def timing(self) -> tuple[int, float, float]:
        """(steps, seconds in the SDK excluding blocked waits, seconds blocked waiting)."""
    def reset_timing(self) -> None: ...
    def close(self) -> None:
        """Disconnects every agent (idempotent). The agents close together: within about a
        second even when the host does not answer (a frozen process, a lost link)."""
    def __enter__(self) -> AgentGroup: ...
    def __exit__(self, *args: object) -> bool: ...
    def __len__(self) -> int: ...
    @property
    def ids(self) -> list[int]: ...
    @property
    def session(self) -> str: ...
    @property
    def config_path(self) -> str: ...
    @property
    def sync_mode(self) -> bool: ...
    @property
    def stop_timeout(self) -> float: ...
    @property
    def step_timeout(self) -> float | None: ...
    @property
    def simulation_time_per_frame(self) -> float: ...
    @property
    def cameras(self) -> list[Camera]: ...
    @property
    def transports(self) -> list[str]: ...
    @property
    def closed(self) -> bool: ...


@final
class HostFrame:
    """One agent's sensor frame of the current cycle, loaned by ``Host.loan``: write its
    images (writable numpy views of the frame's memory, no copy), pose and reward, then
    ``Host.publish`` it. ``publish`` raises ``FrameInUseError`` while any view of the frame
    is alive: ``del`` the views first. Used only on the thread that loaned it."""

    @property
    def agent_id(self) -> int: ...
    @property
    def cycle(self) -> int: ...
    @property
    def sim_time_ns(self) -> int: ...
    @property
    def camera_names(self) -> list[str]: ...
    @property
    def published(self) -> bool: ...
    @property
    def views(self) -> int:
        """Numpy views of this frame alive now (``Host.publish`` requires 0)."""
    def image(self, name: str) -> npt.NDArray[Any]:
        """Camera ``name`` as a WRITABLE view of the frame: H×W×3/H×W×4/H×W uint8 or H×W
        float32. Raises ``KeyError`` for an unknown camera, ``UsageError`` after publish."""
    @property
    def images(self) -> dict[str, npt.NDArray[Any]]:
        """Every image by camera name (writable views), in camera order."""
    @property
    def vector_names(self) -> list[str]: ...
    def vector(self, name: str) -> npt.NDArray[Any]:
        """Vector ``name`` as a WRITABLE float32 view of the frame (``KeyError`` if unknown)."""
    @property
    def vectors(self) -> dict[str, npt.NDArray[Any]]:
        """Every vector by name (writable views)."""
    def set_pose(self, position: Sequence[float], rotation: Sequence[float]) -> None:
        """Body pose the agent reads: position (x, y, z) metres, rotation quaternion (x, y, z, w)."""
    def set_grid(self, position: Sequence[float], rotation_deg: Sequence[float]) -> None:
        """Grid position sensor: position (metres) and Euler rotation (degrees)."""
    def set_head_motion(
        self,
        velocity: Sequence[float],
        acceleration: Sequence[float],
        angular_velocity_deg: Sequence[float],
        angular_acceleration_deg: Sequence[float],
    ) -> None:
        """Head motion sensor (each x, y, z)."""
    def set_eye(
        self, rotation_deg: Sequence[float], rotation_velocity_deg: Sequence[float] = (0, 0, 0)
    ) -> None:
        """Eye position sensor: rotation (pan left, pan right, tilt) and its change per cycle."""
    def add_status(self, action_id: int, state: ActionState) -> bool:
        """Reports a new state of the agent's action ``action_id`` (once; repeated until read)."""
    def add_collision(self, action_id: int, collider_id: int) -> bool:
        """Reports a collision during action ``action_id`` (once; repeated until read)."""
    @property
    def reward(self) -> float: ...
    @reward.setter
    def reward(self, value: float) -> None: ...
    @property
    def memory_range(self) -> tuple[int, int]:
        """Address range of this frame's images (to check that arrays are views)."""

@final
class AgentReport:
    """One agent's part of a cycle (``CycleReport.agents``)."""

    @property
    def agent_id(self) -> int: ...
    @property
    def outcome(self) -> str:
        """``"stopped"``, ``"timed_out"``, ``"not_awaited"``, ``"async"``, ``"evicted"`` or ``"left"``."""
    @property
    def read_cycle(self) -> int | None: ...
    @property
    def evicted(self) -> bool: ...
    @property
    def rejoined(self) -> bool: ...
    @property
    def left(self) -> bool: ...
    @property
    def slow(self) -> bool: ...
    @property
    def commands(self) -> list[Command]:
        """The commands it sent this cycle, in order, as command objects (undecodable ones left out)."""
    @property
    def action_ids(self) -> list[int]:
        """The action id of each of ``commands``."""
    @property
    def invalid_commands(self) -> int:
        """Commands sent this cycle that do not decode (unknown kind, NaN/∞ argument)."""
    @property
    def actions(self) -> dict[str, npt.NDArray[Any] | int | None]:
        """Each configured action's value this cycle: float32 array (copy), int, or None."""
    @property
    def actions_rejected(self) -> int:
        """Action chunks refused this cycle (unknown, wrong length, out of bounds)."""

@final
class CycleReport:
    """What ``Host.collect`` returns: the cycle and every agent's report."""

    @property
    def cycle(self) -> int: ...
    @property
    def sim_time_ns(self) -> int: ...
    @property
    def timed_out(self) -> bool: ...
    @property
    def late_batches(self) -> int: ...
    @property
    def agents(self) -> list[AgentReport]: ...
    def agent(self, agent_id: int) -> AgentReport:
        """The report of agent ``agent_id`` (``KeyError`` for an unknown id)."""

@final
class Host:
    """The simulator side of a vrsync session, for simulators written in Python: serves
    the config's agents over their transports. Per cycle: ``loan`` → write → ``publish``
    for each agent, ``start``, ``collect``. Used only on the thread that created it."""

    def __init__(
        self,
        config: str | PathLike[str],
        *,
        session: str | None = None,
        agents: int | None = None,
    ) -> None: ...
    def wait_for_agents(self, timeout: float | None = None) -> None:
        """Waits until every agent is connected (``HostWaitTimeout`` after ``timeout`` s)."""
    def loan(self, agent_id: int) -> HostFrame:
        """Agent ``agent_id``'s frame for the current cycle."""
    def publish(self, frame: HostFrame) -> None:
        """Sends ``frame`` (``FrameInUseError`` while views of it are alive)."""
    def start(self) -> None:
        """Signals start to every agent, after the cycle's frames are published."""
    def collect(self) -> CycleReport:
        """Ends the cycle (waits for the stops, or the tick in async mode; Ctrl-C ends it)."""
    def set_rejected(self, agent_id: int, rejected: int) -> None:
        """How many of the agent's commands of this cycle the simulator rejected."""
    def is_connected(self, agent_id: int) -> bool:
        """Whether agent ``agent_id`` is connected now; a TCP agent whose link was lost
        counts as connected while its place is held for its return (``[sync]
        resume_window``)."""
    def stats(self) -> dict[str, int]:
        """Counters since the host was created."""
    def cameras(self, agent_id: int) -> list[Camera]:
        """Agent ``agent_id``'s cameras as configured, in image order."""
    def close(self) -> None:
        """Ends the session (idempotent)."""
    def __enter__(self) -> Host: ...
    def __exit__(self, *args: object) -> bool: ...
    @property
    def agent_ids(self) -> list[int]: ...
    @property
    def session(self) -> str: ...
    @property
    def config_path(self) -> str: ...
    @property
    def sync_mode(self) -> bool: ...
    @property
    def simulation_time_per_frame(self) -> float: ...
    @property
    def cycle(self) -> int: ...
    @property
    def sim_time_ns(self) -> int: ...
    @property
    def tcp_address(self) -> str | None:
        """``"host:port"`` where TCP agents connect (the bound port), or ``None``."""
    @property
    def closed(self) -> bool: ...
