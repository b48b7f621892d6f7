"""vrsync.mujoco: the config binding, in-place rendering, stepping, determinism.

The world is driven by a fake host (the spec's loan/publish/start/collect over numpy
buffers, notes/channels-spec.md), so these tests need MuJoCo and an OpenGL platform but
no agents and no bridge host. Skipped when `mujoco` cannot be imported.
"""

from __future__ import annotations

import ctypes.util
import json
import math
import os
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import vrsync

# The OpenGL platform is chosen when mujoco is first imported.
os.environ.setdefault("MUJOCO_GL", "egl")
mujoco = pytest.importorskip("mujoco", reason="the `mujoco` package is not installed")

from vrsync.mujoco import (  # noqa: E402
    SUMMARY_KEYS,
    MujocoConfigError,
    MujocoWorld,
    bench_alone,
    load_config,
)
from vrsync.mujoco.agent import pick_actions  # noqa: E402
from vrsync.mujoco.rewards import negative_target_distance  # noqa: E402
from vrsync.mujoco.scenes import rovers, scene_path  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
ROVERS_TOML = ROOT / "config" / "mujoco-rovers.toml"
ROVERS_N_TOML = ROOT / "config" / "mujoco-rovers-n.toml"

# ---- a fake host: the spec's Python host API over numpy buffers -----------------------


@dataclass
class FakeFrame:
    """A loaned frame: images and vectors are views into one buffer per agent, as a
    loaned shared-memory sample would be."""

    agent_id: int
    images: dict[str, np.ndarray]
    vectors: dict[str, np.ndarray]
    position: tuple[float, ...] = (0.0, 0.0, 0.0)
    rotation: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
    reward: float = 0.0

    def image(self, name: str) -> np.ndarray:
        return self.images[name]

    def vector(self, name: str) -> np.ndarray:
        return self.vectors[name]

    def set_pose(self, position: Any, rotation: Any) -> None:
        self.position = tuple(float(x) for x in position)
        self.rotation = tuple(float(x) for x in rotation)


@dataclass
class FakeAgentReport:
    agent_id: int
    actions: dict[str, Any]
    outcome: str = "stopped"
    evicted: bool = False
    actions_rejected: int = 0
    invalid_commands: int = 0
    commands: list[Any] = field(default_factory=list)


@dataclass
class FakeReport:
    cycle: int
    agents: list[FakeAgentReport]
    timed_out: bool = False
    late_batches: int = 0


Policy = Callable[[int, int], dict[str, Any]]


