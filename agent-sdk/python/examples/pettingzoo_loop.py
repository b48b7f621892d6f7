"""A PettingZoo parallel loop: every agent of the config from one process.

    python pettingzoo_loop.py --config config/default.toml [--cycles 100]

Each step, every agent takes a random action; all of them act in the same cycle.
"""

from __future__ import annotations

import argparse

from vrsync.pettingzoo import VrsyncParallelEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--session")
    parser.add_argument("--cycles", type=int, default=100)
    args = parser.parse_args()

    env = VrsyncParallelEnv(args.config, session=args.session, max_cycles=args.cycles)
    try:
        observations, infos = env.reset(seed=0)
        steps = 0
        while env.agents:
            actions = {a: env.action_space(a).sample() for a in env.agents}
            observations, rewards, terminations, truncations, infos = env.step(actions)
            steps += 1
        print(f"agents {len(env.possible_agents)} steps {steps}", flush=True)
    finally:
        env.close()


if __name__ == "__main__":
    main()
