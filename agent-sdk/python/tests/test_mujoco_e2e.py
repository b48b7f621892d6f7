"""The MuJoCo world end to end: real agent processes over every transport.

Four rovers (config/mujoco-rovers.toml): agents 0-2 are driven by one Python process
through `VrsyncVectorEnv` (continuous `wheels` action, a deterministic policy of the
observed vectors and the step number), agent 3 by the Rust example `channel_agent`
(discrete `drive` action). The host is `python -m vrsync.mujoco run` as a process, or
`MujocoWorld` + `vrsync.Host` in this process when a test needs each cycle's report.
Every wait has a deadline; every process a test starts is killed at its end. Skipped
when `mujoco` cannot be imported.
"""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
import tomllib
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

os.environ.setdefault("MUJOCO_GL", "egl")
pytest.importorskip("mujoco", reason="the `mujoco` package is not installed")

import vrsync  # noqa: E402
from vrsync.mujoco import MujocoWorld  # noqa: E402
from vrsync.mujoco.private_config import dumps  # noqa: E402

from conftest import TRANSPORTS, binary, free_tcp_port, session  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]
ROVERS_TOML = ROOT / "config" / "mujoco-rovers.toml"

DEADLINE = 60.0
"""Seconds any one wait of these tests may take (they take a few seconds)."""

FRAMES = 60
"""Cycles of each hash run: agent 3's choice changes every 10 cycles, so every choice of
its first six is applied."""

# `python -c DRIVER CONFIG IDS JITTER_SEED`: the agents IDS ("0,1,2") of CONFIG driven by
# one VrsyncVectorEnv until the host closes the session. The policy depends only on the
# step number and the observed vectors (wheel angles and speeds, gyro), so the run
# repeats exactly whatever the timing. With a seed >= 0 the process sleeps a seeded
# random 0-20 ms before each step (jitter). Prints {"steps": ..., "low": ..., "high": ...}
# at the end (steps: those whose next frame came).
DRIVER = """
import json, sys, time
import numpy as np
import vrsync
from vrsync.vector import VrsyncVectorEnv

config, ids, jitter_seed = sys.argv[1], [int(i) for i in sys.argv[2].split(",")], int(sys.argv[3])
jitter = np.random.default_rng(jitter_seed) if jitter_seed >= 0 else None
env = VrsyncVectorEnv(config, agent_ids=ids, connect_timeout=60, step_timeout=60)
space = env.single_action_space
obs, _ = env.reset()
k = np.arange(len(ids), dtype=np.float64)
steps = 0
try:
    while True:
        wheels, gyro = obs["wheels"].astype(np.float64), obs["gyro"].astype(np.float64)
        ahead = 10.0 * np.sin(0.15 * steps + k)
        spin = wheels[:, 2] - wheels[:, 3]
        turn = 4.0 * np.cos(0.07 * steps + 0.5 * k) - 0.5 * gyro[:, 2] - 0.05 * spin
        action = np.clip(np.stack([ahead - turn, ahead + turn], axis=1), space.low, space.high)
        if jitter is not None:
            time.sleep(jitter.uniform(0.0, 0.02))
        obs, *_ = env.step(action.astype(np.float32))
        steps += 1
except vrsync.HostClosedError:
    pass
finally:
    env.close()
print(json.dumps({"steps": steps, "low": space.low.tolist(), "high": space.high.tolist()}))
"""

# `python -c PROBE CONFIG ID`: one agent that tries values its action refuses every
# cycle (each must raise ActionError, queueing nothing), then acts with a valid value on
# even cycles only.
# Prints [[cycle, error.action, error.agent_id, str(error)], ...] at the end.
PROBE = """
import json, math, sys
import vrsync

config, agent_id = sys.argv[1], int(sys.argv[2])
seen = []
with vrsync.Agent.connect(config, agent_id, connect_timeout=60) as agent:
    (spec,) = agent.action_specs
    if spec.n is None:
        lo, hi = spec.low, spec.high
        bad = [[hi[0] + 1.0, 0.0], [0.0, lo[1] - 0.5], [math.nan, 0.0], [math.inf, 0.0],
               [0.0], [0.0, 0.0, 0.0]]
        good = [0.5 * hi[0], 0.25 * lo[1]]
    else:
        bad, good = [spec.n, spec.n + 7, -1], spec.n - 1
    for frame in agent.frames(timeout=60):
        for name, value in [(spec.name, v) for v in bad] + [("no_such_action", good)]:
            try:
                agent.act(name, value)
            except vrsync.ActionError as e:
                seen.append([frame.cycle, e.action, e.agent_id, str(e)])
            else:
                seen.append([frame.cycle, None, None, f"accepted {value!r}"])
        if frame.cycle % 2 == 0:
            agent.act(spec.name, good)
        agent.stop()
print(json.dumps(seen))
"""


