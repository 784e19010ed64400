#!/usr/bin/env python
"""Peak memory and time of loading a YAML "billion laughs" (9 levels of 9 aliases under one InsertionConfig field,
323 bytes) as an InsertionConfig: the plain ``yaml.safe_load`` + ``from_dict`` path against ``load_config`` (the
bounded loader), each in a fresh child process (peak RSS from ``os.wait4``), beside a valid config as the baseline.
The plain path runs under an address-space cap (``--cap-gib``) so that it cannot take the machine down.

usage: python -m benchmarks.bench_config_bomb [--cap-gib 3] [--timeout 120] [--out results/reliability/config_bomb.json]
"""

from __future__ import annotations

import argparse
import ast
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CHILD = r"""
import sys, time
from pathlib import Path
t0 = time.perf_counter()
from aias_augment.pipeline.config import InsertionConfig
from aias_augment.core.config import from_dict, load_config
path, how = sys.argv[1], sys.argv[2]
t1 = time.perf_counter()
try:
    if how == "plain_safe_load":
        import yaml
        from_dict(InsertionConfig, yaml.safe_load(Path(path).read_text()), where=path)
    else:
        load_config(InsertionConfig, path)
    outcome = "loaded"
except MemoryError:
    outcome = "MemoryError"
except Exception as e:
    outcome = f"{type(e).__name__}: {str(e)[:200]}"
print(repr((outcome, time.perf_counter() - t1)))
"""


def bomb(levels: int = 9, width: int = 9) -> str:
    names = "abcdefghijklmnop"
    parts = ["&a [" + ",".join(["lol"] * width) + "]"]
    for i in range(1, levels):
        parts.append(f"&{names[i]} [" + ",".join([f"*{names[i - 1]}"] * width) + "]")
    return "motion_blur_px: [" + ", ".join(parts) + "]\n"


def run_child(path: Path, how: str, cap_bytes: int | None, timeout: float) -> dict:
    """One fresh child; reaped with ``os.wait4`` so its peak RSS is known even when it is killed at ``timeout``."""

    def limit():
        if cap_bytes:
            resource.setrlimit(resource.RLIMIT_AS, (cap_bytes, cap_bytes))

    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    with tempfile.TemporaryFile("w+") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-c", CHILD, str(path), how],
            stdout=out,
            stderr=subprocess.STDOUT,
            preexec_fn=limit,
            env=env,
            text=True,
        )
        timed_out = False
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - t0 > timeout:
                proc.kill()
                timed_out = True
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.05)
        proc.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
        wall = time.perf_counter() - t0
        out.seek(0)
        text = out.read().strip()
    last = text.splitlines()[-1] if text else ""
    if last.startswith("("):
        outcome, load_s = ast.literal_eval(last)
    else:
        outcome, load_s = ("killed at the timeout" if timed_out else last[-200:]), None
    return {
        "how": how,
        "outcome": outcome,
        "load_seconds": None if load_s is None else round(load_s, 3),
        "wall_seconds": round(wall, 2),
        "peak_rss_mb": round(usage.ru_maxrss / 1024, 1),
        "timed_out": timed_out,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cap-gib", type=float, default=3.0)
    ap.add_argument("--timeout", type=float, default=120.0)
    ap.add_argument("--out", default="results/reliability/config_bomb.json")
    a = ap.parse_args()
    cap = int(a.cap_gib * 2**30)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        files = {"valid": Path(tmp) / "valid.yaml", "bomb": Path(tmp) / "bomb.yaml"}
        files["valid"].write_text("motion_blur_px: [0.0, 2.0]\n")
        files["bomb"].write_text(bomb())
        for name, how in (("valid", "load_config"), ("bomb", "load_config"), ("bomb", "plain_safe_load")):
            r = run_child(files[name], how, cap, a.timeout)
            rows.append({"file": name, "bytes": files[name].stat().st_size, **r})
            print(rows[-1], flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(
        json.dumps({"command": " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]]), "rows": rows}, indent=1)
    )


if __name__ == "__main__":
    main()
