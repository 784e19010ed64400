"""``InsertionConfig.box_convention``: inserted boxes sit around their objects as the user's labels do.

The truth is the object's own mask (its COCO RLE decoded by pycocotools): a box following margins (left, top,
right, bottom) has, around that mask, exactly those margins as fractions of its own width and height; the pixels
are those of the mask-tight run."""

from dataclasses import replace

import numpy as np
import pytest
from pycocotools import mask as mask_utils

from aias_augment.core.config import ConfigValueError
from aias_augment.pipeline.image import InsertionConfig, insert_into_image
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.pipeline.test_image import K, OneAsset, road_frame

TIGHT = InsertionConfig(categories=("box",), harmonize=False, ssaa=1, min_objects=2, max_objects=2)
MARGINS = (0.06, 0.1, 0.04, 0.02)
BANK = OneAsset(box_asset())


def _insert(cfg, seed):
    return insert_into_image(road_frame(), rng=np.random.default_rng(seed), cfg=cfg, intrinsics=K, bank=BANK)


@pytest.mark.parametrize("seed", [0, 1])
def test_inserted_boxes_carry_the_conventions_margins_around_their_masks(seed):
    tight, loose = _insert(TIGHT, seed), _insert(replace(TIGHT, box_convention=MARGINS), seed)
    assert np.array_equal(tight.image, loose.image)  # only the boxes change
    anns = [a for a in loose.record.annotations if a.visible_box_xywh is not None]
    assert len(anns) >= 1 and len(loose.inserted_bboxes) == len(anns)
    h, w = loose.image.shape[:2]
    for ann, box, tight_box in zip(anns, loose.inserted_bboxes, tight.inserted_bboxes):
        mx, my, mw, mh = mask_utils.toBbox({"size": ann.rle["size"], "counts": ann.rle["counts"].encode()})
        assert np.allclose(tight_box, [mx, my, mw, mh])  # without a convention: the mask's own box
        X, Y, W, H = box
        got = [(mx - X) / W, (my - Y) / H, (X + W - mx - mw) / W, (Y + H - my - mh) / H]
        clipped = [X <= 0, Y <= 0, X + W >= w, Y + H >= h]
        for side in range(4):
            if clipped[side]:
                assert got[side] <= MARGINS[side] + 1e-9  # the frame cut the margin short
            else:
                assert got[side] == pytest.approx(MARGINS[side], abs=1e-9)
    assert "labelling convention" in loose.record.modules["boxes"]
    assert "boxes" not in tight.record.modules


@pytest.mark.parametrize("bad", [(0.5, 0, 0, 0), (-0.01, 0, 0, 0), (0.1, 0.1, 0.1)])
def test_a_convention_out_of_bounds_is_refused_at_construction(bad):
    with pytest.raises((ConfigValueError, TypeError)):
        InsertionConfig(box_convention=bad)
