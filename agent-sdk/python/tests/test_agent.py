"""The loop API against real `vr-sim` hosts, over every transport (conftest.TRANSPORTS)."""

from __future__ import annotations

import math
import gc
import signal
import socket
import struct
import threading
from pathlib import Path

import numpy as np
import pytest
import vrsync

from conftest import TRANSPORTS, binary, run_python, write_config


def circle(frame: vrsync.Frame) -> vrsync.Command:
    """The `vr-agent --policy circle` policy, written again in Python."""
    return vrsync.Move(heading_deg=float(frame.cycle % 360 * 7 % 360), distance_m=0.05)


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_500_cycles_give_the_rust_agents_trajectory(tmp_path: Path, start_host, transport: str) -> None:
    config, name = write_config(tmp_path, "rust", transport=transport)
    rust = start_host(
        config, 500, ["--spawn-agents", "1", "--agent-arg=--policy", "--agent-arg=circle"]
    ).finish(timeout=240)

    config, name = write_config(tmp_path, "py", transport=transport)
    host = start_host(config, 500)
    cycles = []
    with vrsync.Agent.connect(config, 0, connect_timeout=20) as agent:
        for frame in agent.frames(timeout=30):
            cycles.append(frame.cycle)
            agent.send(circle(frame))
            agent.stop()
    py = host.finish(timeout=240)

    assert cycles == list(range(500))
    assert py["stop_timeouts"] == 0 and py["late_stops"] == 0
    assert py["frames"] == rust["frames"] == 500
    assert py["commands_applied"] == rust["commands_applied"] == 500
    assert py["trajectory_hash"] == rust["trajectory_hash"]


def shm_mappings() -> list[tuple[int, int]]:
    spans = []
    for line in Path("/proc/self/maps").read_text().splitlines():
        parts = line.split()
        if len(parts) >= 6 and parts[5].startswith("/dev/shm/"):
            lo, hi = (int(x, 16) for x in parts[0].split("-"))
            spans.append((lo, hi))
    return spans


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_images_are_read_only_views_of_the_frame(tmp_path: Path, start_host, transport: str) -> None:
    cams = (("left", 64, "rgb8"), ("alpha", 32, "rgba8"), ("gray", 48, "gray8"), ("depth", 40, "depth32f"))
    config, _ = write_config(tmp_path, "views", transport=transport, cameras=cams)
    host = start_host(config, 3)
    with vrsync.Agent.connect(config, 0, connect_timeout=20) as agent:
        assert [c.name for c in agent.cameras] == ["left", "alpha", "gray", "depth"]
        frame = agent.wait(timeout=30)
        lo, hi = frame.memory_range
        expected = {c.name: (tuple(c.shape), c.dtype) for c in agent.cameras}
        for name, img in frame.images.items():
            assert (img.shape, str(img.dtype)) == expected[name]
            # A view: its data lies inside the frame's memory and it owns nothing.
            addr = img.__array_interface__["data"][0]
            assert lo <= addr and addr + img.nbytes <= hi
            assert not img.flags.owndata
            if transport == "shm":
                # ... and that memory is the shared-memory sample itself.
                assert any(a <= addr and addr + img.nbytes <= b for a, b in shm_mappings())
            # Read-only, and it cannot be made writable.
            assert not img.flags.writeable
            with pytest.raises(ValueError):
                img[0, 0] = 1
            with pytest.raises(ValueError):
                img.setflags(write=True)
        depth = frame.image("depth")
        assert depth.dtype == np.float32 and np.isfinite(depth).all() and (depth > 0).all()
        assert frame.image("left").any(), "the rendered image is not all black"
        with pytest.raises(KeyError, match="no camera"):
            frame.image("nope")
        # The array keeps the frame alive after every other reference is gone.
        left = frame.image("left")
        copy = left.copy()
        del frame
        gc.collect()
        assert np.array_equal(left, copy)
        del left, img, depth  # release the frame before the next ones
        agent.stop()
        for f in agent.frames(timeout=30):
            agent.stop()
    host.finish()


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_holding_too_many_frames_raises_a_clear_error(tmp_path: Path, start_host, transport: str) -> None:
    config, _ = write_config(tmp_path, "held", transport=transport)
    host = start_host(config, 10)
    with vrsync.Agent.connect(config, 0, connect_timeout=20) as agent:
        kept = []
        with pytest.raises(vrsync.TooManyFramesHeldError, match="copy") as info:
            for _ in range(5):
                frame = agent.wait(timeout=30)
                kept.append(frame.image("left"))  # a view keeps its frame alive
                agent.stop()
        assert info.value.max == 2
        kept.clear()
        # Dropping the arrays is the fix: the agent goes on.
        for frame in agent.frames(timeout=30):
            agent.stop()
    assert host.finish()["frames"] == 10


