"""Run a detector on images or a dataset; detections come back in original image pixels."""

from __future__ import annotations

import dataclasses
import logging

import cv2
import numpy as np
import torch

from .boxes import letterbox_image
from .config import InferenceConfig
from .data import DetectionSet, coco_gt_dict
from .evaluate import coco_evaluate, detections_to_coco
from .loader import CachedImage, cache_image, images_to_tensor, pad_to_square
from .model import Detector, postprocess

log = logging.getLogger(__name__)


def _to_numpy(det: dict, lb, width: int, height: int) -> dict:
    boxes = lb.boxes_from_letterbox(det["boxes"].double()).numpy()
    boxes[:, [0, 2]] = boxes[:, [0, 2]].clip(0, width)
    boxes[:, [1, 3]] = boxes[:, [1, 3]].clip(0, height)
    return {"boxes": boxes, "scores": det["scores"].numpy(), "labels": det["labels"].numpy()}


@torch.no_grad()
def predict_cached(
    model: Detector, cached: list[CachedImage], sizes: list[tuple[int, int]], cfg: InferenceConfig, batch_size: int = 8
) -> list[dict]:
    """Detections for cached letterbox contents; ``sizes`` are the original (width, height)."""
    model.eval()
    out = []
    for start in range(0, len(cached), batch_size):
        chunk = cached[start : start + batch_size]
        batch = images_to_tensor([pad_to_square(c.image, c.letterbox) for c in chunk])
        for c, det, (w, h) in zip(chunk, postprocess(model(batch), cfg), sizes[start : start + batch_size]):
            out.append(_to_numpy(det, c.letterbox, w, h))
    return out


@torch.no_grad()
def predict_images(model: Detector, images_rgb: list[np.ndarray], img_size: int, cfg: InferenceConfig) -> list[dict]:
    """Detections for full-resolution RGB uint8 images (any sizes)."""
    model.eval()
    out = []
    for image in images_rgb:
        canvas, lb = letterbox_image(image, img_size)
        det = postprocess(model(images_to_tensor([canvas])), cfg)[0]
        out.append(_to_numpy(det, lb, image.shape[1], image.shape[0]))
    return out


def evaluate_dataset(
    model: Detector,
    dataset: DetectionSet,
    img_size: int,
    cfg: InferenceConfig,
    cached: list[CachedImage] | None = None,
    batch_size: int = 8,
) -> dict:
    """COCO metrics of ``model`` on ``dataset`` (image ids = 1-based record positions, as in ``coco_gt_dict``).

    Without ``cached``, an image that cannot be read is a logged, counted skip (its labels leave the evaluation
    with it): the metrics then hold ``skipped_images`` {file: reason}; no readable image at all raises ValueError."""
    skipped: dict[str, str] = {}
    if cached is None:
        dataset, cached, skipped = cache_readable(dataset, img_size)
    sizes = [(r.width, r.height) for r in dataset.records]
    dets = predict_cached(model, cached, sizes, cfg, batch_size)
    results = detections_to_coco(range(1, len(dets) + 1), dets, dataset.category_ids)
    metrics = coco_evaluate(coco_gt_dict(dataset), results)
    return {**metrics, "skipped_images": skipped} if skipped else metrics


def cache_readable(dataset: DetectionSet, img_size: int) -> tuple[DetectionSet, list[CachedImage], dict[str, str]]:
    """The records whose image decodes, their cached images, and {file: reason} of the others (each logged)."""
    keep, cached, skipped = [], [], {}
    for i, r in enumerate(dataset.records):
        try:
            cached.append(cache_image(r, img_size))
        except (OSError, ValueError, cv2.error) as e:
            skipped[str(r.image_path)] = " ".join(str(e).split())
            log.warning("skipping unreadable image %s: %s", r.image_path, skipped[str(r.image_path)])
            continue
        keep.append(i)
    if not keep:
        raise ValueError(f"none of the {len(dataset.records)} images could be read (e.g. {next(iter(skipped))})")
    if skipped:
        log.warning("evaluating %d images; %d unreadable images skipped", len(keep), len(skipped))
        counts = {**dataset.skipped, "unreadable image": dataset.skipped.get("unreadable image", 0) + len(skipped)}
        dataset = dataclasses.replace(dataset.subset(keep), skipped=counts)
    return dataset, cached, skipped
