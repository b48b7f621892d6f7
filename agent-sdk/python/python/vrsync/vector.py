"""A batched Gymnasium vector env: N agents of one world, stepped with one call into Rust.

::

    import numpy as np
    from vrsync.vector import VrsyncVectorEnv

    envs = VrsyncVectorEnv("config/default.toml", observation="camera", camera="left",
                           max_episode_steps=200)
    obs, infos = envs.reset(seed=0)          # obs: (N, H, W, 3) uint8
    for _ in range(1000):
        obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
    envs.close()

All N agents (default: every ``[[agent]]`` of the config) live in this process, one
connection each, driven by a :class:`vrsync.AgentGroup`: one ``step`` sends every
agent's commands and stop, then waits (GIL released once) for every agent's next frame
and writes the images straight into stacked ``(N, H, W, C)`` arrays. Every agent acts in
the same lock-step cycle: this is parameter sharing over the agents of one world (for
several independent worlds, run several hosts).

Autoreset: ``autoreset_mode="next_step"`` (the default, Gymnasium's) or
``"same_step"`` (what Stable-Baselines3 expects; :mod:`vrsync.sb3` uses it). See
:class:`VrsyncVectorEnv`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from . import AgentGroup, Command, EnvironmentReset, TrialReset, _channels
from .gym import _FAR_M, DEFAULT_ACTIONS, ActionEntry, _box_for

__all__ = ["VrsyncVectorEnv", "OUTCOMES"]

OUTCOMES = ("none", "stopped", "timed_out")
"""``infos["previous_outcome"]`` codes: how each agent's previous cycle ended."""


def _observation_spaces(
    cameras: Sequence[Any],
    observation: str,
    camera: str | None,
    vectors: Sequence[Any] = (),
) -> tuple[spaces.Space[Any], str | None]:
    """The single-agent observation space, and the camera of ``observation="camera"``."""
    if observation == "dict":
        if camera is not None:
            raise ValueError('camera= is for observation="camera"')
        cams = {c.name: _box_for(c) for c in cameras}
        return (
            spaces.Dict(
                {
                    **cams,
                    "position": spaces.Box(-_FAR_M, _FAR_M, shape=(3,), dtype=np.float32),
                    "rotation": spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32),
                    **_channels.vector_spaces(vectors),
                }
            ),
            None,
        )
    if observation == "camera":
        names = [c.name for c in cameras]
        if not names:
            raise ValueError('observation="camera" needs a camera, and the agents have none')
        name = camera if camera is not None else names[0]
        if name not in names:
            raise ValueError(f"no camera {name!r} (cameras: {names})")
        return _box_for(cameras[names.index(name)]), name
    raise ValueError(f'observation must be "dict" or "camera", got {observation!r}')


def _autoreset_mode(mode: str | AutoresetMode) -> AutoresetMode:
    if isinstance(mode, AutoresetMode):
        if mode is AutoresetMode.DISABLED:
            raise ValueError("autoreset_mode DISABLED is not supported: use next_step or same_step")
        return mode
    modes = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP}
    if mode not in modes:
        raise ValueError(f'autoreset_mode must be "next_step" or "same_step", got {mode!r}')
    return modes[mode]


