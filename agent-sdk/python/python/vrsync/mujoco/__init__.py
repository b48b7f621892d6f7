"""MuJoCo as a vrsync world: an MJCF scene served to agents in lock-step.

:class:`MujocoWorld` loads the scene named by a vrsync config's ``[world.mujoco]`` table
and binds it to the config's agents: a body whose pose is the agent's pose, MJCF
cameras rendered into the agent's camera images, ``qpos``/``qvel``/sensor values
written into its vectors, its actions written into actuator ``ctrl``, and an optional
reward hook. Each cycle it publishes every agent's frame through a host
(``vrsync.Host``), collects the agents' actions, and steps the physics by
``simulation_time_per_frame``::

    import vrsync
    from vrsync.mujoco import MujocoWorld

    with MujocoWorld("config/mujoco-rovers.toml") as world, \\
            vrsync.Host("config/mujoco-rovers.toml") as host:
        summary = world.run(host, frames=200)

Images are rendered by MuJoCo straight into the host's loaned frame (no intermediate
image). Rendering is headless: this package sets ``MUJOCO_GL=egl`` unless it is set
(``osmesa`` works too); it must be imported before anything else imports ``mujoco``
for that to count.

From the command line: ``python -m vrsync.mujoco run --config FILE`` (or
``vrsync-mujoco run``), ``python -m vrsync.mujoco bench``. Every config key is
documented in ``config/mujoco-rovers.toml``. Install with ``pip install vrsync[mujoco]``.
"""

from __future__ import annotations

import os

# The OpenGL platform is fixed when mujoco is first imported.
os.environ.setdefault("MUJOCO_GL", "egl")

# PyTorch's triton (an SB3 learner in the same process) registers its LLVM command-line
# options when it loads; if Mesa's llvmpipe (the headless EGL renderer) loaded the
# system's libLLVM first, torch later crashes with SIGSEGV as it builds an optimizer.
# Loaded before the first render, triton keeps its options apart. Without torch, nothing
# happens here.
try:
    import triton  # noqa: F401
except ImportError:
    pass

try:
    import mujoco as _mujoco  # noqa: F401
except ImportError as _e:  # pragma: no cover - depends on the environment
    raise ImportError(
        f"vrsync.mujoco needs the `mujoco` package ({_e}): pip install 'vrsync[mujoco]'"
    ) from _e

from .bench import bench_alone, physics_rate, render_rate
from .config import MujocoConfigError, WorldConfig, load_config
from .world import SUMMARY_KEYS, LocalFrame, MujocoWorld

__all__ = [
    "SUMMARY_KEYS",
    "LocalFrame",
    "MujocoConfigError",
    "MujocoWorld",
    "WorldConfig",
    "bench_alone",
    "load_config",
    "physics_rate",
    "render_rate",
]