class FakeHost:
    """loan/publish/start/collect in the spec's order, checked; ``policy(cycle, id)``
    gives each agent's actions; every published frame is kept (copied)."""

    def __init__(self, world: MujocoWorld, policy: Policy | None = None) -> None:
        self.agent_ids = [a.id for a in world.config.agents]
        self.simulation_time_per_frame = world.config.simulation_time_per_frame
        self.policy = policy or (lambda cycle, aid: {})
        self.cycle = 0
        self.buffers: dict[int, np.ndarray] = {}
        self.frames: dict[int, FakeFrame] = {}
        for a in world.config.agents:
            sizes = [c.height * c.width * 3 for c in a.cameras]
            # 64 spare bytes before each image: views start inside the buffer.
            buf = np.zeros(sum(s + 64 for s in sizes) + 4 * sum(v.len for v in a.vectors), np.uint8)
            images, at = {}, 0
            for c, s in zip(a.cameras, sizes, strict=True):
                at += 64
                images[c.name] = buf[at : at + s].reshape(c.height, c.width, 3)
                at += s
            vectors = {}
            for v in a.vectors:
                vectors[v.name] = buf[at : at + 4 * v.len].view(np.float32)
                at += 4 * v.len
            self.buffers[a.id] = buf
            self.frames[a.id] = FakeFrame(a.id, images, vectors)
        self.loaned: set[int] = set()
        self.published: dict[int, dict[str, Any]] = {}
        self.history: list[dict[int, dict[str, Any]]] = []
        self.started = False
        self.calls: list[str] = []
        self.rejected: dict[int, int] = {}

    def wait_for_agents(self, timeout: float | None = None) -> None:
        self.calls.append("wait_for_agents")

    def loan(self, agent_id: int) -> FakeFrame:
        assert not self.started, "loan after start"
        assert agent_id not in self.loaned, f"agent {agent_id} loaned twice in cycle {self.cycle}"
        self.loaned.add(agent_id)
        self.calls.append(f"loan {agent_id}")
        return self.frames[agent_id]

    def publish(self, frame: FakeFrame) -> None:
        assert frame.agent_id in self.loaned
        self.calls.append(f"publish {frame.agent_id}")
        self.published[frame.agent_id] = {
            "images": {k: v.copy() for k, v in frame.images.items()},
            "vectors": {k: v.copy() for k, v in frame.vectors.items()},
            "position": frame.position,
            "rotation": frame.rotation,
            "reward": frame.reward,
        }

    def start(self) -> None:
        assert set(self.published) == set(self.agent_ids), "start before every publish"
        self.started = True
        self.calls.append("start")

    def collect(self) -> FakeReport:
        assert self.started, "collect before start"
        self.calls.append("collect")
        report = FakeReport(
            self.cycle, [FakeAgentReport(i, self.policy(self.cycle, i)) for i in self.agent_ids]
        )
        self.history.append(self.published)
        self.published, self.loaned, self.started = {}, set(), False
        self.cycle += 1
        return report

    def set_rejected(self, agent_id: int, rejected: int) -> None:
        self.rejected[agent_id] = rejected

    def stats(self) -> dict[str, int]:
        return {}


