"""Find the red object and walk to it: a numpy agent on zero-copy camera images.

    python seek.py --config config/default.toml --id 0 [--cycles 300]

Tilts the eyes down, looks for red pixels (r > 90, r > 2g, r > 2b) in both eye images,
turns towards them, walks, and stops when red fills enough of the view. Turns on the
spot while nothing red is seen. Prints ``reached <cycle>`` when it arrives.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import vrsync

NEAR_FRACTION = 0.06  # fraction of red pixels at which we are there
HALF_FOV_DEG = 60.0  # half the horizontal field of view of the default cameras


def red_blob(img: np.ndarray) -> tuple[float, float] | None:
    """(center_x in -1..1, fraction of the image) of the red pixels, or None."""
    rgb = img[..., :3].astype(np.int16)  # a small copy: the view itself is read-only
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    mask = (r > 90) & (r > 2 * g) & (r > 2 * b)
    count = int(mask.sum())
    if count == 0:
        return None
    xs = np.nonzero(mask)[1]
    center_x = float(xs.mean()) / (img.shape[1] - 1) * 2.0 - 1.0
    return center_x, count / mask.size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", required=True)
    parser.add_argument("--id", type=int, default=0)
    parser.add_argument("--session")
    parser.add_argument("--cycles", type=int, default=300)
    args = parser.parse_args()

    with vrsync.Agent.connect(args.config, args.id, session=args.session) as agent:
        running: int | None = None  # the action we wait for
        since = 0
        for frame in agent.frames(timeout=30):
            if frame.cycle == 0:
                agent.send(vrsync.EyeMovement(0.0, 0.0, tilt_deg=-25.0))
            states = frame.action_states
            done = running is None or (running in states and states[running].done)
            since += 1
            blobs = [b for b in (red_blob(frame.image(n)) for n in ("left", "right")) if b]
            if blobs:
                fraction = max(f for _, f in blobs)
                center_x = sum(c for c, _ in blobs) / len(blobs)
                if fraction >= NEAR_FRACTION:
                    agent.send(vrsync.CancelMove())
                    agent.stop()
                    print(f"reached {frame.cycle}", flush=True)
                    return
                bearing = math.degrees(math.atan(center_x * math.tan(math.radians(HALF_FOV_DEG))))
                if done or since > 5:
                    if abs(bearing) > 12.0:
                        running = agent.send(vrsync.Turn(angle_deg=bearing))
                    else:
                        heading = (frame.pose.heading_deg + bearing) % 360.0
                        running = agent.send(vrsync.Move(heading_deg=heading, distance_m=0.6))
                    since = 0
            elif done or since > 20:
                running = agent.send(vrsync.Turn(angle_deg=45.0))
                since = 0
            agent.stop()
            if frame.cycle >= args.cycles:
                break
    print("not reached", flush=True)
    raise SystemExit(1)


if __name__ == "__main__":
    main()
