"""Reward hooks for ``[world.mujoco.agent] reward = "module:function"``.

A hook is called once per agent and cycle, before the agent's frame is published, as
``fn(model, data, agent_id) -> float`` with the current state (``mujoco.MjModel``,
``mujoco.MjData``). It must not change ``data``. Keep it cheap: it runs in the host's
cycle for every agent.
"""

from __future__ import annotations

import math

import mujoco

__all__ = ["negative_target_distance"]

# (id(model), agent_id) -> (rover body id, target body id): name lookups once per model.
_IDS: dict[tuple[int, int], tuple[int, int]] = {}


def negative_target_distance(model: mujoco.MjModel, data: mujoco.MjData, agent_id: int) -> float:
    """Minus the horizontal distance (m) from body ``rover{id}`` to body ``target{id}``
    (the names of :func:`vrsync.mujoco.scenes.rovers`): 0 at the target, more negative
    further away.

    Raises:
        ValueError: the scene has no such bodies.
    """
    key = (id(model), agent_id)
    ids = _IDS.get(key)
    if ids is None:
        rover = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"rover{agent_id}")
        target = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"target{agent_id}")
        if rover < 0 or target < 0:
            raise ValueError(
                f"negative_target_distance needs bodies 'rover{agent_id}' and "
                f"'target{agent_id}' in the scene"
            )
        ids = _IDS[key] = (rover, target)
    a = data.xpos[ids[0]]
    b = data.xpos[ids[1]]
    return -math.hypot(float(a[0] - b[0]), float(a[1] - b[1]))
