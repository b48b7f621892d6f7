"""A PettingZoo parallel environment: several vrsync agents driven from one process.

::

    from vrsync.pettingzoo import VrsyncParallelEnv

    env = VrsyncParallelEnv("config/default.toml")          # every agent of the config
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
    env.close()

The agents are one :class:`vrsync.AgentGroup`: one connection each, and one ``step`` is
one call into Rust that sends every agent's commands and stop and then waits for every
agent's next frame, so all act in the same cycle. Agent names are ``"agent_<id>"``.

With supersuit (parameter sharing, e.g. for Stable-Baselines3)::

    import supersuit as ss
    venv = ss.pettingzoo_env_to_vec_env_v1(VrsyncParallelEnv("config/default.toml"))
    venv = ss.concat_vec_envs_v1(venv, 1, num_cpus=0, base_class="stable_baselines3")

``concat_vec_envs_v1`` "copies" the env with cloudpickle; a ``VrsyncParallelEnv`` holds
live connections and cannot be copied, so within its own process unpickling gives back
*the same* env (``num_vec_envs=1``, ``num_cpus=0`` work), while a second copy, or one in
another process (``num_cpus > 0``), raises a ``TypeError`` that says so.
:class:`vrsync.sb3.VrsyncVecEnv` is the direct way to the same thing.
"""

from __future__ import annotations

import functools
import itertools
import os
import weakref
from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from . import AgentGroup, _channels
from .gym import DEFAULT_ACTIONS, ActionEntry
from .vector import OUTCOMES, _observation_spaces

__all__ = ["VrsyncParallelEnv"]

_LIVE: weakref.WeakValueDictionary[int, VrsyncParallelEnv] = weakref.WeakValueDictionary()
_TOKENS = itertools.count(1)


def _live_env(token: int, pid: int) -> VrsyncParallelEnv:
    """Unpickles a VrsyncParallelEnv: the live env itself, in its own process, once."""
    if pid != os.getpid():
        raise TypeError(
            "a VrsyncParallelEnv holds live connections to a vrsync host and cannot move to "
            "another process (supersuit's concat_vec_envs_v1 with num_cpus > 0, "
            "SubprocVecEnv): use num_cpus=0, or vrsync.sb3.VrsyncVecEnv"
        )
    env = _LIVE.pop(token, None)
    if env is None:
        raise TypeError("this VrsyncParallelEnv was closed or already unpickled")
    if env._claimed:
        raise TypeError(
            "a VrsyncParallelEnv cannot be copied (it is the connections to one world): "
            "concat_vec_envs_v1(..., num_vec_envs=1, num_cpus=0) uses it as it is; for more "
            "worlds run more hosts, one VrsyncParallelEnv each"
        )
    env._claimed = True
    return env


