"""A config's ``[world.mujoco]`` names resolved against a loaded ``MjModel``.

Everything a cycle needs is looked up once here: the body id of each agent's pose,
each camera's id, each vector's slices of ``qpos``/``qvel``/``sensordata``, each
action's ``ctrl`` indices (or, for a discrete action, its table of ``ctrl`` rows) and
the reward hook. A cycle then only copies slices: no name lookups, no dicts built.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import mujoco
import numpy as np
import numpy.typing as npt

from .config import (
    ActionSpec,
    AgentSpec,
    DiscreteBinding,
    MujocoConfigError,
    WorldConfig,
)

__all__ = [
    "ActionBinding",
    "AgentBinding",
    "CameraBinding",
    "ResetBinding",
    "RewardFn",
    "VectorBinding",
    "bind_agent",
    "load_hook",
]

#: A reward hook: ``fn(model, data, agent_id) -> float``.
RewardFn = Callable[[mujoco.MjModel, mujoco.MjData, int], float]

# Values a joint of each type has in qpos / qvel (free, ball, slide, hinge).
_QPOS_WIDTH = {0: 7, 1: 4, 2: 1, 3: 1}
_QVEL_WIDTH = {0: 6, 1: 3, 2: 1, 3: 1}


@dataclass(frozen=True)
class CameraBinding:
    """One vrsync camera rendered from one MJCF camera."""

    name: str
    camera_id: int
    width: int
    height: int
    format: str


@dataclass(frozen=True)
class VectorBinding:
    """One vector: ``(source array, start, stop, offset in the vector)`` per source."""

    name: str
    len: int
    parts: tuple[tuple[npt.NDArray[np.float64], int, int, int], ...]

    def fill(self, out: npt.NDArray[np.float32]) -> None:
        """Writes the current values into ``out`` (float32, length ``len``)."""
        for src, start, stop, at in self.parts:
            out[at : at + stop - start] = src[start:stop]


@dataclass(frozen=True)
class ActionBinding:
    """One action: the ``ctrl`` indices it writes, and for a discrete action the row
    of ``ctrl`` values of each choice."""

    name: str
    ctrl_index: npt.NDArray[np.intp]
    choices: npt.NDArray[np.float64] | None

    def apply(self, ctrl: npt.NDArray[np.float64], value: Any) -> None:
        """Writes ``value`` (floats for a continuous action, an int for a discrete one)
        into ``ctrl``. The bridge has checked lengths and bounds already."""
        if self.choices is not None:
            ctrl[self.ctrl_index] = self.choices[int(value)]
        else:
            ctrl[self.ctrl_index] = value


@dataclass(frozen=True)
class ResetBinding:
    """What a reset of one agent puts back: the ``qpos`` and ``qvel`` entries of every
    joint in its body's subtree (the body's own free joint, its wheels, ...) and the
    ``ctrl`` of every actuator that drives one of those joints."""

    qpos_index: npt.NDArray[np.intp]
    qvel_index: npt.NDArray[np.intp]
    ctrl_index: npt.NDArray[np.intp]

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """Puts the agent's joints back to the scene's initial configuration
        (``model.qpos0``), at rest, with its actuators' controls at 0."""
        data.qpos[self.qpos_index] = model.qpos0[self.qpos_index]
        data.qvel[self.qvel_index] = 0.0
        data.ctrl[self.ctrl_index] = 0.0


@dataclass(frozen=True)
class AgentBinding:
    """Everything one agent's cycle touches."""

    id: int
    body_id: int
    cameras: tuple[CameraBinding, ...]
    vectors: tuple[VectorBinding, ...]
    actions: dict[str, ActionBinding]
    reward: RewardFn | None
    reset: ResetBinding


