"""vrsync.mujoco's command line (`python -m vrsync.mujoco`), and the world served by the
real `vrsync.Host` (those tests skip while the build has no Host). The fake host and the
configs come from test_mujoco_world. Skipped when `mujoco` cannot be imported.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("mujoco", reason="the `mujoco` package is not installed")

from test_mujoco_world import ROOT, ROVERS_N_TOML, ROVERS_TOML, FakeHost, wander, write  # noqa: E402
from vrsync.mujoco import MujocoWorld  # noqa: E402

# ---- the command line -----------------------------------------------------------------


def _cli(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "vrsync.mujoco", *args],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=cwd,
    )


def test_cli_help_and_bad_usage() -> None:
    r = _cli("--help")
    assert r.returncode == 0 and "run" in r.stdout and "bench" in r.stdout
    r = _cli("run", "--help")
    assert r.returncode == 0 and "--spawn-agents" in r.stdout and "Exit codes" in r.stdout
    assert _cli("run").returncode == 2
    assert _cli("run", "--config", str(ROVERS_TOML), "--frames", "0").returncode == 2


def test_cli_bad_config_exits_2_with_the_reason(tmp_path: Path) -> None:
    r = _cli("run", "--config", str(write(tmp_path, vlen="9")), "--frames", "1")
    assert r.returncode == 2, r.stderr
    assert "vector 'wheels'" in r.stderr and "len = 9" in r.stderr
    r = _cli("run", "--config", str(tmp_path / "none.toml"))
    assert r.returncode == 2 and "cannot read config file" in r.stderr


def test_cli_run_against_a_stand_in_host(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The run command's own work (resize, spawn and reap agents, summary, exit code)
    with the fake host standing in for vrsync.Host."""
    import vrsync
    from vrsync.mujoco import cli

    made: list[dict[str, Any]] = []

    class StandIn(FakeHost):
        def __init__(self, config: Any, *, session: str | None = None, agents: int | None = None):
            made.append({"config": config, "session": session, "agents": agents})
            with MujocoWorld(config, agents=agents) as shapes:
                super().__init__(shapes, wander)

        def __enter__(self) -> StandIn:
            return self

        def __exit__(self, *exc: object) -> bool:
            return False

    monkeypatch.setattr(vrsync, "Host", StandIn, raising=False)
    summary = tmp_path / "summary.json"
    # Each agent writes what it would read: the session and agent ids of its config.
    code = (
        "import sys, tomllib; doc = tomllib.load(open(sys.argv[1], 'rb')); "
        "ids = [a['id'] for a in doc['agent']]; "
        "open(sys.argv[2], 'w').write('%s %s %s' % (doc['session'], ids, sys.argv[3]))"
    )
    agent = f'{sys.executable} -c "{code}" {{config}} {tmp_path}/agent{{id}} {{session}}:{{agents}}'
    exit_code = cli.main(
        [
            "run", "--config", str(ROVERS_N_TOML), "--frames", "5", "--spawn-agents", "6",
            "--session", "s1", "--summary-json", str(summary), "--quiet", "--agent-cmd", agent,
        ]
    )  # fmt: skip
    assert exit_code == 0
    assert made == [{"config": ROVERS_N_TOML.resolve(), "session": "s1", "agents": 6}]
    s = json.loads(summary.read_text())
    assert (s["frames"], s["agents"]) == (5, 6)
    # wander: wheel speeds for all but agent 3 (a "drive" choice, which this config's
    # agents do not have: rejected) in cycles 0, 1, 2 and 4 (none in cycle 3).
    assert (s["commands_applied"], s["commands_rejected"]) == (4 * 5, 4)
    for i in range(6):
        assert (tmp_path / f"agent{i}").read_text() == "s1 [0, 1, 2, 3, 4, 5] s1:6"
    # A spawned agent that fails fails the run.
    code = cli.main(
        [
            "run", "--config", str(ROVERS_TOML), "--frames", "2", "--spawn-agents", "1",
            "--quiet", "--agent-cmd", f"{sys.executable} -c \"raise SystemExit(3)\"",
        ]
    )  # fmt: skip
    assert code == 1


