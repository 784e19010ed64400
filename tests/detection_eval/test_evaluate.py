from __future__ import annotations

import math

import numpy as np
import pytest

from detection_eval.evaluate import coco_evaluate, detections_to_coco


def _gt():
    return {
        "images": [{"id": 1, "width": 100, "height": 100}, {"id": 2, "width": 100, "height": 100}],
        "categories": [{"id": 1, "name": "cone"}, {"id": 2, "name": "barrel"}],
        "annotations": [
            {"id": 1, "image_id": 1, "category_id": 1, "bbox": [10, 10, 40, 40], "area": 1600, "iscrowd": 0},
            {"id": 2, "image_id": 2, "category_id": 1, "bbox": [50, 50, 45, 45], "area": 2025, "iscrowd": 0},
        ],
    }


def test_zero_detections_score_zero_not_crash():
    m = coco_evaluate(_gt(), [])
    assert m["AP"] == 0.0 and m["AP50"] == 0.0 and m["num_detections"] == 0
    assert m["per_category_AP"]["cone"] == 0.0
    assert math.isnan(m["per_category_AP"]["barrel"])  # no ground truth: undefined, not 0
    assert math.isnan(m["AP_small"])  # both gt boxes are medium (32^2 <= area < 96^2)


def test_perfect_detections_score_one():
    dets = [
        {"boxes": np.array([[10.0, 10.0, 50.0, 50.0]]), "scores": np.array([0.9]), "labels": np.array([0])},
        {"boxes": np.array([[50.0, 50.0, 95.0, 95.0]]), "scores": np.array([0.8]), "labels": np.array([0])},
    ]
    m = coco_evaluate(_gt(), detections_to_coco([1, 2], dets, (1, 2)))
    assert m["AP"] == pytest.approx(1.0) and m["AP_medium"] == pytest.approx(1.0)


def test_half_found_with_iou_between_thresholds():
    # one exact box, one box of IoU 0.5625 with its gt (found at 0.50 and 0.55, missed from 0.60 up)
    dets = [
        {"boxes": np.array([[10.0, 10.0, 50.0, 50.0]]), "scores": np.array([0.9]), "labels": np.array([0])},
        {
            "boxes": np.array([[50.0, 50.0, 95.0, 95.0 * 0.5625 + 50 * 0.4375]]),
            "scores": np.array([0.8]),
            "labels": np.array([0]),
        },
    ]
    m = coco_evaluate(_gt(), detections_to_coco([1, 2], dets, (1, 2)))
    assert m["AP50"] == pytest.approx(1.0)
    # thresholds 0.50 and 0.55: AP 1; 0.60..0.95 (8 thresholds): one of two found at top score -> AP ~ 0.5
    assert m["AP"] == pytest.approx((2 * 1.0 + 8 * 0.5) / 10, abs=0.01)


def test_no_ground_truth_is_an_error():
    gt = _gt()
    gt["annotations"] = []
    with pytest.raises(ValueError):
        coco_evaluate(gt, [])
