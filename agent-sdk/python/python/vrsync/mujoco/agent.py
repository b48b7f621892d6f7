"""A wandering agent for any MuJoCo world: ``python -m vrsync.mujoco.agent``.

The agent ``vrsync.mujoco run --spawn-agents`` starts by default (as ``vr-sim run``
starts ``vr-agent``). It needs no knowledge of the scene: it reads the channel specs
of its ``[[agent]]`` and, every ``--hold`` cycles, picks a new value for each action
(uniform in ``[low, high]`` for a continuous action, a choice in ``0..n`` for a discrete
one) from a generator seeded by ``--seed`` and its id, so two runs act alike whatever
the timing. It reads its vectors every frame and exits 0 when the host closes the
session.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["main", "pick_actions"]


def _field(spec: Any, key: str) -> Any:
    """A channel spec's field, whether the spec is an object or a mapping."""
    if isinstance(spec, dict):
        return spec.get(key)
    return getattr(spec, key, None)


def pick_actions(specs: Sequence[Any], rng: np.random.Generator) -> dict[str, Any]:
    """One value per action channel: an int below ``n`` (discrete) or floats in
    ``[low, high]`` (continuous; infinite bounds count as -1..1)."""
    out: dict[str, Any] = {}
    for spec in specs:
        name = _field(spec, "name")
        n = _field(spec, "n")
        if n is not None:
            out[name] = int(rng.integers(0, int(n)))
            continue
        length = int(_field(spec, "len"))
        low = np.broadcast_to(np.asarray(_field(spec, "low"), dtype=np.float64), (length,))
        high = np.broadcast_to(np.asarray(_field(spec, "high"), dtype=np.float64), (length,))
        low = np.where(np.isfinite(low), low, -1.0)
        high = np.where(np.isfinite(high), high, 1.0)
        out[name] = rng.uniform(low, high).astype(np.float32)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Runs the agent until the host closes the session; returns the exit code."""
    p = argparse.ArgumentParser(prog="python -m vrsync.mujoco.agent", description=__doc__)
    p.add_argument("--config", required=True, help="the world's vrsync config file")
    p.add_argument("--id", type=int, required=True, help="agent id")
    p.add_argument("--session", default=None, help="session name (default: the config's)")
    p.add_argument("--seed", type=int, default=0, help="seed of the action choices (0)")
    p.add_argument("--hold", type=int, default=20, help="cycles each choice is held (20)")
    p.add_argument("--timeout", type=float, default=30.0, help="wait per frame, s (30)")
    args = p.parse_args(argv)

    import vrsync

    rng = np.random.default_rng([args.seed, args.id])
    with vrsync.Agent.connect(args.config, args.id, session=args.session) as agent:
        specs = list(agent.action_specs)
        vector_names = [v.name for v in agent.vector_specs]
        actions: dict[str, Any] = {}
        for cycle, frame in enumerate(agent.frames(timeout=args.timeout)):
            for name in vector_names:
                frame.vector(name).sum()
            if cycle % max(1, args.hold) == 0:
                actions = pick_actions(specs, rng)
            for name, value in actions.items():
                agent.act(name, value)
            agent.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
