"""A Python agent for the Unity package's scene test (SceneTest.cs): checks that every image
it receives is exactly the test pattern of its cycle, agent and camera with the TOP row
first (vrsync's row order), and that the "joints" vector holds what the body wrote; sends
one Move and one "torque" action every cycle (the scene checks both arrive).

usage: python pattern_agent.py CONFIG AGENT_ID
Prints key=value lines; exit 0 when every frame matched, 1 otherwise.
"""

import sys

import numpy as np
import vrsync


def pattern(cycle: int, agent: int, camera: int, shape: tuple[int, ...]) -> np.ndarray:
    """Byte c of pixel (x, y), y from the top: SceneTest.cs's Pattern.At."""
    h, w = shape[0], shape[1]
    channels = shape[2] if len(shape) == 3 else 1
    y = np.arange(h).reshape(h, 1, 1)
    x = np.arange(w).reshape(1, w, 1)
    c = np.arange(channels).reshape(1, 1, channels)
    value = (x * 7 + y * 13 + c * 50 + (cycle % 256) * 3 + agent * 41 + camera * 17) & 0xFF
    return value.astype(np.uint8).reshape(shape)


def main() -> int:
    config, agent_id = sys.argv[1], int(sys.argv[2])
    cycles = images = image_errors = vector_errors = 0
    first_errors: list[str] = []
    with vrsync.Agent.connect(config, agent_id) as agent:
        for frame in agent.frames(timeout=60):  # ends when the host closes the session
            for camera, name in enumerate(frame.camera_names):
                image = frame.image(name)
                images += 1
                expected = pattern(frame.cycle, agent_id, camera, image.shape)
                if not np.array_equal(image, expected):
                    image_errors += 1
                    if len(first_errors) < 5:
                        rows = [int(r) for r in np.nonzero((image != expected).reshape(image.shape[0], -1).any(axis=1))[0]]
                        first_errors.append(f"cycle {frame.cycle} camera {name}: rows {rows[:8]} differ")
            joints = frame.vector("joints")
            want = np.array([frame.cycle % 1000, agent_id, 0.25], dtype=np.float32)
            if not np.array_equal(joints, want):
                vector_errors += 1
                if len(first_errors) < 5:
                    first_errors.append(f"cycle {frame.cycle}: joints {joints}, expected {want}")
            del image, expected, joints
            agent.send(vrsync.Move(heading_deg=float(frame.cycle * 7 % 360), distance_m=0.25))
            agent.act("torque", [(frame.cycle % 10) / 10.0, -0.5])
            del frame
            agent.stop()
            cycles += 1
    for e in first_errors:
        print(f"pattern_agent {agent_id}: {e}", file=sys.stderr)
    print(f"python_agent{agent_id}_cycles={cycles}")
    print(f"python_agent{agent_id}_images={images}")
    print(f"python_agent{agent_id}_image_errors={image_errors}")
    print(f"python_agent{agent_id}_vector_errors={vector_errors}")
    return 0 if cycles > 0 and image_errors == 0 and vector_errors == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
