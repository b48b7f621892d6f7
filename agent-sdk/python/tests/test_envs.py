"""Gymnasium, PettingZoo and the compat layer against real `vr-sim` hosts."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test
from vrsync.compat import Annar4Interface
from vrsync.gym import LateLearnerWarning, VrsyncEnv
from vrsync.pettingzoo import VrsyncParallelEnv

from conftest import TRANSPORTS, write_config


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_gym_env_passes_check_env(tmp_path: Path, start_host, transport: str) -> None:
    config, _ = write_config(tmp_path, "gym", transport=transport)
    host = start_host(config)
    env = VrsyncEnv(config, 0, connect_timeout=20)
    try:
        check_env(env, skip_render_check=True)
    finally:
        env.close()
    host.kill()


def test_gym_env_steps_walks_and_resets(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "gymwalk")
    host = start_host(config)
    env = VrsyncEnv(config, 0, connect_timeout=20, terminated_fn=lambda f: f.cycle >= 12)
    obs, info = env.reset(seed=1)
    start = obs["position"].copy()
    assert info["episode_step"] == 0 and info["episode_sim_time"] == 0.0
    assert obs["left"].shape == env.observation_space["left"].shape
    assert obs["left"].flags.owndata, "copies by default"
    terminated = False
    steps = 0
    while not terminated:
        obs, reward, terminated, truncated, info = env.step(1)  # forward
        steps += 1
        assert not truncated and isinstance(reward, float)
    assert info["episode_step"] == steps
    assert np.linalg.norm(obs["position"] - start) > 0.5, "walking moved the body"
    obs, info = env.reset()
    assert np.allclose(obs["position"], start), "the trial reset put the body back"
    env.close()
    host.kill()


def test_gym_zero_copy_observations_are_views(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "gymview")
    host = start_host(config)
    env = VrsyncEnv(config, 0, connect_timeout=20, copy_observations=False)
    obs, _ = env.reset()
    lo, hi = env.frame.memory_range
    assert lo <= obs["left"].__array_interface__["data"][0] < hi
    del obs
    env.close()
    host.kill()


def test_gym_warns_when_the_learner_is_slower_than_the_stop_timeout(
    tmp_path: Path, start_host
) -> None:
    config, _ = write_config(tmp_path, "gymlate", stop_timeout=0.2, wait_for_stop="timeout")
    host = start_host(config)
    env = VrsyncEnv(config, 0, connect_timeout=20)
    assert env.agent.wait_for_stop == "timeout" and env._step_timeout == pytest.approx(5.4)
    env.reset()
    env._frame_at -= 1.0  # as if the learner had spent a second since the last frame
    with pytest.warns(LateLearnerWarning, match="stop_timeout"):
        env.step(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", LateLearnerWarning)
        env.step(0)  # a fast step does not warn
    env.close()
    host.kill()


def test_gym_waits_for_a_slow_learner_by_default(tmp_path: Path, start_host) -> None:
    # wait_for_stop = "alive" (the default): the host waits for the live learner, so a
    # step after a long pause warns of nothing, and the env waits for frames without limit.
    config, _ = write_config(tmp_path, "gymalive", stop_timeout=0.2)
    host = start_host(config)
    env = VrsyncEnv(config, 0, connect_timeout=20)
    assert env.agent.wait_for_stop == "alive" and env.agent.frame_wait is None
    env.reset()
    env._frame_at -= 1.0  # as if the learner had spent a second since the last frame
    with warnings.catch_warnings():
        warnings.simplefilter("error", LateLearnerWarning)
        env.step(0)
    env.close()
    host.kill()

def test_pettingzoo_env_passes_parallel_api_test(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "pz", agents=2)
    host = start_host(config)
    env = VrsyncParallelEnv(config, connect_timeout=20)
    assert env.possible_agents == ["agent_0", "agent_1"]
    try:
        parallel_api_test(env, num_cycles=40)
    finally:
        env.close()
    host.kill()


def test_pettingzoo_agents_act_in_the_same_cycle(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "pzsame", agents=3)
    host = start_host(config, 30)
    env = VrsyncParallelEnv(config, connect_timeout=20, max_cycles=20)
    env.reset(seed=3)
    cycles = []
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
        cycles.append(env.group.cycles.tolist())
    assert len(cycles) == 20
    assert all(len(set(c)) == 1 for c in cycles), cycles
    env.close()
    summary = host.finish()
    assert summary["stop_timeouts"] == 0


def test_pettingzoo_over_mixed_transports_matches_the_all_shm_world(
    tmp_path: Path, start_host
) -> None:
    hashes = []
    for tag, per_agent in (("pzshm", None), ("pzmixed", {1: "tcp"})):
        config, _ = write_config(tmp_path, tag, agents=2, agent_transports=per_agent)
        host = start_host(config, 41)
        env = VrsyncParallelEnv(config, connect_timeout=20)
        assert env.group.transports == (
            ["shm", "shm"] if per_agent is None else ["shm", "tcp"]
        )
        env.reset(seed=0)
        for step in range(39):
            env.step({a: (step + k) % 4 for k, a in enumerate(env.agents)})
        env.close()
        summary = host.finish()
        assert summary["stop_timeouts"] == 0
        hashes.append(summary["trajectory_hash"])
    assert hashes[0] == hashes[1]


def test_compat_drives_the_original_loop_for_100_cycles(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "compat", transport="tcp")
    host = start_host(config, 100)
    iface = Annar4Interface(config, agentNo=0, connect_timeout=20)
    iface.start()
    cycles = 0
    action = None
    while not iface.closed:
        while not iface.hasStartSyncReceived():
            if iface.closed:
                break
        if iface.closed:
            break
        cycles += 1
        assert iface.checkImages()
        left, right = iface.getImageLeft(), iface.getImageRight()
        assert left.shape == right.shape == (37, 64, 3) and left.flags.writeable
        assert not iface.checkImages(), "images are handed out once per cycle"
        assert iface.checkGridSensorData() and len(iface.getGridSensorData()) == 6
        if action is None or iface.getActionExecState(action) in (1, 2):
            action = iface.sendAgentTurn(20.0)
        iface.sendStopSync()
    iface.stop()
    summary = host.finish()
    assert cycles == 100
    assert summary["stop_timeouts"] == 0 and summary["commands_applied"] > 1
    assert iface.checkActionExecState(action)


def test_gym_env_refuses_a_step_that_would_hold_too_many_frames_and_stays_usable(
    tmp_path: Path, start_host
) -> None:
    import vrsync

    assert vrsync.MAX_FRAMES_HELD == 2
    config, _ = write_config(tmp_path, "gymheld")
    host = start_host(config)
    env = VrsyncEnv(config, 0, connect_timeout=20, copy_observations=False)
    obs0, _ = env.reset()
    obs1, *_ = env.step(0)  # holds the frames of obs0 and obs1 (views)
    cycle = env.frame.cycle
    with pytest.raises(vrsync.TooManyFramesHeldError, match="copy_observations=True") as info:
        env.step(0)
    assert "FrameStackObservation" in str(info.value) and "Nothing was sent" in str(info.value)
    assert info.value.max == 2 and env.agent.frames_held == 2
    assert env.frame.cycle == cycle, "the env did not move"
    del obs0  # the fix: drop (or copy) the old observation ...
    obs2, *_ = env.step(0)  # ... and the same step works
    assert env.frame.cycle == cycle + 1
    del obs1, obs2
    for _ in range(3):
        obs, *_ = env.step(0)  # keeping only the newest view is fine
    assert env.frame.previous_outcome == "stopped"
    del obs
    env.close()
    host.kill()


def test_frame_stacking_needs_copies_and_works_with_them(tmp_path: Path, start_host) -> None:
    import vrsync
    from gymnasium.wrappers import FrameStackObservation

    config, _ = write_config(tmp_path, "gymstack", stop_timeout=1.0)
    host = start_host(config)
    env = FrameStackObservation(VrsyncEnv(config, 0, connect_timeout=20, copy_observations=False), 4)
    env.reset()
    with pytest.raises(vrsync.TooManyFramesHeldError, match="FrameStackObservation"):
        for _ in range(4):
            env.step(0)
    env.close()
    env = FrameStackObservation(VrsyncEnv(config, 0, connect_timeout=20), 4)
    obs, _ = env.reset()
    for _ in range(6):
        obs, *_ = env.step(1)
    assert obs["left"].shape[0] == 4
    env.close()
    host.kill()
