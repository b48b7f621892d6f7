#!/usr/bin/env python3
"""Packs prebuilt executables into a wheel whose install puts them on PATH.

    scripts/bin-wheel.py --name vrsync-sim --version 0.1.0 --tag manylinux_2_28_x86_64 \
        --summary "..." --out DIR EXE...

The executables go to the wheel's `<name>-<version>.data/scripts/`, which pip (and every
other installer) copies into the environment's `bin/` as they are, executable: the way
maturin's `bindings = "bin"` ships one Rust program. Here one wheel carries several, from
two packages of the workspace (vr-sim, and vr-agent / vr-bench-agent beside it, where
`vr-sim demo` and `--spawn-agents` look for them). No Python code: the tag is `py3-none-<tag>`.
Standard library only; prints the wheel's path.
"""

from __future__ import annotations

import argparse
import base64
import hashlib
import re
import sys
import zipfile
from pathlib import Path


def record_hash(data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=")
    return "sha256=" + digest.decode()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--name", required=True)
    parser.add_argument("--version", required=True)
    parser.add_argument("--tag", required=True, help="platform tag, e.g. manylinux_2_28_x86_64")
    parser.add_argument("--summary", required=True)
    parser.add_argument("--license", default="Apache-2.0 OR MIT")
    parser.add_argument("--out", required=True, type=Path)
    parser.add_argument("exe", nargs="+", type=Path)
    args = parser.parse_args()

    dist = re.sub(r"[-_.]+", "_", args.name).lower()
    stem = f"{dist}-{args.version}"
    wheel_tag = f"py3-none-{args.tag}"
    metadata = (
        "Metadata-Version: 2.4\n"
        f"Name: {args.name}\n"
        f"Version: {args.version}\n"
        f"Summary: {args.summary}\n"
        f"License-Expression: {args.license}\n"
        "Classifier: Operating System :: POSIX :: Linux\n"
        "Classifier: Programming Language :: Rust\n"
    )
    wheel = (
        "Wheel-Version: 1.0\n"
        "Generator: vrsync scripts/bin-wheel.py\n"
        "Root-Is-Purelib: false\n"
        f"Tag: {wheel_tag}\n"
    )
    files: list[tuple[str, bytes, int]] = []
    for exe in args.exe:
        files.append((f"{stem}.data/scripts/{exe.name}", exe.read_bytes(), 0o755))
    files.append((f"{stem}.dist-info/METADATA", metadata.encode(), 0o644))
    files.append((f"{stem}.dist-info/WHEEL", wheel.encode(), 0o644))
    record_name = f"{stem}.dist-info/RECORD"
    record = "".join(f"{name},{record_hash(data)},{len(data)}\n" for name, data, _ in files)
    record += f"{record_name},,\n"
    files.append((record_name, record.encode(), 0o644))

    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"{stem}-{wheel_tag}.whl"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED, compresslevel=6) as zf:
        for name, data, mode in files:
            info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
            info.external_attr = (0o100000 | mode) << 16
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, data)
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
