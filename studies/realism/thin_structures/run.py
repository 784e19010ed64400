"""Issue 53 item 2's thin structures on TraCon val: sites behind poles and rails refused (``thin_structures: true``)
against the default, the same seeds.

Per val photo (at most 1280 px wide; its labelled cones given as existing boxes) and seed 7: the balanced preset,
traffic_cone, 3 objects, once with ``thin_structures`` off (the default) and once on. Counted per arm: objects
inserted, inserted objects whose box a detected thin structure crosses by the placement's rule
(:func:`aias_augment.plan.placement.thin_structure_in_front`, the segments of the "on" analysis: for the "off" arm this
counts the objects the rule would have moved), candidate sites refused for a thin structure, and per photo the
thin structures found. The contact sheet shows the first 8 photos whose placements differ, each as a pair squeezed to 800x300: off
(left), on (right, the segments found drawn in cyan).

    PYOPENGL_PLATFORM=egl AIAS_DATA=/work/shared/data python -m studies.realism.thin_structures
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.analyse.analysis import analyse_scene
from aias_augment.core.config import data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.config import load_preset
from aias_augment.pipeline.image import insert_into_image
from aias_augment.plan.placement import thin_structure_in_front
from studies._shared.pictures import write_jpeg

OUT = Path(__file__).resolve().parent / "result"
SEED, MAX_W, SHEET_PAIRS = 7, 1280, 8


def photos():
    """Every val photo: (name, RGB image, COCO boxes of its labelled cones), at most MAX_W wide."""
    root = data_root() / "tracon"
    for p in sorted((root / "images" / "val").glob("*.jpg")):
        img = cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB)
        s = min(1.0, MAX_W / img.shape[1])
        if s < 1:
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        h, w = img.shape[:2]
        lab = root / "labels" / "val" / f"{p.stem}.txt"
        rows = np.loadtxt(lab, ndmin=2) if lab.exists() and lab.stat().st_size else np.zeros((0, 5))
        boxes = np.c_[
            (rows[:, 1] - rows[:, 3] / 2) * w, (rows[:, 2] - rows[:, 4] / 2) * h, rows[:, 3] * w, rows[:, 4] * h
        ]
        yield p.stem, img, boxes


def _crossed(res, segments) -> int:
    return sum(
        thin_structure_in_front(np.array(a.amodal_box_xyxy), segments) is not None for a in res.record.placements
    )


def _refused(res) -> int:
    return sum(v for rep in res.record.placement_reports for k, v in rep.get("rejected", {}).items() if "thin" in k)


def main() -> int:
    OUT.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    arms = {"off": load_preset("balanced", categories=("traffic_cone",), min_objects=3, max_objects=3)}
    arms["on"] = load_preset(
        "balanced", categories=("traffic_cone",), min_objects=3, max_objects=3, thin_structures=True
    )
    per_photo, sheet = [], []
    for name, img, boxes in photos():
        out = {}
        for arm, cfg in arms.items():
            labels = ["traffic_cone"] * len(boxes)
            out[arm] = insert_into_image(img, boxes, labels, np.random.default_rng(SEED), cfg)
        segs = analyse_scene(Frame(img, None), arms["on"]).region.thin_segments
        row = {"photo": name, "thin_structures": int(len(segs))}
        for arm, res in out.items():
            row[arm] = {"inserted": len(res.inserted_bboxes), "crossed": _crossed(res, segs), "refused": _refused(res)}
        per_photo.append(row)
        moved = [p.contact_pixel for p in out["off"].record.placements] != [
            p.contact_pixel for p in out["on"].record.placements
        ]
        if moved and len(sheet) < SHEET_PAIRS:
            right = out["on"].image.copy()
            for x1, y1, x2, y2 in segs:
                cv2.line(right, (int(x1), int(y1)), (int(x2), int(y2)), (0, 255, 255), 1)
            pair = np.concatenate([out["off"].image, np.full((img.shape[0], 8, 3), 255, np.uint8), right], 1)
            sheet.append(cv2.resize(pair, (800, 300)))
    total = {
        arm: {k: int(sum(r[arm][k] for r in per_photo)) for k in ("inserted", "crossed", "refused")} for arm in arms
    }
    res = {
        "photos": len(per_photo),
        "seed": SEED,
        "total": total,
        "photos_with_thin_structures": int(sum(r["thin_structures"] > 0 for r in per_photo)),
        "thin_structures_median": float(np.median([r["thin_structures"] for r in per_photo])),
        "photos_moved": int(sum(r["off"] != r["on"] for r in per_photo)),
        "per_photo": per_photo,
        "seconds": round(time.time() - t0, 1),
    }
    (OUT / "result.json").write_text(json.dumps(res, indent=1) + "\n")
    if sheet:  # two columns of pairs
        sheet += [np.zeros_like(sheet[0])] * (len(sheet) % 2)
        half = len(sheet) // 2
        grid = np.concatenate([np.concatenate(sheet[:half], 0), np.concatenate(sheet[half:], 0)], 1)
        write_jpeg(OUT / "contact_sheet.jpg", cv2.cvtColor(grid, cv2.COLOR_RGB2BGR))
    print(json.dumps({k: v for k, v in res.items() if k != "per_photo"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
