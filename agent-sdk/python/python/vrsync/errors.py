"""The exceptions vrsync raises.

Every one is a :class:`VrsyncError`; where a built-in fits, it is that too, so generic
handlers work: :class:`HostGoneError` is a :class:`ConnectionError`,
:class:`WaitTimeoutError` and :class:`HostWaitTimeout` a :class:`TimeoutError`,
:class:`ConfigError` a :class:`ValueError`, :class:`FrameInUseError` a
:class:`BufferError`. Most carry the ``session`` and ``agent_id`` they concern as
attributes.
"""

from __future__ import annotations

__all__ = [
    "VrsyncError",
    "ConfigError",
    "HostNotFoundError",
    "VersionMismatchError",
    "AgentIdNotServedError",
    "AgentIdInUseError",
    "ChannelMismatchError",
    "ConnectionRefusedByHostError",
    "HostClosedError",
    "HostGoneError",
    "WaitTimeoutError",
    "TooManyFramesHeldError",
    "QueueFullError",
    "UsageError",
    "ProtocolError",
    "TransportError",
    "ActionError",
    "HostWaitTimeout",
    "FrameInUseError",
    "AgentLostError",
]


class VrsyncError(Exception):
    """Base class of every vrsync error."""

    session: str | None = None
    agent_id: int | None = None


class ConfigError(VrsyncError, ValueError):
    """The config file cannot be read, or is invalid (the message names file, line, key)."""

    path: str | None = None


class HostNotFoundError(VrsyncError, ConnectionError):
    """No host serves this session (and agent id) within the connect timeout."""

    waited: float | None = None


class VersionMismatchError(VrsyncError):
    """Host and agent speak different protocol versions or layouts (both are named)."""

    host_version: str | None = None
    agent_version: str | None = None


class AgentIdNotServedError(VrsyncError, ConnectionError):
    """The session's host runs but does not serve this agent id (``served`` lists its ids)."""

    served: list[int] | None = None


class AgentIdInUseError(VrsyncError, ConnectionError):
    """Another process is already connected as this agent id."""


class ChannelMismatchError(VrsyncError, ConnectionError):
    """The host's config declares other channels for this agent than the agent's config.

    Raised at connect. ``channel`` is the first channel that differs, ``table`` its kind
    (``"vector"`` or ``"action"``), ``host`` and ``agent`` what each config says of it
    (e.g. ``"6 floats"``, ``"a choice in 0..3"``, ``"none of that name there"``).
    """

    channel: str | None = None
    table: str | None = None
    host: str | None = None
    agent: str | None = None


class ConnectionRefusedByHostError(VrsyncError, ConnectionError):
    """The host refused the connection (e.g. a missing or wrong ``tcp_token``)."""


class HostClosedError(VrsyncError):
    """The host ended the session cleanly. ``Agent.frames()`` ends instead of raising it."""


class HostGoneError(VrsyncError, ConnectionError):
    """The host is gone without closing the session: its process crashed or was killed, or
    the link to it broke (the message says what the transport saw)."""


class WaitTimeoutError(VrsyncError, TimeoutError):
    """No new frame arrived within the timeout given to ``wait``/``frames``."""


class TooManyFramesHeldError(VrsyncError):
    """The agent cannot receive: image arrays of earlier frames keep too many frames alive.

    Copy what you keep beyond the current cycle (``arr.copy()``) or drop the arrays.
    ``max`` is how many frames an agent may hold.
    """

    max: int | None = None


class QueueFullError(VrsyncError):
    """More commands in one cycle than the config's ``max_commands_per_cycle``."""


class UsageError(VrsyncError):
    """An API call out of order, e.g. ``stop()`` before the first frame or twice a cycle."""


class ProtocolError(VrsyncError):
    """The host sent a frame that violates the protocol."""


class TransportError(VrsyncError):
    """The transport failed in a way not covered by a more specific error."""


class ActionError(VrsyncError, ValueError):
    """``Agent.act`` refused a value: an unknown action, the wrong length, a value outside
    the action's bounds or not finite, or a choice out of range. Nothing was queued.

    ``action`` is the action's name, ``agent_id`` the agent.
    """

    action: str | None = None
    agent_id: int | None = None


class HostWaitTimeout(VrsyncError, TimeoutError):
    """``Host.wait_for_agents`` timed out: ``missing`` lists the agents not connected
    (``left``: those of them that had connected and left again), ``waited`` the seconds."""

    missing: list[int] | None = None
    left: list[int] | None = None
    waited: float | None = None


class FrameInUseError(VrsyncError, BufferError):
    """``Host.publish`` of a frame while numpy views of it are alive.

    A published frame's memory belongs to its agent (and then to later cycles): a view
    kept past publish would write into it. ``del`` every array ``HostFrame.image`` returned
    (and the arrays made from them), then publish again; nothing was published. ``views``
    is how many were alive, ``cycle`` the frame's cycle.
    """

    cycle: int | None = None
    views: int | None = None


class AgentLostError(VrsyncError, ConnectionError):
    """The host lost an agent (its process died or its connection dropped) and the config
    says not to go on without it: ``on_agent_lost = "abort"``, or ``"wait"`` and it did
    not come back within ``connect_timeout``."""
