"""A Gymnasium environment over one vrsync agent.

::

    import gymnasium as gym
    from vrsync.gym import VrsyncEnv

    env = VrsyncEnv("config/default.toml", agent_id=0)
    obs, info = env.reset(seed=0)
    for _ in range(100):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        if terminated or truncated:
            obs, info = env.reset()
    env.close()

One ``step`` is one lock-step cycle: the action's commands are sent with the stop, the
host advances the world by exactly ``simulation_time_per_frame``, and the next frame is
the observation. ``reset`` sends the protocol's trial reset (or, with
``options={"reset": "environment"}``, the environment reset) and returns the frame in
which the reset is done.

Channels: when the config gives the agent ``[[agent.action]]`` entries, the action space is
theirs (one action: its ``Box`` or ``Discrete``; several: a ``Dict`` by name) and each step
sends the action as channel values (continuous values clipped to their bounds) instead of
commands; ``[[agent.vector]]`` entries join the ``"dict"`` observation as ``Box`` entries.

The world's randomness comes from the host's config (``seed``); ``reset(seed=…)`` seeds
only this env's ``np_random`` (for your sampling), as Gymnasium asks.
"""

from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import Any, Union

import gymnasium
import numpy as np
from gymnasium import spaces

from . import (
    MAX_FRAMES_HELD,
    _channels,
    Agent,
    Command,
    EnvironmentReset,
    Frame,
    MoveAhead,
    TooManyFramesHeldError,
    TrialReset,
    Turn,
)

__all__ = ["VrsyncEnv", "DEFAULT_ACTIONS", "LateLearnerWarning"]

ActionEntry = Union[
    Command, MoveAhead, Callable[[Frame], Union[Command, Sequence[Command], None]], None
]
"""What a discrete action maps to: a command, a :class:`vrsync.MoveAhead` (a walk relative
to the body's heading), a function of the current frame returning command(s), or ``None``
(do nothing this cycle). The batched envs (:mod:`vrsync.vector`) take no functions."""


DEFAULT_ACTIONS: tuple[ActionEntry, ...] = (
    None,  # 0: do nothing
    MoveAhead(0.5),  # 1: walk 0.5 m straight ahead (resolved per frame: a Move)
    Turn(angle_deg=-30.0),  # 2: turn 30° to the left
    Turn(angle_deg=30.0),  # 3: turn 30° to the right
)
"""The default action set: ``Discrete(4)`` = nothing, forward 0.5 m, turn left 30°,
turn right 30°."""


class LateLearnerWarning(RuntimeWarning):
    """The learner took longer between two steps than the host's stop timeout, and this
    agent's ``wait_for_stop`` is ``"timeout"``, so the host went on without its commands
    for that cycle. (With ``"alive"``, the default, the host waits for a live learner.)"""


# Bounds of positions and depths in metres: finite (Gymnasium warns about infinite
# bounds), far beyond any world vr-sim builds.
_FAR_M = 1.0e6


def _box_for(camera: Any) -> spaces.Box:
    if camera.dtype == "float32":
        return spaces.Box(0.0, _FAR_M, shape=tuple(camera.shape), dtype=np.float32)
    return spaces.Box(0, 255, shape=tuple(camera.shape), dtype=np.uint8)


