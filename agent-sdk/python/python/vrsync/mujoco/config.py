"""The parts of a vrsync config file that a MuJoCo world reads, checked.

A MuJoCo world reads the same TOML file as its host (:class:`vrsync.Host`): the
session, the cycle length, each ``[[agent]]``'s cameras and channels, and its own
table ``[world.mujoco]``, which binds the MJCF scene to the agents. The host checks
the bridge's keys in full; this module reads only what the world needs and checks the
``[world.mujoco]`` table completely (unknown keys are errors, named with the file).
Every key is documented in ``config/mujoco-rovers.toml``.

Nothing here imports MuJoCo: :mod:`vrsync.mujoco.binding` checks the names against
the loaded model.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ConfigError

__all__ = [
    "ActionSpec",
    "AgentBindingConfig",
    "AgentSpec",
    "CameraSpec",
    "DiscreteBinding",
    "MujocoConfigError",
    "VectorSpec",
    "WorldConfig",
    "load_config",
]

# The defaults of the config (transport/src/config): camera FOVs, the cycle length, the format.
_DEFAULT_FOV_H_DEG = 120.0
_DEFAULT_FOV_V_DEG = 90.0
_DEFAULT_FRAME_S = 0.1
_DEFAULT_FORMAT = "rgb8"
_SOURCE_KINDS = ("sensor", "qpos", "qvel")
_WORLD_KEYS = {"scene", "generator", "agent", "shadows", "pose_axes"}
_POSE_AXES = ("mujoco", "y_up")
_AGENT_KEYS = {"id", "body", "cameras", "vectors", "actions", "reward"}


class MujocoConfigError(ConfigError):
    """A ``[world.mujoco]`` binding that cannot work: the message names the file, the
    agent, the channel and what was expected against what was found."""


@dataclass(frozen=True)
class CameraSpec:
    """One ``[[agent.camera]]``: the image the host loans for it."""

    name: str
    width: int
    height: int
    format: str


@dataclass(frozen=True)
class VectorSpec:
    """One ``[[agent.vector]]``: ``len`` float32 values the world writes every cycle."""

    name: str
    len: int


@dataclass(frozen=True)
class ActionSpec:
    """One ``[[agent.action]]``: continuous (``len`` floats) or discrete (``n`` choices)."""

    name: str
    len: int | None
    n: int | None

    @property
    def discrete(self) -> bool:
        """Whether the action is a choice in ``0..n``."""
        return self.n is not None


@dataclass(frozen=True)
class AgentSpec:
    """One ``[[agent]]`` as the world sees it."""

    id: int
    cameras: tuple[CameraSpec, ...]
    vectors: tuple[VectorSpec, ...]
    actions: tuple[ActionSpec, ...]


@dataclass(frozen=True)
class DiscreteBinding:
    """A discrete action's binding: choice ``k`` writes ``choices[k]`` into the
    actuators' ``ctrl``."""

    actuators: tuple[str, ...]
    choices: tuple[tuple[float, ...], ...]


@dataclass(frozen=True)
class AgentBindingConfig:
    """One agent's ``[[world.mujoco.agent]]`` entry, names already formatted with its id."""

    id: int
    body: str
    cameras: Mapping[str, str]
    vectors: Mapping[str, tuple[str, ...]]
    actions: Mapping[str, tuple[str, ...] | DiscreteBinding]
    reward: str | None


@dataclass(frozen=True)
class WorldConfig:
    """Everything a :class:`~vrsync.mujoco.MujocoWorld` needs from the config file."""

    path: Path
    session: str
    seed: int
    sync_mode: bool
    transport: str
    simulation_time_per_frame: float
    scene: Path | None
    generator: str | None
    shadows: bool
    pose_axes: str
    agents: tuple[AgentSpec, ...]
    bindings: Mapping[int, AgentBindingConfig]

    def agent(self, agent_id: int) -> AgentSpec:
        """The ``[[agent]]`` of ``agent_id`` (``KeyError`` if the config has none)."""
        for a in self.agents:
            if a.id == agent_id:
                return a
        raise KeyError(agent_id)


