"""MuJoCo alone: the cost of a world's cycle without the bridge.

:func:`bench_alone` runs the same scene, the same physics steps and the same renders as
:meth:`MujocoWorld.step_cycle`, into plain numpy arrays (:class:`LocalFrame`) instead
of loaned frames, with no host: the reference the benchmark's MuJoCo rows compare the
bridge's cycle with (DESIGN §9: the bridge adds at most 10 % at 16 agents).
:func:`render_rate` and :func:`physics_rate` measure the two parts on their own.
"""

from __future__ import annotations

import time
from pathlib import Path

import mujoco
import numpy as np

from .config import WorldConfig
from .world import MujocoWorld

__all__ = ["bench_alone", "drive_all", "physics_rate", "render_rate"]


def drive_all(world: MujocoWorld) -> None:
    """Sets every actuator's ``ctrl`` to a fixed value inside its range (60 % of the
    upper limit), so that benchmarks step a moving scene the same way every time."""
    model = world.model
    limited = model.actuator_ctrllimited.astype(bool)
    high = np.where(limited, model.actuator_ctrlrange[:, 1], 1.0)
    world.data.ctrl[:] = 0.6 * high


def bench_alone(
    config: str | Path | WorldConfig,
    frames: int,
    *,
    agents: int | None = None,
    warmup: int = 3,
) -> float:
    """Seconds per cycle of the world alone: for each agent, render every camera into a
    numpy array, fill its vectors, pose and reward; then step the physics one cycle.

    ``agents`` resizes the config's agent list as ``--spawn-agents`` does; ``warmup``
    cycles (OpenGL contexts being made, caches) are run first and not counted.

    Raises:
        MujocoConfigError: as :class:`MujocoWorld`.
        ValueError: ``frames`` < 1.
    """
    if frames < 1:
        raise ValueError(f"frames must be at least 1, found {frames}")
    with MujocoWorld(config, agents=agents) as world:
        drive_all(world)
        local = world.local_frames()
        start = 0.0
        for i in range(warmup + frames):
            if i == warmup:
                start = time.perf_counter()
            for b in world.agents:
                world.write_frame(b, local[b.id])
            world.advance()
        return (time.perf_counter() - start) / frames


def render_rate(
    config: str | Path | WorldConfig,
    *,
    renders: int = 200,
    agents: int | None = None,
) -> float:
    """Renders per second of agent 0's first camera, at its configured size."""
    with MujocoWorld(config, agents=agents) as world:
        cam = world.agents[0].cameras[0]
        out = np.zeros((cam.height, cam.width, 3), np.uint8)
        for _ in range(5):
            world.renderers.render(world.data, cam.camera_id, out)
        start = time.perf_counter()
        for _ in range(renders):
            world.renderers.render(world.data, cam.camera_id, out)
        return renders / (time.perf_counter() - start)


def physics_rate(
    config: str | Path | WorldConfig,
    *,
    steps: int = 5000,
    agents: int | None = None,
) -> float:
    """Physics steps per second of the scene (every actuator driven, see
    :func:`drive_all`)."""
    with MujocoWorld(config, agents=agents) as world:
        drive_all(world)
        model, data = world.model, world.data
        start = time.perf_counter()
        for _ in range(steps):
            mujoco.mj_step(model, data)
        return steps / (time.perf_counter() - start)
