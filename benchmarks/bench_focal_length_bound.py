#!/usr/bin/env python
"""Cost of one insertion whatever the focal length says (issue 28: fx = 1e7 took 57 s and 6.75 GB in the lighting's
environment-map pre-blur). Each fx runs in a fresh process (peak RSS of that process, ru_maxrss) on one 640x480
TraCon road with the fast preset; the wall time is the insertion call alone, after a warm-up call at fx 500.

    python -m benchmarks.bench_focal_length_bound [--out results/bench/focal_length_bound.json]
"""

import argparse
import json
import subprocess
import sys
import time

CHILD = r"""
import json, resource, sys, time, cv2, numpy as np
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics
from aias_augment.pipeline.image import insert_into_image, load_preset
fx = float(sys.argv[1])
img = cv2.cvtColor(cv2.imread(str(data_root() / 'tracon/images/train/imh_237_00000000.jpg')), cv2.COLOR_BGR2RGB)
img = cv2.resize(img, (640, 480), interpolation=cv2.INTER_AREA)
cfg = load_preset("fast")
insert_into_image(img, rng=np.random.default_rng(0), cfg=cfg, intrinsics=Intrinsics(500, 500, 319.5, 239.5, 640, 480))
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.perf_counter()
r = insert_into_image(img, rng=np.random.default_rng(1), cfg=cfg, intrinsics=Intrinsics(fx, fx, 319.5, 239.5, 640, 480))
dt = time.perf_counter() - t
print(json.dumps({"fx": fx, "seconds": dt, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "rss_after_warmup_mb": rss0 / 1024, "objects": len(r.bboxes),
                  "lighting": r.record.modules.get("lighting")}))
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default="results/bench/focal_length_bound.json")
    ap.add_argument("--fx", nargs="*", type=float, default=[5e2, 1e4, 1e6, 1e7])
    a = ap.parse_args()
    rows = []
    for fx in a.fx:
        out = subprocess.run([sys.executable, "-c", CHILD, str(fx)], capture_output=True, text=True, check=True)
        rows.append(json.loads(out.stdout.strip().splitlines()[-1]))
        print(rows[-1], flush=True)
    with open(a.out, "w") as f:
        json.dump(
            {"command": "python " + " ".join(sys.argv), "date": time.strftime("%Y-%m-%d"), "rows": rows}, f, indent=1
        )


if __name__ == "__main__":
    main()