class VrsyncVectorEnv(VectorEnv):  # type: ignore[type-arg]
    """Gymnasium ``VectorEnv`` over N vrsync agents of one session (sync mode: one step =
    one cycle for every agent).

    Args:
        config: the vrsync config file the host runs with.
        agent_ids: the agents (default: every ``[[agent]]`` of the config); they must
            have the same cameras. ``num_envs == len(agent_ids)``.
        actions: the discrete action table, one entry per action: ``None``, a
            :class:`vrsync.Command`, a :class:`vrsync.MoveAhead` or a sequence of those
            (default :data:`vrsync.gym.DEFAULT_ACTIONS`). Entries are built into a table in
            Rust once; a step passes only the N indices. Ignored when the config gives
            the agents ``[[agent.action]]`` channels: their space (``Box``,
            ``Discrete``, or a ``Dict`` of several) is then the action space, and each
            step sends the batched values (continuous ones clipped to their bounds) with
            :meth:`vrsync.AgentGroup.step_actions`. ``[[agent.vector]]`` entries join the
            ``"dict"`` observation, stacked ``(N, len)``.
        action_space, action_fn: a custom single-agent action space and
            ``action_fn(actions) -> sequence of N entries`` (each as in ``actions``),
            given the batched actions; give both or neither.
        terminated_fn: ``terminated_fn(group) -> N booleans``, evaluated after every
            cycle on the :class:`vrsync.AgentGroup` (``group.positions``,
            ``group.rewards``, ``group.collisions``, …); default: never terminates.
        max_episode_steps: truncate an agent's episode after this many steps.
        observation: ``"dict"`` (every camera, ``"position"``, ``"rotation"``) or
            ``"camera"`` (one camera's images as a plain ``Box``, e.g. for SB3's
            ``CnnPolicy``); ``camera`` names it (default: the first camera).
        autoreset_mode: ``"next_step"`` (default) or ``"same_step"``:

            - *next_step* (Gymnasium's default): the step after an agent's episode
              ended resets that agent (its action is ignored; it sends the reset
              instead) and returns its first observation with reward 0 and
              ``terminated = truncated = False``. Every step is exactly one cycle.
            - *same_step*: the step in which agents' episodes end also resets them: one
              more cycle runs in which those agents reset and the others send no
              command; the others' rewards of that cycle are added to the step's, so
              their transition spans two cycles (``infos["step_cycles"]``). The last
              observations are in ``infos["final_obs"]`` (and ``infos["final_info"]``).
        copy_observations: return fresh arrays each step (default). ``False`` returns
            the group's own arrays, which the next step overwrites in place (fastest;
            never keep them across steps); when the config stacks the agents' images
            (``[transport.shm] stacked_images = true``) the images are read-only views of
            the shared memory the host wrote, with no copy at all
            (:attr:`vrsync.AgentGroup.zero_copy`).
        reset_kind: ``"trial"`` (default) or ``"environment"``: the reset command sent.
        session, connect_timeout, step_timeout: as for :class:`vrsync.AgentGroup`.

    ``infos`` (arrays of N, each with its ``_key`` mask as Gymnasium's vector envs give):
    ``episode_step``, ``episode_sim_time`` (seconds), ``collisions`` (count this step),
    ``previous_outcome`` (0 none, 1 stopped, 2 timed out: :data:`OUTCOMES`),
    ``frames_skipped`` (in the episode), ``step_cycles``.

    The env holds live connections: it cannot be pickled or sent to another process;
    build it in the process that uses it. ``render`` is not supported.
    """

    metadata: dict[str, Any] = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}
    render_mode = None

    def __init__(
        self,
        config: str | PathLike[str],
        agent_ids: Sequence[int] | None = None,
        *,
        actions: Sequence[ActionEntry] = DEFAULT_ACTIONS,
        action_space: spaces.Space[Any] | None = None,
        action_fn: Callable[[Any], Sequence[Any]] | None = None,
        terminated_fn: Callable[[AgentGroup], Any] | None = None,
        max_episode_steps: int | None = None,
        observation: str = "dict",
        camera: str | None = None,
        autoreset_mode: str | AutoresetMode = "next_step",
        copy_observations: bool = True,
        reset_kind: str = "trial",
        session: str | None = None,
        connect_timeout: float | None = None,
        step_timeout: float | None = None,
    ) -> None:
        if (action_space is None) != (action_fn is None):
            raise ValueError("give action_space and action_fn together (or neither)")
        if action_space is None and not actions:
            raise ValueError("actions must not be empty")
        if reset_kind not in ("trial", "environment"):
            raise ValueError(f'reset_kind must be "trial" or "environment", got {reset_kind!r}')
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(f"max_episode_steps must be ≥ 1, got {max_episode_steps}")
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.group = AgentGroup.connect(
            config,
            None if agent_ids is None else list(agent_ids),
            session=session,
            connect_timeout=connect_timeout,
            step_timeout=step_timeout,
        )
        """The :class:`vrsync.AgentGroup` that drives the agents."""
        try:
            # The config's [[agent.action]] channels, unless a custom action space
            # replaces them: each step sends them as channel values.
            self._channel_actions = self.group.action_specs if action_fn is None else []
            channel_space = _channels.action_space(self._channel_actions)
            if channel_space is not None:
                single_action: spaces.Space[Any] = channel_space
            elif action_fn is None:
                self.group.set_action_table(list(actions))
                single_action = spaces.Discrete(len(actions))
            else:
                assert action_space is not None
                single_action = action_space
            self._action_fn = action_fn
            self.single_observation_space, self._camera = _observation_spaces(
                self.group.cameras, observation, camera, self.group.vector_specs
            )
        except BaseException:
            self.group.close()
            raise
        self.num_envs = len(self.group)
        self.single_action_space = single_action
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._terminated_fn = terminated_fn
        self._max_steps = max_episode_steps
        self._copy = copy_observations
        # Fresh observations with one copy from shared memory: the group writes each
        # step's images into new arrays (copying the group's arrays would be a second).
        self.group.fresh_images = copy_observations
        # No copy at all where the host stacks the agents' images in one sample.
        self.group.zero_copy = not copy_observations and self.group.stacked
        self._reset_kind = reset_kind
        self._reset_command: Command = (
            TrialReset() if reset_kind == "trial" else EnvironmentReset()
        )
        n = self.num_envs
        self._episode_steps = np.zeros(n, dtype=np.int64)
        self._episode_start_ns = np.zeros(n, dtype=np.uint64)
        self._episode_skipped = np.zeros(n, dtype=np.uint64)
        self._autoreset = np.zeros(n, dtype=np.bool_)
        self._all = np.ones(n, dtype=np.bool_)
        self._all.flags.writeable = False
        self._one_cycle = np.ones(n, dtype=np.int64)
        self._one_cycle.flags.writeable = False
        self._started = False

    # ---- helpers -------------------------------------------------------------------
    def _observe(self) -> Any:
        g = self.group
        if self._camera is not None:
            img = g.image(self._camera)
            return img.copy() if self._copy and not g.fresh_images else img
        copy_images = self._copy and not g.fresh_images
        obs = {name: (a.copy() if copy_images else a) for name, a in g.images.items()}
        obs["position"] = g.positions.copy() if self._copy else g.positions
        obs["rotation"] = g.rotations.copy() if self._copy else g.rotations
        for name, a in g.vectors.items():
            obs[name] = a.copy() if self._copy else a
        return obs

    def _infos(self, step_cycles: int = 1) -> dict[str, Any]:
        g = self.group
        all_ = self._all
        sim = (g.sim_time_ns - self._episode_start_ns).astype(np.float64) * 1e-9
        return {
            "episode_step": self._episode_steps.copy(),
            "_episode_step": all_,
            "episode_sim_time": sim,
            "_episode_sim_time": all_,
            "collisions": g.collisions.copy(),
            "_collisions": all_,
            "previous_outcome": g.previous_outcome.copy(),
            "_previous_outcome": all_,
            "frames_skipped": (g.frames_skipped - self._episode_skipped).astype(np.int64),
            "_frames_skipped": all_,
            "step_cycles": (
                self._one_cycle
                if step_cycles == 1
                else np.full(self.num_envs, step_cycles, dtype=np.int64)
            ),
            "_step_cycles": all_,
        }

    def _begin_episodes(self, which: np.ndarray) -> None:
        g = self.group
        self._episode_steps[which] = 0
        self._episode_start_ns[which] = g.sim_time_ns[which]
        self._episode_skipped[which] = g.frames_skipped[which]

    def _terminated(self) -> np.ndarray:
        if self._terminated_fn is None:
            return np.zeros(self.num_envs, dtype=np.bool_)
        t = np.asarray(self._terminated_fn(self.group), dtype=np.bool_)
        if t.shape != (self.num_envs,):
            raise ValueError(
                f"terminated_fn must return {self.num_envs} booleans, got shape {t.shape}"
            )
        return t

    def _truncated(self) -> np.ndarray:
        if self._max_steps is None:
            return np.zeros(self.num_envs, dtype=np.bool_)
        return self._episode_steps >= self._max_steps

    def _entries(self, actions: Any, reset: np.ndarray | None) -> list[Any]:
        assert self._action_fn is not None
        entries = list(self._action_fn(actions))
        if len(entries) != self.num_envs:
            raise ValueError(
                f"action_fn returned {len(entries)} entries for {self.num_envs} agents"
            )
        if reset is not None:
            for k in np.flatnonzero(reset):
                entries[k] = self._reset_command
        return entries

    def _cycle(self, actions: Any, reset: np.ndarray | None) -> None:
        """One cycle: `actions` for every agent, the reset for those in `reset`."""
        if self._channel_actions:
            self.group.step_actions(
                _channels.batched_values(self._channel_actions, actions),
                reset=reset,
                reset_kind=self._reset_kind,
            )
        elif self._action_fn is not None:
            self.group.step_commands(self._entries(actions, reset))
        elif reset is not None and reset.any():
            self.group.step(actions, reset=reset, reset_kind=self._reset_kind)
        else:
            self.group.step(actions)

    # ---- the Gymnasium API ---------------------------------------------------------
    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Resets every agent (its trial, or ``options={"reset": "environment"}``) in one
        cycle and returns the observations of the frame in which that is done.
        ``seed`` seeds only this env's ``np_random`` (the world's randomness is the
        host config's ``seed``)."""
        if isinstance(seed, Sequence):
            seed = seed[0] if seed else None
        super().reset(seed=seed)
        kind = (options or {}).get("reset", self._reset_kind)
        self.group.reset(kind)
        self._begin_episodes(self._all)
        self._autoreset[:] = False
        self._started = True
        return self._observe(), self._infos()

    def step(
        self, actions: Any
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One cycle for every agent: each sends its action's commands with its stop, then
        every agent's next frame gives its observation and reward (see the class docs
        for the autoreset modes)."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if self.autoreset_mode is AutoresetMode.NEXT_STEP:
            return self._step_next(actions)
        return self._step_same(actions)

    def _step_next(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        resetting = self._autoreset
        any_reset = bool(resetting.any())
        self._cycle(actions, resetting if any_reset else None)
        self._episode_steps += 1
        rewards = self.group.rewards.astype(np.float64)
        terminated = self._terminated()
        truncated = self._truncated()
        if any_reset:
            self._begin_episodes(resetting)
            rewards[resetting] = 0.0
            terminated[resetting] = False
            truncated[resetting] = False
        self._autoreset = terminated | truncated
        return self._observe(), rewards, terminated, truncated, self._infos()

    def _step_same(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        self._cycle(actions, None)
        self._episode_steps += 1
        rewards = self.group.rewards.astype(np.float64)
        terminated = self._terminated()
        truncated = self._truncated()
        done = terminated | truncated
        if not done.any():
            return self._observe(), rewards, terminated, truncated, self._infos()
        # The agents that ended reset in one more cycle; the others send nothing in it.
        infos = self._infos()
        final_obs = np.full(self.num_envs, None, dtype=object)
        final_info: dict[str, Any] = {}
        cycles = 1
        ending = done
        while ending.any():
            obs = self._observe_copy()
            for k in np.flatnonzero(ending):
                final_obs[k] = self._row(obs, k)
            info = self._infos(cycles)
            for key, value in info.items():
                if key.startswith("_"):
                    continue
                if key not in final_info:
                    final_info[key] = np.zeros_like(value)
                    final_info["_" + key] = np.zeros(self.num_envs, dtype=np.bool_)
                final_info[key][ending] = value[ending]
                final_info["_" + key] |= ending
            entries: list[Any] = [
                self._reset_command if e else None for e in ending
            ]
            self.group.step_commands(entries)
            cycles += 1
            self._begin_episodes(ending)
            going_on = ~done
            rewards[going_on] += self.group.rewards[going_on]
            self._episode_steps[ending] = 0
            # An agent that went on may end in the extra cycle: it resets in another.
            t_later = self._terminated() & going_on
            tr_later = self._truncated() & going_on & ~t_later
            terminated |= t_later
            truncated |= tr_later
            ending = t_later | tr_later
            done |= ending
        infos = self._infos(cycles)
        infos["final_obs"] = final_obs
        infos["_final_obs"] = done.copy()
        infos["final_info"] = final_info
        infos["_final_info"] = done.copy()
        return self._observe(), rewards, terminated, truncated, infos

    def _observe_copy(self) -> Any:
        copy, self._copy = self._copy, True
        try:
            return self._observe()
        finally:
            self._copy = copy

    def _row(self, obs: Any, k: int) -> Any:
        if isinstance(obs, dict):
            return {name: a[k] for name, a in obs.items()}
        return obs[k]

    def render(self) -> None:
        """Not supported: the observations are the images."""
        raise NotImplementedError("VrsyncVectorEnv does not render; the observations are the images")

    def close_extras(self, **kwargs: Any) -> None:
        """Disconnects every agent (each leaves the session)."""
        self.group.close()

    def __getstate__(self) -> Any:
        raise TypeError(
            "a VrsyncVectorEnv holds live connections to a vrsync host and cannot be pickled "
            "or sent to another process: build it in the process that uses it"
        )

    def __repr__(self) -> str:
        return f"VrsyncVectorEnv(num_envs={self.num_envs}, session={self.group.session!r})"
