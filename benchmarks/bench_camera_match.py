#!/usr/bin/env python
"""Cost of the camera-pipeline stage (InsertionConfig.camera_match, issue 15). ms per call (process_time, median over N calls, scene analysis cached = 'seen before') of the balanced and
accurate presets with and without camera_match, on one 640x480 TraCon road; plus match_camera alone."""

import sys
import time
from dataclasses import replace

import cv2
import numpy as np

from aias_augment.analyse.cache import SceneCache
from aias_augment.apply.harmonize.api import match_camera
from aias_augment.core.config import data_root
from aias_augment.pipeline.config import load_preset
from aias_augment.pipeline.image import insert_into_image

# usage: python -m benchmarks.bench_camera_match N [preset ...]   (N calls per arm and round; default balanced)
N = int(sys.argv[1])
presets = sys.argv[2:] or ["balanced"]
img = cv2.cvtColor(cv2.imread(str(data_root() / "tracon/images/train/imh_237_00000000.jpg")), cv2.COLOR_BGR2RGB)
img = cv2.resize(img, (640, 480), interpolation=cv2.INTER_AREA)
for name in presets:
    base = load_preset(name)
    cache = SceneCache(max_items=4)
    res = {}
    for cm in (False, True, False, True):  # interleaved twice: drift on the loaded core hits both
        cfg = replace(base, camera_match=cm)
        insert_into_image(img, rng=np.random.default_rng(0), cfg=cfg, scene_cache=cache)  # warm: analysis, models
        ts = []
        for i in range(N):
            t = time.process_time()
            r = insert_into_image(img, rng=np.random.default_rng(100 + i), cfg=cfg, scene_cache=cache)
            ts.append(time.process_time() - t)
        res.setdefault(cm, []).extend(ts)
        print(
            name,
            "camera_match",
            cm,
            "median ms %.1f" % (1000 * np.median(ts)),
            r.record.modules.get("camera_match"),
            flush=True,
        )
    a, b = np.median(res[False]) * 1000, np.median(res[True]) * 1000
    print(f"RESULT {name}: {a:.0f} -> {b:.0f} ms per call (seen image, median of {2 * N}), +{b - a:.0f} ms")
# the stage alone on a composite with two cone-sized objects
mask = np.zeros((480, 640), np.float32)
mask[300:380, 280:320] = 1
mask[260:300, 420:440] = 1
ts = []
for i in range(N):
    t = time.process_time()
    match_camera(img, mask, np.random.default_rng(i), source_rgb_uint8=img)
    ts.append(time.process_time() - t)
print("RESULT match_camera alone (2 objects 40x80, 20x40 px): %.1f ms median" % (1000 * np.median(ts)))
