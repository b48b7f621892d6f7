"""README "Your simulator as the host": its Python block is examples/python_host.py (a
MuJoCo scene the host brings itself), and that host serves four agents with cameras,
vectors and continuous actions over shm and over tcp with equal trajectory hashes and no
stop timeout."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, bin_dir, free_tcp_port, session

pytest.importorskip("mujoco")

EXAMPLE = ROOT / "agent-sdk" / "python" / "examples" / "python_host.py"
CONFIG = ROOT / "config" / "python-host.toml"
HEADING = "### Your simulator as the host"


def readme_block() -> str:
    text = (ROOT / "README.md").read_text()
    section = text.split(f"\n{HEADING}\n", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)  # type: ignore[union-attr]


def test_the_readme_block_is_the_example() -> None:
    assert readme_block() == EXAMPLE.read_text(), (
        f"README.md's {HEADING!r} block differs from {EXAMPLE.relative_to(ROOT)}: "
        "copy the file into the block"
    )


def run_world(tmp_path: Path, transport: str, frames: int) -> str:
    """Runs the example host with the config's 4 agents as `channel_agent` processes;
    returns the host's output line."""
    text = CONFIG.read_text().replace('session = "python-host"', f'session = "{session("ph")}"')
    text = text.replace('kind = "shm"', f'kind = "{transport}"')
    text = text.replace("127.0.0.1:7070", f"127.0.0.1:{free_tcp_port()}")
    config = tmp_path / f"{transport}.toml"
    config.write_text(text)
    agent = bin_dir() / "examples" / "channel_agent"
    if not agent.exists():
        pytest.fail(f"{agent} does not exist: cargo build --examples", pytrace=False)
    procs = [
        subprocess.Popen(
            [sys.executable, str(EXAMPLE), str(config), str(frames)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
    ]
    try:
        procs += [
            subprocess.Popen(
                [str(agent), str(config), str(i), "5"],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                text=True,
            )
            for i in range(4)
        ]
        out, err = procs[0].communicate(timeout=240)
        assert procs[0].returncode == 0, err
        for p in procs[1:]:
            _, agent_err = p.communicate(timeout=60)
            assert p.returncode == 0, agent_err
        return out.strip()
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
                p.wait()


def test_the_example_host_serves_four_agents_alike_over_shm_and_tcp(tmp_path: Path) -> None:
    lines = {t: run_world(tmp_path, t, 200) for t in ("shm", "tcp")}
    for t, line in lines.items():
        words = line.split()
        assert words[:2] == ["stop_timeouts", "0"], f"{t}: {line}"
    assert lines["shm"].split()[-1] == lines["tcp"].split()[-1], lines
