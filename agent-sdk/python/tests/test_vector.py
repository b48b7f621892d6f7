"""The batched core (AgentGroup) and the Gymnasium vector env against real `vr-sim` hosts."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import vrsync
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode
from vrsync.gym import VrsyncEnv
from vrsync.vector import VrsyncVectorEnv

from conftest import run_python, write_config

CAM84 = (("left", 84, "rgb8"),)


def test_group_steps_every_agent_in_the_same_cycle_into_stacked_arrays(
    tmp_path: Path, start_host
) -> None:
    config, _ = write_config(tmp_path, "group", agents=4, cameras=CAM84)
    host = start_host(config, 41)
    group = vrsync.AgentGroup.connect(config, connect_timeout=20)
    assert group.ids == [0, 1, 2, 3] and len(group) == 4
    h, w, c = group.cameras[0].shape
    left = group.images["left"]
    assert left.shape == (4, h, w, c) and left.dtype == np.uint8 and left.flags.c_contiguous
    assert group.positions.shape == (4, 3) and group.rotations.shape == (4, 4)
    with pytest.raises(vrsync.UsageError, match="reset"):
        group.step([0, 0, 0, 0])
    group.set_action_table([None, vrsync.MoveAhead(0.5), vrsync.Turn(-30), [vrsync.Turn(30)]])
    assert group.num_actions == 4
    group.reset()
    start = group.positions.copy()
    cycles = [group.cycles.copy()]
    for step in range(38):
        group.step(np.array([1, 1, 2, (step % 4)], dtype=np.int64))
        cycles.append(group.cycles.copy())
        # the same arrays every step, written in place
        assert np.shares_memory(group.images["left"], left)
    assert all(len(set(c.tolist())) == 1 for c in cycles), cycles
    assert [int(c[0]) for c in cycles] == list(range(int(cycles[0][0]), int(cycles[0][0]) + 39))
    assert len(set(group.sim_time_ns.tolist())) == 1
    moved = np.linalg.norm(group.positions - start, axis=1)
    assert moved[0] > 0.5 and moved[1] > 0.5, "MoveAhead walked"
    assert moved[2] < 1e-3, "turning in place does not move"
    assert group.images["left"].any(), "the images were written"
    assert (group.previous_outcome == 1).all(), "every agent stopped in time"
    steps, sdk_s, wait_s = group.timing
    assert steps == 40 and 0 < sdk_s and 0 <= wait_s  # the first reset waits for frames too
    with pytest.raises(ValueError, match="not in the action table"):
        group.step([0, 9, 0, 0])
    with pytest.raises(TypeError, match="cannot be pickled"):
        pickle.dumps(group)
    group.close()
    assert group.closed
    summary = host.finish()
    assert summary["stop_timeouts"] == 0 and summary["late_stops"] == 0


def test_group_fresh_images_leave_the_arrays_of_earlier_steps_alone(
    tmp_path: Path, start_host
) -> None:
    config, _ = write_config(tmp_path, "fresh", agents=2, cameras=CAM84)
    host = start_host(config, 14)
    group = vrsync.AgentGroup.connect(config, connect_timeout=20)
    assert group.fresh_images is False
    group.set_action_table([vrsync.Turn(30)])
    group.reset()
    group.fresh_images = True
    kept = []
    for _ in range(8):
        group.step(np.zeros(2, dtype=np.int64))
        left = group.images["left"]
        assert np.shares_memory(group.image("left"), left)
        assert left.shape == (2, *group.cameras[0].shape) and left.flags.c_contiguous
        kept.append((left, left.copy()))
    # Each step wrote into new arrays; the turning agents saw something new every cycle.
    assert not np.shares_memory(kept[0][0], kept[1][0])
    assert all(np.array_equal(a, copy) for a, copy in kept)
    assert not np.array_equal(kept[0][1], kept[-1][1])
    group.fresh_images = False
    group.step(np.zeros(2, dtype=np.int64))
    same = group.images["left"]
    group.step(np.zeros(2, dtype=np.int64))
    assert np.shares_memory(same, group.images["left"]), "in place again"
    group.close()
    summary = host.finish()
    assert summary["stop_timeouts"] == 0


def _run_group(
    tmp_path: Path, start_host, tag: str, stacked: bool, steps: int
) -> tuple[list[np.ndarray], str]:
    """Steps a 3-agent group through a fixed action sequence; returns each step's images
    (copies) and the world's trajectory hash."""
    config, _ = write_config(tmp_path, tag, agents=3, cameras=CAM84, stacked=stacked)
    host = start_host(config, steps + 2)
    kept = []
    with vrsync.AgentGroup.connect(config, connect_timeout=20) as group:
        assert group.stacked is stacked
        group.zero_copy = stacked
        group.set_action_table(vrsync.gym.DEFAULT_ACTIONS)
        group.reset()
        for step in range(steps):
            group.step([(step + k) % 4 for k in range(3)])
            left = group.images["left"]
            if stacked:
                # A read-only view of the host's stacked sample, agent after agent.
                assert isinstance(left.base, vrsync.StackedSample)
                assert left.base.cycle == int(group.cycles[0])
                assert not left.flags.writeable and not left.flags.owndata
                assert left.strides[0] >= left[0].nbytes
                assert np.shares_memory(group.image("left"), left)
            kept.append(left.copy())
            del left
    summary = host.finish()
    assert summary["stop_timeouts"] == 0
    return kept, summary["trajectory_hash"]


