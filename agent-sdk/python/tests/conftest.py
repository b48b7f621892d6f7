"""Fixtures: isolated sessions, config files, and real `vr-sim` host processes.

Every host gets its own session name (and a TCP port of its own); every wait has a
deadline; every process a test starts is killed when the test ends.
"""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import pytest

# Some tests render with MuJoCo through Mesa's llvmpipe and others train with torch in
# the same process: torch's triton must load before Mesa's libLLVM (see
# vrsync/mujoco/__init__.py), so before any test renders.
try:
    import triton  # noqa: F401
except ImportError:
    pass

ROOT = Path(__file__).resolve().parents[3]
_COUNTER = itertools.count()


def bin_dir() -> Path:
    """Where `vr-sim` and `vr-agent` are: $VRSYNC_BIN_DIR, else target/debug."""
    return Path(os.environ.get("VRSYNC_BIN_DIR", ROOT / "target" / "debug"))


def binary(name: str) -> Path:
    path = bin_dir() / name
    if not path.exists():
        pytest.fail(
            f"{path} does not exist: build it first (`cargo build -p vrsync-sim -p vrsync-agent-bin`) "
            "or set VRSYNC_BIN_DIR; scripts/test-all does both",
            pytrace=False,
        )
    return path


def session(tag: str) -> str:
    """A session name unique to this test process and call."""
    return f"py{os.getpid()}-{next(_COUNTER)}-{tag}"


CAMERAS_SMALL = (("left", 64, "rgb8"), ("right", 64, "rgb8"))

# Every transport that serves the SDK's agents: the suites parametrized over transports
# take them from here (tests/util.rs `Transport::ALL` is the Rust suites' list; the
# original protocol's transport, legacy, serves only the original clients).
TRANSPORTS = ("shm", "tcp", "zenoh")


