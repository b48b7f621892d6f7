"""`vrsync.Host`: a simulator written in Python serving real agent processes.

The agents are real processes: `vr-agent` (Rust) and small Python agents (`vrsync.Agent`)
that check, pixel by pixel, what the Python host wrote into their frames and answer
with commands that say what they saw. Every wait has a deadline; every process a test
starts is killed at its end.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import vrsync

from conftest import TRANSPORTS, binary, write_config

DEADLINE = 60.0
"""Seconds any one wait of these tests may take (they take well under a second)."""

# A Python agent that checks the pattern the host writes (see `pattern`) in every image
# of every frame, and answers each frame with MoveTo(cycle, mismatching pixels, reward),
# Turn(the value of pixel (1, 2) of its first image), EyeFixation(pose x, grid rotation
# y, eye tilt) and Turn(head velocity x), then stops. It ends when the host closes the
# session.
CHECKING_AGENT = """
import sys
import numpy as np
import vrsync

config, agent_id = sys.argv[1], int(sys.argv[2])

def pattern(shape, cycle, agent, camera):
    h, w = shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    base = x + 2 * y
    if len(shape) == 3:
        base = base[:, :, None] + 3 * np.arange(shape[2])
    return ((base + 7 * cycle + 11 * agent + 13 * camera) % 256).astype(np.uint8)

frames = 0
with vrsync.Agent.connect(config, agent_id, connect_timeout=30) as agent:
    for frame in agent.frames(timeout=30):
        bad = 0
        for i, name in enumerate(frame.camera_names):
            img = frame.image(name)
            bad += int(np.count_nonzero(img != pattern(img.shape, frame.cycle, agent_id, i)))
        first = frame.image(frame.camera_names[0])
        agent.send(vrsync.MoveTo(x=frame.cycle, y=bad, z=frame.reward))
        agent.send(vrsync.Turn(angle_deg=float(first[1, 2, 0])))
        agent.send(vrsync.EyeFixation(
            x=frame.pose.position[0], y=frame.grid.rotation_deg[1], z=frame.eye.rotation_deg[2]
        ))
        agent.send(vrsync.Turn(angle_deg=frame.head_motion.velocity[0]))
        del first
        agent.stop()
        frames += 1
print("frames", frames, flush=True)
"""


def pattern(shape: tuple[int, ...], cycle: int, agent: int, camera: int) -> np.ndarray:
    """What the host writes into image `camera` of `agent`'s frame of `cycle`."""
    h, w = shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    base = x + 2 * y
    if len(shape) == 3:
        base = base[:, :, None] + 3 * np.arange(shape[2])
    return ((base + 7 * cycle + 11 * agent + 13 * camera) % 256).astype(np.uint8)