def test_group_zero_copy_images_are_the_stacked_samples_and_match_the_copies(
    tmp_path: Path, start_host
) -> None:
    copied, copied_hash = _run_group(tmp_path, start_host, "gcopy", False, 12)
    viewed, viewed_hash = _run_group(tmp_path, start_host, "gview", True, 12)
    assert copied_hash == viewed_hash, "the same world"
    assert any(a.any() for a in viewed), "the images were rendered"
    for step, (a, b) in enumerate(zip(copied, viewed)):
        assert a.shape == b.shape and a.shape[0] == 3
        assert np.array_equal(a, b), f"step {step}: the views show the copied pixels"


def test_group_zero_copy_holds_at_most_one_earlier_step_and_needs_stacked_agents(
    tmp_path: Path, start_host
) -> None:
    plain, _ = write_config(tmp_path, "gplain", agents=2, cameras=CAM84)
    host = start_host(plain, 4)
    with vrsync.AgentGroup.connect(plain, connect_timeout=20) as group:
        assert not group.stacked
        with pytest.raises(ValueError, match="stacked_images"):
            group.zero_copy = True
        group.reset()
    host.finish()
    config, _ = write_config(tmp_path, "gheld", agents=2, cameras=CAM84, stacked=True)
    host = start_host(config, 30)
    group = vrsync.AgentGroup.connect(config, connect_timeout=20)
    group.zero_copy = True
    group.set_action_table([None])
    group.reset()
    first = group.images["left"]
    group.step([0, 0])
    second = group.images["left"]
    assert first.base.cycle + 1 == second.base.cycle
    # The images of two earlier steps held: the next step cannot take a third sample.
    with pytest.raises(vrsync.TooManyFramesHeldError):
        group.step([0, 0])
    group.close()
    host.kill()


def test_vector_env_without_copies_views_the_stacked_images(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "vecview", agents=3, cameras=CAM84, stacked=True)
    host = start_host(config, 12)
    envs = VrsyncVectorEnv(
        config, observation="camera", camera="left", copy_observations=False, connect_timeout=20
    )
    assert envs.group.zero_copy
    obs, _ = envs.reset(seed=1)
    for _ in range(6):
        assert isinstance(obs.base, vrsync.StackedSample)
        assert envs.observation_space.contains(obs)
        obs, *_ = envs.step(np.ones(3, dtype=np.int64))
    envs.close()
    # With copies (the default) the env never views shared memory.
    host.finish()
    config, _ = write_config(tmp_path, "veccopy", agents=3, cameras=CAM84, stacked=True)
    host = start_host(config, 4)
    envs = VrsyncVectorEnv(config, observation="camera", camera="left", connect_timeout=20)
    assert not envs.group.zero_copy
    obs, _ = envs.reset(seed=1)
    assert obs.flags.owndata
    envs.close()
    host.finish()