def load_config(path: str | Path, *, agents: int | None = None) -> WorldConfig:
    """Reads ``path`` and checks its ``[world.mujoco]`` table.

    ``agents`` resizes the agent list to ids ``0..agents`` as ``vr-sim run
    --spawn-agents`` and ``vrsync.Host(agents=...)`` do: new agents copy the last
    ``[[agent]]``'s cameras and channels. An agent without a ``[[world.mujoco.agent]]``
    entry of its own uses the entry of the nearest lower id (so the last entry covers
    every added agent); names are formatted with the agent's id
    (``body = "rover{id}"``).

    Raises:
        MujocoConfigError: the file cannot be read or parsed, or a key is missing,
            unknown or of the wrong type.
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            doc = tomllib.load(f)
    except OSError as e:
        raise MujocoConfigError(f"cannot read config file {path}: {e}") from e
    except tomllib.TOMLDecodeError as e:
        raise MujocoConfigError(f"{path}: {e}") from e
    return _Reader(path).world(doc, agents)


class _Reader:
    """Parses one file; every error names it."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def fail(self, key: str, reason: str) -> MujocoConfigError:
        return MujocoConfigError(f"{self.path}: `{key}`: {reason}")

    def world(self, doc: Mapping[str, Any], count: int | None) -> WorldConfig:
        sync = self.table(doc, "sync")
        transport = self.table(doc, "transport")
        world = self.table(doc, "world")
        mj = self.table(world, "mujoco", "world.mujoco", required=True)
        unknown = sorted(set(mj) - _WORLD_KEYS)
        if unknown:
            raise self.fail(
                f"world.mujoco.{unknown[0]}",
                f"unknown key (known: {', '.join(sorted(_WORLD_KEYS))})",
            )
        scene_text = mj.get("scene")
        generator = mj.get("generator")
        if (scene_text is None) == (generator is None):
            raise self.fail(
                "world.mujoco",
                "needs exactly one of `scene` (an MJCF file) and `generator` "
                '("module:function" returning MJCF text)',
            )
        scene = None
        if scene_text is not None:
            scene = (self.path.parent / self.string(scene_text, "world.mujoco.scene")).resolve()
        if generator is not None:
            generator = self.hook(generator, "world.mujoco.generator")
        shadows = mj.get("shadows", False)
        if not isinstance(shadows, bool):
            raise self.fail("world.mujoco.shadows", "must be true or false")
        pose_axes = mj.get("pose_axes", "mujoco")
        if pose_axes not in _POSE_AXES:
            raise self.fail(
                "world.mujoco.pose_axes",
                f"must be one of {', '.join(repr(a) for a in _POSE_AXES)}, found {pose_axes!r}",
            )

        frame_s = sync.get("simulation_time_per_frame", sync.get("SimulationTimePerFrame"))
        frame_s = _DEFAULT_FRAME_S if frame_s is None else frame_s
        if (
            not isinstance(frame_s, int | float)
            or isinstance(frame_s, bool)
            or not math.isfinite(frame_s)
            or frame_s <= 0
        ):
            raise self.fail(
                "sync.simulation_time_per_frame", "must be a positive number of seconds"
            )
        sync_mode = sync.get("sync_mode", sync.get("SyncMode", True))

        agents = self.agents(doc.get("agent", []))
        declared = {a.id for a in agents}
        if count is not None:
            agents = _resize(agents, count, self.path)
        bindings = self.bindings(mj.get("agent", []), agents, declared)
        return WorldConfig(
            path=self.path,
            session=str(doc.get("session", "default")),
            seed=int(doc.get("seed", 0)),
            sync_mode=bool(sync_mode),
            transport=str(transport.get("kind", "shm")),
            simulation_time_per_frame=float(frame_s),
            scene=scene,
            generator=generator,
            shadows=shadows,
            pose_axes=pose_axes,
            agents=agents,
            bindings=bindings,
        )

    def table(
        self, doc: Mapping[str, Any], key: str, full: str | None = None, *, required: bool = False
    ) -> Mapping[str, Any]:
        value = doc.get(key)
        if value is None:
            if required:
                raise self.fail(full or key, "missing: a MuJoCo world needs this table")
            return {}
        if not isinstance(value, dict):
            raise self.fail(full or key, "must be a table")
        return value

    def string(self, value: object, key: str) -> str:
        if not isinstance(value, str) or not value:
            raise self.fail(key, f"must be a non-empty string, found {value!r}")
        return value

    def hook(self, value: object, key: str) -> str:
        text = self.string(value, key)
        module, sep, func = text.partition(":")
        if not sep or not module or not func:
            raise self.fail(key, f'must be "module:function", found {text!r}')
        return text

    def int_(self, value: object, key: str, low: int = 0) -> int:
        if not isinstance(value, int) or isinstance(value, bool) or value < low:
            raise self.fail(key, f"must be an integer >= {low}, found {value!r}")
        return value

    def agents(self, raw: object) -> tuple[AgentSpec, ...]:
        if not isinstance(raw, list) or not raw:
            raise self.fail("agent", "the config needs at least one [[agent]]")
        out = []
        for a in raw:
            aid = self.int_(a.get("id"), "agent.id")
            cams = []
            for c in a.get("camera", []):
                width = self.int_(c.get("width"), f"agent {aid} camera.width", 1)
                height = c.get("height")
                if height is None:
                    fov_h = float(c.get("fov_horizontal_deg", _DEFAULT_FOV_H_DEG))
                    fov_v = float(c.get("fov_vertical_deg", _DEFAULT_FOV_V_DEG))
                    height = derived_height(width, fov_h, fov_v)
                height = self.int_(height, f"agent {aid} camera.height", 1)
                cams.append(
                    CameraSpec(
                        name=self.string(c.get("name"), f"agent {aid} camera.name"),
                        width=width,
                        height=height,
                        format=str(c.get("format", _DEFAULT_FORMAT)),
                    )
                )
            vecs = tuple(
                VectorSpec(
                    name=self.string(v.get("name"), f"agent {aid} vector.name"),
                    len=self.int_(v.get("len"), f"agent {aid} vector.len", 1),
                )
                for v in a.get("vector", [])
            )
            acts = []
            for x in a.get("action", []):
                name = self.string(x.get("name"), f"agent {aid} action.name")
                if "n" in x:
                    acts.append(
                        ActionSpec(name, None, self.int_(x["n"], f"agent {aid} action {name}.n", 1))
                    )
                else:
                    acts.append(ActionSpec(name, _box_len(self, x, aid, name), None))
            out.append(AgentSpec(aid, tuple(cams), vecs, tuple(acts)))
        ids = [a.id for a in out]
        if len(set(ids)) != len(ids):
            raise self.fail("agent.id", f"ids must be unique, found {ids}")
        return tuple(sorted(out, key=lambda a: a.id))

    def bindings(
        self, raw: object, agents: Sequence[AgentSpec], declared: set[int]
    ) -> dict[int, AgentBindingConfig]:
        """Each agent's entry; ``declared``: the file's own [[agent]] ids, which every
        entry must name (a resize to fewer agents leaves the others unused)."""
        if not isinstance(raw, list) or not raw:
            raise self.fail("world.mujoco.agent", "needs at least one [[world.mujoco.agent]] entry")
        entries: dict[int, Mapping[str, Any]] = {}
        for e in raw:
            if not isinstance(e, dict):
                raise self.fail("world.mujoco.agent", "entries must be tables")
            eid = self.int_(e.get("id"), "world.mujoco.agent.id")
            unknown = sorted(set(e) - _AGENT_KEYS)
            if unknown:
                raise self.fail(
                    f"world.mujoco.agent (id {eid}).{unknown[0]}",
                    f"unknown key (known: {', '.join(sorted(_AGENT_KEYS))})",
                )
            if eid in entries:
                raise self.fail("world.mujoco.agent.id", f"id {eid} appears twice")
            entries[eid] = e
        stray = sorted(set(entries) - declared)
        if stray:
            raise self.fail(
                "world.mujoco.agent.id",
                f"id {stray[0]} has no [[agent]] (agents: {sorted(declared)})",
            )
        ordered = sorted(entries)

        def entry_for(aid: int) -> Mapping[str, Any]:
            # The entry of the nearest id at or below `aid`: an entry covers the agents
            # after it up to the next entry, so the last one covers every added agent.
            below = [i for i in ordered if i <= aid]
            return entries[below[-1] if below else ordered[0]]

        return {a.id: self.binding(entry_for(a.id), a) for a in agents}

    def binding(self, e: Mapping[str, Any], agent: AgentSpec) -> AgentBindingConfig:
        aid = agent.id
        where = f"world.mujoco.agent (id {aid})"

        def name(value: object, key: str) -> str:
            text = self.string(value, f"{where}.{key}")
            try:
                return text.format(id=aid)
            except (KeyError, IndexError, ValueError) as err:
                raise self.fail(f"{where}.{key}", f"bad name template {text!r}: {err}") from err

        body = name(e.get("body"), "body")
        cameras_raw = e.get("cameras", {})
        if not isinstance(cameras_raw, dict):
            raise self.fail(f"{where}.cameras", "must be a table: vrsync camera -> MJCF camera")
        cameras = {k: name(v, f"cameras.{k}") for k, v in cameras_raw.items()}
        known_cams = {c.name for c in agent.cameras}
        for c in agent.cameras:
            if c.name not in cameras:
                raise self.fail(
                    f"{where}.cameras",
                    f"agent {aid}'s camera {c.name!r} has no MJCF camera bound",
                )
        for k in cameras:
            if k not in known_cams:
                raise self.fail(
                    f"{where}.cameras.{k}",
                    f"agent {aid} has no camera {k!r} (cameras: {sorted(known_cams)})",
                )

        vectors_raw = e.get("vectors", {})
        if not isinstance(vectors_raw, dict):
            raise self.fail(f"{where}.vectors", "must be a table: vector -> list of sources")
        vectors: dict[str, tuple[str, ...]] = {}
        for k, sources in vectors_raw.items():
            if not isinstance(sources, list) or not sources:
                raise self.fail(f"{where}.vectors.{k}", "must be a non-empty list of sources")
            vectors[k] = tuple(name(s, f"vectors.{k}") for s in sources)
            for s in vectors[k]:
                kind, sep, target = s.partition(":")
                if not sep or kind not in _SOURCE_KINDS or not target:
                    raise self.fail(
                        f"{where}.vectors.{k}",
                        f"source {s!r} must be one of "
                        + ", ".join(f'"{x}:NAME"' for x in _SOURCE_KINDS),
                    )
        self.match_names(where, "vectors", aid, set(vectors), {v.name for v in agent.vectors})

        actions_raw = e.get("actions", {})
        if not isinstance(actions_raw, dict):
            raise self.fail(f"{where}.actions", "must be a table: action -> actuators")
        actions: dict[str, tuple[str, ...] | DiscreteBinding] = {}
        specs = {x.name: x for x in agent.actions}
        for k, v in actions_raw.items():
            key = f"{where}.actions.{k}"
            spec = specs.get(k)
            if isinstance(v, list):
                if spec is not None and spec.discrete:
                    raise self.fail(
                        key,
                        f"agent {aid}'s action {k!r} is discrete (n = {spec.n}): bind it as "
                        "{ actuators = [...], choices = [[...], ...] }",
                    )
                actions[k] = tuple(name(s, f"actions.{k}") for s in v)
            elif isinstance(v, dict):
                if spec is not None and not spec.discrete:
                    raise self.fail(
                        key,
                        f"agent {aid}'s action {k!r} is continuous (len = {spec.len}): "
                        "bind it as a list of actuator names",
                    )
                actions[k] = self.discrete(v, key, name, k)
            else:
                raise self.fail(key, "must be a list of actuators or a discrete binding table")
        self.match_names(where, "actions", aid, set(actions), set(specs))
        reward = e.get("reward")
        if reward is not None:
            reward = self.hook(reward, f"{where}.reward")
        return AgentBindingConfig(aid, body, cameras, vectors, actions, reward)

    def discrete(self, v: Mapping[str, Any], key: str, name: Any, action: str) -> DiscreteBinding:
        unknown = sorted(set(v) - {"actuators", "choices"})
        if unknown:
            raise self.fail(f"{key}.{unknown[0]}", "unknown key (known: actuators, choices)")
        acts = v.get("actuators")
        choices = v.get("choices")
        if not isinstance(acts, list) or not acts:
            raise self.fail(f"{key}.actuators", "must be a non-empty list of actuator names")
        if not isinstance(choices, list) or not choices:
            raise self.fail(f"{key}.choices", "must be a non-empty list of ctrl lists")
        names = tuple(name(s, f"actions.{action}.actuators") for s in acts)
        rows = []
        for i, row in enumerate(choices):
            if not isinstance(row, list) or len(row) != len(names):
                raise self.fail(
                    f"{key}.choices",
                    f"choice {i} must list {len(names)} ctrl values (one per actuator), "
                    f"found {row!r}",
                )
            if not all(isinstance(x, int | float) and not isinstance(x, bool) for x in row):
                raise self.fail(f"{key}.choices", f"choice {i} must hold numbers, found {row!r}")
            rows.append(tuple(float(x) for x in row))
        return DiscreteBinding(names, tuple(rows))

    def match_names(
        self, where: str, what: str, aid: int, bound: set[str], declared: set[str]
    ) -> None:
        for k in sorted(declared - bound):
            raise self.fail(
                f"{where}.{what}", f"agent {aid}'s {what[:-1]} {k!r} is not bound to the scene"
            )
        for k in sorted(bound - declared):
            raise self.fail(
                f"{where}.{what}.{k}",
                f"agent {aid} declares no {what[:-1]} {k!r} (its {what}: {sorted(declared)})",
            )