def bind_agent(
    config: WorldConfig, agent: AgentSpec, model: mujoco.MjModel, data: mujoco.MjData
) -> AgentBinding:
    """Resolves ``agent``'s ``[world.mujoco]`` entry against ``model``.

    Raises:
        MujocoConfigError: a name the model lacks (body, camera, joint, sensor,
            actuator), a vector or action whose bound length differs from its
            ``len``/``n``, or a camera format other than rgb8.
    """
    b = config.bindings[agent.id]
    where = f"{config.path}: [world.mujoco] agent {agent.id}"

    def lookup(kind: mujoco.mjtObj, name: str, what: str, key: str) -> int:
        i = mujoco.mj_name2id(model, kind, name)
        if i < 0:
            raise MujocoConfigError(
                f"{where}: `{key}`: the scene has no {what} named {name!r} "
                f"({_known(model, kind, what)})"
            )
        return int(i)

    body_id = lookup(mujoco.mjtObj.mjOBJ_BODY, b.body, "body", "body")

    cameras = []
    for cam in agent.cameras:
        mj_name = b.cameras[cam.name]
        cid = lookup(mujoco.mjtObj.mjOBJ_CAMERA, mj_name, "camera", f"cameras.{cam.name}")
        if cam.format != "rgb8":
            raise MujocoConfigError(
                f"{where}: camera {cam.name!r} has format {cam.format!r}: a MuJoCo world "
                "renders rgb8 only"
            )
        if cam.width > model.vis.global_.offwidth or cam.height > model.vis.global_.offheight:
            raise MujocoConfigError(
                f"{where}: camera {cam.name!r} is {cam.width}x{cam.height} but the scene's "
                f"offscreen buffer is {model.vis.global_.offwidth}x"
                f"{model.vis.global_.offheight}: raise <visual><global offwidth=.. "
                "offheight=../> in the MJCF"
            )
        cameras.append(CameraBinding(cam.name, cid, cam.width, cam.height, cam.format))

    vectors = []
    for vec in agent.vectors:
        parts = []
        at = 0
        for source in b.vectors[vec.name]:
            src, start, stop = _source(model, data, source, lookup, f"vectors.{vec.name}")
            parts.append((src, start, stop, at))
            at += stop - start
        parts = _merge_runs(parts)
        if at != vec.len:
            raise MujocoConfigError(
                f"{where}: vector {vec.name!r} has len = {vec.len} in [[agent.vector]] but its "
                f"sources {list(b.vectors[vec.name])} give {at} values"
            )
        vectors.append(VectorBinding(vec.name, vec.len, tuple(parts)))

    actions = {}
    for act in agent.actions:
        actions[act.name] = _action(model, act, b.actions[act.name], lookup, where)

    reward = cast(RewardFn, load_hook(b.reward, config.path)) if b.reward else None
    reset = _reset_binding(model, body_id)
    return AgentBinding(
        agent.id, body_id, tuple(cameras), tuple(vectors), actions, reward, reset
    )


def _reset_binding(model: mujoco.MjModel, body_id: int) -> ResetBinding:
    """The joints in the subtree of ``body_id`` and the actuators that drive them."""

    def in_subtree(body: int) -> bool:
        while body != body_id and body != 0:
            body = int(model.body_parentid[body])
        return body == body_id

    joints = [j for j in range(model.njnt) if in_subtree(int(model.jnt_bodyid[j]))]
    qpos: list[int] = []
    qvel: list[int] = []
    for j in joints:
        kind = int(model.jnt_type[j])
        qpos.extend(range(int(model.jnt_qposadr[j]), int(model.jnt_qposadr[j]) + _QPOS_WIDTH[kind]))
        qvel.extend(range(int(model.jnt_dofadr[j]), int(model.jnt_dofadr[j]) + _QVEL_WIDTH[kind]))
    joint_set = set(joints)
    ctrl = [
        a
        for a in range(model.nu)
        if int(model.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)
        and int(model.actuator_trnid[a, 0]) in joint_set
    ]
    return ResetBinding(
        np.array(qpos, dtype=np.intp), np.array(qvel, dtype=np.intp), np.array(ctrl, dtype=np.intp)
    )


def _source(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    source: str,
    lookup: Callable[[mujoco.mjtObj, str, str, str], int],
    key: str,
) -> tuple[npt.NDArray[np.float64], int, int]:
    """The array and slice of ``"sensor:NAME"``, ``"qpos:JOINT"`` or ``"qvel:JOINT"``."""
    kind, _, name = source.partition(":")
    if kind == "sensor":
        i = lookup(mujoco.mjtObj.mjOBJ_SENSOR, name, "sensor", key)
        start = int(model.sensor_adr[i])
        return data.sensordata, start, start + int(model.sensor_dim[i])
    j = lookup(mujoco.mjtObj.mjOBJ_JOINT, name, "joint", key)
    jtype = int(model.jnt_type[j])
    if kind == "qpos":
        start = int(model.jnt_qposadr[j])
        return data.qpos, start, start + _QPOS_WIDTH[jtype]
    start = int(model.jnt_dofadr[j])
    return data.qvel, start, start + _QVEL_WIDTH[jtype]


