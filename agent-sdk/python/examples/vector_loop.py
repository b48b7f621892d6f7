"""A batched Gymnasium vector env over every agent of the config, with random actions.

    python vector_loop.py --config config/default.toml [--steps 1000] [--camera left]

All agents live in this process and act in the same cycle; one step is one call into
Rust. Prints the agent-steps per second of the whole loop and the SDK's own time per
agent-step (inside Rust, blocked waiting excluded).
"""

from __future__ import annotations

import argparse
import time

from vrsync.vector import VrsyncVectorEnv


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--session")
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--camera", help="observe this camera as a plain Box (default: a Dict)")
    parser.add_argument("--no-copy", action="store_true", help="copy_observations=False")
    args = parser.parse_args()

    envs = VrsyncVectorEnv(
        args.config,
        session=args.session,
        observation="camera" if args.camera else "dict",
        camera=args.camera,
        max_episode_steps=200,
        copy_observations=not args.no_copy,
    )
    try:
        envs.reset(seed=0)
        envs.action_space.seed(0)
        envs.group.reset_timing()
        started = time.perf_counter()
        for _ in range(args.steps):
            envs.step(envs.action_space.sample())
        elapsed = time.perf_counter() - started
        calls, sdk_s, _wait_s = envs.group.timing
        agent_steps = envs.num_envs * args.steps
        print(
            f"agents {envs.num_envs} steps {args.steps} "
            f"agent-steps/s {agent_steps / elapsed:.0f} "
            f"sdk-us-per-agent-step {sdk_s / (calls * envs.num_envs) * 1e6:.2f}",
            flush=True,
        )
    finally:
        envs.close()


if __name__ == "__main__":
    main()
