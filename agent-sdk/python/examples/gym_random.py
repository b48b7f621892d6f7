"""A Gymnasium random agent on a vrsync world.

    python gym_random.py --config config/default.toml --id 0 [--steps 200]

Resets, takes random actions from the default action set (nothing / forward / turn left /
turn right), resets every 50 steps, and prints the total reward.
"""

from __future__ import annotations

import argparse

from vrsync.gym import VrsyncEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--id", type=int, default=0)
    parser.add_argument("--session")
    parser.add_argument("--steps", type=int, default=200)
    args = parser.parse_args()

    env = VrsyncEnv(args.config, args.id, session=args.session)
    try:
        obs, info = env.reset(seed=0)
        total = 0.0
        for step in range(1, args.steps + 1):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            total += reward
            if terminated or truncated or step % 50 == 0:
                obs, info = env.reset()
        print(f"steps {args.steps} reward {total:.3f}", flush=True)
    finally:
        env.close()


if __name__ == "__main__":
    main()
