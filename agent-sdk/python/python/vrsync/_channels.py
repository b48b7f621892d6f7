"""Gymnasium spaces of an agent's channels (``[[agent.vector]]``, ``[[agent.action]]``), and
sending an action of such a space. Shared by the single-agent env, the vector env, the SB3
adapter and the PettingZoo env."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

from ._vrsync import Action, Agent, Vector


def vector_spaces(vectors: Sequence[Vector]) -> dict[str, spaces.Box]:
    """One ``Box`` per vector, with its configured bounds (``-inf``/``inf`` when none)."""
    return {
        v.name: spaces.Box(
            np.array(v.low, dtype=np.float32),
            np.array(v.high, dtype=np.float32),
            shape=(v.len,),
            dtype=np.float32,
        )
        for v in vectors
    }


def action_space(actions: Sequence[Action]) -> spaces.Space[Any] | None:
    """The space of the agent's actions: ``None`` without actions, the one action's space
    (``Box`` or ``Discrete``) for one, a ``Dict`` by name for several."""
    if not actions:
        return None
    by_name: dict[str, spaces.Space[Any]] = {}
    for a in actions:
        if a.kind == "discrete":
            assert a.n is not None
            by_name[a.name] = spaces.Discrete(a.n)
        else:
            by_name[a.name] = spaces.Box(
                np.array(a.low, dtype=np.float32),
                np.array(a.high, dtype=np.float32),
                shape=(a.len,),
                dtype=np.float32,
            )
    if len(by_name) == 1:
        return next(iter(by_name.values()))
    return spaces.Dict(by_name)


def _clipped(a: Action, value: Any) -> np.ndarray:
    """``value`` as float32, clipped to the bounds of continuous action ``a`` (per value;
    a batch of rows is clipped row by row)."""
    v = np.asarray(value, dtype=np.float32)
    return np.clip(v, np.asarray(a.low, dtype=np.float32), np.asarray(a.high, dtype=np.float32))


def act(agent: Agent, actions: Sequence[Action], action: Any) -> None:
    """Queues ``action`` (an element of :func:`action_space`) on ``agent``: one value per
    action. A continuous value outside its bounds is clipped to them first, as RL policies
    sample unbounded Gaussians (SB3 clips the same way)."""
    values = {actions[0].name: action} if len(actions) == 1 else action
    for a in actions:
        value = values[a.name]
        if a.kind == "discrete":
            agent.act(a.name, int(value))
        else:
            agent.act(a.name, _clipped(a, np.asarray(value, dtype=np.float32).reshape(-1)))


def batched_values(actions: Sequence[Action], batch: Any) -> dict[str, Any]:
    """The values of a batched action (an element of the vector env's action space) by
    action name, as :meth:`vrsync.AgentGroup.step_actions` takes them; continuous values
    clipped to their bounds."""
    values = {actions[0].name: batch} if len(actions) == 1 else dict(batch)
    out: dict[str, Any] = {}
    for a in actions:
        if a.name not in values:
            continue
        if a.kind == "discrete":
            out[a.name] = np.asarray(values[a.name], dtype=np.int64)
        else:
            out[a.name] = _clipped(a, values[a.name])
    return out


def zero(space: spaces.Space[Any]) -> Any:
    """An all-zero element of an action space of :func:`action_space` (a placeholder for
    the agents that send no action in a batched step)."""
    if isinstance(space, spaces.Dict):
        return {name: zero(s) for name, s in space.spaces.items()}
    if isinstance(space, spaces.Discrete):
        return 0
    return np.zeros(space.shape or (), dtype=np.float32)
