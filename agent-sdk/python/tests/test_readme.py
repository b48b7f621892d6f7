"""The Python code blocks of the READMEs run as written (only the config path is swapped
for a test config of the same shape)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, write_config

READMES = [ROOT / "README.md", ROOT / "agent-sdk" / "python" / "README.md"]


def python_blocks() -> list[tuple[str, str]]:
    blocks = []
    for readme in READMES:
        for i, code in enumerate(re.findall(r"```python\n(.*?)```", readme.read_text(), re.S)):
            # A host of its own (README "Your simulator as the host") is an example file,
            # run by test_python_host.py; these blocks are agents of a vr-sim host.
            if "vrsync.Host(" not in code:
                blocks.append((f"{readme.relative_to(ROOT)}#{i}", code))
    return blocks


BLOCKS = python_blocks()


def test_the_readmes_have_python_blocks() -> None:
    assert len(BLOCKS) >= 4


@pytest.mark.parametrize("name, code", BLOCKS, ids=[n for n, _ in BLOCKS])
def test_readme_block_runs(tmp_path: Path, start_host, name: str, code: str) -> None:
    assert "config/default.toml" in code, "blocks name the default config"
    # A block that drives one agent gets a world of one (the host waits for every agent).
    many = ("VrsyncParallelEnv", "VrsyncVecEnv", "VrsyncVectorEnv")
    agents = 2 if any(name in code for name in many) else 1
    config, _ = write_config(tmp_path, "readme", agents=agents)
    # The loop blocks run until the host closes the session: give them a short run.
    host = start_host(config, 600)
    script = code.replace("config/default.toml", str(config))
    out = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=180,
        # The host and the block share two cores in CI: torch gets one thread.
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    assert out.returncode == 0, f"{name}:\n{out.stderr}"
    host.kill()
