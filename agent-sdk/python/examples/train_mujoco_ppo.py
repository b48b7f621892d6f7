"""Train PPO (Stable-Baselines3) on MuJoCo rovers served through vrsync.

    python examples/train_mujoco_ppo.py --agents 3 --timesteps 30000

A second process serves ``config/mujoco-rovers-n.toml`` (a scene generated for N
rovers, each with a camera, wheel and gyro vectors, a continuous ``wheels`` action and the
reward ``-distance to its target``) as a lock-step vrsync host; this process trains one
shared policy over the N rovers with :class:`vrsync.sb3.VrsyncVecEnv` (observations: the
camera image, the vectors, the pose). Simulated time advances only when every rover has
acted, however long an update takes. An episode ends after ``--episode-steps``; the
env's reset then puts the rover back at its start. Prints the mean reward per step of
every rollout (the learning curve), then of the first and the last, and saves the policy
with ``--save``.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import tempfile
from pathlib import Path

CONFIG = Path(__file__).resolve().parents[3] / "config" / "mujoco-rovers-n.toml"


def serve(config: str, agents: int, session: str) -> None:
    """The host process: the MuJoCo world until its agents leave or it is terminated."""
    import vrsync
    from vrsync.mujoco import MujocoWorld

    with (
        MujocoWorld(config, agents=agents) as world,
        vrsync.Host(config, agents=agents, session=session) as host,
    ):
        world.run(host)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default=str(CONFIG), help="a [world.mujoco] config (%(default)s)")
    p.add_argument("--agents", type=int, default=3, help="rovers, one env each (3)")
    p.add_argument("--timesteps", type=int, default=30_000, help="agent-steps to train (30000)")
    p.add_argument("--n-steps", type=int, default=128, help="PPO rollout length per env (128)")
    p.add_argument("--episode-steps", type=int, default=200, help="steps per episode (200)")
    p.add_argument("--save", default=None, help="where to save the trained policy (.zip)")
    p.add_argument(
        "--observe",
        default=None,
        help="the observation keys the policy sees, comma-separated (default: all: the "
        "camera image, the vectors, position and rotation); e.g. position,rotation,gyro",
    )
    args = p.parse_args()

    import vrsync.mujoco  # noqa: F401  (first: see vrsync.mujoco on torch and Mesa)
    import gymnasium
    import numpy as np
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecEnvWrapper
    from vrsync.mujoco.private_config import agents_config_text
    from vrsync.sb3 import VrsyncVecEnv

    torch.set_num_threads(1)  # leave the other cores to the world's renders
    session = f"ppo-{os.getpid()}"
    with tempfile.TemporaryDirectory() as tmp:
        # The agents' side of the config: the same agents, as many as the host serves.
        agent_config = Path(tmp) / "agents.toml"
        agent_config.write_text(
            agents_config_text(args.config, agents=args.agents, session=session)
        )
        host = multiprocessing.get_context("spawn").Process(
            target=serve, args=(args.config, args.agents, session), daemon=True
        )
        host.start()

        class ForPPO(VecEnvWrapper):  # type: ignore[misc]
            """What PPO learns from, on top of the vrsync VecEnv.

            Actions in [-1, 1], rescaled to the action's bounds: SB3's Gaussian policy
            starts with a standard deviation of 1, which on the wheels' -20..20 rad/s
            would barely turn them. Rewards: the world's reward is minus the distance to
            the target; PPO gets its change (10 x the metres gained since the last step,
            0 on an episode's first step), a potential-based shaping with the same best
            policy and returns of a few units instead of a few hundred. The world's own
            rewards are summed in ``raw_sum``/``raw_n`` for the learning curve."""

            def __init__(self, venv: VrsyncVecEnv, observe: list[str] | None) -> None:
                box = venv.action_space
                self.low, self.high = box.low, box.high
                unit = gymnasium.spaces.Box(-1.0, 1.0, box.shape, np.float32)
                spaces = venv.observation_space.spaces
                unknown = set(observe or ()) - set(spaces)
                if unknown:
                    raise SystemExit(f"--observe: no such observation key {sorted(unknown)} "
                                     f"(the env has {sorted(spaces)})")
                self.keys = observe or list(spaces)
                seen = gymnasium.spaces.Dict({k: spaces[k] for k in self.keys})
                super().__init__(venv, observation_space=seen, action_space=unit)
                self.previous = np.full(venv.num_envs, np.nan)
                self.raw_sum, self.raw_n = 0.0, 0

            def step_async(self, actions: np.ndarray) -> None:
                unit = np.clip(actions, -1.0, 1.0)
                self.venv.step_async(self.low + (unit + 1.0) * 0.5 * (self.high - self.low))

            def reset(self) -> object:
                self.previous[:] = np.nan
                return self.seen(self.venv.reset())

            def seen(self, obs: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
                return {k: obs[k] for k in self.keys}

            def step_wait(self) -> object:
                obs, rewards, dones, infos = self.venv.step_wait()
                obs = self.seen(obs)
                for info in infos:
                    if "terminal_observation" in info:
                        info["terminal_observation"] = self.seen(info["terminal_observation"])
                self.raw_sum += float(rewards.sum())
                self.raw_n += len(rewards)
                shaped = np.nan_to_num(10.0 * (rewards - self.previous)).astype(np.float32)
                self.previous = np.where(dones, np.nan, rewards)
                return obs, shaped, dones, infos

        class Curve(BaseCallback):  # type: ignore[misc]
            """The world's mean reward per agent-step (minus the mean distance to the
            target, m) of every rollout."""

            def __init__(self, env: ForPPO) -> None:
                super().__init__()
                self.env = env
                self.means: list[float] = []

            def _on_step(self) -> bool:
                return True

            def _on_rollout_end(self) -> None:
                self.means.append(self.env.raw_sum / max(self.env.raw_n, 1))
                self.env.raw_sum, self.env.raw_n = 0.0, 0
                print(
                    f"rollout {len(self.means)} ({self.num_timesteps} agent-steps): "
                    f"reward per step {self.means[-1]:.3f}",
                    flush=True,
                )

        observe = args.observe.split(",") if args.observe else None
        env = ForPPO(
            VrsyncVecEnv(agent_config, connect_timeout=60, max_episode_steps=args.episode_steps),
            observe,
        )
        try:
            model = PPO(
                "MultiInputPolicy", env, n_steps=args.n_steps, batch_size=64, seed=0,
                device="cpu",
            )  # fmt: skip
            rewards = Curve(env)
            model.learn(args.timesteps, callback=rewards)
            if args.save:
                model.save(args.save)
        finally:
            env.close()  # the host sees its agents leave
            host.terminate()
            host.join(30)
        print(
            f"rollouts {len(rewards.means)} reward per step: first {rewards.means[0]:.3f} "
            f"last {rewards.means[-1]:.3f}"
        )


if __name__ == "__main__":
    main()
