"""A PettingZoo parallel environment: several vrsync agents driven from one process.

::

    from vrsync.pettingzoo import VrsyncParallelEnv

    env = VrsyncParallelEnv("config/default.toml")          # every agent of the config
    observations, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
    env.close()

Each agent id gets its own connection; in one ``step`` every agent's commands and stop
go out first, then every agent waits for its next frame, so all act in the same cycle.
Agent names are ``"agent_<id>"``. Per-agent options are those of
:class:`vrsync.gym.VrsyncEnv`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping, Sequence
from os import PathLike
from typing import Any

import gymnasium
from gymnasium import spaces
from pettingzoo import ParallelEnv

from . import Frame, config_agent_ids
from .gym import DEFAULT_ACTIONS, ActionEntry, VrsyncEnv

__all__ = ["VrsyncParallelEnv"]


class VrsyncParallelEnv(ParallelEnv[str, dict[str, Any], Any]):
    """PettingZoo ``ParallelEnv`` over several vrsync agents of one session.

    Args:
        config: the vrsync config file the host runs with.
        agent_ids: the agents to drive (default: every ``[[agent]]`` of the config).
        actions: discrete action set for every agent (see :data:`vrsync.gym.DEFAULT_ACTIONS`).
        terminated_fn: ``terminated_fn(agent_name, frame) -> bool``.
        max_cycles: truncate every agent after this many steps of an episode.
        copy_observations, session, connect_timeout, step_timeout: as in
            :class:`vrsync.gym.VrsyncEnv`.
    """

    metadata = {"render_modes": [], "name": "vrsync_parallel_v0", "is_parallelizable": True}

    def __init__(
        self,
        config: str | PathLike[str],
        agent_ids: Sequence[int] | None = None,
        *,
        actions: Sequence[ActionEntry] = DEFAULT_ACTIONS,
        terminated_fn: Callable[[str, Frame], bool] | None = None,
        max_cycles: int | None = None,
        copy_observations: bool = True,
        session: str | None = None,
        connect_timeout: float | None = None,
        step_timeout: float | None = None,
    ) -> None:
        if agent_ids is None:
            agent_ids = config_agent_ids(config)
        self._envs: dict[str, VrsyncEnv] = {}
        try:
            for i in agent_ids:
                name = f"agent_{i}"
                self._envs[name] = VrsyncEnv(
                    config,
                    i,
                    actions=actions,
                    terminated_fn=(
                        (lambda f, n=name: terminated_fn(n, f)) if terminated_fn else None
                    ),
                    copy_observations=copy_observations,
                    session=session,
                    connect_timeout=connect_timeout,
                    step_timeout=step_timeout,
                )
        except BaseException:
            self.close()
            raise
        self.possible_agents = list(self._envs)
        self.agents: list[str] = []
        self.max_cycles = max_cycles
        self._steps = 0

    @functools.lru_cache(maxsize=None)
    def observation_space(self, agent: str) -> spaces.Space[Any]:
        """The observation space of ``agent``: its cameras and pose."""
        return self._envs[agent].observation_space

    @functools.lru_cache(maxsize=None)
    def action_space(self, agent: str) -> spaces.Space[Any]:
        """The action space of ``agent``."""
        return self._envs[agent].action_space

    def reset(
        self, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        """Resets every agent's trial (``options={"reset": "environment"}``: the whole
        environment) in one cycle and returns each agent's frame in which it is done."""
        kind = (options or {}).get("reset", "trial")
        for k, env in enumerate(self._envs.values()):
            # Each agent's generator seeded differently but reproducibly.
            gymnasium.Env.reset(env, seed=None if seed is None else seed + k)
            env._start_episode(kind)
        observations: dict[str, Any] = {}
        infos: dict[str, Any] = {}
        for name, env in self._envs.items():
            observations[name], infos[name] = env._episode_begun(env._receive())
        self.agents = list(self.possible_agents)
        self._steps = 0
        return observations, infos

    def step(self, actions: Mapping[str, Any]) -> tuple[
        dict[str, Any], dict[str, float], dict[str, bool], dict[str, bool], dict[str, Any]
    ]:
        """One cycle: every live agent's commands and stop, then every agent's next frame.
        Agents that ended their episode still stop each cycle (so the host never waits
        for them) but get no observation until ``reset``."""
        unknown = set(actions) - set(self.agents)
        if unknown:
            raise ValueError(f"actions for agents that are not live: {sorted(unknown)}")
        for name, env in self._envs.items():
            if env.frame is None:
                continue
            commands = env._commands(actions[name], env.frame) if name in actions else []
            env._send_stop(commands)
        self._steps += 1
        out: tuple[dict[str, Any], ...] = ({}, {}, {}, {}, {})
        for name, env in self._envs.items():
            frame = env._receive()
            if name not in self.agents:
                continue
            obs, rew, term, _trunc, info = env._step_done(frame)
            trunc = self.max_cycles is not None and self._steps >= self.max_cycles
            for d, v in zip(out, (obs, rew, term, trunc, info)):
                d[name] = v
        observations, rewards, terminations, truncations, infos = out
        self.agents = [a for a in self.agents if not (terminations[a] or truncations[a])]
        return observations, rewards, terminations, truncations, infos

    def close(self) -> None:
        """Disconnects every agent."""
        for env in self._envs.values():
            env.close()
        self.agents = []