def test_stacked_agents_are_read_by_one_group_only(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "gone", agents=2, cameras=CAM84, stacked=True)
    host = start_host(config)
    # A group of the stacked agents in another order cannot view them, but reads them.
    with vrsync.AgentGroup.connect(config, [1, 0], connect_timeout=20) as group:
        assert not group.stacked
    # One agent alone reads the stacked sample; a second reader is refused.
    agent = vrsync.Agent.connect(config, 0, connect_timeout=20)
    with pytest.raises(vrsync.VrsyncError, match="one group in one process"):
        vrsync.Agent.connect(config, 1, connect_timeout=20)
    agent.close()
    host.kill()


def test_group_over_tcp_and_mixed_transports_matches_the_all_shm_world(
    tmp_path: Path, start_host
) -> None:
    hashes = []
    for tag, per_agent in (("gshm", None), ("gmixed", {1: "tcp"})):
        config, _ = write_config(tmp_path, tag, agents=2, agent_transports=per_agent)
        host = start_host(config, 31)
        with vrsync.AgentGroup.connect(config, connect_timeout=20) as group:
            assert group.transports == (["shm", "shm"] if per_agent is None else ["shm", "tcp"])
            group.set_action_table(vrsync.gym.DEFAULT_ACTIONS)
            group.reset()
            for step in range(29):
                group.step([(step + k) % 4 for k in range(2)])
            assert len(set(group.cycles.tolist())) == 1
        summary = host.finish()
        assert summary["stop_timeouts"] == 0
        hashes.append(summary["trajectory_hash"])
    assert hashes[0] == hashes[1]


def test_group_rejects_agents_with_different_cameras(tmp_path: Path) -> None:
    config, _ = write_config(tmp_path, "gcams", agents=2)
    text = config.read_text().replace('width = 64', 'width = 32', 1)
    config.write_text(text)
    with pytest.raises(vrsync.ConfigError, match="same cameras"):
        vrsync.AgentGroup.connect(config, connect_timeout=1)


def test_ctrl_c_while_a_group_waits_raises_keyboard_interrupt(tmp_path: Path, start_host) -> None:
    # Three agents configured, two connect: the host never starts cycle 0, so the group's
    # reset waits until SIGINT.
    config, _ = write_config(tmp_path, "gsigint", agents=3, connect_timeout=300.0)
    start_host(config)
    child = run_python(
        f"""
import os, signal, threading, time, vrsync
group = vrsync.AgentGroup.connect({str(config)!r}, [0, 1], connect_timeout=20)
sent = []
def interrupt():
    sent.append(time.monotonic())
    os.kill(os.getpid(), signal.SIGINT)
threading.Timer(0.5, interrupt).start()
try:
    group.reset()
except KeyboardInterrupt:
    print("interrupted", round(time.monotonic() - sent[0], 3), flush=True)
"""
    )
    try:
        out, err = child.communicate(timeout=60)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(timeout=30)
    assert child.returncode == 0, out + err
    word, seconds = out.split()
    assert word == "interrupted" and float(seconds) < 0.5, out + err


def test_vector_env_spaces_shapes_and_same_cycle(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "vec", agents=4, cameras=CAM84)
    host = start_host(config, 32)
    envs = VrsyncVectorEnv(config, observation="camera", camera="left", connect_timeout=20)
    h, w, c = envs.group.cameras[0].shape
    assert envs.num_envs == 4
    assert envs.single_observation_space == spaces.Box(0, 255, (h, w, c), np.uint8)
    assert envs.observation_space.shape == (4, h, w, c)
    assert envs.single_action_space == spaces.Discrete(4)
    assert envs.action_space == spaces.MultiDiscrete([4, 4, 4, 4])
    assert envs.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    obs, infos = envs.reset(seed=3)
    assert obs.shape == (4, h, w, c) and obs.dtype == np.uint8
    assert envs.observation_space.contains(obs)
    assert (infos["episode_step"] == 0).all() and infos["_episode_step"].all()
    envs.action_space.seed(3)
    for _ in range(29):
        obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
        assert envs.observation_space.contains(obs)
        assert rewards.shape == terminated.shape == truncated.shape == (4,)
        assert rewards.dtype == np.float64 and terminated.dtype == np.bool_
        assert len(set(envs.group.cycles.tolist())) == 1, "all agents in the same cycle"
        assert (infos["step_cycles"] == 1).all()
    assert obs.flags.owndata, "copies by default"
    prev = obs
    obs, *_ = envs.step(np.zeros(4, dtype=np.int64))
    assert not np.shares_memory(prev, obs)
    with pytest.raises(NotImplementedError):
        envs.render()
    with pytest.raises(TypeError, match="cannot be pickled"):
        pickle.dumps(envs)
    envs.close()
    assert envs.closed and envs.group.closed
    summary = host.finish()
    assert summary["stop_timeouts"] == 0 and summary["late_stops"] == 0


