"""The Stable-Baselines3 VecEnv adapter against a real `vr-sim` host (SB3 and torch are
test requirements)."""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecCheckNan, VecEnv, VecMonitor
from vrsync.sb3 import VrsyncVecEnv

from conftest import write_config

CAM84 = (("left", 84, "rgb8"),)


def test_importing_vrsync_does_not_import_sb3() -> None:
    out = subprocess.run(
        [sys.executable, "-c", "import sys, vrsync, vrsync.vector, vrsync.gym; "
         "print('stable_baselines3' in sys.modules, 'torch' in sys.modules)"],
        capture_output=True, text=True, timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]


def test_vec_env_api_and_terminal_observation(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "sb3api", agents=2, cameras=CAM84)
    host = start_host(config)
    env = VrsyncVecEnv(
        config, observation="camera", max_episode_steps=3, connect_timeout=20
    )
    assert isinstance(env, VecEnv) and env.num_envs == 2
    h, w, c = env.venv.group.cameras[0].shape
    assert env.observation_space.shape == (h, w, c)
    assert env.get_attr("num_envs") == [2, 2]
    assert env.env_is_wrapped(VecMonitor) == [False, False]
    assert env.env_method("__repr__", indices=[1]) == [repr(env.venv)]
    env.set_attr("metadata", env.venv.metadata)
    wrapped = VecMonitor(VecCheckNan(env, raise_exception=True))
    env.seed(5)
    obs = wrapped.reset()
    assert obs.shape == (2, h, w, c)
    for step in range(1, 7):
        obs, rewards, dones, infos = wrapped.step(np.array([1, 2]))
        assert obs.shape == (2, h, w, c) and rewards.dtype == np.float32
        if step % 3 == 0:
            assert dones.all()
            for info in infos:
                assert info["terminal_observation"].shape == (h, w, c)
                assert info["TimeLimit.truncated"] is True
                assert info["episode_step"] == 0
            assert "episode" in infos[0], "VecMonitor saw the episode end"
        else:
            assert not dones.any() and "terminal_observation" not in infos[0]
    assert len(set(env.venv.group.cycles.tolist())) == 1
    with pytest.raises(TypeError, match="cannot be pickled"):
        pickle.dumps(env)
    with pytest.raises(TypeError, match="same_step"):
        VrsyncVecEnv(config, autoreset_mode="next_step")
    wrapped.close()
    assert env.venv.group.closed
    host.kill()


def test_ppo_cnn_policy_learns_a_few_steps(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "sb3ppo", agents=2, cameras=CAM84)
    host = start_host(config)
    env = VrsyncVecEnv(config, observation="camera", max_episode_steps=50, connect_timeout=20)
    model = PPO("CnnPolicy", env, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    assert model.num_timesteps == 256
    env.close()
    summary_host = host
    summary_host.kill()