def test_cli_bench_alone_writes_a_row_without_agents(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    r = _cli(
        "bench", "--config", str(ROVERS_TOML), "--frames", "2", "--alone", "--quick",
        "--json", str(out),
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    (row,) = json.loads(out.read_text())
    assert (row["world"], row["agents"], row["width"], row["rounds"]) == ("mujoco-alone", 4, 84, 1)
    assert row["s_per_cycle"] > 0 and row["p50_us"] > 0 and row["frames"] == 2
    assert row["renders_per_s"] > 0 and row["physics_steps_per_s"] > 0
    assert row["bridge_over_alone"] is None


def test_cli_bench_says_where_it_looked_for_the_agent(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "VRSYNC_BIN_DIR"}
    r = subprocess.run(
        [sys.executable, "-m", "vrsync.mujoco", "bench", "--config", str(ROVERS_TOML), "--quick"],
        capture_output=True, text=True, timeout=300, cwd=ROOT, env=env,
    )  # fmt: skip
    assert r.returncode == 2 and "--bin-dir" in r.stderr and "VRSYNC_BIN_DIR" in r.stderr
    r = _cli("bench", "--config", str(ROVERS_TOML), "--quick", "--bin-dir", str(tmp_path))
    assert r.returncode == 2 and "no channel_agent in" in r.stderr and "--alone" in r.stderr


def test_bench_comparison_takes_the_median_of_the_rounds_medians() -> None:
    from vrsync.mujoco.bench import Comparison

    c = Comparison(16)
    # One disturbed round (the middle one) moves the means, not the p50s.
    c.alone = [[1.0, 1.0, 2.0], [9.0, 9.0, 9.0], [1.0, 1.0, 1.0]]
    c.bridge = [[1.1, 1.1, 1.0], [1.1, 1.1, 1.1], [30.0, 30.0, 30.0]]
    assert Comparison.p50_s(c.alone) == 1.0 and Comparison.p50_s(c.bridge) == pytest.approx(1.1)
    assert c.ratio == pytest.approx(1.1)
    assert c.ratio_mean == pytest.approx(Comparison.mean_s(c.bridge) / Comparison.mean_s(c.alone))


# ---- against the real host (vrsync.Host) ----------------------------------------------

EXAMPLES = ROOT / "agent-sdk" / "python" / "examples"


def _needs_host() -> None:
    import vrsync

    if not hasattr(vrsync, "Host"):
        pytest.skip("this vrsync build has no vrsync.Host (the Python host API)")


def test_cli_run_serves_spawned_agents_with_the_same_hash_twice(tmp_path: Path) -> None:
    _needs_host()
    from conftest import session

    hashes = []
    for k in range(2):
        out = tmp_path / f"summary{k}.json"
        r = _cli(
            "run", "--config", str(ROVERS_TOML), "--frames", "30", "--spawn-agents", "4",
            "--session", session(f"mjrun{k}"), "--summary-json", str(out), "--quiet",
        )  # fmt: skip
        assert r.returncode == 0, r.stdout + r.stderr
        s = json.loads(out.read_text())
        assert (s["frames"], s["agents"], s["stop_timeouts"], s["evicted_agents"]) == (30, 4, 0, [])
        # The wandering agents act every cycle.
        assert s["commands_applied"] == 30 * 4
        hashes.append(s["trajectory_hash"])
    assert hashes[0] == hashes[1]


def test_example_mujoco_host(tmp_path: Path) -> None:
    _needs_host()
    from conftest import session

    name = session("mjex")
    host = subprocess.Popen(
        [sys.executable, str(EXAMPLES / "mujoco_host.py"), "--config", str(ROVERS_TOML),
         "--frames", "20", "--session", name],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    agents = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "vrsync.mujoco.agent",
                "--config",
                str(ROVERS_TOML),
                "--id",
                str(i),
                "--session",
                name,
            ],
        )  # fmt: skip
        for i in range(4)
    ]
    try:
        out, err = host.communicate(timeout=120)
        assert host.returncode == 0, out + err
        words = out.split()
        assert words[:4] == ["frames", "20", "stop-timeouts", "0"], out
        for a in agents:
            assert a.wait(timeout=30) == 0
    finally:
        for p in [host, *agents]:
            if p.poll() is None:
                p.kill()
                p.wait()


