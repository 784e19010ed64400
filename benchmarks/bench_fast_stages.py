"""Where a fresh fast insertion's time goes (issue 14): each stage of ``InsertObjects(preset="fast")`` timed by a
wrapper, on one 640x480 TraCon image seen before (scene-cache and view-cache hits: a training loop's steady state).

    python -m benchmarks.bench_fast_stages --calls 300 --warmup 1500 --out results/bench/fast_stages.json

Medians per call in ms, with the command and the machine's load. Wrapping costs ~1 us per wrapped call; the total is
timed around the whole Compose call. Run it on an idle core (``taskset -c 1``): the stages are ~0.1-1 ms each.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import json
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")

import numpy as np

from benchmarks.transform_fixtures import compose_for, tracon_images

#: (module, attribute, stage name, modules that imported the attribute by name and call it from there)
STAGES = (
    ("aias_augment.pipeline.image", "plan_insertion", "plan", ()),
    ("aias_augment.pipeline.image", "apply_plan", "apply (all)", ()),
    ("aias_augment.apply.view_cache", "warp_from_view_cache", "view warp", ("aias_augment.apply.stages",)),
    ("aias_augment.apply.shading", "shade_pixels", "shading", ("aias_augment.apply.stages",)),
    ("aias_augment.apply.stages", "_object_shadow_window", "projected shadow", ()),
    ("aias_augment.apply.composite", "to_uint8", "to_uint8", ()),
    ("aias_augment.apply.frame_steps", "_harmonize", "harmonizer", ()),
    ("aias_augment.apply.harmonize.fast_infer", "predict_affine", "harmonizer: model prediction", ()),
    ("aias_augment.apply.stages", "annotate_in_window", "annotation", ()),
    ("aias_augment.pipeline.image", "assemble_result", "result assembly", ()),
    ("aias_augment.pipeline.bounded", "insert_into_image", "insertion (all)", ()),
)


def _wrap(times: dict, module: str, attr: str, label: str, also: tuple) -> None:
    m = importlib.import_module(module)
    f = getattr(m, attr)

    @functools.wraps(f)
    def timed(*a, **k):
        t0 = time.perf_counter()
        try:
            return f(*a, **k)
        finally:
            times[label].append(time.perf_counter() - t0)

    for target in (m, *(importlib.import_module(x) for x in also)):
        setattr(target, attr, timed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--warmup", type=int, default=1500, help="calls before timing (the view cache fills)")
    ap.add_argument("--out", default="results/bench/fast_stages.json")
    a = ap.parse_args(argv)
    times: dict = defaultdict(list)
    for spec in STAGES:
        _wrap(times, *spec)
    from aias_augment import InsertObjects

    img = tracon_images(1, (640, 480))[0]
    tf = compose_for(InsertObjects(categories=["traffic_cone"], min_objects=1, max_objects=1, preset="fast", p=1.0))
    load_before = os.getloadavg()
    for _ in range(a.warmup):
        tf(image=img, bboxes=np.zeros((0, 4)), labels=[])
    times.clear()
    total = []
    for _ in range(a.calls):
        t0 = time.perf_counter()
        tf(image=img, bboxes=np.zeros((0, 4)), labels=[])
        total.append(time.perf_counter() - t0)
    out = {
        "command": "python -m benchmarks.bench_fast_stages " + " ".join(argv if argv is not None else sys.argv[1:]),
        "loadavg_before": load_before,
        "loadavg_after": os.getloadavg(),
        "calls": a.calls,
        "warmup": a.warmup,
        "median_ms": {
            "call (Compose)": 1e3 * float(np.median(total)),
            **{k: 1e3 * float(np.median(v)) for k, v in times.items()},
        },
        "calls_per_stage": {k: len(v) for k, v in times.items()},
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1))
    for k, v in out["median_ms"].items():
        print(f"{k:32s} {v:7.3f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
