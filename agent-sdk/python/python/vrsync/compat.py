"""The original Python client's names (``Annar4Interface``) over vrsync.

An agent script written for the original system ports by changing its import and its
constructor::

    # from annar4Interface import Annar4Interface
    # iface = Annar4Interface("127.0.0.1", 1337, 0, False)
    from vrsync.compat import Annar4Interface
    iface = Annar4Interface("config/default.toml", agentNo=0)

    iface.start()
    while True:
        while not iface.hasStartSyncReceived():
            time.sleep(0.001)
        if iface.checkImages():
            left, right = iface.getImageLeft(), iface.getImageRight()
        iface.sendAgentMovement(90.0, 0.5)
        iface.sendStopSync()

Differences from the original, on purpose:

- ``send*`` return the action id at once. The original blocked until the action finished,
  which cannot work in sync mode (the world advances only after the stop).
- ``sendStopSync`` really ends the cycle (the original sent an empty message).
- Images are numpy arrays (H×W×3 ``uint8``, copies), not PIL images:
  ``PIL.Image.fromarray(img)`` gives the old type.
- ``hasStartSyncReceived`` returns ``False`` once the host closed the session; check
  ``closed``. A dead host raises :class:`vrsync.HostGoneError`.
"""

from __future__ import annotations

from os import PathLike
from typing import Any

import numpy as np

from . import (
    ActionState,
    Agent,
    CancelMove,
    EnvironmentReset,
    EyeFixation,
    EyeMovement,
    Frame,
    GraspId,
    GraspPos,
    GraspRelease,
    HostClosedError,
    InteractId,
    InteractPos,
    Move,
    MoveTo,
    PointId,
    PointPos,
    TrialReset,
    Turn,
    WaitTimeoutError,
)

__all__ = ["Annar4Interface"]


