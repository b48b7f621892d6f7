"""A Python agent on another machine over zenoh, for real: two network namespaces joined
by a veth pair, the host (`vr-sim run`) and a local shared-memory agent in one, the Python
agent in the other, talking over the veth addresses (not loopback).

Needs root and `ip` (CI runs as root and installs iproute2); skipped with a message only
where `ip netns add` fails.
"""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from conftest import binary, write_config

HOST_IP = "10.78.0.1"
AGENT_IP = "10.78.0.2"
FRAMES = 200
_COUNTER = itertools.count()


def ip(*args: str) -> None:
    """Runs `ip args`; raises with its stderr when it fails."""
    out = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if out.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {out.stderr.strip()}")


@pytest.fixture
def netns() -> Iterator[tuple[str, str]]:
    """(host namespace, agent namespace), joined by a veth pair; deleted afterwards."""
    tag = f"{os.getpid()}x{next(_COUNTER)}"
    host, agents = f"pzh{tag}", f"pza{tag}"
    try:
        ip("netns", "add", host)
    except (OSError, RuntimeError) as e:
        pytest.skip(f"network namespaces cannot be created here ({e}); this test needs root")
    try:
        ip("netns", "add", agents)
        # Interface names are the namespace names (at most 15 bytes).
        ip("link", "add", host, "type", "veth", "peer", "name", agents)
        ip("link", "set", host, "netns", host)
        ip("link", "set", agents, "netns", agents)
        for name, addr in ((host, HOST_IP), (agents, AGENT_IP)):
            ip("-n", name, "addr", "add", f"{addr}/30", "dev", name)
            ip("-n", name, "link", "set", "lo", "up")
            ip("-n", name, "link", "set", name, "up")
        yield host, agents
    finally:
        for name in (host, agents):
            subprocess.run(["ip", "netns", "del", name], capture_output=True, timeout=30)


# The `vr-agent --policy circle` policy, written again in Python (as in test_agent.py).
AGENT = """
import sys, vrsync
cycles = []
with vrsync.Agent.connect(sys.argv[1], int(sys.argv[2]), connect_timeout=30) as agent:
    for frame in agent.frames(timeout=30):
        cycles.append(frame.cycle)
        assert frame.image("left").shape == (37, 64, 3), frame.image("left").shape  # 120°×90°
        agent.send(vrsync.Move(heading_deg=float(frame.cycle % 360 * 7 % 360), distance_m=0.05))
        agent.stop()
assert cycles == list(range(len(cycles))), cycles
print(len(cycles), flush=True)
"""


def test_python_agent_over_zenoh_across_network_namespaces(
    tmp_path: Path, start_host, netns: tuple[str, str]
) -> None:
    host_ns, agent_ns = netns
    cams = (("left", 64, "rgb8"),)
    # The reference: both agents Rust `vr-agent --policy circle` over shared memory.
    config, _ = write_config(tmp_path, "nsref", agents=2, cameras=cams)
    reference = start_host(
        config, FRAMES, ["--spawn-agents", "2", "--agent-arg=--policy", "--agent-arg=circle"]
    ).finish(timeout=240)

    # Agent 0 the same, local, over shm; agent 1 the Python agent, remote, over zenoh.
    config, _ = write_config(
        tmp_path,
        "ns",
        agents=2,
        cameras=cams,
        agent_transports={1: "zenoh"},
        zenoh_endpoint=f"tcp/{HOST_IP}:7447",
    )
    host = start_host(config, FRAMES, prefix=["ip", "netns", "exec", host_ns])
    local = subprocess.Popen(
        ["ip", "netns", "exec", host_ns, str(binary("vr-agent")), "--config", str(config),
         "--id", "0", "--policy", "circle"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    remote = subprocess.Popen(
        ["ip", "netns", "exec", agent_ns, sys.executable, "-c", AGENT, str(config), "1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        summary = host.finish(timeout=240)
        out, err = remote.communicate(timeout=60)
        assert remote.returncode == 0, out + err
        assert out.split() == [str(FRAMES)], out + err
        _, err = local.communicate(timeout=60)
        assert local.returncode == 0, err
    finally:
        for p in (local, remote):
            if p.poll() is None:
                p.kill()
                p.wait(timeout=30)
    assert summary["frames"] == FRAMES, summary
    assert summary["stop_timeouts"] == 0, summary
    assert summary["evicted_agents"] == [], summary
    assert summary["trajectory_hash"] == reference["trajectory_hash"], (summary, reference)