# ---- configs and processes ------------------------------------------------------------


def rovers_config(
    directory: Path,
    tag: str,
    *,
    transport: str = "shm",
    agent_transports: dict[int, str] | None = None,
    agents: int = 4,
    tcp_port: int = 0,
) -> Path:
    """A copy of mujoco-rovers.toml with a session of its own, `transport` (and each
    agent's own from `agent_transports`), its first `agents` agents, the scene by
    absolute path, and a free loopback port for zenoh when an agent uses it."""
    doc: dict[str, Any] = tomllib.loads(ROVERS_TOML.read_text())
    doc["session"] = session(tag)
    doc["sync"]["connect_timeout"] = DEADLINE
    mj = doc["world"]["mujoco"]
    mj["scene"] = str((ROVERS_TOML.parent / mj["scene"]).resolve())
    mj["agent"] = [e for e in mj["agent"] if e["id"] < agents]
    doc["agent"] = doc["agent"][:agents]
    doc["transport"] = {"kind": transport, "tcp_listen": f"127.0.0.1:{tcp_port}"}
    for a in doc["agent"]:
        if agent_transports and a["id"] in agent_transports:
            a["transport"] = agent_transports[a["id"]]
    if "zenoh" in {transport, *(agent_transports or {}).values()}:
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        doc["transport"]["zenoh"] = {"listen": [endpoint], "connect": [endpoint], "lease": 1.0}
    path = directory / f"{doc['session']}.toml"
    path.write_text(dumps(doc))
    return path


def set_tcp_port(config: Path, address: str | None) -> None:
    """Writes the port an in-process host bound for `tcp_listen = ...:0` into its config,
    for the agents started afterwards."""
    assert address is not None
    port = address.rsplit(":", 1)[1]
    text = config.read_text()
    config.write_text(text.replace('"127.0.0.1:0"', f'"127.0.0.1:{port}"'))


class Procs:
    """The processes of one test, their output in files; killed at its end if running."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.procs: list[tuple[subprocess.Popen[bytes], Path, Path]] = []

    def start(self, args: Sequence[str]) -> subprocess.Popen[bytes]:
        n = len(self.procs)
        out, err = self.directory / f"proc{n}.out", self.directory / f"proc{n}.err"
        with out.open("wb") as o, err.open("wb") as e:
            proc = subprocess.Popen([str(a) for a in args], stdout=o, stderr=e)
        self.procs.append((proc, out, err))
        return proc

    def python(self, code: str, *args: object) -> subprocess.Popen[bytes]:
        return self.start([sys.executable, "-c", code, *map(str, args)])

    def channel_agent(self, config: Path, agent_id: int) -> subprocess.Popen[bytes]:
        return self.start([binary("examples/channel_agent"), config, agent_id])

    def mujoco_host(self, config: Path, frames: int, summary: Path) -> subprocess.Popen[bytes]:
        return self.start(
            [sys.executable, "-m", "vrsync.mujoco", "run", "--config", config,
             "--frames", frames, "--summary-json", summary, "--quiet"]
        )  # fmt: skip

    def finish(self, proc: subprocess.Popen[bytes], timeout: float = DEADLINE) -> str:
        """Waits for `proc` to exit 0 and returns its standard output."""
        _, out, err = next(p for p in self.procs if p[0] is proc)
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{proc.args} still running after {timeout} s:\n{err.read_text()}")
        assert proc.returncode == 0, f"{proc.args} exited {proc.returncode}:\n{err.read_text()}"
        return out.read_text()

    def kill(self) -> None:
        for proc, _, _ in self.procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=30)


@pytest.fixture
def procs(tmp_path: Path) -> Iterator[Procs]:
    p = Procs(tmp_path)
    yield p
    p.kill()


def _needs_host() -> None:
    if not hasattr(vrsync, "Host"):
        pytest.skip("this vrsync build has no vrsync.Host (the Python host API)")


# ---- 1. one trajectory over every transport -------------------------------------------


def run_rovers(
    directory: Path, procs: Procs, tag: str, *, jitter_seed: int = -1, **transports: Any
) -> dict[str, Any]:
    """`FRAMES` cycles of the MuJoCo host process serving the driver (agents 0-2) and
    channel_agent (agent 3); checks every process's exit and returns the summary."""
    kinds = {transports.get("transport"), *transports.get("agent_transports", {}).values()}
    # The host process does not say where it listens: a port that was free a moment ago.
    config = rovers_config(
        directory, tag, tcp_port=free_tcp_port() if "tcp" in kinds else 0, **transports
    )
    summary = directory / f"{tag}.summary.json"
    host = procs.mujoco_host(config, FRAMES, summary)
    driver = procs.python(DRIVER, config, "0,1,2", jitter_seed)
    rust = procs.channel_agent(config, 3)
    procs.finish(host)
    # Reset in cycle 0, steps in cycles 1..FRAMES-1; the last one's frame never comes.
    assert json.loads(procs.finish(driver))["steps"] == FRAMES - 2
    procs.finish(rust)
    return json.loads(summary.read_text())