def _merge_runs(
    parts: list[tuple[npt.NDArray[np.float64], int, int, int]],
) -> list[tuple[npt.NDArray[np.float64], int, int, int]]:
    """Joins sources that continue each other in the same array (two hinge joints of
    adjacent dofs, a sensor after a sensor): one slice copy each cycle instead of two."""
    merged: list[tuple[npt.NDArray[np.float64], int, int, int]] = []
    for src, start, stop, at in parts:
        if merged:
            psrc, pstart, pstop, pat = merged[-1]
            same_array = psrc.ctypes.data == src.ctypes.data and psrc.shape == src.shape
            if same_array and pstop == start and pat + (pstop - pstart) == at:
                merged[-1] = (psrc, pstart, stop, pat)
                continue
        merged.append((src, start, stop, at))
    return merged


def _action(
    model: mujoco.MjModel,
    spec: ActionSpec,
    bound: tuple[str, ...] | DiscreteBinding,
    lookup: Callable[[mujoco.mjtObj, str, str, str], int],
    where: str,
) -> ActionBinding:
    key = f"actions.{spec.name}"
    names = bound.actuators if isinstance(bound, DiscreteBinding) else bound
    index = np.array(
        [lookup(mujoco.mjtObj.mjOBJ_ACTUATOR, a, "actuator", key) for a in names], dtype=np.intp
    )
    if len(set(index.tolist())) != len(index):
        raise MujocoConfigError(
            f"{where}: action {spec.name!r} names an actuator twice: {list(names)}"
        )
    if isinstance(bound, DiscreteBinding):
        if len(bound.choices) != spec.n:
            raise MujocoConfigError(
                f"{where}: action {spec.name!r} has n = {spec.n} in [[agent.action]] but its "
                f"binding lists {len(bound.choices)} choices"
            )
        return ActionBinding(spec.name, index, np.array(bound.choices, dtype=np.float64))
    if len(index) != spec.len:
        raise MujocoConfigError(
            f"{where}: action {spec.name!r} has len = {spec.len} in [[agent.action]] but is "
            f"bound to {len(index)} actuators {list(names)}"
        )
    return ActionBinding(spec.name, index, None)


def _known(model: mujoco.MjModel, kind: mujoco.mjtObj, what: str) -> str:
    """A short list of the names the model has, for an error message."""
    count = {
        mujoco.mjtObj.mjOBJ_BODY: model.nbody,
        mujoco.mjtObj.mjOBJ_CAMERA: model.ncam,
        mujoco.mjtObj.mjOBJ_SENSOR: model.nsensor,
        mujoco.mjtObj.mjOBJ_JOINT: model.njnt,
        mujoco.mjtObj.mjOBJ_ACTUATOR: model.nu,
    }[kind]
    names = [mujoco.mj_id2name(model, kind, i) for i in range(count)]
    names = [n for n in names if n]
    plural = "bodies" if what == "body" else f"{what}s"
    if not names:
        return f"it has no named {plural}"
    shown = ", ".join(repr(n) for n in names[:8])
    more = f", ... ({len(names)} in all)" if len(names) > 8 else ""
    return f"{plural}: {shown}{more}"


def load_hook(spec: str, config_path: Path) -> Callable[..., Any]:
    """Imports ``"module:function"``. A module that cannot be imported is looked for as
    a file beside the config (``module`` → ``<config dir>/module.py``).

    Raises:
        MujocoConfigError: no such module or function, or it is not callable.
    """
    module_name, _, func_name = spec.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as e:
        file = config_path.parent / (module_name.replace(".", "/") + ".py")
        if not file.is_file():
            raise MujocoConfigError(
                f"{config_path}: hook {spec!r}: cannot import {module_name!r} ({e}), and "
                f"there is no {file}"
            ) from e
        mod_spec = importlib.util.spec_from_file_location(f"_vrsync_hook_{module_name}", file)
        if mod_spec is None or mod_spec.loader is None:
            raise MujocoConfigError(f"{config_path}: hook {spec!r}: cannot load {file}") from e
        module = importlib.util.module_from_spec(mod_spec)
        sys.modules[mod_spec.name] = module
        mod_spec.loader.exec_module(module)
    func = getattr(module, func_name, None)
    if not callable(func):
        raise MujocoConfigError(
            f"{config_path}: hook {spec!r}: module {module_name!r} has no function {func_name!r}"
        )
    return cast(Callable[..., Any], func)