class Annar4Interface:
    """The original ``Annar4Interface`` API, one agent, over vrsync.

    Args:
        config: the vrsync config file the host runs with.
        agentNo: the agent id.
        session: override the config's session name.
        connect_timeout: seconds ``start()`` waits for the host.
    """

    def __init__(
        self,
        config: str | PathLike[str],
        agentNo: int = 0,
        *,
        session: str | None = None,
        connect_timeout: float | None = None,
    ) -> None:
        self._config = config
        self.agentNo = agentNo
        self._session = session
        self._connect_timeout = connect_timeout
        self._agent: Agent | None = None
        self._frame: Frame | None = None
        self._fresh: set[str] = set()
        self.closed = False
        #: The latest state per action id, as the original ``actionExecutionMap``.
        self.actionExecutionMap: dict[int, int] = {}

    # ---- life cycle ----------------------------------------------------------------
    def start(self) -> None:
        """Connects (the protocol's version check happens here)."""
        self._agent = Agent.connect(
            self._config,
            self.agentNo,
            session=self._session,
            connect_timeout=self._connect_timeout,
        )

    def stop(self, wait: bool = True) -> None:
        """Disconnects."""
        self._frame = None
        if self._agent is not None:
            self._agent.close()

    def _a(self) -> Agent:
        if self._agent is None:
            raise RuntimeError("call start() first")
        return self._agent

    # ---- receiving -----------------------------------------------------------------
    def hasStartSyncReceived(self) -> bool:
        """Whether a new cycle started (a new frame arrived); ``True`` once per cycle."""
        if self.closed:
            return False
        try:
            frame = self._a().wait(timeout=0)
        except WaitTimeoutError:
            return False
        except HostClosedError:
            self.closed = True
            return False
        self._frame = frame
        self._fresh = {"images", "grid", "head", "eye", "reward", "collision"}
        for s in frame.statuses:
            self.actionExecutionMap[s.action_id] = int(s.state)
        return True

    def _take(self, what: str) -> bool:
        return self._frame is not None and what in self._fresh

    def checkImages(self) -> bool:
        """Whether this cycle's images are there (then ``getImageLeft``/``Right``)."""
        return self._take("images")

    def _image(self, name: str) -> np.ndarray[Any, Any]:
        if self._frame is None:
            raise RuntimeError("no frame yet: wait for hasStartSyncReceived()")
        self._fresh.discard("images")
        return np.array(self._frame.image(name))

    def getImageLeft(self) -> np.ndarray[Any, Any]:
        """The left camera image (H×W×3 ``uint8``, a copy)."""
        return self._image("left")

    def getImageRight(self) -> np.ndarray[Any, Any]:
        """The right camera image (H×W×3 ``uint8``, a copy)."""
        return self._image("right")

    def getImageMain(self) -> np.ndarray[Any, Any]:
        """The ``main`` camera image, where the config has one."""
        return self._image("main")

    def checkGridSensorData(self) -> bool:
        """Whether this cycle's grid position is there."""
        return self._take("grid")

    def getGridSensorData(self) -> tuple[float, float, float, float, float, float]:
        """Grid position: x, y, z (metres) and Euler rotation x, y, z (degrees)."""
        self._fresh.discard("grid")
        g = self._current().grid
        return (*g.position, *g.rotation_deg)

    def checkHeadMotion(self) -> bool:
        """Whether this cycle's head motion is there."""
        return self._take("head")

    def getHeadMotion(self) -> tuple[float, ...]:
        """Head motion: velocity, acceleration, angular velocity, angular acceleration
        (12 floats, each x, y, z)."""
        self._fresh.discard("head")
        h = self._current().head_motion
        return (*h.velocity, *h.acceleration, *h.angular_velocity_deg, *h.angular_acceleration_deg)

    def checkEyePosition(self) -> bool:
        """Whether this cycle's eye position is there."""
        return self._take("eye")

    def getEyePosition(self) -> tuple[float, ...]:
        """Eye rotation (pan left, pan right, tilt) and its change per cycle (6 floats)."""
        self._fresh.discard("eye")
        e = self._current().eye
        return (*e.rotation_deg, *e.rotation_velocity_deg)

    def checkExternalReward(self) -> bool:
        """Whether this cycle brought a non-zero reward."""
        return self._take("reward") and self._current().reward != 0.0

    def getExternalReward(self) -> float:
        """The reward received since the previous cycle."""
        self._fresh.discard("reward")
        return float(self._current().reward)

    def checkActionExecState(self, actionID: int) -> bool:
        """Whether a state for ``actionID`` was reported."""
        return actionID in self.actionExecutionMap

    def getActionExecState(self, actionID: int) -> int:
        """The latest state of ``actionID``: 0 InExecution, 1 Finished, 2 Aborted,
        3 Walking, 4 Rotating, 5 WalkingRotating; -1 if none was reported yet."""
        return self.actionExecutionMap.get(actionID, -1)

    def checkCollision(self) -> bool:
        """Whether collisions happened since the previous cycle."""
        return self._take("collision") and bool(self._current().collisions)

    def getCollision(self) -> list[tuple[int, int]]:
        """Collisions since the previous cycle as ``(actionID, colliderID)`` pairs."""
        self._fresh.discard("collision")
        return [(c.action_id, c.collider_id) for c in self._current().collisions]

    def _current(self) -> Frame:
        if self._frame is None:
            raise RuntimeError("no frame yet: wait for hasStartSyncReceived()")
        return self._frame

    # ---- sending -------------------------------------------------------------------
    def _send(self, command: Any) -> int:
        action_id = self._a().send(command)
        self.actionExecutionMap[action_id] = int(ActionState.InExecution)
        return action_id

    def sendAgentMovement(self, degree: float, distance: float) -> int:
        """Walk towards ``degree`` (world heading) for ``distance`` metres."""
        return self._send(Move(heading_deg=degree, distance_m=distance))

    def sendAgentTurn(self, degree: float) -> int:
        """Turn by ``degree`` (clockwise seen from above)."""
        return self._send(Turn(angle_deg=degree))

    def sendAgentMoveTo(self, x: float, y: float, z: float, targetMode: int = 0) -> int:
        """Walk to the world position (x, y, z); ``targetMode`` is ignored, as it was."""
        return self._send(MoveTo(x, y, z))

    def sendAgentCancelMovement(self) -> int:
        """Cancel the running movement."""
        return self._send(CancelMove())

    def sendEyeMovement(self, panLeft: float, panRight: float, tilt: float = 0.0) -> int:
        """Move the eyes (degrees)."""
        return self._send(EyeMovement(panLeft, panRight, tilt))

    def sendEyeFixation(self, x: float, y: float, z: float) -> int:
        """Fixate the world point (x, y, z)."""
        return self._send(EyeFixation(x, y, z))

    def sendGraspID(self, objectID: int) -> int:
        """Grasp an object by id."""
        return self._send(GraspId(objectID))

    def sendGraspPos(self, x: float, y: float) -> int:
        """Grasp what is seen at a left-image position."""
        return self._send(GraspPos(x, y))

    def sendPointID(self, objectID: int) -> int:
        """Point at an object by id."""
        return self._send(PointId(objectID))

    def sendPointPos(self, x: float, y: float) -> int:
        """Point at what is seen at a left-image position."""
        return self._send(PointPos(x, y))

    def sendInteractionID(self, objectID: int) -> int:
        """Interact with an object by id."""
        return self._send(InteractId(objectID))

    def sendInteractionPos(self, x: float, y: float) -> int:
        """Interact with what is seen at a left-image position."""
        return self._send(InteractPos(x, y))

    def sendGraspRelease(self) -> int:
        """Release the grasped object."""
        return self._send(GraspRelease())

    def sendEnvironmentReset(self, type: int = 0) -> int:  # noqa: A002 (the original name)
        """Reset the environment."""
        return self._send(EnvironmentReset(type))

    def sendTrialReset(self, type: int = 0) -> int:  # noqa: A002 (the original name)
        """Reset the trial."""
        return self._send(TrialReset(type))

    def sendStopSync(self) -> None:
        """End this cycle: send the queued commands with the stop."""
        try:
            self._a().stop()
        except HostClosedError:
            self.closed = True