def test_a_frame_dropped_on_another_thread_is_released(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "thread")
    host = start_host(config, 40)
    with vrsync.Agent.connect(config, 0, connect_timeout=20) as agent:
        n = 0
        for frame in agent.frames(timeout=30):
            box = [frame, frame.image("left")]
            del frame
            t = threading.Thread(target=box.clear)  # the last references die there
            t.start()
            t.join(timeout=10)
            agent.stop()
            n += 1
    assert n == 40
    assert host.finish()["frames"] == 40


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_the_frame_iterator_ends_when_the_host_finishes(tmp_path: Path, start_host, transport: str) -> None:
    config, _ = write_config(tmp_path, "end", transport=transport)
    host = start_host(config, 5)
    with vrsync.Agent.connect(config, 0, connect_timeout=20) as agent:
        seen = []
        for frame in agent.frames(timeout=30):
            seen.append((frame.cycle, frame.sim_time_ns))
            agent.stop()
        assert seen == [(c, c * 100_000_000) for c in range(5)]
        with pytest.raises(vrsync.HostClosedError):
            agent.wait(timeout=5)
    host.finish()


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_killed_host_raises_connection_error_within_a_second(
    tmp_path: Path, start_host, transport: str
) -> None:
    config, name = write_config(tmp_path, "kill", transport=transport)
    host = start_host(config)
    with vrsync.Agent.connect(config, 0, connect_timeout=20) as agent:
        agent.wait(timeout=30)
        host.kill(signal.SIGKILL)
        with pytest.raises(ConnectionError) as info:
            # The deadline is the property under test: a dead host is noticed within 1 s.
            agent.wait(timeout=1.0)
        assert isinstance(info.value, vrsync.HostGoneError)
        assert info.value.session == name


def test_no_host_names_the_session(tmp_path: Path) -> None:
    config, name = write_config(tmp_path, "nohost")
    with pytest.raises(vrsync.HostNotFoundError) as info:
        vrsync.Agent.connect(config, 0, connect_timeout=0.3)
    assert isinstance(info.value, ConnectionError)
    assert info.value.session == name and name in str(info.value)
    # How long it waited in all (the connect timeout), not its last attempt.
    assert info.value.waited >= 0.3


def test_an_id_the_host_does_not_serve_names_the_served_ids(tmp_path: Path, start_host) -> None:
    host_config, name = write_config(tmp_path, "served", agents=2)
    start_host(host_config)
    # The agent's config has a third agent the host does not serve.
    agent_config, _ = write_config(tmp_path, "served3", agents=3)
    with pytest.raises(vrsync.AgentIdNotServedError) as info:
        vrsync.Agent.connect(agent_config, 2, session=name, connect_timeout=10)
    assert info.value.served == [0, 1] and info.value.agent_id == 2
    assert isinstance(info.value, ConnectionError)


def test_a_bad_config_is_a_config_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('session = "x"\n[sync]\nsync_mode = "yes"\n')
    with pytest.raises(vrsync.ConfigError) as info:
        vrsync.Agent.connect(bad, 0)
    assert isinstance(info.value, ValueError) and "bad.toml" in str(info.value)
    config, _ = write_config(tmp_path, "noid")
    with pytest.raises(vrsync.ConfigError, match="no \\[\\[agent\\]\\] with id 3"):
        vrsync.Agent.connect(config, 3)