def wander(cycle: int, agent_id: int) -> dict[str, Any]:
    """Deterministic actions for mujoco-rovers.toml: wheel speeds (agents 0..2) or a
    drive choice (agent 3); nothing every 4th cycle (the ctrl stays)."""
    if cycle % 4 == 3:
        return {"wheels": None, "drive": None}
    if agent_id == 3:
        return {"drive": (cycle // 2) % 5}
    s = float((cycle + agent_id) % 7 - 2)
    return {"wheels": np.array([4.0 * s, 3.0 * s + agent_id], np.float32)}


@pytest.fixture(scope="module")
def world() -> Any:
    with MujocoWorld(ROVERS_TOML) as w:
        yield w


# ---- config and binding ---------------------------------------------------------------

BASE = """
session = "mjtest"
[sync]
simulation_time_per_frame = {dt}
[[agent]]
id = 0
[[agent.camera]]
name = "eye"
width = 32
height = 24
format = "{fmt}"
[[agent.vector]]
name = "wheels"
len = {vlen}
[[agent.action]]
name = "wheels"
len = {alen}
low = -20.0
high = 20.0
[[agent.action]]
name = "drive"
n = {n}
[world.mujoco]
scene = "{scene}"
{world_extra}
[[world.mujoco.agent]]
id = 0
body = "{body}"
{agent_extra}
[world.mujoco.agent.cameras]
eye = "{camera}"
[world.mujoco.agent.vectors]
wheels = {sources}
[world.mujoco.agent.actions]
wheels = {actuators}
[world.mujoco.agent.actions.drive]
actuators = ["rover{{id}}_left", "rover{{id}}_right"]
choices = {choices}
"""

GOOD = {
    "dt": "0.05",
    "fmt": "rgb8",
    "vlen": "3",
    "alen": "2",
    "n": "2",
    "scene": str(scene_path()),
    "world_extra": "",
    "agent_extra": "",
    "body": "rover{{id}}",
    "camera": "rover{{id}}_eye",
    "sources": '["sensor:rover{{id}}_left_pos", "qpos:rover{{id}}_right", "qvel:rover{{id}}_left"]',
    "actuators": '["rover{{id}}_left", "rover{{id}}_right"]',
    "choices": "[[0.0, 0.0], [5.0, 5.0]]",
}


def write(tmp_path: Path, **changes: str) -> Path:
    path = tmp_path / "mj.toml"
    path.write_text(BASE.format(**{**GOOD, **changes}).replace("{{id}}", "{id}"))
    return path


def test_the_test_config_binds(tmp_path: Path) -> None:
    with MujocoWorld(write(tmp_path)) as w:
        (a,) = w.agents
        assert a.body_id == mujoco.mj_name2id(w.model, mujoco.mjtObj.mjOBJ_BODY, "rover0")
        assert [c.name for c in a.cameras] == ["eye"]
        assert sorted(a.actions) == ["drive", "wheels"]


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"vlen": "5"}, ["agent 0", "vector 'wheels'", "len = 5", "give 3"]),
        (
            {"alen": "3", "actuators": '["rover0_left", "rover0_right"]'},
            ["agent 0", "action 'wheels'", "len = 3", "2 actuators"],
        ),
        ({"n": "3"}, ["agent 0", "action 'drive'", "n = 3", "2 choices"]),
        ({"body": "nobody"}, ["agent 0", "`body`", "no body named 'nobody'", "'rover0'"]),
        ({"camera": "rover0_nose"}, ["agent 0", "`cameras.eye`", "no camera named 'rover0_nose'"]),
        (
            {"actuators": '["rover0_left", "rover0_wing"]'},
            ["agent 0", "`actions.wheels`", "no actuator named 'rover0_wing'"],
        ),
        (
            {"sources": '["sensor:rover0_left_pos", "sensor:sonar", "qvel:rover0_left"]'},
            ["`vectors.wheels`", "no sensor named 'sonar'"],
        ),
        (
            {"sources": '["qpos:axle", "qvel:rover0_left", "qvel:rover0_right"]'},
            ["`vectors.wheels`", "no joint named 'axle'"],
        ),
        ({"sources": '["joint:rover0_left"]'}, ["vectors.wheels", "source 'joint:rover0_left'"]),
        (
            {"choices": "[[0.0, 0.0], [5.0]]"},
            ["actions.drive.choices", "choice 1", "2 ctrl values"],
        ),
        ({"dt": "0.0512"}, ["simulation_time_per_frame = 0.0512", "whole number", "0.005"]),
        ({"fmt": "rgba8"}, ["agent 0", "'eye'", "'rgba8'", "rgb8 only"]),
        ({"world_extra": "shadow = true"}, ["world.mujoco.shadow", "unknown key"]),
        ({"agent_extra": "pose_body = 'x'"}, ["pose_body", "unknown key"]),
        ({"world_extra": 'generator = "vrsync.mujoco.scenes:rovers"'}, ["exactly one of"]),
        ({"scene": "missing.xml"}, ["world.mujoco.scene", "no such file", "missing.xml"]),
        (
            {"agent_extra": 'reward = "vrsync.mujoco.rewards:nothing"'},
            ["vrsync.mujoco.rewards:nothing", "no function 'nothing'"],
        ),
        (
            {"agent_extra": 'reward = "no_such_module_xyz:f"'},
            ["cannot import 'no_such_module_xyz'"],
        ),
        ({"agent_extra": 'reward = "just_a_name"'}, ["reward", '"module:function"']),
    ],
)
def test_binding_errors_name_agent_channel_and_lengths(
    tmp_path: Path, changes: dict[str, str], needles: list[str]
) -> None:
    path = write(tmp_path, **changes)
    with pytest.raises(MujocoConfigError) as e:
        MujocoWorld(path).close()
    message = str(e.value)
    assert str(path) in message
    for needle in needles:
        assert needle in message, f"{needle!r} not in {message!r}"


