"""vrsync agent SDK for Python.

Connect to a vrsync host (a simulator), receive one sensor frame per cycle — camera
images as read-only numpy arrays that view shared memory without copying, pose, grid
position, head motion, eye position, reward, action statuses, collisions — and answer
with motor commands and a stop::

    import vrsync

    with vrsync.Agent.connect("config/default.toml", agent_id=0) as agent:
        for frame in agent.frames(timeout=10):      # ends cleanly when the host closes
            left = frame.image("left")              # H×W×3 uint8, a view, no copy
            agent.send(vrsync.Move(heading_deg=90, distance_m=0.5))
            agent.stop()

In sync mode the simulator advances by exactly one step per cycle, after every agent's
stop: simulated time never depends on how long the agent computed.

:class:`AgentGroup` drives N agents of one session from one process with one call into
Rust per lock-step cycle, writing every frame into stacked numpy arrays.

Also here: :mod:`vrsync.gym` (a Gymnasium env), :mod:`vrsync.vector` (a batched Gymnasium
vector env over N agents of one world), :mod:`vrsync.sb3` (a Stable-Baselines3 ``VecEnv``
on the same core), :mod:`vrsync.pettingzoo` (a PettingZoo parallel env) and
:mod:`vrsync.compat` (the original ``Annar4Interface`` names).
"""

from __future__ import annotations

from . import errors
from ._vrsync import (
    MAX_FRAMES_HELD,
    PROTOCOL_VERSION,
    Action,
    ActionState,
    ActionStatus,
    Agent,
    AgentGroup,
    Camera,
    CancelMove,
    Collision,
    Command,
    EnvironmentReset,
    EyeFixation,
    EyeMovement,
    EyePosition,
    Frame,
    GraspId,
    GraspPos,
    GraspRelease,
    GridPosition,
    HeadMotion,
    InteractId,
    InteractPos,
    Move,
    MoveAhead,
    MoveTo,
    PointId,
    PointPos,
    Pose,
    TrialReset,
    Turn,
    Vector,
    __version__,
    config_agent_ids,
)
from .errors import (
    ActionError,
    AgentIdInUseError,
    AgentIdNotServedError,
    ConfigError,
    ConnectionRefusedByHostError,
    HostClosedError,
    HostGoneError,
    HostNotFoundError,
    ProtocolError,
    QueueFullError,
    TooManyFramesHeldError,
    TransportError,
    UsageError,
    VersionMismatchError,
    VrsyncError,
    WaitTimeoutError,
)

__all__ = [
    "MAX_FRAMES_HELD",
    "PROTOCOL_VERSION",
    "Action",
    "ActionError",
    "ActionState",
    "ActionStatus",
    "Agent",
    "AgentGroup",
    "AgentIdInUseError",
    "AgentIdNotServedError",
    "Camera",
    "CancelMove",
    "Collision",
    "Command",
    "ConfigError",
    "ConnectionRefusedByHostError",
    "EnvironmentReset",
    "EyeFixation",
    "EyeMovement",
    "EyePosition",
    "Frame",
    "GraspId",
    "GraspPos",
    "GraspRelease",
    "GridPosition",
    "HeadMotion",
    "HostClosedError",
    "HostGoneError",
    "HostNotFoundError",
    "InteractId",
    "InteractPos",
    "Move",
    "MoveAhead",
    "MoveTo",
    "PointId",
    "PointPos",
    "Pose",
    "ProtocolError",
    "QueueFullError",
    "TooManyFramesHeldError",
    "TransportError",
    "TrialReset",
    "Turn",
    "UsageError",
    "Vector",
    "VersionMismatchError",
    "VrsyncError",
    "WaitTimeoutError",
    "__version__",
    "config_agent_ids",
    "errors",
]