def test_vector_env_dict_observation_matches_the_single_env_space(
    tmp_path: Path, start_host
) -> None:
    config, _ = write_config(tmp_path, "vecdict1")
    host1 = start_host(config)
    single = VrsyncEnv(config, 0, connect_timeout=20)
    space = single.observation_space
    single.close()
    host1.kill()
    config, _ = write_config(tmp_path, "vecdict2", agents=2)
    host = start_host(config)
    envs = VrsyncVectorEnv(config, [1, 0], connect_timeout=20)
    assert envs.group.ids == [1, 0]
    assert envs.single_observation_space == space
    obs, _ = envs.reset()
    assert set(obs) == {"left", "right", "position", "rotation"}
    assert obs["left"].shape == (2, *space["left"].shape) and obs["position"].shape == (2, 3)
    assert envs.observation_space.contains(obs)
    envs.close()
    host.kill()


def test_vector_env_next_step_autoreset(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "vecnext", agents=2)
    host = start_host(config)
    # Agent 0 terminates on its 2nd step of every episode; both truncate after 4 steps.
    envs = VrsyncVectorEnv(
        config,
        observation="dict",
        max_episode_steps=4,
        terminated_fn=lambda g: np.array([True, False]) & (envs._episode_steps == 2),
        connect_timeout=20,
    )
    obs, _ = envs.reset()
    start = obs["position"].copy()
    walk = np.array([1, 1])
    _, _, term, trunc, info = envs.step(walk)
    assert not term.any() and not trunc.any() and info["episode_step"].tolist() == [1, 1]
    obs, _, term, trunc, info = envs.step(walk)
    assert term.tolist() == [True, False] and not trunc.any()
    assert np.linalg.norm(obs["position"][0] - start[0]) > 0.01
    # Next step: agent 0 resets (its action ignored), agent 1 walks on.
    obs, rewards, term, trunc, info = envs.step(walk)
    assert info["episode_step"].tolist() == [0, 3]
    assert rewards[0] == 0.0 and not term.any() and not trunc.any()
    assert np.allclose(obs["position"][0], start[0]), "agent 0 is back at its start"
    assert info["episode_sim_time"][0] == 0.0
    _, _, term, trunc, info = envs.step(walk)
    assert trunc.tolist() == [False, True] and info["episode_step"].tolist() == [1, 4]
    obs, _, term, trunc, info = envs.step(walk)
    assert info["episode_step"].tolist() == [2, 0]
    assert term.tolist() == [True, False]
    assert np.allclose(obs["position"][1], start[1])
    assert len(set(envs.group.cycles.tolist())) == 1
    envs.close()
    host.kill()


def test_vector_env_same_step_autoreset(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "vecsame", agents=2)
    host = start_host(config)
    envs = VrsyncVectorEnv(
        config,
        autoreset_mode="same_step",
        terminated_fn=lambda g: np.array([True, False]) & (envs._episode_steps == 2),
        connect_timeout=20,
    )
    assert envs.metadata["autoreset_mode"] is AutoresetMode.SAME_STEP
    obs, _ = envs.reset()
    start = obs["position"].copy()
    walk = np.array([1, 1])
    envs.step(walk)
    obs, rewards, term, trunc, info = envs.step(walk)
    assert term.tolist() == [True, False]
    assert info["_final_obs"].tolist() == [True, False]
    final = info["final_obs"][0]
    assert np.linalg.norm(final["position"] - start[0]) > 0.01, "the final obs is the walked one"
    assert np.allclose(obs["position"][0], start[0]), "the returned obs is the reset one"
    assert info["step_cycles"].tolist() == [2, 2]
    assert info["episode_step"].tolist() == [0, 2]
    assert info["final_info"]["episode_step"][0] == 2
    _, _, term, _, info = envs.step(walk)
    assert not term.any() and info["episode_step"].tolist() == [1, 3]
    assert len(set(envs.group.cycles.tolist())) == 1
    envs.close()
    host.kill()