def test_a_config_error_is_a_value_error_and_a_vrsync_config_error(tmp_path: Path) -> None:
    import vrsync

    with pytest.raises(ValueError):
        load_config(write(tmp_path, world_extra="bogus = 1"))
    with pytest.raises(vrsync.ConfigError):
        load_config(write(tmp_path, world_extra="bogus = 1"))


def test_unbound_and_undeclared_channels_are_named(tmp_path: Path) -> None:
    text = write(tmp_path).read_text()
    (tmp_path / "a.toml").write_text(
        text.replace('[world.mujoco.agent.cameras]\neye = "rover{id}_eye"\n', "")
    )
    with pytest.raises(MujocoConfigError, match="camera 'eye' has no MJCF camera bound"):
        load_config(tmp_path / "a.toml")
    (tmp_path / "b.toml").write_text(text + "[world.mujoco.agent.cameras.extra]\n")
    with pytest.raises(MujocoConfigError, match="cameras"):
        load_config(tmp_path / "b.toml")
    (tmp_path / "c.toml").write_text(
        text.replace(
            "[world.mujoco.agent.actions]\n",
            '[world.mujoco.agent.actions]\ngear = ["rover0_left"]\n',
        )
    )
    with pytest.raises(MujocoConfigError, match="agent 0 declares no action 'gear'"):
        load_config(tmp_path / "c.toml")
    (tmp_path / "d.toml").write_text(text + '[[world.mujoco.agent]]\nid = 5\nbody = "rover1"\n')
    with pytest.raises(MujocoConfigError, match=r"id 5 has no \[\[agent\]\] \(agents: \[0\]\)"):
        load_config(tmp_path / "d.toml")


def test_the_shipped_config_binds_four_rovers(world: MujocoWorld) -> None:
    assert [a.id for a in world.agents] == [0, 1, 2, 3]
    assert world.steps_per_cycle == 10
    assert world.agents[3].actions["drive"].choices is not None
    assert world.agents[0].actions["wheels"].choices is None
    # Names are formatted per agent: agent 2 drives rover2's wheels.
    names = [
        mujoco.mj_id2name(world.model, mujoco.mjtObj.mjOBJ_ACTUATOR, int(i))
        for i in world.agents[2].actions["wheels"].ctrl_index
    ]
    assert names == ["rover2_left", "rover2_right"]


def test_added_agents_copy_the_last_entry_and_the_scene_grows_with_them() -> None:
    cfg = load_config(ROVERS_N_TOML, agents=6)
    assert [a.id for a in cfg.agents] == list(range(6))
    assert cfg.bindings[5].body == "rover5"
    with MujocoWorld(cfg) as w:
        assert len(w.agents) == 6
        assert mujoco.mj_name2id(w.model, mujoco.mjtObj.mjOBJ_BODY, "rover5") == w.agents[5].body_id
    # In the shipped file, agents 1 and 2 use entry 0 (continuous), 3 its own (discrete),
    # and added agents the last entry.
    more = load_config(ROVERS_TOML, agents=6)
    assert isinstance(more.bindings[1].actions["wheels"], tuple)
    assert more.bindings[5].body == "rover5" and "drive" in more.bindings[5].actions


def test_the_example_config_documents_every_key() -> None:
    from vrsync.mujoco import config as cfg

    text = ROVERS_TOML.read_text()
    keys = cfg._WORLD_KEYS | cfg._AGENT_KEYS | {"actuators", "choices"}  # noqa: SLF001
    for key in sorted(keys):
        assert f"{key} =" in text or f"{key}]" in text or f"`{key}`" in text, key
    for kind in cfg._SOURCE_KINDS:  # noqa: SLF001
        assert f'"{kind}:' in text, kind


def test_the_shipped_scene_is_the_generators_output() -> None:
    assert scene_path().read_text() == rovers(4), (
        "rovers.xml is out of date: write vrsync.mujoco.scenes.rovers(4) into it"
    )


# ---- rendering ------------------------------------------------------------------------