class VrsyncParallelEnv(ParallelEnv[str, Any, Any]):
    """PettingZoo ``ParallelEnv`` over several vrsync agents of one session.

    Args:
        config: the vrsync config file the host runs with.
        agent_ids: the agents to drive (default: every ``[[agent]]`` of the config); they
            must have the same cameras.
        actions: discrete action table for every agent (``None``, a command, a
            :class:`vrsync.MoveAhead` or a sequence of those; see
            :data:`vrsync.gym.DEFAULT_ACTIONS`).
        terminated_fn: ``terminated_fn(group) -> N booleans`` on the
            :class:`vrsync.AgentGroup` after each cycle (as in
            :class:`vrsync.vector.VrsyncVectorEnv`; row ``k`` is ``possible_agents[k]``).
        max_cycles: truncate every agent after this many steps of an episode.
        observation, camera: ``"dict"`` (default) or ``"camera"`` with the camera's name,
            as in :class:`vrsync.gym.VrsyncEnv`.
        copy_observations: fresh arrays per step (default); ``False`` gives rows of the
            group's arrays, overwritten by the next step.
        session, connect_timeout, step_timeout: as for :class:`vrsync.AgentGroup`.

    Agents whose episode ended keep stopping each cycle (the host never waits for them)
    but get no observation until ``reset``.
    """

    metadata = {"render_modes": [], "name": "vrsync_parallel_v0", "is_parallelizable": True}
    render_mode = None

    def __init__(
        self,
        config: str | PathLike[str],
        agent_ids: Sequence[int] | None = None,
        *,
        actions: Sequence[ActionEntry] = DEFAULT_ACTIONS,
        terminated_fn: Callable[[AgentGroup], Any] | None = None,
        max_cycles: int | None = None,
        observation: str = "dict",
        camera: str | None = None,
        copy_observations: bool = True,
        session: str | None = None,
        connect_timeout: float | None = None,
        step_timeout: float | None = None,
    ) -> None:
        if not actions:
            raise ValueError("actions must not be empty")
        self._claimed = False
        self.group = AgentGroup.connect(
            config,
            None if agent_ids is None else list(agent_ids),
            session=session,
            connect_timeout=connect_timeout,
            step_timeout=step_timeout,
        )
        """The :class:`vrsync.AgentGroup` that drives the agents."""
        try:
            self.group.set_action_table(list(actions))
            self._obs_space, self._camera = _observation_spaces(
                self.group.cameras, observation, camera, self.group.vector_specs
            )
        except BaseException:
            self.group.close()
            raise
        self._actions_given = list(actions)
        # The config's [[agent.action]] channels replace the action table when there
        # are some (as in the vector env).
        self._channel_actions = self.group.action_specs
        self._act_space: spaces.Space[Any] = _channels.action_space(
            self._channel_actions
        ) or spaces.Discrete(len(actions))
        self.possible_agents = [f"agent_{i}" for i in self.group.ids]
        self._index = {a: k for k, a in enumerate(self.possible_agents)}
        self.agents: list[str] = []
        self.max_cycles = max_cycles
        self._terminated_fn = terminated_fn
        self._copy = copy_observations
        n = len(self.possible_agents)
        self._steps = 0
        self._episode_start_ns = np.zeros(n, dtype=np.uint64)
        self._episode_skipped = np.zeros(n, dtype=np.uint64)

    @functools.lru_cache(maxsize=None)
    def observation_space(self, agent: str) -> spaces.Space[Any]:
        """The observation space of ``agent``: its cameras and pose (or one camera)."""
        return self._obs_space

    @functools.lru_cache(maxsize=None)
    def action_space(self, agent: str) -> spaces.Space[Any]:
        """The action space of ``agent``."""
        return self._act_space

    # ---- helpers -------------------------------------------------------------------
    def _observation(self, k: int) -> Any:
        g = self.group
        if self._camera is not None:
            row = g.image(self._camera)[k]
            return row.copy() if self._copy else row
        obs = {name: (a[k].copy() if self._copy else a[k]) for name, a in g.images.items()}
        obs["position"] = g.positions[k].copy()
        obs["rotation"] = g.rotations[k].copy()
        for name, a in g.vectors.items():
            obs[name] = a[k].copy()
        return obs

    def _info(self, k: int) -> dict[str, Any]:
        g = self.group
        return {
            "episode_step": self._steps,
            "episode_sim_time": int(g.sim_time_ns[k] - self._episode_start_ns[k]) * 1e-9,
            "collisions": int(g.collisions[k]),
            "previous_outcome": OUTCOMES[int(g.previous_outcome[k])],
            "frames_skipped": int(g.frames_skipped[k] - self._episode_skipped[k]),
        }

    # ---- the PettingZoo API --------------------------------------------------------
    def reset(
        self, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Resets every agent's trial (``options={"reset": "environment"}``: the whole
        environment) in one cycle and returns each agent's frame in which it is done.
        ``seed`` seeds the action spaces (each agent's differently, reproducibly); the
        world's randomness is the host config's ``seed``."""
        if seed is not None:
            for k, a in enumerate(self.possible_agents):
                self.action_space(a).seed(seed + k)
        self.group.reset((options or {}).get("reset", "trial"))
        g = self.group
        self._episode_start_ns[:] = g.sim_time_ns
        self._episode_skipped[:] = g.frames_skipped
        self._steps = 0
        self.agents = list(self.possible_agents)
        observations = {a: self._observation(k) for k, a in enumerate(self.possible_agents)}
        infos = {a: self._info(k) for k, a in enumerate(self.possible_agents)}
        return observations, infos

    def step(self, actions: Mapping[str, Any]) -> tuple[
        dict[str, Any], dict[str, float], dict[str, bool], dict[str, bool], dict[str, Any]
    ]:
        """One cycle: every live agent's commands and stop, then every agent's next frame,
        in one call into Rust. Agents that ended their episode still stop each cycle (so
        the host never waits for them) but get no observation until ``reset``."""
        if not self.agents:
            raise RuntimeError("no live agents: call reset() first")
        unknown = set(actions) - set(self.agents)
        if unknown:
            raise ValueError(f"actions for agents that are not live: {sorted(unknown)}")
        live = set(self.agents)
        n = len(self.possible_agents)
        if self._channel_actions:
            self._step_channels(actions)
        elif len(actions) == n:
            self.group.step(np.fromiter((actions[a] for a in self.possible_agents), np.int64, n))
        else:
            table = self._actions_given
            self.group.step_commands(
                [table[int(actions[a])] if a in actions else None for a in self.possible_agents]
            )
        self._steps += 1
        g = self.group
        rewards = g.rewards
        if self._terminated_fn is not None:
            term = np.asarray(self._terminated_fn(g), dtype=np.bool_)
            if term.shape != (n,):
                raise ValueError(f"terminated_fn must return {n} booleans, got shape {term.shape}")
        else:
            term = np.zeros(n, dtype=np.bool_)
        trunc = self.max_cycles is not None and self._steps >= self.max_cycles
        out: tuple[dict[str, Any], ...] = ({}, {}, {}, {}, {})
        observations, rew, terminations, truncations, infos = out
        for k, a in enumerate(self.possible_agents):
            if a not in live:
                continue
            observations[a] = self._observation(k)
            rew[a] = float(rewards[k])
            terminations[a] = bool(term[k])
            truncations[a] = bool(trunc)
            infos[a] = self._info(k)
        self.agents = [a for a in self.agents if not (terminations[a] or truncations[a])]
        return observations, rew, terminations, truncations, infos

    def _step_channels(self, actions: Mapping[str, Any]) -> None:
        """One cycle with channel actions; agents without an action only stop."""
        active = np.array([a in actions for a in self.possible_agents], dtype=np.bool_)
        space = self._act_space
        filler = _channels.zero(space)  # the rows of agents that only stop: ignored
        rows = [actions.get(a, filler) for a in self.possible_agents]
        if isinstance(space, spaces.Dict):
            batch: Any = {name: np.stack([r[name] for r in rows]) for name in space.spaces}
        else:
            batch = np.stack([np.asarray(r) for r in rows])
        self.group.step_actions(
            _channels.batched_values(self._channel_actions, batch), active=active
        )

    def close(self) -> None:
        """Disconnects every agent (each leaves the session)."""
        self.group.close()
        self.agents = []

    def __reduce__(self) -> Any:
        # supersuit's concat_vec_envs_v1 "copies" the env with cloudpickle even with
        # num_cpus=0: hand back this live env instead (see the module docs).
        token = next(_TOKENS)
        _LIVE[token] = self
        return (_live_env, (token, os.getpid()))

    @property
    def unwrapped(self) -> VrsyncParallelEnv:
        return self
