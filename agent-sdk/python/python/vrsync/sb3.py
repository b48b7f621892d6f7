"""A Stable-Baselines3 ``VecEnv`` over N agents of one world (parameter sharing).

::

    from stable_baselines3 import PPO
    from vrsync.sb3 import VrsyncVecEnv

    env = VrsyncVecEnv("config/default.toml", observation="camera", camera="left",
                       max_episode_steps=200)       # every [[agent]] of the config
    model = PPO("CnnPolicy", env, n_steps=128, verbose=1)
    model.learn(10_000)
    env.close()

This is :class:`vrsync.vector.VrsyncVectorEnv` (one :class:`vrsync.AgentGroup`: all N
agents in this process, stepped together with one call into Rust per cycle) with its
``same_step`` autoreset, seen through SB3's ``VecEnv`` API: ``dones`` and
``infos[i]["terminal_observation"]`` when agent ``i``'s episode ended (the returned
observation is then the first of its next episode), ``infos[i]["TimeLimit.truncated"]``
for ``max_episode_steps``. Do not wrap it in ``SubprocVecEnv``/``DummyVecEnv``: it is
already vectorised, and it holds live connections, so it cannot be pickled; build it in
the process that trains. Importing :mod:`vrsync` does not import SB3; this module does.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from os import PathLike
from typing import Any

import gymnasium
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from .vector import VrsyncVectorEnv

__all__ = ["VrsyncVecEnv"]


class VrsyncVecEnv(VecEnv):
    """SB3 ``VecEnv`` over N vrsync agents of one session.

    Args:
        config: the vrsync config file the host runs with.
        agent_ids: the agents (default: every ``[[agent]]`` of the config).
        **kwargs: the options of :class:`vrsync.vector.VrsyncVectorEnv` (``actions``,
            ``terminated_fn``, ``max_episode_steps``, ``observation``, ``camera``,
            ``session``, ``connect_timeout``, ``step_timeout``, …) except
            ``autoreset_mode`` (always ``same_step``, as SB3 expects).

    ``venv`` is the underlying :class:`~vrsync.vector.VrsyncVectorEnv` and ``venv.group``
    its :class:`vrsync.AgentGroup`. ``get_attr``/``set_attr``/``env_method`` act on that
    one env (every index gets the same answer); ``env_is_wrapped`` is ``False`` for all.
    """

    def __init__(
        self, config: str | PathLike[str], agent_ids: Sequence[int] | None = None, **kwargs: Any
    ) -> None:
        if "autoreset_mode" in kwargs:
            raise TypeError("VrsyncVecEnv always uses autoreset_mode='same_step' (SB3's)")
        self.venv = VrsyncVectorEnv(config, agent_ids, autoreset_mode="same_step", **kwargs)
        self.render_mode = None
        super().__init__(
            self.venv.num_envs, self.venv.single_observation_space, self.venv.single_action_space
        )
        self._actions: np.ndarray | None = None

    def reset(self) -> VecEnvObs:
        """Resets every agent; SB3 keeps the infos in ``reset_infos``."""
        seed = self._seeds[0] if self._seeds else None
        options = self._options[0] if self._options else None
        obs, infos = self.venv.reset(seed=seed, options=options or None)
        self.reset_infos = self._split(infos)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None:
            raise RuntimeError("step_async() must come before step_wait()")
        obs, rewards, terminated, truncated, infos = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        per_env = self._split(infos)
        if dones.any():
            final = infos["final_obs"]
            for k in np.flatnonzero(dones):
                per_env[k]["terminal_observation"] = final[k]
                per_env[k]["TimeLimit.truncated"] = bool(truncated[k] and not terminated[k])
        return obs, rewards.astype(np.float32), dones, per_env

    def _split(self, infos: dict[str, Any]) -> list[dict[str, Any]]:
        keys = [k for k in infos if not k.startswith("_") and k not in ("final_obs", "final_info")]
        return [{k: infos[k][i] for k in keys} for i in range(self.num_envs)]

    def close(self) -> None:
        """Disconnects every agent (each leaves the session)."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs: Any
    ) -> list[Any]:
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gymnasium.Wrapper[Any, Any, Any, Any]], indices: VecEnvIndices = None
    ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """Not supported (the observations are the images)."""
        return [None for _ in range(self.num_envs)]

    def _get_indices(self, indices: VecEnvIndices) -> Iterable[int]:
        return super()._get_indices(indices)

    def __getstate__(self) -> Any:
        raise TypeError(
            "a VrsyncVecEnv holds live connections to a vrsync host and cannot be pickled "
            "or sent to another process (e.g. by SubprocVecEnv): build it in the process "
            "that trains; it is already vectorised over the agents"
        )