def test_render_writes_in_place_into_a_view_over_a_bigger_buffer(world: MujocoWorld) -> None:
    cam = world.agents[0].cameras[0]
    h, w = cam.height, cam.width
    buf = np.zeros(h * w * 3 + 1000, np.uint8)
    view = buf[500 : 500 + h * w * 3].reshape(h, w, 3)
    address = view.__array_interface__["data"][0]
    out = world.renderers.render(world.data, cam.camera_id, view)
    assert out is view
    assert view.__array_interface__["data"][0] == address
    assert view.any(), "nothing was rendered"
    # Only the view was written: the bytes around it are untouched.
    assert not buf[:500].any() and not buf[500 + h * w * 3 :].any()
    # The same pixels as MuJoCo's own fresh array (rows flipped the same way).
    fresh = world.renderers.renderer(h, w)
    fresh.update_scene(world.data, camera=cam.camera_id)
    np.testing.assert_array_equal(fresh.render(), view)


def test_one_renderer_per_size_and_shadows_off(world: MujocoWorld) -> None:
    world.renderers.render(world.data, 0, np.zeros((84, 84, 3), np.uint8))
    world.renderers.render(world.data, 1, np.zeros((84, 84, 3), np.uint8))
    world.renderers.render(world.data, 1, np.zeros((24, 32, 3), np.uint8))
    assert set(world.renderers._by_size) >= {(84, 84), (24, 32)}  # noqa: SLF001
    assert len(world.renderers._by_size) == len(set(world.renderers._by_size))  # noqa: SLF001
    for r in world.renderers._by_size.values():  # noqa: SLF001
        assert not r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW]
    assert world.model.vis.quality.shadowsize == 0


_GL_PROBE = """
import sys
import mujoco, numpy as np
m = mujoco.MjModel.from_xml_string(
    '<mujoco><worldbody><light pos="0 0 2"/><geom type="box" size=".1 .1 .1" rgba="1 0 0 1"/>'
    '<camera name="c" pos="0 -1 0" xyaxes="1 0 0 0 0 1"/></worldbody></mujoco>')
d = mujoco.MjData(m); mujoco.mj_forward(m, d)
r = mujoco.Renderer(m, 16, 16); r.update_scene(d, camera="c")
img = r.render(out=np.zeros((16, 16, 3), np.uint8))
sys.exit(0 if img[8, 8, 0] > 100 else 3)
"""


def _gl_backend_renders(backend: str) -> subprocess.CompletedProcess[str]:
    # A fresh process: the platform is fixed at import, and mujoco's import of EGL set
    # PYOPENGL_PLATFORM in this one.
    env = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"}
    env["MUJOCO_GL"] = backend
    return subprocess.run(
        [sys.executable, "-c", _GL_PROBE],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )


def test_headless_rendering_with_egl() -> None:
    r = _gl_backend_renders("egl")
    assert r.returncode == 0, f"MUJOCO_GL=egl cannot render (needs Mesa's libEGL):\n{r.stderr}"


def test_headless_rendering_with_osmesa() -> None:
    if ctypes.util.find_library("OSMesa") is None:
        pytest.skip("libOSMesa is not installed (Debian: libosmesa6)")
    r = _gl_backend_renders("osmesa")
    assert r.returncode == 0, f"MUJOCO_GL=osmesa cannot render:\n{r.stderr}"


# ---- cycles against the fake host -----------------------------------------------------