def test_a_host_of_another_protocol_version_is_refused_naming_both(tmp_path: Path) -> None:
    listener = socket.create_server(("127.0.0.1", 0))
    config, _ = write_config(tmp_path, "version", transport="tcp", tcp_port=listener.getsockname()[1])
    listener.settimeout(20)

    def fake_host() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.settimeout(20)
            length, _kind = struct.unpack("<II", conn.recv(8, socket.MSG_WAITALL))
            conn.recv(length, socket.MSG_WAITALL)  # the hello
            # WELCOME (kind 2) for protocol 999, layout 0xdeadbeef, max record 1024.
            conn.sendall(struct.pack("<IIIQI", 16, 2, 999, 0xDEADBEEF, 1024))

    t = threading.Thread(target=fake_host)
    t.start()
    try:
        with pytest.raises(vrsync.VersionMismatchError) as info:
            vrsync.Agent.connect(config, 0, connect_timeout=10)
    finally:
        t.join(timeout=30)
        listener.close()
    assert info.value.host_version == "999"
    assert info.value.agent_version == str(vrsync.PROTOCOL_VERSION)
    assert "999" in str(info.value) and f"protocol {vrsync.PROTOCOL_VERSION}" in str(info.value)


@pytest.mark.parametrize(
    "make, error",
    [
        (lambda: vrsync.Move(heading_deg=math.nan, distance_m=1), ValueError),
        (lambda: vrsync.Move(heading_deg=0, distance_m=math.inf), ValueError),
        (lambda: vrsync.Move(heading_deg=0, distance_m=-1), ValueError),
        (lambda: vrsync.Move(heading_deg=1e9, distance_m=1), ValueError),
        (lambda: vrsync.Move(heading_deg="north", distance_m=1), TypeError),
        (lambda: vrsync.Turn(angle_deg=None), TypeError),
        (lambda: vrsync.MoveTo(1e39, 0, 0), ValueError),
        (lambda: vrsync.EyeMovement(200, 0, 0), ValueError),
        (lambda: vrsync.GraspId(-1), ValueError),
        (lambda: vrsync.GraspId(2**32), ValueError),
        (lambda: vrsync.GraspId(1.5), TypeError),
        (lambda: vrsync.PointPos(-3, 4), ValueError),
        (lambda: vrsync.TrialReset(-1), ValueError),
    ],
)
def test_bad_command_values_raise_before_anything_is_sent(make, error) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(error):
        make()


def test_commands_reach_the_host_and_bad_ones_never_do(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "cmds")
    host = start_host(config, 4)
    with vrsync.Agent.connect(config, 0, connect_timeout=20) as agent:
        frame = agent.wait(timeout=30)
        ids = [agent.send(vrsync.Turn(angle_deg=15)), agent.send(vrsync.EyeMovement(10, 10, -5))]
        with pytest.raises(ValueError):
            agent.send(vrsync.Turn(angle_deg=math.nan))
        with pytest.raises(TypeError):
            agent.send("turn")  # type: ignore[arg-type]
        agent.stop()
        with pytest.raises(vrsync.UsageError):
            agent.stop()
        states = {}
        for frame in agent.frames(timeout=30):
            states.update(frame.action_states)
            agent.stop()
        assert ids == [ids[0], ids[0] + 1] and set(ids) <= set(states)
        assert all(isinstance(s, vrsync.ActionState) for s in states.values())
    summary = host.finish()
    assert summary["commands_applied"] == 2 and summary["commands_rejected"] == 0


def test_connecting_leaves_python_signal_handlers_alone(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "handlers", agents=2)
    start_host(config)
    child = run_python(
        f"""
import os, signal, vrsync
got = []
signal.signal(signal.SIGINT, lambda *a: got.append("int"))
signal.signal(signal.SIGTERM, lambda *a: got.append("term"))
agent = vrsync.Agent.connect({str(config)!r}, 0, connect_timeout=20)
try:
    agent.wait(timeout=0.2)
except vrsync.WaitTimeoutError:
    pass
os.kill(os.getpid(), signal.SIGINT)
os.kill(os.getpid(), signal.SIGTERM)
try:
    agent.wait(timeout=0.2)   # handlers run at the next check
except vrsync.WaitTimeoutError:
    pass
print(",".join(got), flush=True)
"""
    )
    out, err = child.communicate(timeout=60)
    assert child.returncode == 0, err
    assert out.strip() == "int,term", out + err


def test_vr_sim_binary_is_there() -> None:
    assert binary("vr-sim").exists()
