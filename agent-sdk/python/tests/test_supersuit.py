"""The PettingZoo env through supersuit's vector-env conversions, against a real host."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
import supersuit as ss
from vrsync.pettingzoo import VrsyncParallelEnv, _live_env

from conftest import write_config


def test_pettingzoo_env_to_vec_env_and_concat_for_sb3(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "ss", agents=2, cameras=(("left", 84, "rgb8"),))
    host = start_host(config)
    env = VrsyncParallelEnv(config, observation="camera", max_cycles=5, connect_timeout=20)
    assert env.render_mode is None
    venv = ss.pettingzoo_env_to_vec_env_v1(env)
    assert venv.num_envs == 2
    sb3 = ss.concat_vec_envs_v1(venv, 1, num_cpus=0, base_class="stable_baselines3")
    obs = sb3.reset()
    assert obs.shape == (2, *env.observation_space("agent_0").shape)
    dones_seen = 0
    for _ in range(10):
        obs, rewards, dones, infos = sb3.step(np.array([1, 2]))
        assert obs.shape[0] == 2 and rewards.shape == (2,)
        if dones.all():
            dones_seen += 1
            assert "terminal_observation" in infos[0]
    assert dones_seen == 2, "max_cycles=5: two episodes in 10 steps, each reset by supersuit"
    assert len(set(env.group.cycles.tolist())) == 1
    sb3.close()
    assert env.group.closed
    host.kill()


def test_copies_of_the_env_fail_clearly(tmp_path: Path, start_host) -> None:
    config, _ = write_config(tmp_path, "sscopy", agents=2)
    host = start_host(config)
    env = VrsyncParallelEnv(config, connect_timeout=20)
    venv = ss.pettingzoo_env_to_vec_env_v1(env)
    with pytest.raises(TypeError, match="cannot be copied"):
        ss.concat_vec_envs_v1(venv, 2, num_cpus=0, base_class="stable_baselines3")
    with pytest.raises(TypeError, match="cannot be copied"):
        pickle.loads(pickle.dumps(env))
    # another process gets a clear error instead of a broken connection
    _, (token, pid) = env.__reduce__()
    with pytest.raises(TypeError, match="another process"):
        _live_env(token, pid + 1)
    env.close()
    host.kill()
