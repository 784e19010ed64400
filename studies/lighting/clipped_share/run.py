#!/usr/bin/env python
"""Exposure and white balance of inserted objects against what the photo shows around them.

TraCon train photos that hold labelled cones (the seeded draw of ``eval_neutral_whites.py``): 1-3 objects are
inserted with a preset's defaults (the real boxes passed as existing boxes). Per photo:

- clipped share: pixels with a channel >= 250 among the inserted objects' visible pixels, against the same share in
  their surroundings (a ring of half the object's box height around each object, other inserted objects left out)
  and in the photo's own labelled cones (their boxes). Target of the lighting issue: inserted <= surroundings + 2
  percentage points on >= 95 % of the photos.
- white balance: the inserted cones' white parts (rendered albedo white, eroded, unclipped) against the photo's own
  white cone sleeves, (R/G, B/G) inserted / real (target band 0.94-1.06 on >= 90 % of the photos).

    python -m studies.lighting.clipped_share --photos 40 --out studies/lighting/clipped_share/result
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from pycocotools import mask as mask_utils

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion
from studies._shared.cone_whites import chroma, inserted_white_rgb, labelled_cone_photos, real_white_rgb

CLIP = 250


def clipped(img: np.ndarray, m: np.ndarray) -> float | None:
    return None if m.sum() < 20 else float(np.mean(img[m].max(-1) >= CLIP))


def object_masks(annotations, shape) -> list[np.ndarray]:
    out = []
    for a in annotations:
        if a.decoy or a.visible_box_xywh is None:
            continue
        out.append(mask_utils.decode({"size": list(shape), "counts": a.rle["counts"].encode()}).astype(bool))
    return out


def surroundings(masks: list[np.ndarray], annotations) -> np.ndarray:
    allm = np.any(masks, axis=0)
    ring = np.zeros_like(allm)
    for m, a in zip(masks, [a for a in annotations if not a.decoy and a.visible_box_xywh is not None]):
        r = max(3, int(0.5 * a.visible_box_xywh[3]))
        ring |= cv2.dilate(m.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1,) * 2)) > 0
    return ring & ~allm


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--presets", nargs="+", default=["fast", "balanced"])
    ap.add_argument("--out", type=Path, default=Path("studies/lighting/clipped_share/result"))
    a = ap.parse_args(argv)
    rows, t0 = [], time.perf_counter()
    for stem, img, boxes in labelled_cone_photos(a.seed):
        if len(rows) >= a.photos:
            break
        H, W = img.shape[:2]
        real_box = np.zeros((H, W), bool)
        for x0, y0, x1, y1 in boxes.round().astype(int):
            real_box[max(y0, 0) : max(y1, 0), max(x0, 0) : max(x1, 0)] = True
        real_white = real_white_rgb(img, boxes)
        row = {"photo": stem, "real_cones_clipped": clipped(img, real_box)}
        for preset in a.presets:
            cfg = load_preset(preset)
            frame = Frame(img, None)
            an = analyse_scene(frame, cfg)
            if an.region is None:
                continue
            plan = plan_insertion(
                an, cfg, np.random.default_rng([a.seed, len(rows)]), n_objects=3, existing_boxes_xyxy=boxes
            )
            if not plan.objects:
                continue
            res = apply_plan(frame, an, plan, cfg)
            masks = object_masks(res.annotations, (H, W))
            if not masks:
                continue
            obj = np.any(masks, axis=0)
            row[f"{preset}_object_clipped"] = clipped(res.image, obj)
            row[f"{preset}_surroundings_clipped"] = clipped(img, surroundings(masks, res.annotations))
            ins_white = inserted_white_rgb(res.image, plan, an)
            if ins_white is not None and real_white is not None:
                row[f"{preset}_white_ratio"] = (chroma(ins_white) / chroma(real_white)).round(4).tolist()
        if any(k.endswith("_object_clipped") for k in row):
            rows.append(row)
            print(f"[{len(rows)}/{a.photos} {time.perf_counter() - t0:.0f}s] {row}", flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "rows.json").write_text(json.dumps(rows, indent=1))
    summary = {
        "command": "python -m studies.lighting.clipped_share " + " ".join(argv or sys.argv[1:]),
        "photos": len(rows),
    }
    lines = [
        "# Clipped share and white balance of inserted objects (lighting issue targets)\n",
        f"`{summary['command']}` ({round(time.perf_counter() - t0)} s). {len(rows)} TraCon train photos with labelled "
        "cones, 1-3 objects inserted with each preset's defaults. Clipped: a channel >= 250.\n",
        "| preset | photos | inserted clipped (median) | surroundings clipped (median) | photo's cones clipped (median) | "
        "inserted <= surroundings + 2 pp | white R/G, B/G (median) | whites within 0.94-1.06 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for preset in a.presets:
        r = [x for x in rows if f"{preset}_object_clipped" in x and x[f"{preset}_surroundings_clipped"] is not None]
        if not r:
            continue
        o = np.array([x[f"{preset}_object_clipped"] or 0.0 for x in r])
        s_ = np.array([x[f"{preset}_surroundings_clipped"] for x in r])
        c = np.array([x["real_cones_clipped"] for x in r if x["real_cones_clipped"] is not None])
        ok = float(np.mean(o <= s_ + 0.02))
        w = np.array([x[f"{preset}_white_ratio"] for x in r if f"{preset}_white_ratio" in x])
        wok = float(np.mean(np.all((w >= 0.94) & (w <= 1.06), axis=1))) if len(w) else None
        summary[preset] = {
            "photos": len(r),
            "object_clipped_median": float(np.median(o)),
            "surroundings_clipped_median": float(np.median(s_)),
            "real_cones_clipped_median": float(np.median(c)) if len(c) else None,
            "within_surroundings_plus_2pp": ok,
            "white_photos": len(w),
            "white_median": None if not len(w) else np.median(w, axis=0).round(3).tolist(),
            "white_within_band": wok,
        }
        lines.append(
            f"| {preset} | {len(r)} | {100 * np.median(o):.1f} % | {100 * np.median(s_):.1f} % | "
            f"{100 * np.median(c):.1f} % | {100 * ok:.0f} % | "
            + ("-" if not len(w) else " / ".join(f"{v:.3f}" for v in np.median(w, axis=0)))
            + f" ({len(w)} photos) | "
            + ("-" if wok is None else f"{100 * wok:.0f} %")
            + " |"
        )
    (a.out / "summary.json").write_text(json.dumps(summary, indent=1))
    (a.out / "README.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
