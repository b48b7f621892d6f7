"""Serve a MuJoCo scene to vrsync agents from Python: a simulator as the host.

    python examples/mujoco_host.py --config ../../config/mujoco-rovers.toml --frames 200
    # and one agent per [[agent]] id, e.g. the wandering agent:
    python -m vrsync.mujoco.agent --config ../../config/mujoco-rovers.toml --id 0

Each cycle the world renders every agent's cameras straight into the frame the host
loaned (no image copy), writes its vectors, pose and reward, publishes it, signals
start, collects the agents' actions, applies them to the actuators and steps the
physics by the config's simulation_time_per_frame. Prints
``frames N stop-timeouts T actions A hash H`` at the end.
"""

from __future__ import annotations

import argparse

import vrsync
from vrsync.mujoco import MujocoWorld


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", required=True, help="a config with a [world.mujoco] table")
    p.add_argument("--frames", type=int, default=200, help="cycles to run")
    p.add_argument("--session", default=None, help="session name (default: the config's)")
    args = p.parse_args()

    with (
        MujocoWorld(args.config) as world,
        vrsync.Host(args.config, session=args.session) as host,
    ):
        world.check_host(host)  # same agents, same cycle length
        host.wait_for_agents()
        timeouts = 0
        for _ in range(args.frames):
            # loan -> render/write -> publish for each agent, start, collect, act, step
            report = world.step_cycle(host)
            timeouts += int(report.timed_out)
        print(
            f"frames {world.frames} stop-timeouts {timeouts} "
            f"actions {world.commands_applied} hash {world.trajectory_hash[:16]}"
        )


if __name__ == "__main__":
    main()