def test_vector_env_reset_seeds_np_random_and_resets_every_agent(
    tmp_path: Path, start_host
) -> None:
    config, _ = write_config(tmp_path, "vecseed", agents=2)
    host = start_host(config)
    envs = VrsyncVectorEnv(config, connect_timeout=20)
    obs, _ = envs.reset(seed=11)
    start = obs["position"].copy()
    a = envs.np_random.integers(0, 1000, 5)
    for _ in range(5):
        envs.step(np.array([1, 1]))
    obs, infos = envs.reset(seed=11)
    assert (envs.np_random.integers(0, 1000, 5) == a).all()
    assert np.allclose(obs["position"], start)
    assert (infos["episode_step"] == 0).all() and (infos["episode_sim_time"] == 0).all()
    envs.close()
    host.kill()


def test_vector_env_custom_action_fn(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "vecfn", agents=2)
    host = start_host(config)
    envs = VrsyncVectorEnv(
        config,
        action_space=spaces.Box(-30.0, 30.0, (1,), np.float32),
        action_fn=lambda acts: [vrsync.Turn(angle_deg=float(a[0])) for a in acts],
        connect_timeout=20,
    )
    assert envs.action_space.shape == (2, 1)
    envs.reset()
    before = envs.group.rotations.copy()
    envs.step(np.array([[30.0], [0.0]], dtype=np.float32))
    envs.step(np.array([[30.0], [0.0]], dtype=np.float32))
    assert not np.allclose(envs.group.rotations[0], before[0])
    assert np.allclose(envs.group.rotations[1], before[1])
    envs.close()
    host.kill()


def test_vector_env_options_are_checked(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "vecopts", agents=1)
    host = start_host(config)
    with pytest.raises(ValueError, match="no camera 'nope'"):
        VrsyncVectorEnv(config, observation="camera", camera="nope", connect_timeout=20)
    with pytest.raises(ValueError, match="autoreset_mode"):
        VrsyncVectorEnv(config, autoreset_mode="never", connect_timeout=20)
    with pytest.raises(TypeError, match="function of the frame"):
        VrsyncVectorEnv(config, actions=[lambda f: None], connect_timeout=20)
    # every failed construction let its agent go: the id connects again at once
    envs = VrsyncVectorEnv(config, connect_timeout=20)
    envs.close()
    host.kill()


def test_single_env_camera_observation_is_a_plain_box(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "gymcam")
    host = start_host(config)
    env = VrsyncEnv(config, 0, observation="camera", camera="right", connect_timeout=20)
    assert isinstance(env.observation_space, spaces.Box)
    obs, _ = env.reset()
    assert obs.shape == env.observation_space.shape and env.observation_space.contains(obs)
    obs, *_ = env.step(1)
    assert obs.shape == env.observation_space.shape
    check_env(env, skip_render_check=True)
    env.close()
    host.kill()


def test_bench_vector_drives_every_agent_until_the_host_closes(tmp_path: Path, start_host) -> None:
    import subprocess
    import sys

    config, _ = write_config(tmp_path, "benchvec", agents=3, cameras=CAM84)
    host = start_host(config, 60)
    out = subprocess.run(
        [sys.executable, "-m", "vrsync.bench_vector", "--config", str(config)],
        capture_output=True, text=True, timeout=120,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    lines = out.stdout.split("\n")
    assert lines[0].startswith("checksum ") and int(lines[0].split()[1]) >= 0
    assert lines[1].startswith("sdk_us_per_agent_step ") and float(lines[1].split()[1]) > 0
    summary = host.finish()
    assert summary["frames"] == 60 and summary["stop_timeouts"] == 0
