"""Headless rendering into memory the caller owns.

``mujoco.Renderer.render(out=view)`` reads the pixels straight into ``view`` when it is
a C-contiguous ``(H, W, 3)`` uint8 array, then flips it in place (rows come bottom-up
from OpenGL). ``view`` can be the host's loaned frame image: the pixels land in the
agent's shared-memory sample with no intermediate image. Any other ``out`` (strided,
another dtype) still works but costs MuJoCo a temporary image and a copy.

One ``mujoco.Renderer`` (an OpenGL context and framebuffer) is kept per image size, not
per camera: cameras of one size share it, each with its own prebuilt ``MjvCamera``.
Shadows cost ~15x at 84x84 on llvmpipe, so they are off unless the config asks
(``[world.mujoco] shadows = true``).

The OpenGL platform is chosen when ``mujoco`` is first imported, from ``MUJOCO_GL``:
:mod:`vrsync.mujoco` sets it to ``egl`` unless it is set already (``osmesa`` works too,
with Debian's ``libosmesa6``).
"""

from __future__ import annotations

import mujoco
import numpy as np
import numpy.typing as npt

__all__ = ["Renderers"]

# MuJoCo's default <visual><quality shadowsize>.
_DEFAULT_SHADOW_MAP_PX = 4096


class Renderers:
    """The renderers of one model: one per ``(height, width)``."""

    def __init__(self, model: mujoco.MjModel, *, shadows: bool = False) -> None:
        self._model = model
        self._shadows = shadows
        # Read when a renderer's context is made: with 0 no shadow map is allocated.
        if not shadows:
            model.vis.quality.shadowsize = 0
        elif model.vis.quality.shadowsize == 0:
            # Asked for, but the scene has no map (rovers.xml): MuJoCo's default size.
            model.vis.quality.shadowsize = _DEFAULT_SHADOW_MAP_PX
        self._by_size: dict[tuple[int, int], mujoco.Renderer] = {}
        self._cameras: dict[int, mujoco.MjvCamera] = {}
        self._option = mujoco.MjvOption()

    def renderer(self, height: int, width: int) -> mujoco.Renderer:
        """The renderer of images of this size (made on first use)."""
        key = (height, width)
        r = self._by_size.get(key)
        if r is None:
            r = mujoco.Renderer(self._model, height=height, width=width)
            r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self._shadows
            self._by_size[key] = r
        return r

    def camera(self, camera_id: int) -> mujoco.MjvCamera:
        """A fixed ``MjvCamera`` of MJCF camera ``camera_id`` (made once)."""
        cam = self._cameras.get(camera_id)
        if cam is None:
            cam = mujoco.MjvCamera()
            cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
            cam.fixedcamid = camera_id
            self._cameras[camera_id] = cam
        return cam

    def render(
        self, data: mujoco.MjData, camera_id: int, out: npt.NDArray[np.uint8]
    ) -> npt.NDArray[np.uint8]:
        """Renders MJCF camera ``camera_id`` of ``data``'s state into ``out``
        (``(H, W, 3)`` uint8, written in place) and returns ``out``."""
        height, width = out.shape[0], out.shape[1]
        r = self.renderer(height, width)
        r.update_scene(data, camera=self.camera(camera_id), scene_option=self._option)
        return r.render(out=out)  # type: ignore[no-any-return]

    def close(self) -> None:
        """Frees every OpenGL context (idempotent)."""
        for r in self._by_size.values():
            r.close()
        self._by_size.clear()

    def __enter__(self) -> Renderers:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
