from __future__ import annotations

import numpy as np
import pytest

from detection_eval.config import AugmentConfig
from detection_eval.transforms import augment_sample, hflip, mosaic, place_scaled


def _patch_image():
    image = np.zeros((50, 80, 3), np.uint8)
    image[10:30, 20:40] = 200
    return image, np.array([[20.0, 10.0, 40.0, 30.0]])


def test_place_scaled_moves_pixels_and_boxes_together():
    image, boxes = _patch_image()
    canvas, out = place_scaled(image, boxes, 128, 1.5, (7, -3))
    assert np.allclose(out, [[37.0, 12.0, 67.0, 42.0]])
    x0, y0, x1, y1 = out[0].astype(int)
    assert canvas[y0 + 1 : y1 - 1, x0 + 1 : x1 - 1].min() > 150
    assert canvas[y1 + 2 :, :].max() <= 114 and canvas[y1 + 2 :, :].min() >= 0


def test_hflip_twice_is_identity():
    image, boxes = _patch_image()
    i1, b1 = hflip(image, boxes)
    assert np.allclose(b1, [[40.0, 10.0, 60.0, 30.0]])
    i2, b2 = hflip(i1, b1)
    assert np.array_equal(i2, image) and np.allclose(b2, boxes)


def test_mosaic_keeps_every_box_inside_and_labels_aligned():
    image, boxes = _patch_image()
    rng = np.random.default_rng(0)
    samples = [(image, boxes, np.array([k])) for k in range(4)]
    canvas, b, lab = mosaic(samples, 96, AugmentConfig(), rng)
    assert canvas.shape == (96, 96, 3) and len(b) == len(lab) == 4 and sorted(lab.tolist()) == [0, 1, 2, 3]
    assert (b >= 0).all() and (b <= 96).all()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_augment_is_seeded_and_does_not_mutate(seed):
    image, boxes = _patch_image()
    img0, boxes0 = image.copy(), boxes.copy()
    out1 = augment_sample(image, boxes, np.array([0]), 64, AugmentConfig(), np.random.default_rng(seed))
    out2 = augment_sample(image, boxes, np.array([0]), 64, AugmentConfig(), np.random.default_rng(seed))
    assert np.array_equal(out1[0], out2[0]) and np.array_equal(out1[1], out2[1])
    assert np.array_equal(image, img0) and np.array_equal(boxes, boxes0)
    assert out1[0].shape == (64, 64, 3) and out1[0].dtype == np.uint8
