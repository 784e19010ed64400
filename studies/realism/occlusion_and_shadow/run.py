"""Issue 53 items 1 (shading rule) and 2 on TraCon val photos with their labels: inserted objects drawn over a
nearer labelled cone, and the darkest sun shadow against the sun decision's confidence, before and after.

Per photo (the val photos with the most labelled cones, at most 1280 px wide) and seed (7, 8, 9): one analysis and
one plan (balanced, traffic_cone and barrel, 3 objects, the labelled boxes as existing boxes; an inserted box may
overlap them by 0.6 of its area, as an arranged row's may, so that objects stand among the labelled cones), applied
twice:

* before: the labelled boxes not given to ``apply_plan`` (every inserted object drawn over them, as before the
  labelled occluders) and the sun shadow without the confidence limits (``sun_shadow_limits`` replaced by the old
  rule: the sun's own disc, darkness from the sun/sky ratio alone);
* after: the door as shipped (``apply_plan(..., labelled_xywh=boxes)``).

Measured on the output against the input: an inserted object is "drawn over a nearer labelled one" when a labelled
box whose bottom edge lies lower in the image than the object's (nearer on the ground) has >= 20 px of its object
(GrabCut mask of the box, eroded 2 px) inside the object's amodal box, outside the boxes of other inserted objects
nearer than the labelled one, changed by more than 8 levels. The darkest
shadow is the least ratio (linear luminance, output / input) over the changed pixels outside the objects' boxes
(4 px wider) where the input is not near black (linear luminance >= 0.01).

    PYOPENGL_PLATFORM=egl AIAS_DATA=/work/shared/data python -m studies.realism.occlusion_and_shadow
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.cache import SceneCache
from aias_augment.analyse.instances import labelled_ground
from aias_augment.apply import stages
from aias_augment.apply.composite import to_linear
from aias_augment.apply.occluders import object_mask_from_box
from aias_augment.apply.shadows import SUN_ANGULAR_RADIUS_RAD, SunShadowLimits
from aias_augment.core.config import data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.plan.insertion import plan_insertion

OUT = Path(__file__).resolve().parent / "result"
N_PHOTOS, SEEDS, MAX_W = 6, (7, 8, 9), 1280
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)


def photos(n: int):
    """The ``n`` val photos with the most labelled cones: (name, RGB image, COCO boxes), at most MAX_W wide."""
    root = data_root() / "tracon"
    counts = sorted(
        ((len(p.read_text().split("\n")), p.stem) for p in (root / "labels" / "val").glob("*.txt")), reverse=True
    )
    for _, stem in counts[:n]:
        img = cv2.cvtColor(cv2.imread(str(root / "images" / "val" / f"{stem}.jpg")), cv2.COLOR_BGR2RGB)
        s = min(1.0, MAX_W / img.shape[1])
        if s < 1:
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        h, w = img.shape[:2]
        rows = np.loadtxt(root / "labels" / "val" / f"{stem}.txt", ndmin=2)
        boxes = np.c_[
            (rows[:, 1] - rows[:, 3] / 2) * w, (rows[:, 2] - rows[:, 4] / 2) * h, rows[:, 3] * w, rows[:, 4] * h
        ]
        yield stem, img, boxes


def _box(shape, p) -> tuple[np.ndarray, int]:
    x0, y0, x1, y1 = (int(round(v)) for v in p.amodal_box_xyxy)
    box = np.zeros(shape, bool)
    box[max(y0, 0) : y1, max(x0, 0) : x1] = True
    return box, y1


def drawn_over(image, out, boxes, applied) -> int:
    """Inserted objects with >= 20 changed px inside a nearer labelled object's eroded GrabCut mask (outside the
    boxes of the inserted objects nearer than that labelled one, which may cover it)."""
    changed = np.abs(out.astype(int) - image.astype(int)).max(-1) > 8
    kernel = np.ones((5, 5), np.uint8)
    masks = [cv2.erode(object_mask_from_box(image, b)[0].astype(np.uint8), kernel) > 0 for b in boxes]
    objs = [_box(changed.shape, p) for p in applied.placements]
    n = 0
    for k, (box, bottom) in enumerate(objs):
        hit = False
        for b, m in zip(boxes, masks):
            if b[1] + b[3] <= bottom:  # the labelled object is not nearer
                continue
            free = ~np.logical_or.reduce([o for j, (o, y1) in enumerate(objs) if j != k and y1 >= b[1] + b[3]] + [~box])
            hit |= np.count_nonzero(m & free & changed) >= 20
        n += hit
    return n


def darkest_shadow(image, out, applied) -> float:
    lum = to_linear(image) @ LUMA
    ratio = (to_linear(out) @ LUMA) / np.maximum(lum, 1e-4)
    keep = (lum >= 0.01) & (out != image).any(-1)
    for p in applied.placements:
        x0, y0, x1, y1 = (int(round(v)) for v in p.amodal_box_xyxy)
        keep[max(y0 - 4, 0) : y1 + 4, max(x0 - 4, 0) : x1 + 4] = False
    return float(ratio[keep].min()) if keep.any() else 1.0


def old_limits(confidence: float) -> SunShadowLimits:
    return SunShadowLimits(0.0, SUN_ANGULAR_RADIUS_RAD, 0.5)


def main() -> None:
    base = load_preset("balanced")
    pcfg = replace(base.placement_cfg, max_overlap_existing=0.6)
    cfg = replace(base, categories=("traffic_cone", "barrel"), placement_cfg=pcfg)
    rows, tiles = [], []
    new_limits = stages.sun_shadow_limits
    t0 = time.time()
    cache = SceneCache(max_items=4)
    for (stem, img, boxes), seed in ((p, s) for p in photos(N_PHOTOS) for s in SEEDS):
        frame = Frame(img, None)
        analysis = cache.get(frame, cfg)
        rng = np.random.default_rng(seed)
        c = cfg.for_image(rng)
        xyxy = np.c_[boxes[:, :2], boxes[:, :2] + boxes[:, 2:]]
        plan = plan_insertion(
            analysis,
            c,
            rng,
            existing_boxes_xyxy=xyxy,
            existing_labels=["cone"] * len(boxes),
            n_objects=3,
            labelled_ground=labelled_ground(img, xyxy) if c.arrangement == "row" else None,  # as the door
        )
        stages.sun_shadow_limits = old_limits
        before = stages.apply_plan(frame, analysis, plan, c)
        stages.sun_shadow_limits = new_limits
        after = stages.apply_plan(frame, analysis, plan, c, labelled_xywh=boxes)
        light = analysis.lighting
        rows.append(
            {
                "photo": stem,
                "seed": seed,
                "labelled": len(boxes),
                "inserted": len(after.placements),
                "sun": bool(light.dominant_sun),
                "confidence": round(light.confidence, 3),
                "drawn_over_before": drawn_over(img, before.image, boxes, before),
                "drawn_over_after": drawn_over(img, after.image, boxes, after),
                "darkest_before": round(darkest_shadow(img, before.image, before), 3),
                "darkest_after": round(darkest_shadow(img, after.image, after), 3),
            }
        )
        print(rows[-1], flush=True)
        r = rows[-1]
        if len(tiles) < 6 and (r["drawn_over_before"] or r["darkest_after"] > r["darkest_before"] + 0.05):
            tiles.append(np.concatenate([before.image, after.image], axis=1))
    total = {k: sum(r[k] for r in rows) for k in ("inserted", "drawn_over_before", "drawn_over_after")}
    result = {"photos": rows, "total": total, "seconds": round(time.time() - t0, 1)}
    (OUT / "result.json").write_text(json.dumps(result, indent=1) + "\n")
    print(total)
    if not tiles:
        return print("no photo changed: no contact sheet")
    side = 1200  # the results' pictures: at most 1200 px on a side
    sheet = np.concatenate([cv2.resize(t, (side, int(t.shape[0] * side / t.shape[1]))) for t in tiles], axis=0)
    if sheet.shape[0] > side:
        sheet = cv2.resize(sheet, (int(side * sheet.shape[1] / sheet.shape[0]), side), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(OUT / "contact_sheet.jpg"), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 80])


if __name__ == "__main__":
    main()
