"""The ray-cast cone by window size: supersampling every pixel against supersampling only the outline.

    taskset -c 0 nice python -m benchmarks.bench_raycast_outline --out results/bench/raycast_outline

``raycast_cone_window`` (the fast preset's render of a procedural cone) with ``everywhere=True`` (``ssaa`` x
``ssaa`` rays in every pixel) and with the outline pass forced on every window (``ADAPTIVE_MIN_PIXELS = 0``: one
ray per pixel, then ``ssaa`` x ``ssaa`` rays where the 3x3 neighbourhood is not one surface). 30 family cones per
distance on a 640x480, 700 px focal camera, 3-12 deg above the horizon, at six distances; the textures are drawn in
a warm-up pass so that only the ray cast is timed. Per distance: the median window, the best of ``--repeats``
alternating passes (ms per cone), the rays cast, and what the outline pass changes where both cover a pixel fully
(mean absolute sRGB difference). The default threshold (``ADAPTIVE_MIN_PIXELS``) should sit where the two lines
cross.

Writes ``<out>.json``, ``<out>.md`` (with the command) and ``<out>.jpg``: three cones at 5 m, 3 m and 1.8 m
rendered both ways over a grey ground, the supersampled pixels marked, and the difference x10.
"""

from __future__ import annotations

import argparse
import json
import platform
import shlex
import sys
import time
from pathlib import Path

import cv2
import numpy as np

DISTANCES = (30.0, 18.0, 12.0, 8.0, 5.0, 3.0)
FOCAL = 700.0


def _view(dist: float, elev_deg: float, az_deg: float) -> np.ndarray:
    from aias_augment.assets.bank.thumbnails import look_at_cam_from_object

    e, a = np.radians(elev_deg), np.radians(az_deg)
    eye = [dist * np.cos(e) * np.cos(a), dist * np.cos(e) * np.sin(a), dist * np.sin(e)]
    return look_at_cam_from_object(np.array(eye), np.array([0.0, 0.0, 0.35]))


def _srgb255(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.clip(x, 0, None) ** (1 / 2.4) - 0.055) * 255


def _rays(counter: list, fn):
    """``fn`` wrapped to count the rays it is given (its third argument)."""

    def wrapped(shape, origin, dirs, *rest):
        counter[0] += len(dirs)
        return fn(shape, origin, dirs, *rest)

    return wrapped


def measure(repeats: int, n: int) -> list[dict]:
    from aias_augment.apply import cone_raycast
    from aias_augment.assets.bank.procedural import procedural_asset_from_seed
    from aias_augment.core.geometry import Intrinsics

    K = Intrinsics(FOCAL, FOCAL, 320.0, 240.0, 640, 480)
    assets = [procedural_asset_from_seed("traffic_cone", i) for i in range(n)]
    rng = np.random.default_rng(0)
    cone_raycast.ADAPTIVE_MIN_PIXELS = 0
    cast, counter = cone_raycast._cast, [0]
    rows = []
    for dist in DISTANCES:
        views = [
            _view(dist * float(f), float(e), float(a))
            for f, e, a in zip(rng.uniform(0.9, 1.1, n), rng.uniform(3, 12, n), rng.uniform(0, 360, n))
        ]
        diffs, windows = [], []
        for a, v in zip(assets, views):  # the texture levels both passes read
            ref = cone_raycast.raycast_cone_window(a, v, K, everywhere=True)[1]
            got = cone_raycast.raycast_cone_window(a, v, K)[1]
            full = ref.alpha == 1
            windows.append(ref.alpha.size)
            if full.any():
                diffs.append(
                    float(np.abs(_srgb255(got.albedo_linear[full]) - _srgb255(ref.albedo_linear[full])).mean())
                )
        ms, rays = {True: [], False: []}, {}
        cone_raycast._cast = _rays(counter, cast)
        try:
            for _ in range(repeats):
                for everywhere in (True, False):
                    counter[0] = 0
                    t0 = time.perf_counter()
                    for a, v in zip(assets, views):
                        cone_raycast.raycast_cone_window(a, v, K, everywhere=everywhere)
                    ms[everywhere].append(1e3 * (time.perf_counter() - t0) / n)
                    rays[everywhere] = counter[0] / n
        finally:
            cone_raycast._cast = cast
        rows.append(
            {
                "distance_m": dist,
                "window_px_median": float(np.median(windows)),
                "everywhere_ms": min(ms[True]),
                "outline_ms": min(ms[False]),
                "everywhere_rays": rays[True],
                "outline_rays": rays[False],
                "full_pixels_mean_abs_srgb": float(np.median(diffs)) if diffs else None,
            }
        )
        print(rows[-1], flush=True)
    return rows