class VrsyncEnv(gymnasium.Env[dict[str, Any], Any]):
    """Gymnasium env for one vrsync agent (sync mode: one step = one cycle).

    Args:
        config: the vrsync config file the host runs with.
        agent_id: which agent of the config this env drives.
        actions: the discrete action set (see :data:`DEFAULT_ACTIONS`); ignored when
            ``action_space`` and ``action_fn`` are given, or when the config declares
            ``[[agent.action]]`` channels for the agent (their space is the action space).
        action_space: a custom action space; requires ``action_fn``.
        action_fn: ``action_fn(action, frame) -> Command | list[Command] | None``.
        terminated_fn: ``terminated_fn(frame) -> bool``; default: never terminates
            (wrap in ``gymnasium.wrappers.TimeLimit`` for episodes).
        observation: ``"dict"`` (default: a ``Dict`` of every camera plus ``"position"``
            and ``"rotation"``) or ``"camera"``: one camera's images as a plain ``Box``
            (so that e.g. SB3's ``CnnPolicy`` works); ``camera`` names it (default: the
            first camera).
        copy_observations: observations are fresh copies (the default, as Gymnasium
            expects); ``False`` returns read-only views into shared memory — fastest,
            but an agent can hold at most :data:`vrsync.MAX_FRAMES_HELD` (2) frames, the
            current one and one more: never store such views, and do not use
            frame-stacking wrappers (``FrameStackObservation`` keeps its last
            observations) with them. A ``step`` that would exceed the limit raises
            :class:`vrsync.TooManyFramesHeldError` *before* it sends anything, so the
            env stays usable: release the views and call ``step`` again.
        session: override the config's session name.
        connect_timeout: seconds to wait for the host.
        step_timeout: seconds to wait for the next frame in ``step``/``reset``
            (default ``agent.frame_wait``: without limit when the host waits for live
            agents, ``[sync] wait_for_stop = "alive"``, as a learner updating in another
            process holds the cycle; else ``2 × stop_timeout + 5``. A dead host ends the
            wait either way).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        config: str | PathLike[str],
        agent_id: int = 0,
        *,
        actions: Sequence[ActionEntry] = DEFAULT_ACTIONS,
        action_space: spaces.Space[Any] | None = None,
        action_fn: Callable[[Any, Frame], Command | Sequence[Command] | None] | None = None,
        terminated_fn: Callable[[Frame], bool] | None = None,
        observation: str = "dict",
        camera: str | None = None,
        copy_observations: bool = True,
        session: str | None = None,
        connect_timeout: float | None = None,
        step_timeout: float | None = None,
    ) -> None:
        if observation not in ("dict", "camera"):
            raise ValueError(f'observation must be "dict" or "camera", got {observation!r}')
        if camera is not None and observation != "camera":
            raise ValueError('camera= is for observation="camera"')
        if (action_space is None) != (action_fn is None):
            raise ValueError("give action_space and action_fn together (or neither)")
        if action_space is None and not actions:
            raise ValueError("actions must not be empty")
        self.agent = Agent.connect(
            config, agent_id, session=session, connect_timeout=connect_timeout
        )
        self._actions = tuple(actions)
        self._action_fn = action_fn
        # The config's [[agent.action]] channels, when it declares some and no custom
        # action space replaces them: the action goes to the host as channel values.
        self._channel_actions = self.agent.action_specs if action_space is None else []
        channel_space = _channels.action_space(self._channel_actions)
        self.action_space = (
            action_space
            if action_space is not None
            else channel_space
            if channel_space is not None
            else spaces.Discrete(len(self._actions))
        )
        self._terminated_fn = terminated_fn
        self._copy = copy_observations
        self._step_timeout = (
            step_timeout if step_timeout is not None else self.agent.frame_wait
        )
        cams = {c.name: _box_for(c) for c in self.agent.cameras}
        self._camera: str | None = None
        if observation == "camera":
            if not cams:
                self.agent.close()
                raise ValueError('observation="camera" needs a camera, and the agent has none')
            self._camera = camera if camera is not None else next(iter(cams))
            if self._camera not in cams:
                self.agent.close()
                raise ValueError(f"no camera {self._camera!r} (cameras: {list(cams)})")
            self.observation_space: spaces.Space[Any] = cams[self._camera]
        else:
            self.observation_space = spaces.Dict(
                {
                    **cams,
                    "position": spaces.Box(-_FAR_M, _FAR_M, shape=(3,), dtype=np.float32),
                    "rotation": spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32),
                    **_channels.vector_spaces(self.agent.vector_specs),
                }
            )
        self.frame: Frame | None = None
        """The current frame (the one the last observation came from)."""
        self._frame_at = 0.0
        self._episode_start_ns = 0
        self._episode_steps = 0
        self._episode_skipped = 0

    # ---- helpers -------------------------------------------------------------------
    def _observe(self, frame: Frame) -> Any:
        if self._camera is not None:
            img = frame.image(self._camera)
            return np.array(img) if self._copy else img
        obs: dict[str, Any] = {}
        for name, img in frame.images.items():
            obs[name] = np.array(img) if self._copy else img
        pose = frame.pose
        obs["position"] = np.array(pose.position, dtype=np.float32)
        obs["rotation"] = np.clip(np.array(pose.rotation, dtype=np.float32), -1.0, 1.0)
        for name, values in frame.vectors.items():
            obs[name] = np.array(values) if self._copy else values
        return obs

    def _info(self, frame: Frame) -> dict[str, Any]:
        # Only what is the same for the same seed and actions: the absolute cycle and the
        # action ids live on `self.frame` and `self.agent`.
        return {
            "episode_step": self._episode_steps,
            "episode_sim_time": (frame.sim_time_ns - self._episode_start_ns) * 1e-9,
            "collisions": [c.collider_id for c in frame.collisions],
            "previous_outcome": frame.previous_outcome,
            "frames_skipped": self.agent.frames_skipped - self._episode_skipped,
        }

    def _commands(self, action: Any, frame: Frame) -> list[Command]:
        if self._channel_actions:
            _channels.act(self.agent, self._channel_actions, action)
            return []
        if self._action_fn is not None:
            out = self._action_fn(action, frame)
        else:
            index = int(action)
            if not 0 <= index < len(self._actions):
                raise ValueError(f"action {action!r} is not in {self.action_space}")
            entry = self._actions[index]
            out = entry(frame) if callable(entry) and not isinstance(entry, Command) else entry
        if out is None:
            return []
        if isinstance(out, Command):
            return [out]
        return list(out)

    def _check_frames_held(self) -> None:
        """Raises TooManyFramesHeldError if the next wait could not receive, before
        anything is sent (so the env stays usable once the views are released)."""
        held = self.agent.frames_held
        # Released before the wait unless something besides this env refers to it (its
        # image views do): the env's attribute and getrefcount's argument are 2.
        if self.frame is not None and sys.getrefcount(self.frame) <= 2:
            held -= 1
        if held >= MAX_FRAMES_HELD:
            e = TooManyFramesHeldError(
                f"agent {self.agent.id} would hold {held + 1} frames after this step, more "
                f"than the {MAX_FRAMES_HELD} it may (the frame being read and one more): "
                "observations with copy_observations=False are views that keep their "
                "frames alive. Nothing was sent: drop the old observations (or copy what "
                "you keep, `arr.copy()`) and call step() again, or build the env with "
                "copy_observations=True (the default), which frame-stacking wrappers such "
                "as gymnasium.wrappers.FrameStackObservation need"
            )
            e.session, e.agent_id, e.max = self.agent.session, self.agent.id, MAX_FRAMES_HELD
            raise e

    def _send_stop(self, commands: list[Command]) -> None:
        """Sends `commands` and the stop for the current frame (warns if it is late)."""
        late = time.monotonic() - self._frame_at
        # With wait_for_stop = "alive" the host waits for this (live) learner: nothing lost.
        if (
            self.agent.sync_mode
            and self.agent.wait_for_stop == "timeout"
            and late > self.agent.stop_timeout
        ):
            warnings.warn(
                f"agent {self.agent.id}: the learner took {late:.2f} s between steps, more "
                f"than the host's stop_timeout of {self.agent.stop_timeout:g} s, so the host "
                "went on without this agent's commands (raise [sync] stop_timeout in the "
                "config, or step faster)",
                LateLearnerWarning,
                stacklevel=4,
            )
        for c in commands:
            self.agent.send(c)
        self.agent.stop()
        self.frame = None  # release the old frame before waiting for the next

    def _receive(self) -> Frame:
        """Waits for the next frame and makes it the current one."""
        frame = self.agent.wait(timeout=self._step_timeout)
        self._frame_at = time.monotonic()
        self.frame = frame
        return frame

    def _start_episode(self, kind: str) -> None:
        """Sends the reset of `kind` ("trial" or "environment") with this cycle's stop."""
        if kind not in ("trial", "environment"):
            raise ValueError(f'options["reset"] must be "trial" or "environment", got {kind!r}')
        if self.frame is None:
            self._receive()
        elif not self._copy:
            self._check_frames_held()
        self._send_stop([TrialReset() if kind == "trial" else EnvironmentReset()])

    def _episode_begun(self, frame: Frame) -> tuple[dict[str, Any], dict[str, Any]]:
        self._episode_start_ns = frame.sim_time_ns
        self._episode_steps = 0
        self._episode_skipped = self.agent.frames_skipped
        return self._observe(frame), self._info(frame)

    def _step_done(self, frame: Frame) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        self._episode_steps += 1
        terminated = bool(self._terminated_fn(frame)) if self._terminated_fn else False
        return self._observe(frame), float(frame.reward), terminated, False, self._info(frame)

    # ---- the Gymnasium API ---------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Resets the trial (``options={"reset": "environment"}`` resets the whole
        environment) and returns the observation of the frame in which it is done."""
        super().reset(seed=seed)
        self._start_episode((options or {}).get("reset", "trial"))
        return self._episode_begun(self._receive())

    def step(
        self, action: Any
    ) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        """Sends the action's commands with this cycle's stop and returns the next frame's
        observation, its reward, ``terminated_fn(frame)``, ``False`` and an info dict."""
        if self.frame is None:
            raise RuntimeError(
                "call reset() before step(): this env has no current frame (it was not "
                "reset yet, or the last step/reset failed while waiting for its frame)"
            )
        if not self._copy:
            self._check_frames_held()
        self._send_stop(self._commands(action, self.frame))
        return self._step_done(self._receive())

    def close(self) -> None:
        """Disconnects the agent (the host evicts it and goes on)."""
        self.frame = None
        self.agent.close()
        super().close()
