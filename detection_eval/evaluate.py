"""COCO-style scoring with pycocotools, split from the conversion of detections to COCO format.

Metrics: AP (0.50:0.95), AP50, AP75, AP by size (small < 32^2 px, medium, large >= 96^2 px), and AP per category.
An undefined metric (no ground truth of that kind) is ``nan`` (pycocotools' -1). Zero detections are scored as such
(AP 0 where ground truth exists): ``COCO.loadRes([])`` raises, so an empty result set is built directly.
"""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from .boxes import xyxy_to_xywh

SUMMARY_NAMES = (
    "AP",
    "AP50",
    "AP75",
    "AP_small",
    "AP_medium",
    "AP_large",
    "AR1",
    "AR10",
    "AR100",
    "AR_small",
    "AR_medium",
    "AR_large",
)


def detections_to_coco(image_ids, detections, category_ids) -> list[dict]:
    """Per-image ``{"boxes" xyxy (N, 4), "scores" (N,), "labels" (N,)}`` (numpy or torch, original pixels) ->
    COCO result list."""
    out = []
    for image_id, det in zip(image_ids, detections):
        boxes = np.asarray(det["boxes"], np.float64).reshape(-1, 4)
        for box, score, label in zip(xyxy_to_xywh(boxes), np.asarray(det["scores"]), np.asarray(det["labels"])):
            out.append(
                {
                    "image_id": int(image_id),
                    "category_id": int(category_ids[int(label)]),
                    "bbox": [round(float(v), 3) for v in box],
                    "score": float(score),
                }
            )
    return out


def _quiet(fn, *args):
    with contextlib.redirect_stdout(io.StringIO()):
        return fn(*args)


def _nan_if_undefined(x: float) -> float:
    return float("nan") if x < 0 else float(x)


def coco_evaluate(gt: dict, results: list[dict]) -> dict:
    """Score COCO ``results`` against the COCO ground-truth dict ``gt``."""
    if not gt.get("annotations"):
        raise ValueError("ground truth has no annotations: AP is undefined")
    coco_gt = COCO()
    coco_gt.dataset = {k: list(v) for k, v in gt.items()}
    _quiet(coco_gt.createIndex)
    if results:
        coco_dt = _quiet(coco_gt.loadRes, results)
    else:
        coco_dt = COCO()
        coco_dt.dataset = {"images": list(gt["images"]), "categories": list(gt["categories"]), "annotations": []}
        _quiet(coco_dt.createIndex)
    ev = COCOeval(coco_gt, coco_dt, "bbox")
    _quiet(ev.evaluate)
    _quiet(ev.accumulate)
    _quiet(ev.summarize)
    metrics = {name: _nan_if_undefined(v) for name, v in zip(SUMMARY_NAMES, ev.stats)}
    # precision: (iou thresholds, recall thresholds, categories, area ranges, max dets); area 0 = all, maxDets 100
    precision = ev.eval["precision"]
    per_category = {}
    for k, cat_id in enumerate(ev.params.catIds):
        p = precision[:, :, k, 0, -1]
        p = p[p > -1]
        name = coco_gt.cats[cat_id]["name"]
        per_category[name] = float(p.mean()) if p.size else float("nan")
    metrics["per_category_AP"] = per_category
    metrics["num_detections"] = len(results)
    metrics["num_gt"] = len(gt["annotations"])
    metrics["num_images"] = len(gt["images"])
    return metrics


def format_metrics(m: dict) -> str:
    def f(x):
        return "nan" if isinstance(x, float) and math.isnan(x) else f"{x:.4f}"

    head = "  ".join(f"{k}={f(m[k])}" for k in ("AP", "AP50", "AP75", "AP_small", "AP_medium", "AP_large"))
    cats = "  ".join(f"{k}={f(v)}" for k, v in m["per_category_AP"].items())
    skipped = f" ({len(m['skipped_images'])} unreadable images skipped)" if m.get("skipped_images") else ""
    return (
        f"{head}\nper category: {cats}\n{m['num_detections']} detections, {m['num_gt']} gt boxes, "
        f"{m['num_images']} images{skipped}"
    )
