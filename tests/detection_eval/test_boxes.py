from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from detection_eval.boxes import (
    box_iou,
    cxcywh_to_xyxy,
    letterbox_image,
    letterbox_params,
    xywh_to_xyxy,
    xyxy_to_cxcywh,
    xyxy_to_xywh,
)


def test_conversions_round_trip():
    b = np.array([[10.0, 20.0, 30.0, 60.0]])
    assert np.allclose(xywh_to_xyxy(xyxy_to_xywh(b)), b)
    assert np.allclose(cxcywh_to_xyxy(xyxy_to_cxcywh(b)), b)
    assert np.allclose(xyxy_to_xywh(b), [[10, 20, 20, 40]])


def test_giou_known_values():
    from detection_eval.boxes import aligned_giou

    a = torch.tensor([[0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 10.0], [0.0, 0.0, 10.0, 10.0]])
    b = torch.tensor([[0.0, 0.0, 10.0, 10.0], [5.0, 0.0, 15.0, 10.0], [20.0, 0.0, 30.0, 10.0]])
    # identical: 1; half overlap: IoU 50/150, hull 150 = union -> 1/3; disjoint: 0 - (300 - 200) / 300 = -1/3
    assert torch.allclose(aligned_giou(a, b), torch.tensor([1.0, 1 / 3, -1 / 3]), atol=1e-5)


def test_iou_known_values():
    a = torch.tensor([[0.0, 0.0, 2.0, 2.0]])
    b = torch.tensor([[1.0, 1.0, 3.0, 3.0], [5.0, 5.0, 6.0, 6.0], [0.0, 0.0, 2.0, 2.0], [1.0, 1.0, 1.0, 1.0]])
    assert torch.allclose(box_iou(a, b), torch.tensor([[1 / 7, 0.0, 1.0, 0.0]]), atol=1e-6)


@settings(max_examples=40, deadline=None)
@given(h=st.integers(8, 900), w=st.integers(8, 900), size=st.sampled_from([64, 320, 640]), center=st.booleans())
def test_letterbox_box_round_trip(h, w, size, center):
    lb = letterbox_params(h, w, size, center)
    boxes = np.array([[0.0, 0.0, w, h], [w * 0.25, h * 0.5, w * 0.75, h * 0.9]])
    mapped = lb.boxes_to_letterbox(boxes)
    assert np.allclose(lb.boxes_from_letterbox(mapped), boxes)
    # the whole image maps inside the canvas and touches it on the longer side
    assert mapped[0].min() >= -1e-9 and mapped[0].max() <= size + 1e-9
    assert max(mapped[0, 2] - mapped[0, 0], mapped[0, 3] - mapped[0, 1]) == pytest.approx(size)


def test_letterbox_image_places_content_where_boxes_say():
    image = np.zeros((100, 200, 3), np.uint8)
    image[40:60, 100:140] = 255  # a white patch, xyxy (100, 40, 140, 60)
    canvas, lb = letterbox_image(image, 64)
    assert canvas.shape == (64, 64, 3)
    x0, y0, x1, y1 = lb.boxes_to_letterbox(np.array([[100.0, 40.0, 140.0, 60.0]]))[0]
    inner = canvas[int(np.ceil(y0)) + 1 : int(y1) - 1, int(np.ceil(x0)) + 1 : int(x1) - 1]
    assert inner.min() > 200
    assert (canvas[: int(lb.pad_y) - 1] == 114).all()  # padding above the content


def test_letterbox_rejects_bad_input():
    with pytest.raises(ValueError):
        letterbox_image(np.zeros((10, 10), np.uint8), 64)
    with pytest.raises(ValueError):
        letterbox_params(0, 10, 64)
