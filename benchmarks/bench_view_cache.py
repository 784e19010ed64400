"""The view cache's binning: error against the full render vs how fast the cache warms up (issue 14).

For each binning: the poses the planner draws for one traffic cone on TraCon road images (``--size``), and per pose
the view-cache layers against a full 4x-supersampled render of the same asset and pose, both shaded with
``shade_object`` under one sun + SH light: box IoU, mask IoU, mean absolute difference over the pixels both call the
object (sRGB levels); and the hit rate of a cache that has seen the previous poses (after n objects).

    python -m benchmarks.bench_view_cache --objects 200 --size 640x480 --out results/bench

Writes ``<out>/view_cache.md`` and ``.json`` with the command.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")

import cv2
import numpy as np

from aias_augment.analyse.cache import SceneCache
from aias_augment.analyse.lighting.estimate import LightingEstimate
from aias_augment.apply.render import linear_to_srgb, render_object_window
from aias_augment.apply.shading import shade_object
from aias_augment.apply.view_cache import ViewBinning, ViewCache, render_from_view_cache
from aias_augment.core.config import data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion

BINNINGS = {
    "7.5 deg, 4 deg, 0.04 (default)": ViewBinning(7.5, 4.0, 0.04),
    "15 deg, 5 deg, 0.05": ViewBinning(15.0, 5.0, 0.05),
    "30 deg, 8 deg, 0.08": ViewBinning(30.0, 8.0, 0.08),
}


def _light():
    sh = np.zeros((9, 3))
    sh[0] = (0.25, 0.27, 0.32)
    sun = np.array([0.5, -0.6, 0.3]) / np.linalg.norm([0.5, -0.6, 0.3])
    return LightingEstimate(sun, np.array([2.4, 2.2, 2.0]), sh, 3.0, True, 0.9, "metadata", np.array([0.0, -1.0, 0.0]))


def _in(win, roi, a):
    out = np.zeros((win[3] - win[1], win[2] - win[0]) + a.shape[2:], np.float32)
    out[roi[1] - win[1] : roi[3] - win[1], roi[0] - win[0] : roi[2] - win[0]] = a
    return out


def _box(m):
    ys, xs = np.nonzero(m)
    return xs.min(), ys.min(), xs.max() + 1, ys.max() + 1


def _iou(a, b):
    ix = max(0, min(a[2], b[2]) - max(a[0], b[0])) * max(0, min(a[3], b[3]) - max(a[1], b[1]))
    return ix / ((a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - ix)


def poses(n: int, size: tuple[int, int]):
    """(asset, cam_from_object, intrinsics) of n planned cones on TraCon images (the fast preset's planner)."""
    files = sorted((data_root() / "tracon" / "images" / "train").glob("*.jpg"))[:40]
    cfg = load_preset("fast", categories=("traffic_cone",))
    cache = SceneCache(64)
    rng = np.random.default_rng(0)
    out = []
    i = 0
    while len(out) < n:
        img = cv2.resize(cv2.imread(str(files[i % len(files)]))[..., ::-1], size, interpolation=cv2.INTER_AREA)
        an = cache.get(Frame(np.ascontiguousarray(img), None), cfg)
        plan = plan_insertion(an, cfg, rng, n_objects=1)
        out += [(o.asset, o.cam_from_object, an.intrinsics) for o in plan.objects]
        i += 1
    return out[:n]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", type=int, default=200)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--compare-every", type=int, default=4, help="compare against the full render every k-th pose")
    ap.add_argument("--out", default="results/bench")
    a = ap.parse_args(argv)
    cmd = "python -m benchmarks.bench_view_cache " + " ".join(argv if argv is not None else sys.argv[1:])
    size = tuple(int(x) for x in a.size.split("x"))
    ps = poses(a.objects, size)
    light = _light()
    res = {"command": cmd, "size": a.size, "objects": a.objects, "loadavg": os.getloadavg(), "binnings": {}}
    for name, b in BINNINGS.items():
        cache = ViewCache(binning=b)
        hits, stats, fallback, t_hit = [], [], 0, []
        for k, (asset, T, K) in enumerate(ps):
            h0 = cache.hits
            t0 = time.perf_counter()
            got = render_from_view_cache(asset, T, K, cache)
            dt = time.perf_counter() - t0
            if got is None:
                fallback += 1
                continue
            hits.append(cache.hits > h0)
            if hits[-1]:
                t_hit.append(dt)
            if k % a.compare_every:
                continue
            roi_v, view = got
            roi_f, full = render_object_window(asset, T, K, ssaa=4)
            if full.alpha.max() <= 0.5 or view.alpha.max() <= 0.5:
                continue
            win = tuple(min(roi_f[i], roi_v[i]) for i in (0, 1)) + tuple(max(roi_f[i], roi_v[i]) for i in (2, 3))
            sa = [_in(win, roi_f, getattr(full, f)) for f in ("albedo_linear", "normals_in_cam", "alpha")]
            sb = [_in(win, roi_v, getattr(view, f)) for f in ("albedo_linear", "normals_in_cam", "alpha")]
            ma, mb = sa[2] > 0.5, sb[2] > 0.5
            ca = linear_to_srgb(shade_object(sa[0], sa[1], sa[2] > 0, light)) * 255
            cb = linear_to_srgb(shade_object(sb[0], sb[1], sb[2] > 0, light)) * 255
            box_h = _box(ma)[3] - _box(ma)[1]
            stats.append(
                (
                    box_h,
                    _iou(_box(ma), _box(mb)),
                    (ma & mb).sum() / (ma | mb).sum(),
                    float(np.abs(ca - cb)[ma & mb].mean()),
                )
            )
        st = np.array(stats)
        hits = np.array(hits)
        big = st[:, 0] >= 40
        q = len(hits) // 4
        res["binnings"][name] = {
            "entries": len(cache),
            "MB": cache.nbytes / 2**20,
            "fallback_full_render": fallback,
            "hit_rate_by_quarter": [float(hits[i * q : (i + 1) * q].mean()) for i in range(4)],
            "hit_ms_median": 1000 * float(np.median(t_hit)) if t_hit else None,
            "compared": len(st),
            "box_iou_min": float(st[:, 1].min()),
            "box_iou_median": float(np.median(st[:, 1])),
            "box_iou_min_40px": float(st[big, 1].min()) if big.any() else None,
            "mask_iou_median": float(np.median(st[:, 2])),
            "mad_median": float(np.median(st[:, 3])),
            "mad_p90": float(np.percentile(st[:, 3], 90)),
            "box_height_px_median": float(np.median(st[:, 0])),
        }
        print(name, json.dumps(res["binnings"][name]), flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "view_cache.json").write_text(json.dumps(res, indent=2))
    lines = [
        "# View cache: binning error vs warm-up",
        "",
        f"Command: `{cmd.strip()}`",
        "",
        f"{a.objects} cones placed by the fast preset's planner on TraCon images at {a.size}; "
        f"every {a.compare_every}th pose compared with a full 4x-supersampled render, both shaded by "
        "`shade_object` (one sun + SH ambient). MAD: mean absolute difference over the pixels both masks "
        f"hold, sRGB levels. Load average {res['loadavg'][0]:.1f}.",
        "",
        "| binning (azimuth, elevation, nearness) | entries | MB | hit rate by quarter of the poses | "
        "hit ms | box IoU min / median (min for boxes >= 40 px) | mask IoU median | MAD median / p90 |",
        "|---|---:|---:|---|---:|---|---:|---|",
    ]
    for name, r in res["binnings"].items():
        hr = " / ".join(f"{x:.2f}" for x in r["hit_rate_by_quarter"])
        b40 = "-" if r["box_iou_min_40px"] is None else f"{r['box_iou_min_40px']:.3f}"
        hms = "-" if r["hit_ms_median"] is None else f"{r['hit_ms_median']:.2f}"
        lines.append(
            f"| {name} | {r['entries']} | {r['MB']:.1f} | {hr} | {hms} | {r['box_iou_min']:.3f} / "
            f"{r['box_iou_median']:.3f} ({b40}) | {r['mask_iou_median']:.3f} | {r['mad_median']:.1f} / "
            f"{r['mad_p90']:.1f} |"
        )
    (out / "view_cache.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