def test_a_cycle_follows_the_protocol_and_fills_every_channel() -> None:
    with MujocoWorld(ROVERS_TOML) as w:
        host = FakeHost(w, wander)
        addresses = {
            i: f.images["eye"].__array_interface__["data"][0] for i, f in host.frames.items()
        }
        w.run(host, frames=1)
        assert host.calls == (
            ["wait_for_agents"]
            + [c for i in range(4) for c in (f"loan {i}", f"publish {i}")]
            + ["start", "collect"]
        )
        # Cycle 0 shows the initial state; the frame was written through the loaned views.
        for i, f in host.frames.items():
            assert f.images["eye"].__array_interface__["data"][0] == addresses[i]
        first = host.history[0]
        model = mujoco.MjModel.from_xml_path(str(scene_path()))
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        for i in range(4):
            got = first[i]
            assert got["images"]["eye"].any()
            body = model.body(f"rover{i}").id
            np.testing.assert_allclose(got["position"], data.xpos[body], atol=1e-6)
            qw, qx, qy, qz = data.xquat[body]
            np.testing.assert_allclose(got["rotation"], (qx, qy, qz, qw), atol=1e-6)
            sensor = lambda name: data.sensor(name).data  # noqa: E731
            np.testing.assert_allclose(
                got["vectors"]["wheels"],
                np.concatenate(
                    [
                        sensor(f"rover{i}_left_pos"),
                        sensor(f"rover{i}_right_pos"),
                        data.joint(f"rover{i}_left").qvel,
                        data.joint(f"rover{i}_right").qvel,
                    ]
                ),
                atol=1e-6,
            )
            assert got["vectors"]["gyro"].shape == (3,)
            assert got["reward"] == pytest.approx(negative_target_distance(model, data, i))
            assert got["reward"] < 0
        # Different rovers see different pictures.
        assert not np.array_equal(first[0]["images"]["eye"], first[1]["images"]["eye"])


def test_pose_axes_y_up_gives_vrsyncs_heading(tmp_path: Path) -> None:
    text = ROVERS_TOML.read_text().replace('pose_axes = "mujoco"', 'pose_axes = "y_up"')
    text = text.replace('scene = "../', f'scene = "{ROOT}/')
    (tmp_path / "y.toml").write_text(text)
    with MujocoWorld(tmp_path / "y.toml") as w:
        host = FakeHost(w)
        w.step_cycle(host)
        for i in range(len(w.agents)):
            got = host.history[0][i]
            x, y, z, qw = got["rotation"]
            # vrsync.Pose.heading_deg: the body's forward (+z) turned by the rotation.
            fx = 2 * (x * z + qw * y)
            fz = 1 - 2 * (x * x + y * y)
            heading = math.degrees(math.atan2(fx, fz)) % 360
            # rovers(4) puts rover i at 90 * i degrees round the ring, facing outwards.
            assert heading == pytest.approx(90.0 * i, abs=1e-3)
            px, py, pz = got["position"]
            assert py == pytest.approx(0.05, abs=0.01)  # the height is vrsync's y
            assert math.hypot(px, pz) == pytest.approx(1.0, abs=0.01)
    with pytest.raises(MujocoConfigError, match="pose_axes"):
        (tmp_path / "z.toml").write_text(text.replace('"y_up"', '"z_down"'))
        load_config(tmp_path / "z.toml")


def test_actions_reach_ctrl_and_none_keeps_the_previous_value() -> None:
    with MujocoWorld(ROVERS_TOML) as w:
        plan = {
            0: {0: {"wheels": np.array([3.0, -2.0], np.float32)}, 3: {"drive": 1}},
            1: {0: {"wheels": None}, 3: {"drive": 4}},
        }
        host = FakeHost(w, lambda c, i: plan.get(c, {}).get(i, {}))
        ctrl = w.data.ctrl
        left0, right0 = w.agents[0].actions["wheels"].ctrl_index
        left3, right3 = w.agents[3].actions["drive"].ctrl_index
        w.step_cycle(host)
        assert (ctrl[left0], ctrl[right0]) == (3.0, -2.0)
        assert (ctrl[left3], ctrl[right3]) == (12.0, 12.0)
        w.step_cycle(host)
        assert (ctrl[left0], ctrl[right0]) == (3.0, -2.0)
        assert (ctrl[left3], ctrl[right3]) == (6.0, -6.0)
        assert w.commands_applied == 3


