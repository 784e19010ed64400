"""Speed vs accuracy of the insertion presets.

Speed: median seconds per image (several repeats) of ``insert_into_image`` on real frames, per preset.
Accuracy of the render: mean absolute error of the object coverage (alpha) against a 4x-supersampled reference of the
same placement (edge quality), and the harmonizer used.

    python -m benchmarks.bench_insertion --repeats 3 --out results/bench
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from aias_augment.apply.render import render_object
from aias_augment.assets.asset import default_asset
from aias_augment.cli.demo import demo_items
from aias_augment.cli.offline import read_rgb
from aias_augment.core.geometry import Intrinsics
from aias_augment.pipeline.image import PRESETS, insert_into_image, load_preset
from aias_augment.scenes.stereo import stereo_depth


def load_inputs(n_tracon: int):
    out = []
    for it in demo_items(n_tracon):
        img = read_rgb(it.path)
        intr = depth = None
        if it.K is not None:
            intr = Intrinsics.from_matrix(np.asarray(it.K), img.shape[1], img.shape[0])
            depth = stereo_depth(img, read_rgb(it.stereo_right), intr, it.baseline_m)
        out.append((Path(it.path).name, img, intr, depth))
    return out


def edge_error(ssaa: int) -> float:
    """Mean |alpha - alpha_ref| over the pixels the object touches, reference ssaa=4."""
    K = Intrinsics(700.0, 700.0, 319.5, 239.5, 640, 480)
    cone = default_asset("traffic_cone")
    errs = []
    for z, x in ((6.0, 0.2), (12.0, -1.0), (25.0, 1.5)):
        T = np.eye(4)
        T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
        T[:3, 3] = [x, 1.5, z]
        a = render_object(cone, T, K, ssaa=ssaa, with_normals=False).alpha
        ref = render_object(cone, T, K, ssaa=4, with_normals=False).alpha
        touched = (a > 0) | (ref > 0)
        errs.append(float(np.abs(a - ref)[touched].mean()))
    return float(np.mean(errs))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tracon", type=int, default=4)
    ap.add_argument("--out", default="results/bench")
    a = ap.parse_args(argv)
    inputs = load_inputs(a.tracon)
    rows = []
    # Warm-up: renderer creation, mesh upload.
    insert_into_image(inputs[0][1], rng=np.random.default_rng(0), cfg=load_preset("fast"), intrinsics=inputs[0][2])
    for preset in PRESETS:
        cfg = replace(load_preset(preset), categories=("traffic_cone",), min_objects=2, max_objects=2)
        times, modules = [], set()
        for r in range(a.repeats):
            for i, (name, img, intr, depth) in enumerate(inputs):
                t0 = time.perf_counter()
                res = insert_into_image(img, rng=np.random.default_rng([r, i]), cfg=cfg, intrinsics=intr, depth=depth)
                times.append(time.perf_counter() - t0)
                modules.add(res.record.modules.get("harmonize", ""))
        rows.append(
            {
                "preset": preset,
                "ssaa": cfg.ssaa,
                "harmonize": cfg.harmonize_method,
                "median_s_per_image": float(np.median(times)),
                "p90_s": float(np.percentile(times, 90)),
                "n": len(times),
                "edge_alpha_mae_vs_ssaa4": edge_error(cfg.ssaa),
                "harmonize_outcomes": sorted(modules),
            }
        )
        print(rows[-1])
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    cmd = "python -m benchmarks.bench_insertion " + " ".join(argv if argv is not None else sys.argv[1:])
    (out / "insertion.json").write_text(json.dumps({"command": cmd, "rows": rows}, indent=2))
    lines = [
        "# Insertion presets: speed vs accuracy",
        "",
        f"Command: `{cmd.strip()}` (2 CPU cores, llvmpipe EGL)",
        "",
        f"{len(inputs)} real images (KITTI with stereo depth, TraCon roads), 2 cones each, {a.repeats} repeats.",
        "",
        "| preset | ssaa | harmonizer | median s/image | p90 s | edge alpha MAE vs 4x |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['preset']} | {r['ssaa']} | {r['harmonize']} | {r['median_s_per_image']:.2f} | "
            f"{r['p90_s']:.2f} | {r['edge_alpha_mae_vs_ssaa4']:.3f} |"
        )
    (out / "insertion.md").write_text("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