def _box_len(reader: _Reader, x: Mapping[str, Any], aid: int, name: str) -> int:
    """A continuous action's length: ``len``, else the length of a ``low``/``high`` list."""
    if "len" in x:
        return reader.int_(x["len"], f"agent {aid} action {name}.len", 1)
    for bound in ("low", "high"):
        if isinstance(x.get(bound), list):
            return len(x[bound])
    raise reader.fail(f"agent {aid} action {name}", "needs `len` (continuous) or `n` (discrete)")


def _resize(agents: tuple[AgentSpec, ...], count: int, path: Path) -> tuple[AgentSpec, ...]:
    """Ids ``0..count``; new ones copy the last agent's cameras and channels (the bridge's
    ``Config::with_agent_count``)."""
    if count < 1:
        raise MujocoConfigError(f"{path}: agent count must be at least 1, found {count}")
    by_id = {a.id: a for a in agents}
    last = agents[-1]
    return tuple(
        by_id.get(i, AgentSpec(i, last.cameras, last.vectors, last.actions)) for i in range(count)
    )


def derived_height(width_px: int, fov_h_deg: float, fov_v_deg: float) -> int:
    """The bridge's camera height when only the FOVs are given:
    ``round(W * tan(fov_v/2) / tan(fov_h/2))``."""
    h = width_px * math.tan(math.radians(fov_v_deg) / 2) / math.tan(math.radians(fov_h_deg) / 2)
    # Rust's f64::round: halves away from zero (Python's round() goes to even).
    return max(1, math.floor(h + 0.5))
