"""Stable-Baselines3 PPO over every agent of one world (parameter sharing), one process.

    python train_ppo.py --config config/default.toml --camera left [--steps 20000]
                        [--save ppo_vrsync.zip]

Start the host first (`vr-sim run --config config/default.toml`). All agents of the
config are driven by one batched vector env (`vrsync.sb3.VrsyncVecEnv`: one call into Rust
per cycle for all of them) and share one `CnnPolicy` that sees one camera as an image.
The world waits while PPO updates: in sync mode the host keeps waiting for a live,
busy learner (`[sync] wait_for_stop = "alive"`, the default), so no cycle is lost however
long an update takes. Prints the steps, the mean episode reward of the last episodes and
the learner's agent-steps per second.
"""

from __future__ import annotations

import argparse
import time

from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor
from vrsync.sb3 import VrsyncVecEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--session")
    parser.add_argument("--camera", required=True, help="the camera the policy sees")
    parser.add_argument("--steps", type=int, default=20_000, help="agent-steps to train")
    parser.add_argument("--n-steps", type=int, default=128, help="PPO rollout per agent")
    parser.add_argument("--episode", type=int, default=200, help="steps per episode")
    parser.add_argument("--save", help="write the trained model here (.zip)")
    args = parser.parse_args()

    env = VecMonitor(
        VrsyncVecEnv(
            args.config,
            session=args.session,
            observation="camera",
            camera=args.camera,
            max_episode_steps=args.episode,
        )
    )
    try:
        model = PPO(
            "CnnPolicy",
            env,
            n_steps=args.n_steps,
            batch_size=64,
            n_epochs=4,
            seed=0,
            device="cpu",
            verbose=0,
        )
        started = time.perf_counter()
        model.learn(total_timesteps=args.steps)
        elapsed = time.perf_counter() - started
        rewards = [e["r"] for e in model.ep_info_buffer]
        mean = sum(rewards) / len(rewards) if rewards else float("nan")
        print(
            f"agents {env.num_envs} steps {model.num_timesteps} "
            f"mean-episode-reward {mean:.3f} agent-steps/s {model.num_timesteps / elapsed:.0f}",
            flush=True,
        )
        if args.save:
            model.save(args.save)
    finally:
        env.close()


if __name__ == "__main__":
    main()