def test_each_cycle_steps_the_physics_by_simulation_time_per_frame() -> None:
    with MujocoWorld(ROVERS_TOML) as w:
        host = FakeHost(w, wander)
        calls = 0
        real_step = mujoco.mj_step

        def counting_step(m: Any, d: Any) -> None:
            nonlocal calls
            calls += 1
            real_step(m, d)

        import vrsync.mujoco.world as world_module

        world_module.mujoco.mj_step = counting_step  # type: ignore[attr-defined]
        try:
            summary = w.run(host, frames=3)
        finally:
            world_module.mujoco.mj_step = real_step  # type: ignore[attr-defined]
        assert calls == 3 * 10
        assert w.data.time == pytest.approx(3 * 0.05, abs=1e-12)
        assert summary["physics_steps"] == 30
        assert summary["sim_time_s"] == pytest.approx(0.15)


def _run_hash(frames: int, policy: Policy) -> tuple[str, dict[str, Any]]:
    with MujocoWorld(ROVERS_TOML) as w:
        host = FakeHost(w, policy)
        summary = w.run(host, frames=frames)
        return summary["trajectory_hash"], host.history[-1][0]


def test_same_actions_same_trajectory_hash() -> None:
    a, frame_a = _run_hash(12, wander)
    b, frame_b = _run_hash(12, wander)
    assert a == b
    np.testing.assert_array_equal(frame_a["images"]["eye"], frame_b["images"]["eye"])
    c, _ = _run_hash(12, lambda cycle, aid: wander(cycle + 1, aid))
    assert c != a, "other actions, same hash: the hash does not see the trajectory"


def test_the_rovers_move_when_driven() -> None:
    with MujocoWorld(ROVERS_TOML) as w:
        start = w.data.xpos[w.agents[0].body_id].copy()
        host = FakeHost(w, lambda c, i: {"wheels": np.array([15.0, 15.0], np.float32), "drive": 1})
        w.run(host, frames=10)
        moved = np.linalg.norm(w.data.xpos[w.agents[0].body_id][:2] - start[:2])
        # 0.5 s at up to 0.75 m/s (after spinning up): clearly driving, not tipping over.
        assert 0.05 < moved < 0.5
        assert w.data.xpos[w.agents[0].body_id][2] == pytest.approx(0.05, abs=0.02)


def test_summary_has_vr_sims_keys_and_counts_reports() -> None:
    with MujocoWorld(ROVERS_TOML) as w:
        host = FakeHost(w, wander)
        original = host.collect

        def collect() -> FakeReport:
            report = original()
            if report.cycle == 1:
                report.timed_out = True
                report.late_batches = 2
                report.agents[2].evicted = True
                report.agents[1].actions_rejected = 1
                report.agents[1].invalid_commands = 1
                report.agents[1].commands = ["Move"]
                report.agents[0].actions = {"wheels": None, "gear": 2}
            return report

        host.collect = collect  # type: ignore[method-assign]
        summary = w.run(host, frames=4)
    assert set(SUMMARY_KEYS) <= set(summary)
    assert summary["mode"] == "sync" and summary["transport"] == "shm"
    assert summary["agents"] == 4 and summary["frames"] == 4
    assert summary["stop_timeouts"] == 1 and summary["late_stops"] == 2
    assert summary["evicted_agents"] == [2]
    # A refused action, an undecodable command, a catalogue command (Move means nothing
    # here) and an action the world does not bind (gear).
    assert summary["commands_rejected"] == 4
    # The agents whose own commands the world rejected are told (the bridge's counts
    # reach them from the bridge).
    assert host.rejected == {0: 1, 1: 1}
    # wander: 4 agents act in cycles 0, 1, 2 and none in cycle 3; agent 0 not in cycle 1.
    assert summary["commands_applied"] == 11
    assert len(summary["trajectory_hash"]) == 64
    json.dumps(summary)


