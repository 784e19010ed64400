from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from detection_eval.online import albumentations_transform, insertion_transform  # noqa: E402


def test_albumentations_adapter_flips_boxes_and_is_seeded():
    import albumentations as A

    compose = A.Compose(
        [A.HorizontalFlip(p=1.0)], bbox_params=A.BboxParams(format="pascal_voc", label_fields=["labels"])
    )
    t = albumentations_transform(compose)
    image = np.zeros((40, 100, 3), np.uint8)
    image[:, :10] = 255
    out, boxes, labels = t(image, np.array([[10.0, 5.0, 30.0, 25.0]]), np.array([0]), np.random.default_rng(0))
    assert out[:, -10:].min() == 255 and out[:, :10].max() == 0
    assert np.allclose(boxes, [[70.0, 5.0, 90.0, 25.0]]) and labels.tolist() == [0]


def test_insertion_adapter_adds_labelled_boxes():
    pipeline = pytest.importorskip("aias_augment.pipeline.image")
    cfg = pipeline.InsertionConfig(naive_paste=True, min_objects=2, max_objects=2)
    t = insertion_transform(cfg, label=0, p=1.0)
    image = np.full((160, 240, 3), 90, np.uint8)
    out, boxes, labels = t(image, np.zeros((0, 4)), np.zeros(0, np.int64), np.random.default_rng(1))
    assert out.shape == image.shape and len(boxes) == len(labels) >= 1 and set(labels.tolist()) == {0}
    assert (boxes[:, 2] > boxes[:, 0]).all() and (boxes[:, 3] > boxes[:, 1]).all()
    assert not np.array_equal(out, image)  # something was drawn
    with pytest.raises(ValueError):
        insertion_transform(cfg, p=1.5)
