"""Cheap scene analysis (the fast preset's analysis_max_width) against the full-resolution analysis (issue 14).

For 16 TraCon images at 640x480: CPU ms of analyse_scene and how far its estimates move from the full-resolution
ones (ground normal, sun direction, dominant-sun decision, SH ambient DC, sun/sky ratio).

    python -m benchmarks.bench_cheap_analysis > results/bench/cheap_analysis.md
"""

import os
import time

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.core.config import data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset

files = sorted((data_root() / "tracon" / "images" / "train").glob("*.jpg"))
imgs = [
    np.ascontiguousarray(cv2.resize(cv2.imread(str(f))[..., ::-1], (640, 480), interpolation=cv2.INTER_AREA))
    for f in files[40:56]
]
ref, ref_ts = [], []
for im in imgs:
    t0 = time.process_time()
    ref.append(analyse_scene(Frame(im, None), load_preset("fast", analysis_max_width=0)))
    ref_ts.append(time.process_time() - t0)


def ang(a, b):
    if a is None or b is None:
        return np.nan
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


print(
    "# Cheap scene analysis vs the full-resolution analysis\n\nCommand: `python -m benchmarks.bench_cheap_analysis`"
    f" (load average {os.getloadavg()[0]:.1f})\n\n16 TraCon images at 640x480, fast preset; differences from the same "
    "image analysed at full resolution (analysis_max_width 0; CPU ms median "
    f"{1000 * np.median(ref_ts):.0f}).\n\n| analysis_max_width | CPU ms median | ground normal deg median / max | "
    "sun direction deg median / p75 / max | dominant-sun agrees | SH DC rel. diff median | sun/sky rel. diff median |"
    "\n|---:|---:|---|---|---:|---:|---:|"
)
for mw in (160, 240, 320):
    cfg = load_preset("fast", analysis_max_width=mw)
    rows, ts = [], []
    for im, r in zip(imgs, ref):
        t0 = time.process_time()
        a = analyse_scene(Frame(im, None), cfg)
        ts.append(time.process_time() - t0)
        rows.append(
            (
                ang(a.ground.normal, r.ground.normal),
                ang(a.lighting.sun_direction_in_cam, r.lighting.sun_direction_in_cam),
                a.lighting.dominant_sun == r.lighting.dominant_sun,
                np.abs(a.lighting.ambient_sh[0] - r.lighting.ambient_sh[0]).max()
                / max(np.abs(r.lighting.ambient_sh[0]).max(), 1e-6),
                abs(a.lighting.sun_sky_ratio - r.lighting.sun_sky_ratio) / max(r.lighting.sun_sky_ratio, 1e-6),
            )
        )
    R = np.array(rows, float)
    print(
        f"| {mw} | {1000 * np.median(ts):.0f} | {np.nanmedian(R[:, 0]):.1f} / {np.nanmax(R[:, 0]):.1f} | "
        f"{np.nanmedian(R[:, 1]):.0f} / {np.nanpercentile(R[:, 1], 75):.0f} / {np.nanmax(R[:, 1]):.0f} | "
        f"{R[:, 2].mean():.2f} | {np.median(R[:, 3]):.2f} | {np.nanmedian(R[:, 4]):.2f} |"
    )
