#!/usr/bin/env python
"""Peak memory and time of ``--envmap`` (``aias_augment.cli.augment.envmap_fact``, then ``lighting_from_envmap``)
at the HDR size bound (a real 8192x4096 EXR, the largest decoded) and above it (an EXR whose header says
16384x8192, refused from the header), each in a fresh child process (peak RSS from ``os.wait4``).

usage: python -m benchmarks.bench_envmap_bound [--out results/reliability/envmap_bound.json]
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CHILD = r"""
import sys, time
from aias_augment.cli.augment import envmap_fact
from aias_augment.analyse.lighting.estimate import lighting_from_envmap
t0 = time.perf_counter()
try:
    lighting_from_envmap(envmap_fact(sys.argv[1]))
    outcome = "lit"
except Exception as e:
    outcome = f"{type(e).__name__}: {str(e)[:240]}"
print(repr((outcome, time.perf_counter() - t0)))
"""


def write_maps(folder: Path) -> dict[str, Path]:
    from aias_augment.core.hdr import write_exr

    rng = np.random.default_rng(0)
    h = 4096
    sky = np.full((h, 2 * h, 3), 0.5, np.float32) * rng.uniform(0.9, 1.1, (1, 2 * h, 1)).astype(np.float32)
    sky[h // 4 : h // 4 + 20, h : h + 20] = 5e4  # a sun
    maps = {"8192x4096 (the bound)": folder / "map8k.exr"}
    write_exr(maps["8192x4096 (the bound)"], sky, half=True)
    del sky
    small = folder / "small.exr"
    write_exr(small, np.ones((8, 16, 3), np.float32))
    data = bytearray(small.read_bytes())
    key = b"dataWindow\0box2i\0" + struct.pack("<i", 16)
    at = data.index(key) + len(key)
    data[at : at + 16] = struct.pack("<4i", 0, 0, 16383, 8191)
    maps["16384x8192 header"] = folder / "map16k.exr"
    maps["16384x8192 header"].write_bytes(bytes(data))
    return maps


def run_child(path: Path) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    with tempfile.TemporaryFile("w+") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=out, stderr=subprocess.STDOUT, env=env)
        while True:  # reaped with wait4 (its peak RSS), killed after 300 s
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t0 > 300:
                proc.kill()
                _, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.05)
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
        wall = time.perf_counter() - t0
        out.seek(0)
        last = (out.read().strip().splitlines() or [""])[-1]
    import ast

    outcome, seconds = ast.literal_eval(last) if last.startswith("(") else (last[-240:], None)
    return {
        "outcome": outcome,
        "seconds": None if seconds is None else round(seconds, 2),
        "wall_seconds": round(wall, 2),
        "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
        "file_mb": round(path.stat().st_size / 2**20, 2),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default="results/reliability/envmap_bound.json")
    ap.add_argument("--write-maps", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.write_maps:
        write_maps(Path(a.write_maps))
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        # written by another process: a child's peak RSS starts from its parent's at the fork
        subprocess.run([sys.executable, __file__, "--write-maps", tmp], check=True)
        maps = {"8192x4096 (the bound)": Path(tmp) / "map8k.exr", "16384x8192 header": Path(tmp) / "map16k.exr"}
        for name, path in maps.items():
            rows.append({"map": name, **run_child(path)})
            print(rows[-1], flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    command = " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]])
    out.write_text(json.dumps({"command": command, "peak_rss_of": "resource.ru_maxrss of each child", "rows": rows}))


if __name__ == "__main__":
    sys.exit(main())
