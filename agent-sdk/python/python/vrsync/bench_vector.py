"""The batched Python benchmark agent: every agent of a config from one process.

    python -m vrsync.bench_vector --config FILE [--session NAME] [--ids 0,1,...] [--warmup N]

Drives the agents through :class:`vrsync.vector.VrsyncVectorEnv` (one
:class:`vrsync.AgentGroup`: one call into Rust per cycle for all of them) and does the work
of ``vrsync.bench_agent`` for each agent: read the first and the last byte of every row of
every image (vectorised over the stacked ``(N, H, W, C)`` arrays), one command (turn 1°),
stop; until the host closes the session. Then prints ``checksum <sum>``,
``sdk_us_per_agent_step <t>``: the time per agent-step spent inside the SDK's Rust code,
blocked waiting for the host excluded, and ``allocs_per_cycle <a>``: the allocations of
the extension's Rust code per agent-step (what a Rust bench agent reports per cycle),
both over the steps after the first ``--warmup`` (the host's warm-up cycles; default 0).
"""

from __future__ import annotations

import argparse

import numpy as np
import vrsync
from vrsync import _vrsync
from vrsync.vector import VrsyncVectorEnv


def touch_rows(images: np.ndarray) -> int:
    """Sum of the first and the last byte of every row of every image of the stack."""
    rows = images.reshape(images.shape[0], images.shape[1], -1)
    if rows.dtype != np.uint8:
        rows = rows.view(np.uint8)
    step = max(rows.shape[2] - 1, 1)
    return int(rows[:, :, ::step].sum())


def main() -> None:
    parser = argparse.ArgumentParser(
        prog="python -m vrsync.bench_vector", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--config", required=True)
    parser.add_argument("--session")
    parser.add_argument("--ids", help="comma-separated agent ids (default: every agent)")
    parser.add_argument(
        "--warmup", type=int, default=0, help="steps before the SDK time is measured (default 0)"
    )
    args = parser.parse_args()
    ids = [int(i) for i in args.ids.split(",")] if args.ids else None
    total = 0
    envs = VrsyncVectorEnv(
        args.config,
        ids,
        actions=[vrsync.Turn(angle_deg=1.0)],
        copy_observations=False,
        session=args.session,
        step_timeout=60,
    )
    try:
        obs, _ = envs.reset()
        actions = np.zeros(envs.num_envs, dtype=np.int64)
        envs.group.reset_timing()
        steps = 0
        allocs_at_warmup = allocs_done = _vrsync._allocations()
        try:
            while True:
                total += sum(touch_rows(a) for k, a in obs.items() if k not in ("position", "rotation"))
                obs, *_ = envs.step(actions)
                # Up to the last step that returned (the one the host's close ends
                # allocates its exception).
                allocs_done = _vrsync._allocations()
                steps += 1
                if steps == args.warmup:
                    envs.group.reset_timing()
                    allocs_at_warmup = _vrsync._allocations()
        except vrsync.HostClosedError:
            pass  # the session ended
        # Nothing measured if the session ended within the warm-up.
        calls, sdk_s, _ = envs.group.timing if steps >= args.warmup else (0, 0.0, 0.0)
        allocs = allocs_done - allocs_at_warmup
    finally:
        envs.close()
    print(f"checksum {total}", flush=True)
    per = sdk_s / (calls * envs.num_envs) * 1e6 if calls else float("nan")
    print(f"sdk_us_per_agent_step {per:.3f}", flush=True)
    per = allocs / (calls * envs.num_envs) if calls else float("nan")
    print(f"allocs_per_cycle {per:.3f}", flush=True)


if __name__ == "__main__":
    main()