def check_run(s: dict[str, Any]) -> None:
    assert (s["frames"], s["agents"], s["stop_timeouts"], s["evicted_agents"]) == (
        FRAMES, 4, 0, []
    ), s
    assert not s["interrupted"]
    # The driver resets in cycle 0 (one reset per agent, applied: its body is already at
    # the start) and acts in every later cycle; channel_agent acts in every cycle.
    assert (s["commands_applied"], s["commands_rejected"]) == (3 + 3 * (FRAMES - 1) + FRAMES, 0), s
    stats = s["host_stats"]
    assert (stats["actions_rejected"], stats["evictions"], stats["late_batches"]) == (0, 0, 0)


@pytest.fixture(scope="module")
def shm_summary(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """The reference run: every agent on shared memory."""
    _needs_host()
    directory = tmp_path_factory.mktemp("shm")
    procs = Procs(directory)
    try:
        yield run_rovers(directory, procs, "mjshm")
    finally:
        procs.kill()


VARIANTS: dict[str, dict[str, Any]] = {
    "shm": {"transport": "shm"},
    "tcp": {"transport": "tcp"},
    "zenoh": {"transport": "zenoh"},
    "mixed": {"agent_transports": {0: "shm", 1: "tcp", 2: "zenoh", 3: "shm"}},
    "mixed-jitter": {
        "agent_transports": {0: "shm", 1: "tcp", 2: "zenoh", 3: "shm"},
        "jitter_seed": 3,
    },
    "shm-jitter": {"transport": "shm", "jitter_seed": 5},
}


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_the_trajectory_hash_is_the_same_over_every_transport(
    tmp_path: Path, procs: Procs, shm_summary: dict[str, Any], variant: str
) -> None:
    if variant == "shm":
        check_run(shm_summary)
        return
    s = run_rovers(tmp_path, procs, f"mj{variant}", **VARIANTS[variant])
    check_run(s)
    assert s["trajectory_hash"] == shm_summary["trajectory_hash"], variant


# ---- the world in this process: each cycle's report ------------------------------------


class _Spec:
    """An ``[[agent.action]]`` entry with the fields of ``vrsync.Action``."""

    def __init__(self, entry: dict[str, Any]) -> None:
        self.name: str = entry["name"]
        self.n: int | None = entry.get("n")
        self.len: int = 1 if self.n is not None else entry["len"]
        self.low = np.full(self.len, entry.get("low", -np.inf), np.float32)
        self.high = np.full(self.len, entry.get("high", np.inf), np.float32)


def specs_of(config: Path) -> dict[int, list[_Spec]]:
    """Each agent's action specs, read from `config`."""
    doc = tomllib.loads(config.read_text())
    return {a["id"]: [_Spec(e) for e in a.get("action", [])] for a in doc["agent"]}


def in_bounds(report: Any, specs: dict[int, list[_Spec]]) -> None:
    """Every action value the host handed over lies within its spec; nothing refused."""
    for ar in report.agents:
        assert (ar.actions_rejected, ar.invalid_commands) == (0, 0), (report.cycle, ar)
        for spec in specs[ar.agent_id]:
            value = ar.actions[spec.name]
            if value is None:
                continue
            if spec.n is not None:
                assert isinstance(value, int) and 0 <= value < spec.n, (report.cycle, value)
            else:
                v = np.asarray(value)
                assert v.shape == (spec.len,) and np.isfinite(v).all(), (report.cycle, v)
                assert (v >= spec.low).all() and (v <= spec.high).all(), (report.cycle, v)


def serve(
    world: MujocoWorld,
    host: Any,
    until: Callable[[Any], bool],
    what: str,
    max_cycles: int = 5000,
) -> Any:
    """Cycles until `until(report)` holds (within `DEADLINE` s and `max_cycles`); returns
    that report."""
    deadline = time.monotonic() + DEADLINE
    for _ in range(max_cycles):
        report = world.step_cycle(host)
        if until(report):
            return report
        if time.monotonic() > deadline:
            break
    pytest.fail(f"no cycle {what} within {DEADLINE} s / {max_cycles} cycles")


# ---- 2. a killed agent is evicted and rejoins -----------------------------------------


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_a_killed_agent_is_evicted_and_rejoins(
    tmp_path: Path, procs: Procs, transport: str
) -> None:
    """Agent 3 (channel_agent, on `transport`) is SIGKILLed and started again; the
    others (shm) go on meanwhile."""
    _needs_host()
    config = rovers_config(tmp_path, f"mjkill-{transport}", agent_transports={3: transport})
    specs = specs_of(config)
    reports: list[Any] = []

    def check(report: Any) -> Any:
        in_bounds(report, specs)
        reports.append(report)
        return report

    with MujocoWorld(config) as world, vrsync.Host(config) as host:
        if transport == "tcp":
            set_tcp_port(config, host.tcp_address)
        driver = procs.python(DRIVER, config, "0,1,2", -1)
        doomed = procs.channel_agent(config, 3)
        host.wait_for_agents(timeout=DEADLINE)
        serve(world, host, lambda r: check(r).cycle == 9, "9")
        assert all(r.agent(3).actions["drive"] is not None for r in reports)
        doomed.kill()  # SIGKILL between cycles
        doomed.wait(timeout=DEADLINE)
        lost = serve(world, host, lambda r: check(r).agent(3).evicted, "evicting agent 3")
        assert lost.agent(3).actions["drive"] is None and not lost.timed_out
        back = procs.channel_agent(config, 3)
        serve(world, host, lambda r: check(r).agent(3).rejoined, "where agent 3 rejoined")
        # The new process acts from its first frame on.
        tail = [check(world.step_cycle(host)) for _ in range(5)]
        assert all(r.agent(3).actions["drive"] is not None for r in tail)
        summary = world.summary(host)
    procs.finish(back)
    assert json.loads(procs.finish(driver))["steps"] == len(reports) - 2
    stats = summary["host_stats"]
    assert stats["evictions"] >= 1 and stats["rejoins"] >= 1, stats
    assert (summary["evicted_agents"], summary["stop_timeouts"]) == ([3], 0), summary
    assert summary["frames"] == len(reports) and stats["actions_rejected"] == 0


# ---- 3. values outside an action are refused by the agent's SDK ------------------------


def test_bad_actions_are_refused_and_nothing_is_queued(tmp_path: Path, procs: Procs) -> None:
    _needs_host()
    config = rovers_config(tmp_path, "mjbad", agent_transports={1: "tcp", 2: "tcp"})
    specs = specs_of(config)
    cycles = 10
    with MujocoWorld(config) as world, vrsync.Host(config) as host:
        set_tcp_port(config, host.tcp_address)
        probes = {i: procs.python(PROBE, config, i) for i in (0, 3)}
        driver = procs.python(DRIVER, config, "1,2", -1)
        host.wait_for_agents(timeout=DEADLINE)
        for cycle in range(cycles):
            report = world.step_cycle(host)
            assert report.cycle == cycle
            in_bounds(report, specs)
            wheels, drive = report.agent(0).actions["wheels"], report.agent(3).actions["drive"]
            if cycle % 2:
                assert (wheels, drive) == (None, None), cycle
            else:
                np.testing.assert_array_equal(wheels, np.float32([10.0, -5.0]))
                assert drive == 4
        stats = host.stats()
    assert stats["actions_rejected"] == 0 and stats["stop_timeouts"] == 0
    procs.finish(driver)
    # What each refusal says, in the order PROBE tries the values: the action's name and
    # what it takes (bounds, length, choices).
    expected = {
        0: ["outside [-20, 20]"] * 4 + ["takes 2 floats, got 1", "takes 2 floats, got 3"],
        3: ["is a choice in 0..5, got 5", "is a choice in 0..5, got 12", "is a choice in 0..5"],
    }
    for agent_id, proc in probes.items():
        seen = json.loads(procs.finish(proc))
        name = specs[agent_id][0].name
        tries = len(expected[agent_id]) + 1
        assert len(seen) == cycles * tries, seen
        for k, (cycle, action, who, message) in enumerate(seen):
            assert (cycle, who) == (k // tries, agent_id), seen[k]
            if k % tries == tries - 1:
                assert action == "no_such_action" and "no_such_action" in message, seen[k]
                continue
            assert action == name and f'action "{name}"' in message, seen[k]
            assert expected[agent_id][k % tries] in message, seen[k]


# ---- 4. a trainer: SB3's PPO on the MuJoCo world ---------------------------------------

# PPO ("MultiInputPolicy": the camera through a CNN, the vectors, position and rotation)
# on VrsyncVecEnv over every agent of CONFIG, UPDATES rollouts of N_STEPS steps each.
# Prints what the env and the model say afterwards. A process of its own: torch's triton
# segfaults when it loads into a process that rendered with Mesa's llvmpipe (both bring
# LLVM), and the in-process tests here render.
TRAINER = """
import json, sys, time
t0 = time.monotonic()
import torch
from stable_baselines3 import PPO

# One thread: on a small machine torch's spinning workers starve the host's renders.
torch.set_num_threads(1)
from vrsync.sb3 import VrsyncVecEnv

config, n_steps, updates = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
t1 = time.monotonic()
env = VrsyncVecEnv(config, connect_timeout=60, step_timeout=60)
try:
    model = PPO("MultiInputPolicy", env, n_steps=n_steps, batch_size=32, n_epochs=1, seed=0,
                device="cpu")
    t2 = time.monotonic()
    model.learn(updates * n_steps * env.num_envs)
    t3 = time.monotonic()
    out = {
        "num_envs": env.num_envs,
        "num_timesteps": model.num_timesteps,
        "action_space": [env.action_space.low.tolist(), env.action_space.high.tolist()],
        "observations": sorted(env.observation_space.spaces),
        "import_s": t1 - t0, "setup_s": t2 - t1, "learn_s": t3 - t2,
    }
finally:
    env.close()
print(json.dumps(out))
"""


def test_ppo_trains_on_three_rovers_sharing_the_wheels_action(
    tmp_path: Path, procs: Procs
) -> None:
    _needs_host()
    if importlib.util.find_spec("stable_baselines3") is None:
        pytest.skip("stable-baselines3 is not installed")
    config = rovers_config(tmp_path, "mjppo", agents=3)
    summary = tmp_path / "ppo.summary.json"
    # More cycles than training takes: the host is ended with SIGTERM (as Ctrl-C).
    host = procs.mujoco_host(config, 1_000_000, summary)
    n_steps, updates = 32, 3
    trainer = procs.python(TRAINER, config, n_steps, updates)
    out = json.loads(procs.finish(trainer, timeout=3 * DEADLINE))
    assert (out["num_envs"], out["num_timesteps"]) == (3, updates * n_steps * 3)
    assert out["action_space"] == [[-20.0, -20.0], [20.0, 20.0]]
    assert {"eye", "wheels", "gyro"} <= set(out["observations"])
    host.send_signal(signal.SIGTERM)
    procs.finish(host)
    s = json.loads(summary.read_text())
    assert s["interrupted"] and (s["agents"], s["stop_timeouts"], s["evicted_agents"]) == (3, 0, [])
    # A reset cycle, then one cycle per step: every rover acted in each step's cycle.
    assert s["frames"] >= 1 + updates * n_steps, s
    assert s["commands_applied"] >= updates * n_steps * 3, s
    assert s["host_stats"]["actions_rejected"] == 0
