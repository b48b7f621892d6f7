"""Ctrl-C and close with a polluted iceoryx2 registry.

Killed processes leave dead iceoryx2 nodes behind. These tests put a few hundred of them
into the registry (nodes of another program, created by a child process that then exits
without removing them) and check that an agent still answers Ctrl-C at once in every
place it blocks (connect, wait, ``reset``, ``step``, ``close``), and that vrsync leaves
those nodes alone (it cleans its own session's dead nodes only).

Each child interrupts itself from a helper thread once its main thread is on the line
that blocks (seen through the main thread's current frame), so the signal certainly
arrives while blocking, and prints the time from ``os.kill`` to the ``KeyboardInterrupt``.
The target is 100 ms; the tests fail beyond 1 s (a hang or a slow registry walk would
take seconds) and print what they measured.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import vrsync

from conftest import TRANSPORTS, run_python, write_config

DEAD_NODES = 300
"""Dead nodes put into the registry for each test."""

LATENCY_LIMIT_S = 1.0

# The child's prologue: a helper thread interrupts the main thread once it is on the
# line marked `# BLOCKS` (its number is filled in before the child starts) and the
# handler reports the latency of the KeyboardInterrupt.
PROLOGUE = """
import os, signal, sys, threading, time, vrsync
from vrsync.gym import VrsyncEnv
MAIN = threading.main_thread().ident
SENT = []

def interrupt_when_blocking():
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        frame = sys._current_frames().get(MAIN)
        while frame is not None and frame.f_code.co_name != "<module>":
            frame = frame.f_back   # the call may be Python (env.reset) or Rust
        if frame is not None and frame.f_lineno == BLOCK_LINE:
            break
        time.sleep(0.005)
    time.sleep(0.2)   # let the main thread get deep into the blocking call
    SENT.append(time.monotonic())
    os.kill(os.getpid(), signal.SIGINT)
"""

CATCH = """
threading.Thread(target=interrupt_when_blocking, daemon=True).start()
try:
    {call}  # BLOCKS
except KeyboardInterrupt:
    print("interrupted after", round(time.monotonic() - SENT[0], 4), "s", flush=True)
