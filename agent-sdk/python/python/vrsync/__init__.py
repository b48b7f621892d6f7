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

:class:`Host` is the other side, for simulators written in Python: it serves agents
(Rust, C++, Python, ...) over the config's transports, and each agent's images are
written straight into its frame through writable numpy views::

    with vrsync.Host("world.toml") as host:
        host.wait_for_agents()
        for cycle in range(1000):
            for agent_id in host.agent_ids:
                frame = host.loan(agent_id)
                frame.image("left")[:] = render(agent_id)   # or render(out=view)
                host.publish(frame)                         # no view may be alive here
            host.start()
            report = host.collect()                         # each agent's commands
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
    AgentReport,
    Camera,
    CancelMove,
    Collision,
    Command,
    CycleReport,
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
    Host,
    HostFrame,
    InteractId,
    InteractPos,
    Move,
    MoveAhead,
    MoveTo,
    PointId,
    PointPos,
    Pose,
    StackedSample,
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
    AgentLostError,
    ChannelMismatchError,
    ConfigError,
    ConnectionRefusedByHostError,
    FrameInUseError,
    HostClosedError,
    HostGoneError,
    HostNotFoundError,
    HostWaitTimeout,
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
    "AgentLostError",
    "AgentReport",
    "Camera",
    "CancelMove",
    "ChannelMismatchError",
    "Collision",
    "Command",
    "ConfigError",
    "ConnectionRefusedByHostError",
    "CycleReport",
    "EnvironmentReset",
    "EyeFixation",
    "EyeMovement",
    "EyePosition",
    "Frame",
    "FrameInUseError",
    "GraspId",
    "GraspPos",
    "GraspRelease",
    "GridPosition",
    "HeadMotion",
    "Host",
    "HostClosedError",
    "HostFrame",
    "HostGoneError",
    "HostNotFoundError",
    "HostWaitTimeout",
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
    "StackedSample",
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
