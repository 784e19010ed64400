"""Online augmentation adapters: plug object insertion (or any albumentations pipeline) into training as a
``SampleTransform`` ``(image, boxes_xyxy, labels, rng) -> (image, boxes_xyxy, labels)``, applied to each cached
sample before the detector's own augmentation. Pass the result to ``train_detector(sample_transform=...)``.

Offline generation (``detection_eval.study``) is the faster choice on CPU: rendering costs seconds per image.
"""

from __future__ import annotations

import numpy as np

from .loader import SampleTransform


def insertion_transform(insertion_cfg, label: int = 0, p: float = 0.5) -> SampleTransform:
    """With probability ``p`` insert objects with ``aias_augment.pipeline.image.insert_into_image``; inserted objects get
    class ``label``; existing boxes that end up hidden are dropped by the pipeline's visibility rule."""
    if not 0 <= p <= 1:
        raise ValueError(f"p must lie in [0, 1], got {p}")
    from aias_augment.pipeline.image import insert_into_image

    def apply(image, boxes_xyxy, labels, rng: np.random.Generator):
        if rng.random() >= p:
            return image, boxes_xyxy, labels
        boxes = np.asarray(boxes_xyxy, np.float64).reshape(-1, 4)
        res = insert_into_image(
            image, np.c_[boxes[:, :2], boxes[:, 2:] - boxes[:, :2]], list(range(len(boxes))), rng, insertion_cfg
        )
        ins = np.asarray(res.inserted_bboxes, np.float64).reshape(-1, 4)
        keep = np.asarray(res.keep_existing, bool)
        out_boxes = np.concatenate([boxes[keep], np.c_[ins[:, :2], ins[:, :2] + ins[:, 2:]]])
        out_labels = np.concatenate([np.asarray(labels)[keep], np.full(len(ins), label)]).astype(np.int64)
        return res.image, out_boxes, out_labels

    return apply


def albumentations_transform(compose) -> SampleTransform:
    """Wrap an ``A.Compose`` built with ``bbox_params=A.BboxParams(format="pascal_voc", label_fields=["labels"])``.
    Its seed is drawn from the sample's generator, so runs stay reproducible."""

    def apply(image, boxes_xyxy, labels, rng: np.random.Generator):
        compose.set_random_seed(int(rng.integers(2**31 - 1)))
        out = compose(
            image=image, bboxes=np.asarray(boxes_xyxy, np.float64).reshape(-1, 4), labels=np.asarray(labels, np.int64)
        )
        return out["image"], np.asarray(out["bboxes"], np.float64).reshape(-1, 4), np.asarray(out["labels"], np.int64)

    return apply
