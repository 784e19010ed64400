#!/usr/bin/env python
"""Peak memory and time of reading a 20000x20000 RGB PNG (1.2 MB of zeros, 1.2 GB decoded): ``cv2.imread`` (a reader
that decodes first) against ``aias_augment.core.image_io.read_image`` (the pixel count checked from the header,
refused above its bound before decoding), each in a fresh child process (peak RSS from ``os.wait4``), beside a
640x480 PNG as the baseline.

usage: python -m benchmarks.bench_image_header_bound [--out results/reliability/image_header_bound.json]
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

CHILD = r"""
import sys, time
how, path = sys.argv[1], sys.argv[2]
import cv2
from aias_augment.core.image_io import DEFAULT_MAX_PIXELS, read_image
t0 = time.perf_counter()
try:
    if how == "cv2.imread":
        img = cv2.imread(path, cv2.IMREAD_COLOR)
        outcome = f"decoded {img.shape}"
    else:
        img = read_image(path, max_pixels=DEFAULT_MAX_PIXELS)
        outcome = f"decoded {img.shape}"
except Exception as e:
    outcome = f"{type(e).__name__}: {str(e)[:200]}"
print(repr((outcome, time.perf_counter() - t0)))
"""


def write_png(path: Path, width: int, height: int) -> None:
    """An RGB PNG of zeros, compressed row by row (never the whole image in memory)."""

    def chunk(tag: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body))

    z = zlib.compressobj(9)
    row = b"\0" * (1 + 3 * width)  # filter byte + pixels
    idat = b"".join(z.compress(row) for _ in range(height)) + z.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


def run_child(how: str, path: Path) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    with tempfile.TemporaryFile("w+") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-c", CHILD, how, str(path)], stdout=out, stderr=subprocess.STDOUT, env=env
        )
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
        wall = time.perf_counter() - t0
        out.seek(0)
        last = (out.read().strip().splitlines() or [""])[-1]
    outcome, seconds = ast.literal_eval(last) if last.startswith("(") else (last[-200:], None)
    return {
        "reader": how,
        "outcome": outcome,
        "seconds": None if seconds is None else round(seconds, 3),
        "wall_seconds": round(wall, 2),
        "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="results/reliability/image_header_bound.json")
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        files = {"640x480": Path(tmp) / "small.png", "20000x20000": Path(tmp) / "huge.png"}
        write_png(files["640x480"], 640, 480)
        write_png(files["20000x20000"], 20000, 20000)
        for name, path in files.items():
            for how in ("cv2.imread", "read_image"):
                rows.append({"image": name, "file_mb": round(path.stat().st_size / 2**20, 2), **run_child(how, path)})
                print(rows[-1], flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    command = " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]])
    out.write_text(json.dumps({"command": command, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
