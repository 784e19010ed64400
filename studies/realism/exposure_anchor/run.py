"""Brightness of inserted cones against the same photo's real cones, under exposure-anchor settings.

    taskset -c 0 python -m studies.realism.exposure_anchor --half A --out studies/realism/exposure_anchor/result/choice.md

Cones are inserted into the matched protocol's road-scene cone photos (``eval_realism_matched.road_photo_halves``;
half A was the development half for this choice, half B is where the realism report is made) with the study's
insertion config, each variant of ``LightingConfig.ground_albedo_range`` in turn, the photo's real cones passed as
existing boxes; copy j draws from ``default_rng([pool_seed, 7, j])`` in every variant (paired). For every inserted
cone with at least 20 fluorescent-orange pixels (HSV hue <= 12 or >= 170 of 180, saturation >= 120, value >= 60)
in a photo whose real cones have as many: the median max channel of its orange pixels over the same of the photo's
real cones (same light, same camera), and the share of orange pixels at 250 or more (clipped).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from studies.realism.arms.run import study_cfg
from studies.realism.matched.run import downscaled, road_photo_halves

REPO = Path(__file__).resolve().parents[3]
VARIANTS = {  # (ground_albedo_range, ground_anchor_max_gain)
    "off": (None, 1.0),
    "0.06-0.15": ((0.06, 0.15), 1e9),
    "0.05-0.2": ((0.05, 0.2), 1e9),
    "0.05-0.3": ((0.05, 0.3), 1e9),
    "0.05-0.2 gain<=2": ((0.05, 0.2), 2.0),
    "0.05-0.2 gain<=3": ((0.05, 0.2), 3.0),
    "0.05-0.2 gain<=5": ((0.05, 0.2), 5.0),
}


def orange_pixels(img: np.ndarray, box) -> np.ndarray:
    """(N, 3) uint8 fluorescent-orange pixels of ``img`` inside ``box`` (xyxy)."""
    x0, y0, x1, y1 = (int(round(v)) for v in box)
    c = img[max(y0, 0) : y1, max(x0, 0) : x1]
    hsv = cv2.cvtColor(c, cv2.COLOR_RGB2HSV)
    m = ((hsv[..., 0] <= 12) | (hsv[..., 0] >= 170)) & (hsv[..., 1] >= 120) & (hsv[..., 2] >= 60)
    return c[m]


def measure(photos, ins_cfg, pool_seed: int, max_side: int) -> np.ndarray:
    """(K, 4): per inserted cone, its orange median max channel, the real cones', and both clipped shares."""
    from aias_augment.pipeline.image import insert_into_image

    rows = []
    for j, ph in enumerate(photos):
        img, _ = downscaled(ph.path, max_side)
        existing = np.c_[ph.boxes_xyxy[:, :2], ph.boxes_xyxy[:, 2:] - ph.boxes_xyxy[:, :2]]
        try:
            res = insert_into_image(
                img, existing, ["cone"] * len(existing), np.random.default_rng([pool_seed, 7, j]), ins_cfg
            )
        except Exception:  # counted by the caller as fewer cones
            continue
        real = [o for o in (orange_pixels(res.image, b) for b in ph.boxes_xyxy) if len(o)]
        real = np.concatenate(real) if real else np.zeros((0, 3), np.uint8)
        for b in np.asarray(res.inserted_bboxes, float).reshape(-1, 4):
            ins = orange_pixels(res.image, [b[0], b[1], b[0] + b[2], b[1] + b[3]])
            if len(ins) >= 20 and len(real) >= 20:
                mi, mr = ins.max(1), real.max(1)
                rows.append((np.median(mi), np.median(mr), np.mean(mi >= 250), np.mean(mr >= 250)))
    return np.array(rows).reshape(-1, 4)


def main() -> None:
    from detection_eval.data import load_yolo_dir
    from detection_eval.study.arms import insertion_config_for_arm
    from detection_eval.study.config import dataset_root

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--half", choices=("A", "B"), default="A")
    ap.add_argument("--n", type=int, default=106, help="photos of the half")
    ap.add_argument("--variants", nargs="*", default=list(VARIANTS)[:4], choices=list(VARIANTS))
    ap.add_argument("--out", default=None, help="markdown table (default: print only)")
    args = ap.parse_args()
    cfg = study_cfg("out/realism/exposure", args.n)
    train = load_yolo_dir(dataset_root(cfg), cfg.train_split, cfg.class_names)
    a, b = road_photo_halves(cfg)
    photos = (a if args.half == "A" else b)[: args.n]
    base = insertion_config_for_arm(cfg, "inserted", train)
    lines = [
        f"`python -m studies.realism.exposure_anchor {shlex.join(sys.argv[1:])}`: {len(photos)} photos of half {args.half}.",
        "",
        "| ground_albedo_range | cones | inserted / real orange brightness, median [quartiles] | clipped orange, "
        "inserted | clipped orange, real |",
        "|---|---|---|---|---|",
    ]
    for name in args.variants:
        rng_, gain = VARIANTS[name]
        c = replace(
            base, lighting_cfg=replace(base.lighting_cfg, ground_albedo_range=rng_, ground_anchor_max_gain=gain)
        )
        r = measure(photos, c, cfg.insertion.pool_seed, cfg.insertion.max_side_px)
        q = np.percentile(r[:, 0] / r[:, 1], [50, 25, 75])
        lines.append(
            f"| {name} | {len(r)} | {q[0]:.2f} [{q[1]:.2f}, {q[2]:.2f}] | {r[:, 2].mean():.1%} | {r[:, 3].mean():.1%} |"
        )
        print(lines[-1], flush=True)
    if args.out:
        Path(args.out).write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
