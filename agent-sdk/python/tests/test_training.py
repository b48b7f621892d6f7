"""Stable-Baselines3 PPO end to end against a real `vr-sim run` host, a few thousand
steps each: on the single-agent Gymnasium env and on the batched vector env (4 agents,
one 84×84 camera each, observed as a plain image for ``CnnPolicy``).

The learner is slow on purpose: every PPO update (rollout end) takes longer than the
host's `stop_timeout`. In sync mode a live, busy learner must not cost a cycle: the host
reports the agent as slow and keeps waiting (``[sync] wait_for_stop = "alive"``, the
default), so the summary shows no stop timeout, no late stop and no skipped frame, and
every transition the learner saw had its action applied.
"""

from __future__ import annotations

import signal
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from gymnasium.wrappers import TimeLimit
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from vrsync import HostClosedError
from vrsync.gym import VrsyncEnv

from conftest import Host, write_config

STOP_TIMEOUT_S = 0.5
"""The host's stop timeout in these tests; each update takes longer."""

CAMERA_84 = (("eye", 84, "rgb8", 84),)

# One thread for torch: the host and the learner share two cores in CI.
torch.set_num_threads(1)


class SlowUpdates(BaseCallback):
    """Makes every PPO update last longer than the host's stop timeout (as a large
    network or a checkpoint to disk would), and counts them."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self.updates = 0

    def _on_step(self) -> bool:
        return True

    def _on_rollout_end(self) -> None:
        self.updates += 1
        # Compute time, not synchronisation: the host must wait for it, whatever it is.
        time.sleep(self.seconds)


def finish_host(host: Host, step: Any) -> dict[str, Any]:
    """Ends the run from the host's side (Ctrl-C ends it after the current cycle) while
    the agent keeps stepping, and returns the summary. `step()` takes one env step."""
    host.proc.send_signal(signal.SIGINT)
    deadline = time.monotonic() + 60
    with pytest.raises(HostClosedError):
        while time.monotonic() < deadline:
            step()
    return host.finish()


def assert_no_cycle_lost(summary: dict[str, Any], agents: int) -> None:
    assert summary["stop_timeouts"] == 0, summary
    assert summary["late_stops"] == 0, summary
    assert summary["agent_timeouts"] == 0, summary
    assert summary["evicted_agents"] == [], summary
    # Each update was longer than stop_timeout: the host did wait for the learner.
    assert summary["slow_stops"] >= 1, summary
    assert summary["frames_undelivered"] == 0, summary
    # One frame per agent and cycle (the cycle Ctrl-C interrupted may have sent its own).
    frames = summary["frames"]
    assert frames * agents <= summary["frames_delivered"] <= (frames + 1) * agents, summary


def test_ppo_on_the_single_agent_env_loses_no_cycle_while_it_learns(
    tmp_path: Path, start_host
) -> None:
    config, _ = write_config(tmp_path, "ppo1", stop_timeout=STOP_TIMEOUT_S, cameras=CAMERA_84)
    host = start_host(config)
    env = TimeLimit(
        VrsyncEnv(config, 0, observation="camera", camera="eye", connect_timeout=60),
        max_episode_steps=256,
    )
    slow = SlowUpdates(2 * STOP_TIMEOUT_S)
    model = PPO("CnnPolicy", env, n_steps=256, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=2048, callback=slow)
    assert slow.updates == 8
    assert env.unwrapped.agent.frames_skipped == 0
    summary = finish_host(host, lambda: env.step(0))
    env.close()
    assert_no_cycle_lost(summary, agents=1)
    # Every env step was one cycle of the host (PPO's steps, its resets, the last steps).
    assert summary["frames"] >= model.num_timesteps


def test_ppo_on_the_vector_env_with_four_agents_loses_no_cycle(
    tmp_path: Path, start_host
) -> None:
    from vrsync.sb3 import VrsyncVecEnv

    config, _ = write_config(
        tmp_path, "ppo4", agents=4, stop_timeout=STOP_TIMEOUT_S, cameras=CAMERA_84
    )
    host = start_host(config)
    venv = VrsyncVecEnv(
        config, observation="camera", camera="eye", max_episode_steps=128, connect_timeout=60
    )
    assert venv.num_envs == 4 and venv.observation_space.shape == (84, 84, 3)
    slow = SlowUpdates(2 * STOP_TIMEOUT_S)
    model = PPO("CnnPolicy", venv, n_steps=128, batch_size=128, n_epochs=1, seed=0, device="cpu")
    model.learn(total_timesteps=2048, callback=slow)
    assert slow.updates == 4
    actions = np.zeros(4, dtype=np.int64)
    summary = finish_host(host, lambda: venv.step(actions))
    venv.close()
    assert_no_cycle_lost(summary, agents=4)
    assert summary["frames"] * 4 >= model.num_timesteps