# ---- the spawned agents' config ------------------------------------------------------


@pytest.mark.parametrize("name", sorted(p.name for p in (ROOT / "config").glob("*.toml")))
def test_dumps_reads_back_equal(name: str) -> None:
    import tomllib

    from vrsync.mujoco.private_config import dumps

    doc = tomllib.loads((ROOT / "config" / name).read_text())
    assert tomllib.loads(dumps(doc)) == doc


def test_dumps_quotes_what_needs_it() -> None:
    import math
    import tomllib

    from vrsync.mujoco.private_config import dumps

    doc = {"a b": 'q"\\\n\x01', "x": [1.5, -math.inf, True], "t": {"in": {"k": 1}}}
    back = tomllib.loads(dumps(doc))
    assert back["a b"] == doc["a b"] and back["t"] == doc["t"]
    assert back["x"][0] == 1.5 and back["x"][1] == -math.inf and back["x"][2] is True


def test_agents_config_resizes_renames_and_drops_the_world() -> None:
    import tomllib

    from vrsync.mujoco.private_config import agents_config_text

    doc = tomllib.loads(
        agents_config_text(ROVERS_TOML, agents=6, session="s2", tcp_listen="127.0.0.1:4000")
    )
    assert doc["session"] == "s2" and doc["transport"]["tcp_listen"] == "127.0.0.1:4000"
    assert "world" not in doc
    assert [a["id"] for a in doc["agent"]] == list(range(6))
    original = tomllib.loads(ROVERS_TOML.read_text())["agent"]
    assert doc["agent"][:4] == original
    for added in doc["agent"][4:]:
        assert {k: v for k, v in added.items() if k != "id"} == {
            k: v for k, v in original[3].items() if k != "id"
        }
    fewer = tomllib.loads(agents_config_text(ROVERS_TOML, agents=2))
    assert [a["id"] for a in fewer["agent"]] == [0, 1]
    assert fewer["session"] == "mujoco-rovers"


def test_cli_bench_sets_the_bridge_against_mujoco_alone(tmp_path: Path) -> None:
    """The bench's bridge rows: the world serving real `channel_agent` processes, against
    MuJoCo alone stepping the same states (the alone rounds apply the controls a first
    bridge run recorded; the bench fails when the runs' trajectory hashes differ)."""
    _needs_host()
    from conftest import bin_dir, binary

    binary("examples/channel_agent")
    out, csv = tmp_path / "bench.json", tmp_path / "bench.csv"
    r = _cli(
        "bench", "--config", str(ROVERS_N_TOML), "--agents", "2", "--quick",
        "--bin-dir", str(bin_dir()), "--json", str(out), "--csv", str(csv),
    )  # fmt: skip
    assert r.returncode == 0, r.stdout + r.stderr
    alone, bridge = json.loads(out.read_text())
    assert (alone["world"], bridge["world"]) == ("mujoco-alone", "mujoco-bridge")
    assert alone["agents"] == bridge["agents"] == 2
    assert bridge["frames"] == 3 and bridge["p50_us"] > 0
    assert bridge["bridge_over_alone"] == pytest.approx(bridge["p50_us"] / alone["p50_us"])
    assert "mujoco bridge / alone, 2 agents" in r.stdout
    from vrsync.mujoco.cli import BENCH_COLUMNS

    header, *lines = csv.read_text().splitlines()
    assert header.split(",") == list(BENCH_COLUMNS) and len(lines) == 2
