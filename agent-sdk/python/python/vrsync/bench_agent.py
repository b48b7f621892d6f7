"""The Python benchmark agent that ``vr-sim bench`` starts for its ``python`` rows.

    python -m vrsync.bench_agent --config FILE --id N [--session NAME]

Does the work of the Rust ``vr-bench-agent`` in its SDK mode, in Python: per cycle, read
the first and the last byte of every row of every image (vectorised with numpy, on the
zero-copy views), send one command, stop; until the host closes the session.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np
import vrsync


def touch_rows(img: np.ndarray[Any, Any]) -> int:
    """Sum of the first and the last byte of every row (the Rust agent's `touch_rows`):
    one strided view picks both columns, one reduction sums them."""
    rows = img.reshape(img.shape[0], -1)
    if rows.dtype != np.uint8:
        rows = rows.view(np.uint8)
    step = max(rows.shape[1] - 1, 1)
    return int(rows[:, ::step].sum())


def main() -> None:
    parser = argparse.ArgumentParser(prog="python -m vrsync.bench_agent", description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--id", type=int, default=0)
    parser.add_argument("--session")
    args = parser.parse_args()
    total = 0
    with vrsync.Agent.connect(args.config, args.id, session=args.session) as agent:
        turn = vrsync.Turn(angle_deg=1.0)
        try:
            for frame in agent.frames(timeout=60):
                total += sum(touch_rows(img) for img in frame.images.values())
                del frame  # release the sample before the next wait
                agent.send(turn)
                agent.stop()
        except vrsync.HostClosedError:
            pass  # the session ended between our last frame and our stop
    print(f"checksum {total}", flush=True)


if __name__ == "__main__":
    main()
