#!/usr/bin/env python
"""Contact sheet for studies/lighting/neutral_whites/result: per TraCon train photo, a real cone of the photo, then the same
inserted cones (same plan) with the previous appearance (scene-coloured ambient, full harmonizer) and the current
defaults (neutral ambient, harmonizer luminance only).

    python -m studies.lighting.neutral_whites.sheet --photos 8 --out studies/lighting/neutral_whites/result/sheet.jpg
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion
from studies._shared.cone_whites import labelled_cone_photos

TILE = 160


def crop(img: np.ndarray, box, pad: float = 0.6) -> np.ndarray:
    x0, y0, x1, y1 = box
    s = max(x1 - x0, y1 - y0) * (1 + pad)
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    H, W = img.shape[:2]
    a, b = int(max(0, cx - s / 2)), int(max(0, cy - s / 2))
    c, d = int(min(W, cx + s / 2)), int(min(H, cy + s / 2))
    return cv2.resize(img[b:d, a:c], (TILE, TILE), interpolation=cv2.INTER_AREA)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--photos", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="studies/lighting/neutral_whites/result/sheet.jpg")
    a = ap.parse_args(argv)
    new = load_preset("balanced")
    old = replace(
        new,
        harmonize_colour="full",
        lighting_cfg=replace(new.lighting_cfg, ambient_colour="scene", ground_white_balance=0.75),
    )
    rows = []
    for stem, img, boxes in labelled_cone_photos(a.seed):
        if len(rows) >= a.photos:
            break
        frame = Frame(img, None)
        an_old, an_new = analyse_scene(frame, old), analyse_scene(frame, new)
        if an_new.region is None:
            continue
        plan = plan_insertion(
            an_new, new, np.random.default_rng([a.seed, len(rows)]), n_objects=1, existing_boxes_xyxy=boxes
        )
        if not plan.objects:
            continue
        box = plan.objects[0].placement.amodal_box_xyxy
        if box[3] - box[1] < 24:
            continue
        real = boxes[int(np.argmax(boxes[:, 3] - boxes[:, 1]))]
        rows.append(
            np.hstack(
                [
                    crop(img, real),
                    crop(apply_plan(frame, an_old, plan, old).image, box),
                    crop(apply_plan(frame, an_new, plan, new).image, box),
                ]
            )
        )
        print(f"{len(rows)}/{a.photos} {stem}", flush=True)
    sheet = np.vstack(rows)
    head = np.full((28, sheet.shape[1], 3), 255, np.uint8)
    for k, t in enumerate(("real cone", "scene ambient, full harm.", "neutral, luminance (now)")):
        cv2.putText(head, t, (k * TILE + 4, 19), cv2.FONT_HERSHEY_SIMPLEX, 0.34, (0, 0, 0), 1, cv2.LINE_AA)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(a.out, cv2.cvtColor(np.vstack([head, sheet]), cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 90])
    print("wrote", a.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
