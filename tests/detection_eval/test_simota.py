"""SimOTA on hand-made cases whose assignment follows from the definition."""

from __future__ import annotations

import torch

from detection_eval.config import AssignerConfig
from detection_eval.simota import candidate_masks, dynamic_k, simota_assign


def _anchors(points, stride=8.0):
    c = torch.tensor(points, dtype=torch.float32)
    return c, torch.full((len(points),), stride)


def test_no_gt_gives_no_positive():
    centers, strides = _anchors([[4, 4], [12, 4]])
    a = simota_assign(
        torch.zeros(0, 4),
        torch.zeros(0, dtype=torch.long),
        torch.rand(2, 4) * 10,
        torch.full((2, 1), 0.5),
        centers,
        strides,
    )
    assert a.num_fg == 0 and (a.matched_gt == -1).all()


def test_candidates_inside_box_or_centre_region():
    gt = torch.tensor([[0.0, 0.0, 16.0, 16.0]])  # centre (8, 8); centre region +-2.5*8 = +-20
    centers, strides = _anchors([[4, 4], [20, 8], [40, 8]])
    in_box, in_center = candidate_masks(gt, centers, strides, 2.5)
    assert in_box.tolist() == [[True, False, False]]
    assert in_center.tolist() == [[True, True, False]]  # 20 - 8 = 12 < 20; 40 - 8 = 32 > 20


def test_dynamic_k_is_floor_of_topk_iou_sum_at_least_one():
    ious = torch.tensor([[0.9, 0.8, 0.7, 0.1], [0.2, 0.1, 0.0, 0.0]])
    assert dynamic_k(ious, 3).tolist() == [2, 1]  # floor(2.4) = 2; floor(0.3) -> clamped to 1
    assert dynamic_k(ious, 10).tolist() == [2, 1]  # k capped at the number of candidates


def test_best_prediction_wins_single_gt():
    gt = torch.tensor([[0.0, 0.0, 32.0, 32.0]])
    centers, strides = _anchors([[12, 12], [20, 20], [100, 100]])
    preds = torch.tensor(
        [
            [0.0, 0.0, 32.0, 32.0],  # perfect box
            [8.0, 8.0, 40.0, 40.0],  # IoU 24^2 / (2 * 32^2 - 24^2) = 0.39
            [0.0, 0.0, 32.0, 32.0],
        ]
    )  # perfect box but far outside: never a candidate
    probs = torch.full((3, 1), 0.5)
    a = simota_assign(gt, torch.tensor([0]), preds, probs, centers, strides)
    # top-k IoU sum = 1.0 + 0.39 -> k = 1: only the lowest-cost (perfect, inside) anchor
    assert a.fg_mask.tolist() == [True, False, False]
    assert a.matched_gt.tolist() == [0, -1, -1]
    assert torch.allclose(a.matched_iou[0], torch.tensor(1.0), atol=1e-5)


def test_min_k_raises_k_within_box_and_centre_only():
    gt = torch.tensor([[0.0, 0.0, 32.0, 32.0]])  # centre (16, 16), centre region +-20 at stride 8
    centers, strides = _anchors([[12, 12], [20, 20], [28, 4], [34, 16]])  # 3 inside both; (34, 16) only in the centre
    preds = torch.tensor([[0.0, 0.0, 4.0, 4.0]] * 4)  # poor boxes: IoU 1/64 each -> YOLOX's k = 1
    probs = torch.full((4, 1), 0.5)
    assert simota_assign(gt, torch.tensor([0]), preds, probs, centers, strides).num_fg == 1
    a = simota_assign(gt, torch.tensor([0]), preds, probs, centers, strides, AssignerConfig(min_k=5))
    assert a.fg_mask.tolist() == [True, True, True, False]  # capped at the 3 anchors inside box and centre


def test_dynamic_k_two_positives_when_ious_high():
    gt = torch.tensor([[0.0, 0.0, 32.0, 32.0]])
    centers, strides = _anchors([[12, 12], [20, 20], [14, 18]])
    preds = torch.tensor([[0.0, 0.0, 32.0, 32.0], [1.0, 1.0, 32.0, 32.0], [0.0, 0.0, 20.0, 20.0]])
    a = simota_assign(gt, torch.tensor([0]), preds, torch.full((3, 1), 0.5), centers, strides)
    # IoUs 1.0, 0.94, 0.39 -> floor(2.33) = 2 anchors: the two best
    assert a.fg_mask.tolist() == [True, True, False]


def test_shared_anchor_goes_to_lower_cost_gt():
    gts = torch.tensor([[0.0, 0.0, 32.0, 32.0], [4.0, 4.0, 36.0, 36.0]])
    centers, strides = _anchors([[16, 16]])
    preds = torch.tensor([[4.0, 4.0, 36.0, 36.0]])  # matches gt 1 exactly; IoU with gt 0 = 0.62
    a = simota_assign(gts, torch.tensor([0, 0]), preds, torch.full((1, 1), 0.5), centers, strides)
    assert a.fg_mask.tolist() == [True]
    assert a.matched_gt.tolist() == [1]


def test_class_cost_prefers_confident_class():
    gts = torch.tensor([[0.0, 0.0, 32.0, 32.0], [0.0, 0.0, 32.0, 32.0]])
    centers, strides = _anchors([[16, 16]])
    preds = torch.tensor([[0.0, 0.0, 32.0, 32.0]])
    probs = torch.tensor([[0.05, 0.95]])  # predicts class 1
    a = simota_assign(gts, torch.tensor([0, 1]), preds, probs, centers, strides)
    assert a.matched_gt.tolist() == [1]


def test_outside_cost_keeps_anchor_in_box_and_centre():
    gt = torch.tensor([[0.0, 0.0, 64.0, 64.0]])  # centre (32, 32), centre region +-20 at stride 8
    centers, strides = _anchors([[60, 60], [30, 30]])  # first: in box only; second: in both
    preds = torch.tensor([[0.0, 0.0, 64.0, 64.0], [8.0, 8.0, 56.0, 56.0]])  # the in-box-only one is better
    a = simota_assign(
        gt, torch.tensor([0]), preds, torch.full((2, 1), 0.5), centers, strides, AssignerConfig(candidate_topk=1)
    )
    assert a.fg_mask.tolist() == [False, True]
