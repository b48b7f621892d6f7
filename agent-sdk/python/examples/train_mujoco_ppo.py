"""Train PPO (Stable-Baselines3) on MuJoCo rovers served through vrsync.

    python examples/train_mujoco_ppo.py --agents 3 --timesteps 30000

A second process serves ``config/mujoco-rovers-n.toml`` (a scene generated for N
rovers, each with a camera, wheel and gyro vectors, a continuous ``wheels`` action and the
reward ``-distance to its target``) as a lock-step vrsync host; this process trains one
shared policy over the N rovers with :class:`vrsync.sb3.VrsyncVecEnv` (observations: the
camera image, the vectors, the pose). Simulated time advances only when every rover has
acted, however long an update takes. Prints the mean reward per step of the first and of
the last rollout, then saves the policy with ``--save``.
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
    args = p.parse_args()

    import vrsync.mujoco  # noqa: F401  (first: see vrsync.mujoco on torch and Mesa)
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
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

        class Rewards(BaseCallback):  # type: ignore[misc]
            """Mean reward per agent-step of every rollout."""

            def __init__(self) -> None:
                super().__init__()
                self.means: list[float] = []
                self._sum = 0.0
                self._n = 0

            def _on_step(self) -> bool:
                rewards = self.locals["rewards"]
                self._sum += float(rewards.sum())
                self._n += len(rewards)
                return True

            def _on_rollout_end(self) -> None:
                self.means.append(self._sum / max(self._n, 1))
                self._sum, self._n = 0.0, 0

        env = VrsyncVecEnv(
            agent_config, connect_timeout=60, max_episode_steps=args.episode_steps
        )
        try:
            model = PPO(
                "MultiInputPolicy", env, n_steps=args.n_steps, batch_size=64, seed=0,
                device="cpu",
            )  # fmt: skip
            rewards = Rewards()
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