def picture(path: Path) -> None:
    """Three cones, each rendered both ways and composited over grey; the outline pass's supersampled pixels in
    magenta; |difference| x10."""
    from aias_augment.apply import cone_raycast
    from aias_augment.assets.bank.procedural import procedural_asset_from_seed
    from aias_augment.core.geometry import Intrinsics

    K = Intrinsics(FOCAL, FOCAL, 320.0, 240.0, 640, 480)
    cone_raycast.ADAPTIVE_MIN_PIXELS = 0
    tiles = []
    for seed, dist in ((3, 5.0), (11, 3.0), (17, 1.8)):
        a = procedural_asset_from_seed("traffic_cone", seed)
        T = _view(dist, 8.0, 30.0 * seed)
        ref = cone_raycast.raycast_cone_window(a, T, K, everywhere=True)[1]
        got = cone_raycast.raycast_cone_window(a, T, K)[1]
        grey = np.full(ref.alpha.shape + (3,), 0.2, np.float32)
        views = [
            np.clip(_srgb255(L.albedo_linear) * L.alpha[..., None] + 255 * grey * (1 - L.alpha[..., None]), 0, 255)
            for L in (ref, got)
        ]
        # the partly covered pixels: part of what the outline pass supersamples (it adds where the surface changes)
        edge = (got.alpha > 0) & (got.alpha < 1)
        marked = views[1].copy()
        marked[edge] = (255, 0, 255)
        diff = np.clip(np.abs(views[0] - views[1]) * 10, 0, 255)
        row = np.concatenate([views[0], views[1], marked, diff], axis=1).astype(np.uint8)
        scale = 240 / row.shape[0]
        tiles.append(cv2.resize(row, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST))
    width = max(t.shape[1] for t in tiles)
    sheet = np.concatenate([np.pad(t, ((0, 4), (0, width - t.shape[1]), (0, 0))) for t in tiles], axis=0)
    if sheet.shape[1] > 1200:
        sheet = cv2.resize(sheet, (1200, round(sheet.shape[0] * 1200 / sheet.shape[1])), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(path), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])


def write_md(rows: list[dict], path: Path, command: str, default_min: int) -> None:
    lines = [
        "# The ray-cast cone: supersampling everywhere or only along the outline",
        "",
        f"    {command}",
        "",
        f"One core, {platform.processor() or platform.machine()}; textures made before timing; ms per cone, the best"
        " of the alternating passes. The default outline threshold is "
        f"`ADAPTIVE_MIN_PIXELS = {default_min}` window pixels.",
        "",
        "| distance | median window px | everywhere ms | outline ms | ratio | rays everywhere | rays outline |"
        " full pixels, mean abs sRGB diff |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        d = r["full_pixels_mean_abs_srgb"]
        lines.append(
            f"| {r['distance_m']:g} m | {r['window_px_median']:.0f} | {r['everywhere_ms']:.2f} | {r['outline_ms']:.2f}"
            f" | {r['outline_ms'] / r['everywhere_ms']:.2f} | {r['everywhere_rays']:.0f} | {r['outline_rays']:.0f} |"
            f" {'' if d is None else f'{d:.2f}'} |"
        )
    lines += [
        "",
        f"![both ways]({path.with_suffix('.jpg').name}): everywhere | outline | outline's supersampled"
        " pixels: the partly covered ones in magenta (it also supersamples where the surface changes) | |difference| x10.",
        "",
    ]
    path.write_text("\n".join(lines))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("results/bench/raycast_outline"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cones", type=int, default=30)
    a = ap.parse_args(argv)
    from aias_augment.apply import cone_raycast

    default_min = cone_raycast.ADAPTIVE_MIN_PIXELS
    command = "python -m benchmarks.bench_raycast_outline " + shlex.join(sys.argv[1:] if argv is None else argv)
    rows = measure(a.repeats, a.cones)
    a.out.parent.mkdir(parents=True, exist_ok=True)
    picture(a.out.with_suffix(".jpg"))
    a.out.with_suffix(".json").write_text(json.dumps({"command": command, "rows": rows}, indent=1) + "\n")
    write_md(rows, a.out.with_suffix(".md"), command, default_min)
    return 0


if __name__ == "__main__":
    sys.exit(main())
