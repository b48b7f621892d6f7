"""numpy's own share of the ``python`` bench rows: the ``floor-numpy`` rows of ``vr-sim bench``.

    python -m vrsync.bench_numpy --width W --height H [--cameras 3] [--frames 4]
        --warmup N --cycles N --out FILE.json

The row reads of ``vrsync.bench_agent`` (its ``touch_rows``: the first and the last byte
of every row of every image, one strided reduction per image) with no SDK and no host: on
memory like a received frame's (a file in ``/dev/shm``, every byte written once through
a writable mapping as a host renders, then mapped again read-only as an agent's
subscriber maps it, in 4 KiB pages), ``--frames`` frames of ``--cameras`` rgb8 images
taken in turn as an agent takes the samples of its host's pool. Each cycle first marks
the first byte of each image of the next frame (what the bench host writes per cycle),
then times the reads of that frame. Writes ``--out``, a JSON object: ``cycles`` (as run)
and ``read_ns`` (each measured cycle's reads, ns).
"""

from __future__ import annotations

import argparse
import json
import mmap
import os
import tempfile
import time

import numpy as np

from vrsync.bench_agent import touch_rows


def main() -> None:
    parser = argparse.ArgumentParser(
        prog="python -m vrsync.bench_numpy", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--width", type=int, required=True)
    parser.add_argument("--height", type=int, required=True)
    parser.add_argument("--cameras", type=int, default=3)
    parser.add_argument(
        "--frames", type=int, default=4, help="frames taken in turn (default 4: a host's pool)"
    )
    parser.add_argument("--warmup", type=int, default=10)
    parser.add_argument("--cycles", type=int, required=True)
    parser.add_argument("--out", required=True)
    args = parser.parse_args()
    image = args.height * args.width * 3
    frame = image * args.cameras
    size = frame * args.frames
    read_ns: list[int] = []
    total = 0
    with tempfile.TemporaryFile(dir="/dev/shm", prefix="vrsync-bench-numpy-") as f:
        os.ftruncate(f.fileno(), size)
        with mmap.mmap(f.fileno(), size) as rw, mmap.mmap(
            f.fileno(), size, prot=mmap.PROT_READ
        ) as ro:
            written = np.frombuffer(rw, np.uint8)
            written[:] = 1
            read = np.frombuffer(ro, np.uint8)
            shape = (args.height, args.width, 3)
            views = [
                [
                    read[k * frame + c * image : k * frame + (c + 1) * image].reshape(shape)
                    for c in range(args.cameras)
                ]
                for k in range(args.frames)
            ]
            for cycle in range(args.warmup + args.cycles):
                k = cycle % args.frames
                for c in range(args.cameras):
                    written[k * frame + c * image] = cycle & 0xFF
                t0 = time.perf_counter_ns()
                total += sum(touch_rows(img) for img in views[k])
                t1 = time.perf_counter_ns()
                if cycle >= args.warmup:
                    read_ns.append(t1 - t0)
            del written, read, views
    with open(args.out, "w", encoding="utf-8") as out:
        json.dump({"cycles": args.cycles, "read_ns": read_ns}, out)
    print(f"checksum {total}", flush=True)


if __name__ == "__main__":
    main()