def test_a_host_serving_other_agents_is_refused() -> None:
    with MujocoWorld(ROVERS_TOML) as w:
        host = FakeHost(w)
        host.agent_ids = [0, 1]
        with pytest.raises(MujocoConfigError, match=r"host serves agents \[0, 1\]"):
            w.run(host, frames=1)
        host.agent_ids = [0, 1, 2, 3]
        host.simulation_time_per_frame = 0.1
        with pytest.raises(MujocoConfigError, match="simulation_time_per_frame"):
            w.run(host, frames=1)


def test_bench_alone_gives_seconds_per_cycle() -> None:
    per_cycle = bench_alone(ROVERS_TOML, 3, warmup=1)
    assert 0 < per_cycle < 60


def test_the_wandering_agent_picks_actions_within_bounds() -> None:
    rng = np.random.default_rng(1)
    specs = [
        {"name": "wheels", "len": 2, "low": [-20.0, -1.0], "high": [20.0, 1.0]},
        {"name": "torque", "len": 3, "low": -math.inf, "high": math.inf},
        {"name": "drive", "n": 5},
    ]
    for _ in range(50):
        a = pick_actions(specs, rng)
        assert a["wheels"].dtype == np.float32 and a["wheels"].shape == (2,)
        assert -20 <= a["wheels"][0] <= 20 and -1 <= a["wheels"][1] <= 1
        assert np.all(np.abs(a["torque"]) <= 1)
        assert 0 <= a["drive"] < 5 and isinstance(a["drive"], int)


def test_a_reset_puts_only_that_agents_body_back_at_rest() -> None:
    # Every rover drives for 20 cycles; then agent 1 sends a trial reset and agent 2 an
    # environment reset, with no action: both are back at the scene's start, at rest,
    # their wheels' controls at 0; agents 0 and 3 are where they drove.
    driving = 20

    def policy(cycle: int, agent_id: int) -> dict[str, Any]:
        return wander(cycle, agent_id) if cycle < driving else {"wheels": None, "drive": None}

    with MujocoWorld(ROVERS_TOML) as w:
        start = {b.id: w.data.xpos[b.body_id].copy() for b in w.agents}
        host = FakeHost(w, policy)
        original = host.collect

        def collect() -> FakeReport:
            report = original()
            if report.cycle == driving:
                report.agents[1].commands = [vrsync.TrialReset()]
                report.agents[2].commands = [vrsync.EnvironmentReset()]
            return report

        host.collect = collect  # type: ignore[method-assign]
        for _ in range(driving):
            w.step_cycle(host)
        moved = {b.id: w.data.xpos[b.body_id].copy() for b in w.agents}
        assert all(np.linalg.norm(moved[i] - start[i]) > 0.02 for i in start), (moved, start)
        applied, rejected = w.commands_applied, w.commands_rejected
        host.rejected.clear()
        # Cycle `driving`, by hand, to look between its resets and its physics.
        for b in w.agents:
            frame = host.loan(b.id)
            w.write_frame(b, frame)
            host.publish(frame)
        host.start()
        w.apply_report(host.collect(), host)
        for b in w.agents[1:3]:
            r = b.reset
            assert len(r.qpos_index) == 7 + 2 and len(r.qvel_index) == 6 + 2, r  # free + 2 wheels
            np.testing.assert_array_equal(w.data.qpos[r.qpos_index], w.model.qpos0[r.qpos_index])
            assert not w.data.qvel[r.qvel_index].any() and not w.data.ctrl[r.ctrl_index].any()
        # One cycle of physics from rest at the start: barely moved (it settles on its wheels).
        w.advance()
        for i in (1, 2):
            assert np.linalg.norm(w.data.xpos[w.agents[i].body_id] - start[i]) < 0.01
        for i in (0, 3):
            assert np.linalg.norm(w.data.xpos[w.agents[i].body_id] - start[i]) > 0.02
        assert (w.commands_applied, w.commands_rejected) == (applied + 2, rejected)
        assert host.rejected == {}
