"""One huge frame (default 6000x4000) through ``InsertObjects``' insertion (``insert_bounded``): wall and CPU
seconds and peak RSS of a fresh process per run, with the working resolution bounded (analysis and plan at 2 MP,
render at full size) and, with ``--unbounded``, without the bound (the issue-16 baseline: 204 s and 5.7 GB).

  python -m benchmarks.bench_offline_transform_huge --out results/bench/offline_huge.json [--unbounded]
  python -m benchmarks.bench_offline_transform_huge --width 1920 --height 1216 --presets fast balanced accurate \
      --out results/bench/worker_rss_1920.json     # the worker bound (<= 1 GiB on a 1920x1216 frame)

Also reported, after the calls: the process's private memory (its own heap and arrays) and its shared library pages
(/proc/self/smaps_rollup): RSS counts both, and the shared ones are mapped once for every DataLoader worker.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import textwrap
from pathlib import Path

_ONE = textwrap.dedent("""
    import json, resource, sys, time
    import numpy as np
    from dataclasses import replace
    from aias_augment.pipeline.image import load_preset
    from aias_augment.pipeline.bounded import insert_bounded
    from aias_augment.analyse.cache import SceneCache
    w, h, preset, max_pixels, calls = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], int(sys.argv[4]) or None, \\
        int(sys.argv[5])
    rng = np.random.default_rng(0)
    img = np.full((h, w, 3), 110, np.uint8)
    img[: h // 2] = (150, 180, 220)
    img = np.clip(img + rng.integers(-8, 8, img.shape, dtype=np.int16), 0, 255).astype(np.uint8)
    cfg = replace(load_preset(preset), categories=("traffic_cone",), min_objects=1, max_objects=1)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    cache = SceneCache(8)
    out = []
    for i in range(calls):   # call 0: analysis + plan + render; later calls: the cached analysis, a new plan
        t, c = time.perf_counter(), time.process_time()
        res = insert_bounded(img, rng=np.random.default_rng(i), cfg=cfg, scene_cache=cache, max_pixels=max_pixels)
        out.append({"wall_s": time.perf_counter() - t, "cpu_s": time.process_time() - c,
                    "objects": len(res.inserted_labels)})
    # After the calls: what of the resident memory is this process's own (private: heap, arrays, the renderer's
    # buffers) and what is shared library pages (torch, Mesa, OpenCV: mapped once, shared by every worker).
    sm = {}
    for line in open("/proc/self/smaps_rollup"):
        p = line.split()
        if len(p) >= 3 and p[-1] == "kB":
            sm[p[0].rstrip(":")] = int(p[1]) / 1024.0
    print(json.dumps({"calls": out, "base_rss_mb": base / 1e3,
                      "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e3,
                      "after_rss_mib": sm.get("Rss"), "after_pss_mib": sm.get("Pss"),
                      "after_private_mib": sm.get("Private_Clean", 0.0) + sm.get("Private_Dirty", 0.0),
                      "after_shared_mib": sm.get("Shared_Clean", 0.0) + sm.get("Shared_Dirty", 0.0)}))
""")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--width", type=int, default=6000)
    ap.add_argument("--height", type=int, default=4000)
    ap.add_argument("--presets", nargs="+", default=["fast", "balanced"])
    ap.add_argument("--calls", type=int, default=3)
    ap.add_argument("--unbounded", action="store_true", help="also run without the bound (slow: minutes, GBs)")
    ap.add_argument("--out", default="results/bench/offline_huge.json")
    ap.add_argument("--note", default="")
    a = ap.parse_args(argv)
    rows = []
    for preset in a.presets:
        for max_pixels in [2_000_000, 0] if a.unbounded else [2_000_000]:
            r = subprocess.run(
                [sys.executable, "-c", _ONE, str(a.width), str(a.height), preset, str(max_pixels), str(a.calls)],
                capture_output=True,
                text=True,
            )
            row = {
                "preset": preset,
                "size": f"{a.width}x{a.height}",
                "working_resolution": "analysis and plan at <= 2 MP" if max_pixels else "unbounded",
            }
            if r.returncode:
                row["error"] = r.stderr[-1500:]
            else:
                row.update(json.loads(r.stdout.strip().splitlines()[-1]))
            rows.append(row)
            print(json.dumps(row), flush=True)
    res = {
        "command": "python -m benchmarks.bench_offline_transform_huge "
        + " ".join(sys.argv[1:] if argv is None else argv),
        "rows": rows,
        "note": a.note,
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
