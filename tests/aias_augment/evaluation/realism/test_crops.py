"""Crop windows against hand-computed coordinates; colour statistics against hand-made pixels."""

import numpy as np

from aias_augment.evaluation.realism.appearance import box_colour_stats, saturated_orange_mask
from aias_augment.evaluation.realism.crops import CropConfig, context_window, normalise_crop, object_crops


def test_context_window_by_hand():
    # box 40 x 20 at (100, 100): side 40 x 1.5 = 60, centred on (120, 110) -> (90, 80, 150, 140)
    assert context_window((100, 100, 140, 120), (480, 640), 0.25) == (90, 80, 150, 140)
    # near the left/top edge it is shifted inside: centre (5, 5), side 15 -> (0, 0, 15, 15)
    assert context_window((0, 0, 10, 10), (480, 640), 0.25) == (0, 0, 15, 15)
    # larger than the image: cut to the image's smaller side (480), still centred on x = 300 -> 60..540
    assert context_window((0, 0, 600, 400), (480, 640), 0.25) == (60, 0, 540, 480)


def test_normalise_crop_shape_and_skips():
    cfg = CropConfig()
    w = np.full((90, 90, 3), 128, np.uint8)
    out = normalise_crop(w, 60.0, 24.0, cfg)
    assert out.shape == (64, 64, 3) and abs(int(out.mean()) - 128) <= 1
    img = np.zeros((200, 200, 3), np.uint8)
    crops, kept = object_crops(img, np.array([[10, 10, 60, 80], [0, 0, 4, 4]]), np.random.default_rng(0), cfg)
    assert kept == [0] and crops[0].shape == (64, 64, 3)


def test_saturated_orange_and_box_stats():
    px = np.array([[255, 72, 18], [208, 64, 16], [255, 255, 255], [120, 40, 10], [30, 90, 255], [255, 0, 80]], np.uint8)
    # fluorescent orange, darker orange (s 0.92, v 0.82), white, dark orange (v 0.47 < 0.5), blue, pink (hue < 0)
    assert saturated_orange_mask(px).tolist() == [True, True, False, False, False, False]
    img = np.zeros((100, 100, 3), np.uint8)
    img[20:40, 20:40] = (255, 72, 18)
    img[20:30, 20:40] = 255
    s = box_colour_stats(img, np.array([[20, 20, 40, 40]]))[0]
    assert s["saturated_orange_fraction"] == 0.5 and s["clipped_fraction"] == 1.0  # R is 255 everywhere
    assert s["clipped_fraction_ring"] == 0.0