"""


def interrupted(call: str) -> str:
    """Child lines that run `call` (which must block) and interrupt it."""
    return CATCH.format(call=call)


def run_interrupted_child(body: str) -> tuple[str, str]:
    """Runs the prologue and `body` in a child, which must exit 0 and have been
    interrupted on its `# BLOCKS` line; returns its (stdout, stderr) and prints the
    measured latency of the KeyboardInterrupt."""
    code = PROLOGUE + body
    lines = code.splitlines()
    block_line = next(i + 1 for i, l in enumerate(lines) if l.rstrip().endswith("# BLOCKS"))
    # Same line count: the number goes onto an existing line.
    child = run_python(code.replace("MAIN = ", f"BLOCK_LINE = {block_line}; MAIN = ", 1))
    try:
        out, err = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(timeout=30)
    assert child.returncode == 0, out + err
    assert re.search(r"interrupted after ([0-9.]+) s", out), out + err
    return out, err


def run_child(body: str) -> float:
    """Runs the prologue and `body` in a child; returns the measured latency (s)."""
    out, err = run_interrupted_child(body)
    match = re.search(r"interrupted after ([0-9.]+) s", out)
    assert match, out + err
    latency = float(match.group(1))
    print(f"KeyboardInterrupt {latency * 1e3:.1f} ms after SIGINT")
    assert latency < LATENCY_LIMIT_S, out + err
    return latency


def leftover_prefix() -> str:
    return f"leftover-{os.getpid()}-{os.urandom(3).hex()}"


@pytest.fixture
def dead_nodes() -> Iterator[str]:
    """Fills the registry with `DEAD_NODES` dead nodes of another program; removes them
    afterwards (they are this test's own leftovers)."""
    prefix = leftover_prefix()
    child = subprocess.run(
        [
            sys.executable,
            "-c",
            f"import vrsync._vrsync as v; v._leak_nodes_for_tests({prefix!r}, {DEAD_NODES})",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert child.returncode == 0, child.stderr
    assert vrsync._vrsync._dead_nodes_for_tests(prefix) == DEAD_NODES
    yield prefix
    vrsync._vrsync._remove_dead_nodes_for_tests(prefix)


def test_ctrl_c_while_connecting_to_an_absent_host(tmp_path: Path, dead_nodes: str) -> None:
    config, _ = write_config(tmp_path, "int-connect")
    run_child(interrupted(f"vrsync.Agent.connect({str(config)!r}, 0, connect_timeout=60)"))


def two_agent_setup(config: Path) -> str:
    """Child lines: agent 1 connects and never stops, so the host never ends a cycle
    after the first one (it waits for agent 1's stop, which never comes)."""
    return f"other = vrsync.Agent.connect({str(config)!r}, 1, connect_timeout=60)\n"


def test_ctrl_c_while_waiting_for_a_frame(tmp_path: Path, start_host, dead_nodes: str) -> None:
    # Two agents configured, one connects: cycle 0 never starts.
    config, _ = write_config(tmp_path, "int-wait", agents=2, connect_timeout=300.0)
    start_host(config)
    run_child(
        f"agent = vrsync.Agent.connect({str(config)!r}, 0, connect_timeout=60)\n"
        + interrupted("agent.wait()")
    )


def test_ctrl_c_in_reset_and_in_step(tmp_path: Path, start_host, dead_nodes: str) -> None:
    # Agent 1 takes cycle 0 and never stops it: the host keeps waiting for it (stop
    # timeout far beyond the test), so the env's reset blocks on its second frame.
    config, _ = write_config(tmp_path, "int-reset", agents=2, stop_timeout=600.0)
    start_host(config)
    run_child(
        two_agent_setup(config)
        + f"env = VrsyncEnv({str(config)!r}, 0, connect_timeout=60)\n"
        + "other.wait(timeout=60)\n"
        + interrupted("env.reset()")
    )
    config, _ = write_config(tmp_path, "int-step", agents=2, stop_timeout=600.0)
    start_host(config)
    # Here agent 1 stops cycle 0 and no more: the env's reset gets cycle 1's frame, its
    # step then waits for cycle 2, which never comes.
    run_child(
        two_agent_setup(config)
        + f"env = VrsyncEnv({str(config)!r}, 0, connect_timeout=60)\n"
        + "other.wait(timeout=60); other.stop()\n"
        + "env.reset()\n"
        + interrupted("env.step(0)")
    )


def test_close_is_quick_and_leaves_other_programs_dead_nodes_alone(
    tmp_path: Path, start_host, dead_nodes: str
) -> None:
    config, _ = write_config(tmp_path, "int-close")
    start_host(config)
    child = run_python(
        f"""
import time, vrsync
t = time.monotonic()
agent = vrsync.Agent.connect({str(config)!r}, 0, connect_timeout=60)
connected = time.monotonic() - t
agent.wait(timeout=60)
t = time.monotonic()
agent.close()
print("connect", round(connected, 4), "close", round(time.monotonic() - t, 4), flush=True)
"""
    )
    out, err = child.communicate(timeout=120)
    assert child.returncode == 0, out + err
    words = out.split()
    connect_s, close_s = float(words[1]), float(words[3])
    print(f"connect {connect_s * 1e3:.1f} ms, close {close_s * 1e3:.1f} ms with {DEAD_NODES} dead nodes")
    assert close_s < LATENCY_LIMIT_S, out
    # Nothing of ours removed the other program's leftovers.
    assert vrsync._vrsync._dead_nodes_for_tests(dead_nodes) == DEAD_NODES


CLOSE_LIMIT_S = 3.0
"""How long `close()` may take with a frozen host: zenoh's close waits for the host (up
to ~1 s per close, all of a group's at once); shm and TCP do not wait."""


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_one_ctrl_c_in_step_then_close_ends_with_a_frozen_host(
    tmp_path: Path, start_host, transport: str
) -> None:
    # 16 agents in one vector env; the host is frozen (SIGSTOP) after a step, the next
    # step is interrupted by one SIGINT: one KeyboardInterrupt, and close() returns in a
    # bounded time without raising (zenoh's close took 10-30 s here before the closes of a
    # group overlapped).
    config, _ = write_config(
        tmp_path, f"int-frozen-{transport}", agents=16, transport=transport, stop_timeout=600.0
    )
    host = start_host(config)
    try:
        out, err = run_interrupted_child(
            f"""
from vrsync.vector import VrsyncVectorEnv
env = VrsyncVectorEnv({str(config)!r}, connect_timeout=60)
env.reset(seed=0)
actions = env.action_space.sample()
env.step(actions)
os.kill({host.proc.pid}, signal.SIGSTOP)
"""
            + interrupted("env.step(actions)")
            + """
t = time.monotonic()
try:
    env.close()
    print("closed in", round(time.monotonic() - t, 4), "s", flush=True)
except KeyboardInterrupt:
    print("close raised KeyboardInterrupt", flush=True)
"""
        )
    finally:
        host.kill(signal.SIGKILL)
    closed = re.search(r"closed in ([0-9.]+) s", out)
    assert closed, out + err
    close_s = float(closed.group(1))
    print(f"{transport}: close {close_s * 1e3:.0f} ms with the host frozen")
    assert close_s < CLOSE_LIMIT_S, out