def free_tcp_port() -> int:
    """A loopback port that was free a moment ago (for zenoh, whose host cannot report a
    port-0 listener's port)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def write_config(
    directory: Path,
    tag: str,
    *,
    agents: int = 1,
    transport: str = "shm",
    sync_mode: bool = True,
    stop_timeout: float = 5.0,
    connect_timeout: float = 20.0,
    cameras: Sequence[tuple[str, int, str] | tuple[str, int, str, int]] = CAMERAS_SMALL,
    tcp_port: int = 0,
    agent_transports: dict[int, str] | None = None,
    zenoh_endpoint: str | None = None,
    wait_for_stop: str | None = None,
    stacked: bool = False,
) -> tuple[Path, str]:
    """Writes a config for `agents` agents with `cameras` ((name, width, format), height
    from a 120°×90° field of view, or (name, width, format, height)) and returns (path, session). `agent_transports` gives
    agents a transport of their own (default: `transport`). TCP hosts bind port 0
    unless `tcp_port` is given; `start_host` puts the bound port into the file.
    `zenoh_endpoint` (e.g. ``"tcp/10.0.0.1:7447"``) is where a zenoh host listens and
    its agents connect (lease 1 s; default for a zenoh session: a free loopback port). `wait_for_stop` (``"alive"``/``"timeout"``) sets
    `[sync] wait_for_stop` (default: not written, i.e. ``"alive"``). `stacked` sets
    `[transport.shm] stacked_images`."""
    name = session(tag)
    port = tcp_port
    lines = [
        f'session = "{name}"',
        "seed = 7",
        "[sync]",
        f"sync_mode = {'true' if sync_mode else 'false'}",
        "simulation_time_per_frame = 0.1",
        f"stop_timeout = {stop_timeout}",
        f"connect_timeout = {connect_timeout}",
        *([f'wait_for_stop = "{wait_for_stop}"'] if wait_for_stop else []),
        "[transport]",
        f'kind = "{transport}"',
        f'tcp_listen = "127.0.0.1:{port}"',
    ]
    if stacked:
        lines += ["[transport.shm]", "stacked_images = true"]
    uses_zenoh = transport == "zenoh" or "zenoh" in (agent_transports or {}).values()
    if zenoh_endpoint is None and uses_zenoh:
        zenoh_endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    if zenoh_endpoint is not None:
        lines += [
            "[transport.zenoh]",
            f'listen = ["{zenoh_endpoint}"]',
            f'connect = ["{zenoh_endpoint}"]',
            "lease = 1.0",
        ]
    for i in range(agents):
        lines += ["[[agent]]", f"id = {i}"]
        if agent_transports and i in agent_transports:
            lines.append(f'transport = "{agent_transports[i]}"')
        for cam, width, fmt, *height in cameras:
            lines += [
                "[[agent.camera]]",
                f'name = "{cam}"',
                f"width = {width}",
                *(f"height = {h}" for h in height),
                f'format = "{fmt}"',
                "fov_horizontal_deg = 120.0",
                "fov_vertical_deg = 90.0",
            ]
    text = "\n".join(lines) + "\n"
    # The world of the default config (room, objects, starts, rewards).
    default = (ROOT / "config" / "default.toml").read_text()
    text += default[default.index("\n[world]") :]
    path = directory / f"{name}.toml"
    path.write_text(text)
    return path, name


EVENT_DEADLINE = 60.0


class Host:
    """A `vr-sim run` process; killed at the end of the test if still running.

    Once it listens, a config whose `tcp_listen` port is 0 is rewritten with the bound
    port (from vr-sim's `listening` event), so agents started afterwards find the host.
    """

    def __init__(
        self,
        config: Path,
        frames: int | None,
        extra: Sequence[str] = (),
        prefix: Sequence[str] = (),
    ) -> None:
        self.summary_path = config.with_suffix(".summary.json")
        self.events_path = config.with_suffix(".events.jsonl")
        # `prefix`: e.g. ["ip", "netns", "exec", NAME], which execs vr-sim in a namespace.
        args = [*prefix, str(binary("vr-sim")), "run", "--config", str(config), "--quiet"]
        if frames is not None:
            args += ["--frames", str(frames)]
        args += ["--summary-json", str(self.summary_path), "--events", str(self.events_path)]
        args += list(extra)
        self.proc = subprocess.Popen(
            args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        listening = self.wait_event("listening")
        address = listening.get("address")
        text = config.read_text()
        if address and ':0"' in text:
            port = address.rsplit(":", 1)[1]
            config.write_text(text.replace('tcp_listen = "127.0.0.1:0"', f'tcp_listen = "127.0.0.1:{port}"'))

    def wait_event(self, kind: str, timeout: float = EVENT_DEADLINE) -> dict[str, Any]:
        """Waits for the first event `kind` in the host's events file."""
        deadline = time.monotonic() + timeout
        while True:
            if self.events_path.exists():
                for line in self.events_path.read_text().splitlines():
                    if line.strip():
                        event = json.loads(line)
                        if event.get("event") == kind:
                            return event
            if self.proc.poll() is not None:
                _, err = self.proc.communicate(timeout=10)
                pytest.fail(f"vr-sim exited {self.proc.returncode} before {kind!r}:\n{err}")
            if time.monotonic() >= deadline:
                pytest.fail(f"vr-sim wrote no {kind!r} event within {timeout} s")
            time.sleep(0.02)  # polling a file, with a deadline

    def paused_without_agents(self) -> bool:
        """Whether the host paused because no agent is connected any more: a
        `waiting_for_agents` event after the first `all_agents_connected`."""
        if not self.events_path.exists():
            return False
        kinds = [
            json.loads(line).get("event")
            for line in self.events_path.read_text().splitlines()
            if line.strip()
        ]
        if "all_agents_connected" not in kinds:
            return False
        return "waiting_for_agents" in kinds[kinds.index("all_agents_connected") :]

    def finish(self, timeout: float = 60.0) -> dict[str, Any]:
        """Waits for the host to exit 0 and returns its summary. A host whose agents all
        left before its --frames were done pauses for them (up to connect_timeout):
        it is ended with SIGINT then (exit 0, `interrupted` in the summary)."""
        deadline = time.monotonic() + timeout
        while self.proc.poll() is None and time.monotonic() < deadline:
            if self.paused_without_agents():
                self.proc.send_signal(signal.SIGINT)
                break
            time.sleep(0.05)  # polling a process and a file, with a deadline
        try:
            out, err = self.proc.communicate(timeout=max(deadline - time.monotonic(), 1.0))
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(f"vr-sim did not finish within {timeout} s")
        assert self.proc.returncode == 0, f"vr-sim exited {self.proc.returncode}:\n{err}"
        return json.loads(self.summary_path.read_text())

    def kill(self, sig: int = signal.SIGKILL) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            self.proc.wait(timeout=30)


@pytest.fixture(autouse=True)
def _sb3_logs_in_tmp_path(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Stable-Baselines3 makes a log folder per training run, by default
    `$TMPDIR/SB3-<date>` (left behind); its `$SB3_LOGDIR` puts it in the test's tmp_path."""
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path / "sb3"))


@pytest.fixture
def hosts() -> Iterator[list[Host]]:
    """Start hosts with `hosts.append(Host(...))`; all are killed at the end."""
    started: list[Host] = []
    yield started
    for h in started:
        h.kill()


@pytest.fixture
def start_host(hosts: list[Host]):  # type: ignore[no-untyped-def]
    def start(
        config: Path,
        frames: int | None = None,
        extra: Sequence[str] = (),
        prefix: Sequence[str] = (),
    ) -> Host:
        h = Host(config, frames, extra, prefix)
        hosts.append(h)
        return h

    return start


def run_python(code: str, timeout: float = 60.0, **popen: Any) -> subprocess.Popen[str]:
    """Starts `python -c code` (same interpreter); the caller waits with a deadline."""
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        **popen,
    )