class Agents:
    """Agent processes of one test: killed at its end if still running."""

    def __init__(self, tmp_path: Path) -> None:
        self.tmp_path = tmp_path
        self.procs: list[subprocess.Popen[str]] = []

    def vr_agent(self, config: Path, agent_id: int, policy: str = "wander") -> subprocess.Popen[str]:
        proc = subprocess.Popen(
            [str(binary("vr-agent")), "--config", str(config), "--id", str(agent_id),
             "--policy", policy],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        self.procs.append(proc)
        return proc

    def python(self, code: str, *args: str) -> subprocess.Popen[str]:
        script = self.tmp_path / f"agent{len(self.procs)}.py"
        script.write_text(code)
        proc = subprocess.Popen(
            [sys.executable, str(script), *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        self.procs.append(proc)
        return proc

    def kill(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                p.kill()
            p.communicate(timeout=30)


@pytest.fixture
def agents(tmp_path: Path) -> Iterator[Agents]:
    a = Agents(tmp_path)
    yield a
    a.kill()


def finish(proc: subprocess.Popen[str]) -> str:
    """Waits for an agent process to end (it does when the host closes) and returns
    its output; fails on a non-zero exit."""
    out, err = proc.communicate(timeout=DEADLINE)
    assert proc.returncode == 0, f"agent exited {proc.returncode}:\n{out}\n{err}"
    return out


def with_tcp_port(config: Path, address: str | None) -> None:
    """Writes the port a `tcp_listen = ...:0` host bound into its config, for its agents."""
    assert address is not None
    port = address.rsplit(":", 1)[1]
    text = config.read_text()
    config.write_text(text.replace('tcp_listen = "127.0.0.1:0"', f'tcp_listen = "127.0.0.1:{port}"'))


def test_sync_cycles_over_shm_and_tcp_carry_the_pixels_written_in_python(
    tmp_path: Path, agents: Agents
) -> None:
    config, session = write_config(tmp_path, "host", agents=3, agent_transports={2: "tcp"})
    cycles = 20
    with vrsync.Host(config) as host:
        assert host.session == session
        assert host.agent_ids == [0, 1, 2]
        assert host.sync_mode
        with_tcp_port(config, host.tcp_address)
        checkers = {0: agents.python(CHECKING_AGENT, str(config), "0"),
                    2: agents.python(CHECKING_AGENT, str(config), "2")}  # fmt: skip
        agents.vr_agent(config, 1)
        host.wait_for_agents(timeout=DEADLINE)
        wander_commands = 0
        for cycle in range(cycles):
            assert host.cycle == cycle
            for agent_id in host.agent_ids:
                frame = host.loan(agent_id)
                assert (frame.agent_id, frame.cycle) == (agent_id, cycle)
                for i, name in enumerate(frame.camera_names):
                    view = frame.image(name)
                    view[...] = pattern(view.shape, cycle, agent_id, i)
                    del view
                frame.set_pose((cycle * 0.1, 0.0, 1.0), (0.0, 0.0, 0.0, 1.0))
                frame.set_grid((0, 0, 0), (0, cycle, 0))
                frame.set_eye((0, 0, cycle))
                frame.set_head_motion((2 * cycle, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0))
                frame.reward = cycle * 0.5
                host.publish(frame)
                assert frame.published
            host.start()
            report = host.collect()
            assert report.cycle == cycle
            assert not report.timed_out
            for ar in report.agents:
                assert ar.outcome == "stopped", ar
            for agent_id in checkers:
                ar = report.agent(agent_id)
                assert ar.commands == [
                    vrsync.MoveTo(x=cycle, y=0, z=cycle * 0.5),
                    vrsync.Turn(angle_deg=float(pattern((3, 3, 3), cycle, agent_id, 0)[1, 2, 0])),
                    vrsync.EyeFixation(x=cycle * 0.1, y=cycle, z=cycle),
                    vrsync.Turn(angle_deg=2 * cycle),
                ], (agent_id, cycle)
                assert ar.invalid_commands == 0
                assert len(ar.action_ids) == 4
            wander = report.agent(1).commands
            assert all(isinstance(c, vrsync.Command) for c in wander)
            wander_commands += len(wander)
        assert wander_commands >= 1  # vr-agent's wander sends its first command at once
        stats = host.stats()
        assert stats["cycles"] == cycles
        assert stats["frames_delivered"] == 3 * cycles
        assert stats["stop_timeouts"] == 0
    for proc in checkers.values():
        assert finish(proc).split() == ["frames", str(cycles)]


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_every_transport_carries_the_pixels(tmp_path: Path, agents: Agents, transport: str) -> None:
    config, _ = write_config(tmp_path, f"host-{transport}", transport=transport)
    cycles = 5
    with vrsync.Host(config) as host:
        if transport == "tcp":
            with_tcp_port(config, host.tcp_address)
        else:
            assert host.tcp_address is None
        checker = agents.python(CHECKING_AGENT, str(config), "0")
        host.wait_for_agents(timeout=DEADLINE)
        for cycle in range(cycles):
            frame = host.loan(0)
            for i, view in enumerate(frame.images.values()):
                view[...] = pattern(view.shape, cycle, 0, i)
            del view
            frame.reward = 1.0
            host.publish(frame)
            host.start()
            ar = host.collect().agent(0)
            assert ar.outcome == "stopped"
            assert ar.commands[0] == vrsync.MoveTo(x=cycle, y=0, z=1.0), (transport, cycle)
    assert finish(checker).split() == ["frames", str(cycles)]


def test_image_views_are_writable_zero_copy_and_must_be_gone_before_publish(
    tmp_path: Path,
) -> None:
    cameras = (("rgb", 32, "rgb8", 8), ("rgba", 16, "rgba8", 4), ("gray", 8, "gray8", 6),
               ("depth", 12, "depth32f", 5))  # fmt: skip
    config, _ = write_config(tmp_path, "views", cameras=cameras)
    with vrsync.Host(config) as host, vrsync.Host(config, session=f"{host.session}-b") as other:
        assert [c.name for c in host.cameras(0)] == ["rgb", "rgba", "gray", "depth"]
        frame = host.loan(0)
        start, end = frame.memory_range
        shapes = {}
        for name in frame.camera_names:
            view = frame.image(name)
            assert view.flags.writeable
            assert start <= view.ctypes.data < end  # a view of the loaned memory
            view[...] = 1
            shapes[name] = (view.shape, view.dtype.name)
        del view
        assert shapes == {
            "rgb": ((8, 32, 3), "uint8"),
            "rgba": ((4, 16, 4), "uint8"),
            "gray": ((6, 8), "uint8"),
            "depth": ((5, 12), "float32"),
        }
        # Two arrays over the same memory: a write through one is seen by the other.
        a, b = frame.image("depth"), frame.image("depth")
        a[2, 3] = 1.5
        assert b[2, 3] == 1.5
        del a, b

        view = frame.image("rgb")
        row = view[1]  # arrays made from a view count too
        del view
        assert frame.views == 1
        with pytest.raises(vrsync.FrameInUseError) as e:
            host.publish(frame)
        assert isinstance(e.value, BufferError)
        assert (e.value.agent_id, e.value.cycle, e.value.views) == (0, 0, 1)
        assert not frame.published
        base = row
        while isinstance(base, np.ndarray):
            base = base.base  # the views' base object, which a user could dig out
        del row
        assert frame.views == 1  # ... counts as long as it lives
        with pytest.raises(vrsync.FrameInUseError):
            host.publish(frame)
        with pytest.raises(TypeError):
            memoryview(base)  # and is no way to the memory: it exports no buffer
        del base
        assert frame.views == 0

        with pytest.raises(vrsync.UsageError, match="another vrsync.Host"):
            other.publish(frame)
        host.publish(frame)  # no agent connected: dropped and counted, not an error
        assert frame.published and host.stats()["frames_undelivered"] == 1
        fresh = host.loan(0)  # the sensors start neutral, whatever the memory held
        assert fresh.reward == 0.0
        fresh.reward = 5.0
        fresh.set_pose((1, 2, 3), (0, 0, 0, 1))
        fresh.set_grid((1, 2, 3), (0, 90, 0))
        fresh.set_head_motion((1, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0))
        fresh.set_eye((1, 2, 3))
        with pytest.raises(ValueError, match="rotation must be 4 finite numbers"):
            fresh.set_pose((1, 2, 3), (0, 0, 1))
        with pytest.raises(ValueError, match="finite"):
            fresh.reward = float("nan")
        del fresh
        with pytest.raises(vrsync.UsageError, match="published"):
            frame.image("rgb")
        with pytest.raises(vrsync.UsageError, match="published already"):
            host.publish(frame)

        with pytest.raises(KeyError, match='no camera "nope"'):
            host.loan(0).image("nope")
        with pytest.raises(KeyError):
            host.loan(7)
        stale = host.loan(0)
        with pytest.raises(vrsync.TransportError, match="still alive"):
            host.loan(0)  # shared memory lends one frame per agent at a time
        host.start()
        host.collect()  # no frame published: nothing to wait for
        with pytest.raises(vrsync.UsageError, match="cycle 0"):
            host.publish(stale)
        assert "HostFrame agent=0 cycle=0" in repr(stale)
    assert host.closed and "closed" in repr(host)
    with pytest.raises(vrsync.UsageError, match="closed"):
        host.loan(0)


def test_async_mode_ticks_and_takes_commands_as_they_come(tmp_path: Path, agents: Agents) -> None:
    config, _ = write_config(tmp_path, "async", sync_mode=False)
    with vrsync.Host(config) as host:
        assert not host.sync_mode
        agent = agents.vr_agent(config, 0)
        host.wait_for_agents(timeout=DEADLINE)
        commands = []
        deadline = time.monotonic() + DEADLINE
        while not commands and time.monotonic() < deadline:
            frame = host.loan(0)
            frame.image("left")[...] = 0  # the temporary view is gone after this line
            host.publish(frame)
            host.start()
            report = host.collect()
            assert report.agent(0).outcome == "async"
            commands += report.agent(0).commands
        assert commands, "vr-agent's first command never arrived"
        assert host.stats()["cycles"] == report.cycle + 1
    agent.communicate(timeout=DEADLINE)
    assert agent.returncode == 0


def test_wait_for_agents_names_the_missing_ones(tmp_path: Path) -> None:
    config, session = write_config(tmp_path, "missing", agents=2)
    with vrsync.Host(config, session=f"{session}-x", agents=3) as host:
        assert (host.session, host.agent_ids) == (f"{session}-x", [0, 1, 2])
        with pytest.raises(vrsync.HostWaitTimeout) as e:
            host.wait_for_agents(timeout=0.3)
    assert isinstance(e.value, TimeoutError)
    assert e.value.missing == [0, 1, 2] and e.value.session == f"{session}-x"
    with pytest.raises(vrsync.ConfigError):
        vrsync.Host(config, session="not a session name")
    assert e.value.waited >= 0.3
# A Python host blocked in `wait_for_agents` (its agent never comes) or in `collect` (its
# agent takes its frame and never stops: the host waits for it as long as it lives). A
# helper thread prints "blocking" once the main thread is on the blocking line; the
# parent then sends SIGINT. The child prints when KeyboardInterrupt arrived.
BLOCKED_HOST = """
import sys, threading, time, vrsync
config, where = sys.argv[1], sys.argv[2]
MAIN = threading.main_thread().ident

def report_when_blocking(line):
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        frame = sys._current_frames().get(MAIN)
        while frame is not None and frame.f_code.co_name != "<module>":
            frame = frame.f_back
        if frame is not None and frame.f_lineno == line:
            print("blocking", flush=True)
            return
        time.sleep(0.005)

host = vrsync.Host(config)
if where == "collect":
    host.wait_for_agents(timeout=60)
    host.publish(host.loan(0))
    host.start()
line = sys._getframe().f_lineno + 3
threading.Thread(target=report_when_blocking, args=(line,), daemon=True).start()
try:
    host.collect() if where == "collect" else host.wait_for_agents(timeout=600)
except KeyboardInterrupt:
    print("interrupted", time.monotonic(), flush=True)
    sys.exit(0)
print("returned", flush=True)
sys.exit(1)
"""

SILENT_AGENT = """
import sys, vrsync
with vrsync.Agent.connect(sys.argv[1], 0, connect_timeout=30) as agent:
    agent.wait(timeout=30)
    sys.stdin.read()  # never stops; ends when the test kills it
"""


@pytest.mark.parametrize("where", ["wait_for_agents", "collect"])
def test_ctrl_c_ends_a_blocked_host_with_keyboard_interrupt(
    tmp_path: Path, agents: Agents, where: str
) -> None:
    config, _ = write_config(tmp_path, "ctrlc", stop_timeout=0.2)
    host = agents.python(BLOCKED_HOST, str(config), where)
    if where == "collect":
        agent = subprocess.Popen(
            [sys.executable, "-c", SILENT_AGENT, str(config)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        agents.procs.append(agent)
    assert host.stdout is not None
    assert host.stdout.readline().strip() == "blocking", host.communicate(timeout=DEADLINE)
    # Past the stop timeout (0.2 s) the host keeps waiting for the live agent.
    time.sleep(0.5)  # not synchronisation: lets the call get well into its wait
    assert host.poll() is None, host.communicate(timeout=DEADLINE)
    sent = time.monotonic()
    host.send_signal(signal.SIGINT)
    out, err = host.communicate(timeout=DEADLINE)
    assert host.returncode == 0, (out, err)
    word, when = out.split()[-2:]
    assert word == "interrupted", (out, err)
    latency = float(when) - sent
    print(f"{where} ended {latency * 1000:.1f} ms after SIGINT")
    assert latency < DEADLINE  # measured, not a speed limit: the wait ends, it does not hang


# An agent with channels: it checks the vector the host wrote (joints = arange + cycle)
# and answers with both actions: torque = (joints[0] / 100, 1 if the vector was right
# else -1), gear = cycle % 3.
CHANNEL_AGENT = """
import sys
import numpy as np
import vrsync

with vrsync.Agent.connect(sys.argv[1], 0, connect_timeout=30) as agent:
    for frame in agent.frames(timeout=30):
        joints = frame.vector("joints")
        right = np.array_equal(joints, np.arange(joints.size, dtype=np.float32) + frame.cycle)
        agent.act("torque", [joints[0] / 100.0, 1.0 if right else -1.0])
        agent.act("gear", frame.cycle % 3)
        del joints
        agent.stop()
"""

CHANNELS = """
[[agent.vector]]
name = "joints"
len = 5
[[agent.action]]
name = "torque"
len = 2
low = -1.0
high = 1.0
[[agent.action]]
name = "gear"
n = 3
"""


def with_channels(config: Path) -> Path:
    """Gives the (last) agent of `config` the vector and actions of `CHANNELS`."""
    text = config.read_text()
    at = text.index("\n[world]")
    config.write_text(text[:at] + CHANNELS + text[at:])
    return config


def test_vector_views_are_writable_and_refused_at_publish_while_alive(tmp_path: Path) -> None:
    config = with_channels(write_config(tmp_path, "vectors")[0])
    with vrsync.Host(config) as host:
        frame = host.loan(0)
        assert frame.vector_names == ["joints"]
        joints = frame.vector("joints")
        assert joints.shape == (5,) and joints.dtype == np.float32 and joints.flags.writeable
        joints[:] = np.arange(5)
        again = frame.vectors["joints"]
        assert again.ctypes.data == joints.ctypes.data and again.tolist() == [0, 1, 2, 3, 4]
        with pytest.raises(vrsync.FrameInUseError) as e:
            host.publish(frame)
        assert e.value.views == 2
        del joints, again
        with pytest.raises(KeyError, match="no vector"):
            frame.vector("nope")
        host.publish(frame)
        with pytest.raises(vrsync.UsageError, match="published"):
            frame.vector("joints")


def test_vectors_written_in_python_arrive_and_actions_come_back(
    tmp_path: Path, agents: Agents
) -> None:
    config = with_channels(write_config(tmp_path, "channels")[0])
    with vrsync.Host(config) as host:
        agents.python(CHANNEL_AGENT, str(config))
        host.wait_for_agents(timeout=DEADLINE)
        for cycle in range(5):
            frame = host.loan(0)
            assert frame.vector_names == ["joints"]
            joints = frame.vector("joints")
            assert joints.shape == (5,) and joints.dtype == np.float32 and joints.flags.writeable
            joints[:] = np.arange(5) + cycle
            with pytest.raises(vrsync.FrameInUseError):
                host.publish(frame)
            del joints
            with pytest.raises(KeyError, match="no vector"):
                frame.vector("nope")
            host.publish(frame)
            host.start()
            ar = host.collect().agent(0)
            assert ar.outcome == "stopped"
            actions = ar.actions
            assert list(actions) == ["torque", "gear"]
            assert actions["torque"].dtype == np.float32
            assert actions["torque"].tolist() == pytest.approx([cycle / 100.0, 1.0])
            assert actions["gear"] == cycle % 3
            assert ar.actions_rejected == 0
            assert ar.commands == []  # actions are not commands
        assert host.stats()["actions_rejected"] == 0


# An agent whose config declares one float more of "joints" than the host's: refused at
# connect; it prints what the error says of the channel, then connects with the host's
# config and runs one cycle.
MISMATCHED_AGENT = """
import sys
import vrsync

try:
    vrsync.Agent.connect(sys.argv[2], 0, connect_timeout=30)
except vrsync.ChannelMismatchError as e:
    print(e.table, e.channel, e.host.replace(" ", "_"), e.agent.replace(" ", "_"), flush=True)
    print(str(e), file=sys.stderr, flush=True)
with vrsync.Agent.connect(sys.argv[1], 0, connect_timeout=30) as agent:
    for frame in agent.frames(timeout=30):
        agent.stop()
"""


@pytest.mark.parametrize("transport", ["shm", "tcp"])
def test_an_agent_with_other_channels_is_refused_at_connect_naming_the_channel(
    tmp_path: Path, agents: Agents, transport: str
) -> None:
    config = with_channels(write_config(tmp_path, f"mismatch-{transport}", transport=transport)[0])
    with vrsync.Host(config) as host:
        if transport == "tcp":
            with_tcp_port(config, host.tcp_address)
        theirs = tmp_path / "theirs.toml"
        theirs.write_text(config.read_text().replace("len = 5", "len = 6"))
        agent = agents.python(MISMATCHED_AGENT, str(config), str(theirs))
        host.wait_for_agents(timeout=DEADLINE)
        host.publish(host.loan(0))
        host.start()
        assert host.collect().agent(0).outcome == "stopped"
    out, err = agent.communicate(timeout=DEADLINE)
    assert agent.returncode == 0, err
    assert out.split() == ["vector", "joints", "5_floats", "6_floats"], (out, err)
    assert '"joints"' in err, err


# One command of every class, as Python source both the agent and the host evaluate.
EVERY_COMMAND = """[
    vrsync.Move(heading_deg=90.5, distance_m=1.25),
    vrsync.Turn(angle_deg=-30.0),
    vrsync.MoveTo(x=1.0, y=0.0, z=-2.5),
    vrsync.CancelMove(),
    vrsync.EyeMovement(pan_left_deg=5.0, pan_right_deg=-5.0, tilt_deg=2.0),
    vrsync.EyeFixation(x=0.5, y=1.5, z=2.5),
    vrsync.GraspId(object_id=7),
    vrsync.GraspPos(x_px=10.0, y_px=20.0),
    vrsync.PointId(object_id=8),
    vrsync.PointPos(x_px=11.0, y_px=21.0),
    vrsync.InteractId(object_id=9),
    vrsync.InteractPos(x_px=12.0, y_px=22.0),
    vrsync.GraspRelease(),
    vrsync.EnvironmentReset(reset_type=1),
    vrsync.TrialReset(reset_type=2),
]"""

SENDING_AGENT = """
import sys, vrsync
with vrsync.Agent.connect(sys.argv[1], 0, connect_timeout=30) as agent:
    for frame in agent.frames(timeout=30):
        if frame.cycle == 0:
            for i, command in enumerate(COMMANDS):
                agent.send_with_id(1000 + i, command)
        else:  # what the host said of the previous cycle's commands
            agent.send(vrsync.Turn(angle_deg=frame.previous_rejected))
            state = frame.action_states.get(1000)
            hits = [c.collider_id for c in frame.collisions if c.action_id == 1000]
            agent.send(vrsync.MoveTo(x=-1 if state is None else int(state), y=len(hits), z=sum(hits)))
        agent.stop()
""".replace("COMMANDS", EVERY_COMMAND)


def test_every_command_class_comes_back_and_statuses_reach_the_agent(tmp_path: Path, agents: Agents) -> None:
    sent = eval(EVERY_COMMAND, {"vrsync": vrsync})
    assert {type(c) for c in sent} == set(vrsync.Command.__subclasses__())
    config, _ = write_config(tmp_path, "commands")
    with vrsync.Host(config) as host:
        agents.python(SENDING_AGENT, str(config))
        host.wait_for_agents(timeout=DEADLINE)
        host.publish(host.loan(0))
        host.start()
        ar = host.collect().agent(0)
        host.set_rejected(0, 4)
        frame = host.loan(0)
        assert frame.add_status(1000, vrsync.ActionState.Finished)
        assert frame.add_collision(1000, 42)
        host.publish(frame)
        host.start()
        assert host.collect().agent(0).commands == [
            vrsync.Turn(angle_deg=4),
            vrsync.MoveTo(x=int(vrsync.ActionState.Finished), y=1, z=42),
        ]
    got = ar.commands
    assert [type(c) for c in got] == [type(c) for c in sent]
    assert got == sent
    assert [repr(c) for c in got] == [repr(c) for c in sent]
    assert ar.action_ids == [1000 + i for i in range(len(sent))]
    assert ar.invalid_commands == 0


def one_cycle(host: vrsync.Host) -> vrsync.CycleReport:
    for agent_id in host.agent_ids:
        host.publish(host.loan(agent_id))
    host.start()
    return host.collect()


@pytest.mark.parametrize("on_agent_lost", ["evict", "abort"])
def test_an_agent_killed_between_cycles_is_evicted_or_aborts_the_run(
    tmp_path: Path, agents: Agents, on_agent_lost: str
) -> None:
    config, _ = write_config(tmp_path, f"lost-{on_agent_lost}", agents=2)
    config.write_text(
        config.read_text().replace("[sync]\n", f'[sync]\non_agent_lost = "{on_agent_lost}"\n', 1)
    )
    with vrsync.Host(config) as host:
        agents.vr_agent(config, 0, policy="idle")
        doomed = agents.vr_agent(config, 1, policy="idle")
        host.wait_for_agents(timeout=DEADLINE)
        for _ in range(2):
            assert [a.outcome for a in one_cycle(host).agents] == ["stopped", "stopped"]
        doomed.kill()
        doomed.wait(timeout=DEADLINE)
        if on_agent_lost == "abort":
            with pytest.raises(vrsync.AgentLostError) as e:
                one_cycle(host)
            assert isinstance(e.value, ConnectionError) and e.value.agent_id == 1
            return
        report = one_cycle(host)  # the loss is noticed in this cycle (or at its publish)
        lost = report.agent(1)
        assert lost.evicted or lost.outcome == "not_awaited", lost
        assert report.agent(0).outcome == "stopped"
        report = one_cycle(host)
        assert [a.outcome for a in report.agents] == ["stopped", "not_awaited"]
        assert host.stats()["evictions"] == 1


# A Python agent that takes part in `cycles` cycles, then leaves gracefully (`close()`)
# and prints the last cycle it stopped.
LEAVING_AGENT = """
import sys
import vrsync

config, agent_id, cycles = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
agent = vrsync.Agent.connect(config, agent_id, connect_timeout=30)
last = None
for _ in range(cycles):
    frame = agent.wait(timeout=30)
    last = frame.cycle
    del frame
    agent.stop()
agent.close()
print("left after", last, flush=True)
"""


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_an_agent_that_leaves_is_let_go_at_once_and_its_id_rejoins(
    tmp_path: Path, agents: Agents, transport: str
) -> None:
    """As the Rust host's leave: the cycle after a graceful leave ends without a stop
    timeout and without an eviction, the report says `left`; a new connection of the same
    id takes part from the next cycle and is reported `rejoined`."""
    config, _ = write_config(tmp_path, "pyleave", agents=1, transport=transport,
                             stop_timeout=30.0)  # fmt: skip
    with vrsync.Host(config) as host:
        if transport == "tcp":
            with_tcp_port(config, host.tcp_address)
        first = agents.python(LEAVING_AGENT, str(config), "0", "3")
        host.wait_for_agents(DEADLINE)
        left_in = rejoined_in = None
        started = time.monotonic()
        while rejoined_in is None:
            if time.monotonic() - started > DEADLINE:
                for p in agents.procs:
                    p.kill()
                said = " | ".join(p.communicate(timeout=30)[1] for p in agents.procs)
                pytest.fail(f"no leave and rejoin in time (left in {left_in}): {said}")
            host.publish(host.loan(0))
            host.start()
            report = host.collect()
            a = report.agent(0)
            assert not report.timed_out and not a.evicted, report
            if a.left:
                left_in = report.cycle
                # Its last stop came in this cycle or the one before (the leave follows it).
                last = int(finish(first).split()[-1])
                assert report.cycle - 1 <= last <= report.cycle, (last, report.cycle)
                agents.python(LEAVING_AGENT, str(config), "0", "2")
            if a.rejoined:
                rejoined_in = report.cycle
        stats = host.stats()
    assert left_in is not None and rejoined_in > left_in
    assert (stats["leaves"], stats["rejoins"], stats["evictions"]) == (1, 1, 0), stats
    assert stats["stop_timeouts"] == 0, stats
