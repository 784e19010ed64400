"""Loss terms on hand-made positives: the IoU-loss variants and YOLOX's L1 in regression units."""

from __future__ import annotations

import math

import pytest
import torch

from detection_eval.config import AssignerConfig, LossConfig
from detection_eval.losses import Targets, detection_loss, l1_box_loss


def test_l1_box_loss_in_strides_and_log_size():
    gt = torch.tensor([[0.0, 0.0, 16.0, 32.0]])
    assert l1_box_loss(gt, gt, torch.tensor([8.0])).item() == pytest.approx(0.0)
    shifted = torch.tensor([[8.0, 0.0, 24.0, 64.0]])  # centre +8 px in x, +16 px in y; height x2
    expected = 8 / 8 + 16 / 8 + 0.0 + math.log(2.0)
    assert l1_box_loss(shifted, gt, torch.tensor([8.0])).item() == pytest.approx(expected, rel=1e-5)


def _one_positive_case():
    """One gt and one candidate anchor whose predicted box is half the gt: a known IoU of 0.5."""
    centers = torch.tensor([[12.0, 12.0], [100.0, 100.0]])
    strides = torch.tensor([8.0, 8.0])
    decoded = torch.zeros(1, 2, 6)
    decoded[0, 0, :4] = torch.tensor([0.0, 0.0, 24.0, 12.0])
    decoded[0, 1, :4] = torch.tensor([90.0, 90.0, 110.0, 110.0])
    targets = Targets(torch.tensor([[[0.0, 0.0, 24.0, 24.0]]]), torch.zeros(1, 1, dtype=torch.long), torch.tensor([1]))
    return decoded, centers, strides, targets


@pytest.mark.parametrize("iou_type, expected", [("iou_squared", 0.75), ("iou", 0.5), ("giou", 0.5)])
def test_iou_loss_types(iou_type, expected):
    decoded, centers, strides, targets = _one_positive_case()
    out = detection_loss(decoded, centers, strides, targets, AssignerConfig(), LossConfig(iou_type=iou_type))
    assert out["num_fg"].item() == 1
    assert out["iou"].item() == pytest.approx(expected, abs=1e-5)  # hull = union here, so GIoU = IoU
    assert "l1" not in out


def test_l1_term_only_when_weighted():
    decoded, centers, strides, targets = _one_positive_case()
    base = detection_loss(decoded, centers, strides, targets, AssignerConfig(), LossConfig())
    with_l1 = detection_loss(decoded, centers, strides, targets, AssignerConfig(), LossConfig(l1_weight=1.0))
    # pred centre (12, 6) vs gt (12, 12): 6 / 8; height 12 vs 24: log 2
    assert with_l1["l1"].item() == pytest.approx(6 / 8 + math.log(2.0), rel=1e-5)
    assert with_l1["loss"].item() == pytest.approx(base["loss"].item() + with_l1["l1"].item(), rel=1e-5)
    with pytest.raises(ValueError):
        LossConfig(iou_type="diou")
