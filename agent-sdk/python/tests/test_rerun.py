"""`vr-sim run --rrd FILE`: the Rerun recording, read back with the matching `rerun-sdk`.

Needs a vr-sim built with the `rerun` cargo feature (scripts/test-all and CI build the
workspace with `--features vrsync-sim/rerun`).
"""

from __future__ import annotations

import json
import subprocess
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from conftest import binary, write_config

import pyarrow as pa  # rerun-sdk's dependency
import rerun.experimental as rr_experimental

FRAMES = 30
AGENTS = 2
CAMERAS = ("left", "right")
WIDTH, HEIGHT = 64, 48


def run_vr_sim(tmp_path: Path, every: int) -> tuple[Path, Path]:
    """Runs 2 spawned circling agents for FRAMES cycles with --rrd and --record."""
    config, _ = write_config(
        tmp_path, f"rerun{every}", agents=AGENTS, cameras=[(c, WIDTH, "rgb8", HEIGHT) for c in CAMERAS]
    )
    rrd = tmp_path / "run.rrd"
    record = tmp_path / "run.jsonl"
    args = [
        str(binary("vr-sim")), "run", "--config", str(config), "--quiet",
        "--frames", str(FRAMES), "--spawn-agents", str(AGENTS),
        "--agent-arg=--policy", "--agent-arg=circle",
        "--rrd", str(rrd), "--record", str(record), "--rerun-every", str(every),
    ]  # fmt: skip
    try:
        done = subprocess.run(args, capture_output=True, text=True, timeout=180)
    except subprocess.TimeoutExpired:
        pytest.fail("vr-sim did not finish within 180 s")
    if done.returncode == 2 and "without the `rerun` feature" in done.stderr:
        pytest.fail(
            "this vr-sim was built without the `rerun` feature: build it with "
            "`cargo build --workspace --features vrsync-sim/rerun` (as scripts/test-all does)",
            pytrace=False,
        )
    assert done.returncode == 0, f"vr-sim exited {done.returncode}:\n{done.stderr}"
    return rrd, record


def read_rrd(path: Path) -> dict[str, list[dict[str, Any]]]:
    """Every row of the recording, by entity path: {column name: value}, static rows with
    `static: True`."""
    rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for chunk in rr_experimental.RrdReader(path).stream():
        batch = chunk.to_record_batch()
        # The wall-clock `log_time` (ns timestamps) is of no use here.
        keep = [f.name for f in batch.schema if not pa.types.is_timestamp(f.type)]
        for row in batch.select(keep).to_pylist():
            row["static"] = chunk.is_static
            rows[chunk.entity_path].append(row)
    return rows


def column(row: dict[str, Any], name: str) -> list[Any]:
    """The instances of component column `name` (e.g. ``"Image:buffer"``) in `row`."""
    assert name in row, f"no column {name} in {sorted(row)}"
    value = row[name]
    assert isinstance(value, list), (name, value)
    return value


def has_column(row: dict[str, Any], name: str) -> bool:
    return row.get(name) is not None


@pytest.mark.parametrize("every", [1, 7])
def test_the_rrd_holds_images_and_the_recorded_poses(tmp_path: Path, every: int) -> None:
    rrd, record = run_vr_sim(tmp_path, every)
    rows = {p.lstrip("/"): r for p, r in read_rrd(rrd).items()}

    expected_paths = {"world", "world/room", "world/room/walls", "host/wait_ms", "host/stop_timeouts"}
    for a in range(AGENTS):
        expected_paths |= {
            f"world/room/agents/{a}/body",
            f"world/room/agents/{a}/trajectory/0",
            f"agents/{a}/commands",
            f"agents/{a}/statuses",
            f"agents/{a}/reward_total",
        }
        for cam in CAMERAS:
            expected_paths |= {f"agents/{a}/cameras/{cam}", f"world/room/agents/{a}/eyes/{cam}"}
    assert expected_paths <= set(rows), f"missing: {sorted(expected_paths - set(rows))}"

    recorded: dict[tuple[int, int], dict[str, Any]] = {}
    for line in record.read_text().splitlines():
        entry = json.loads(line)
        if "agent" in entry:
            recorded[(entry["agent"], entry["cycle"])] = entry
    assert len(recorded) == AGENTS * FRAMES
    assert all(line["sensed"] for line in recorded.values())

    # Exactly one image per agent and camera per logged cycle (0, every, 2*every, ...),
    # at the sim time of the cycle's start.
    logged_cycles = list(range(0, FRAMES, every))
    for a in range(AGENTS):
        for cam in CAMERAS:
            images = [r for r in rows[f"agents/{a}/cameras/{cam}"] if has_column(r, "Image:buffer")]
            assert sorted(r["cycle"] for r in images) == logged_cycles, (a, cam)
            for r in images:
                (fmt,) = column(r, "Image:format")
                assert (fmt["width"], fmt["height"]) == (WIDTH, HEIGHT), fmt
                (buffer,) = column(r, "Image:buffer")
                assert len(buffer) == WIDTH * HEIGHT * 3
                assert r["sim_time"].total_seconds() == pytest.approx(r["cycle"] * 0.1)

    # One pose per agent and cycle, equal (as f32) to the record's state after the cycle,
    # at the record's sim time.
    moved = False
    for a in range(AGENTS):
        poses = [
            r for r in rows[f"world/room/agents/{a}/body"]
            if not r["static"] and has_column(r, "Transform3D:translation")
        ]  # fmt: skip
        assert sorted(r["cycle"] for r in poses) == list(range(FRAMES)), a
        for r in poses:
            line = recorded[(a, r["cycle"])]
            (translation,) = column(r, "Transform3D:translation")
            (quaternion,) = column(r, "Transform3D:quaternion")
            where = (a, r["cycle"])
            assert np.array_equal(np.float32(translation), np.float32(line["position"])), where
            assert np.array_equal(np.float32(quaternion), np.float32(line["rotation"])), where
            assert r["sim_time"].total_seconds() == pytest.approx(line["sim_time_s"])
        moved |= recorded[(a, FRAMES - 1)]["position"] != recorded[(a, 0)]["position"]
    assert moved, "the circling agents did not move: the pose comparison shows nothing"

    # Every command (as the record's `sent` writes it) and every status change, once.
    for a in range(AGENTS):
        lines = [recorded[(a, c)] for c in range(FRAMES)]
        commands = [t for r in rows[f"agents/{a}/commands"] for t in column(r, "TextLog:text")]
        assert [json.loads(t) for t in commands] == [s for line in lines for s in line["sent"]]
        statuses = [t for r in rows[f"agents/{a}/statuses"] for t in column(r, "TextLog:text")]
        assert len(statuses) == sum(len(line["statuses"]) for line in lines) > 0
