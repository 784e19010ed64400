"""YOLOX losses on SimOTA positives: IoU loss (1 - IoU^2; or 1 - IoU, 1 - GIoU by ``LossConfig.iou_type``),
objectness BCE on all anchors, class BCE with IoU-aware targets on positives; each normalised by the number of positives
and weighted by ``LossConfig``."""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from .boxes import aligned_giou, aligned_iou
from .config import AssignerConfig, LossConfig
from .simota import simota_assign


@dataclass(frozen=True)
class Targets:
    """Padded per-batch ground truth. ``boxes_xyxy`` (B, G, 4) pixels, ``labels`` (B, G) long, ``num_gt`` (B,) long:
    only the first ``num_gt[b]`` rows of image b are real (padding is carried explicitly, never guessed)."""

    boxes_xyxy: torch.Tensor
    labels: torch.Tensor
    num_gt: torch.Tensor

    def to(self, device) -> "Targets":
        return Targets(self.boxes_xyxy.to(device), self.labels.to(device), self.num_gt.to(device))


def detection_loss(
    decoded: torch.Tensor,
    anchor_centers: torch.Tensor,
    anchor_strides: torch.Tensor,
    targets: Targets,
    assigner: AssignerConfig,
    weights: LossConfig,
) -> dict[str, torch.Tensor]:
    """``decoded`` (B, A, 5 + C): xyxy boxes, objectness logit, class logits."""
    batch, num_anchors = decoded.shape[:2]
    num_classes = decoded.shape[-1] - 5
    boxes, obj_logit, cls_logit = decoded[..., :4], decoded[..., 4], decoded[..., 5:]
    obj_targets = torch.zeros(batch, num_anchors, dtype=decoded.dtype, device=decoded.device)
    fg_boxes, fg_gt_boxes, fg_cls_logits, fg_cls_targets, fg_strides = [], [], [], [], []
    with torch.no_grad():
        joint = (cls_logit.sigmoid() * obj_logit.sigmoid()[..., None]).sqrt()
    for b in range(batch):
        n = int(targets.num_gt[b])
        gt_boxes, gt_labels = targets.boxes_xyxy[b, :n], targets.labels[b, :n]
        a = simota_assign(gt_boxes, gt_labels, boxes[b].detach(), joint[b], anchor_centers, anchor_strides, assigner)
        if a.num_fg == 0:
            continue
        obj_targets[b, a.fg_mask] = 1.0
        gt_idx = a.matched_gt[a.fg_mask]
        fg_boxes.append(boxes[b, a.fg_mask])
        fg_gt_boxes.append(gt_boxes[gt_idx])
        fg_strides.append(anchor_strides[a.fg_mask])
        fg_cls_logits.append(cls_logit[b, a.fg_mask])
        fg_cls_targets.append(
            F.one_hot(gt_labels[gt_idx].long(), num_classes).to(decoded.dtype) * a.matched_iou[a.fg_mask, None]
        )
    num_fg = sum(len(x) for x in fg_boxes)
    norm = float(max(num_fg, 1))
    loss_obj = F.binary_cross_entropy_with_logits(obj_logit, obj_targets, reduction="sum") / norm
    if num_fg:
        pred, gt = torch.cat(fg_boxes), torch.cat(fg_gt_boxes)
        if weights.iou_type == "giou":
            loss_iou = (1 - aligned_giou(pred, gt)).sum() / norm
        else:
            iou = aligned_iou(pred, gt)
            loss_iou = (1 - (iou.pow(2) if weights.iou_type == "iou_squared" else iou)).sum() / norm
        loss_cls = (
            F.binary_cross_entropy_with_logits(torch.cat(fg_cls_logits), torch.cat(fg_cls_targets), reduction="sum")
            / norm
        )
        loss_l1 = l1_box_loss(pred, gt, torch.cat(fg_strides)).sum() / norm if weights.l1_weight else None
    else:  # keep the graph connected so backward works on images without objects
        loss_iou = boxes.sum() * 0.0
        loss_cls = cls_logit.sum() * 0.0
        loss_l1 = boxes.sum() * 0.0 if weights.l1_weight else None
    total = weights.iou_weight * loss_iou + weights.obj_weight * loss_obj + weights.cls_weight * loss_cls
    out = {"iou": loss_iou.detach(), "obj": loss_obj.detach(), "cls": loss_cls.detach()}
    if loss_l1 is not None:
        total = total + weights.l1_weight * loss_l1
        out["l1"] = loss_l1.detach()
    return {"loss": total, **out, "num_fg": torch.tensor(float(num_fg))}


def l1_box_loss(pred_xyxy: torch.Tensor, gt_xyxy: torch.Tensor, strides: torch.Tensor) -> torch.Tensor:
    """YOLOX's L1 in the regression's own units: |d centre| / stride and |d log size| (the head predicts
    ``centre / stride - grid`` and ``log(size / stride)``). (N, 4), (N, 4), (N,) -> (N,). Sizes are clamped at
    ``1e-3`` px before the log (a degenerate gt box)."""

    def parts(b):
        centre = (b[:, :2] + b[:, 2:]) / 2 / strides[:, None]
        return centre, torch.log((b[:, 2:] - b[:, :2]).clamp(min=1e-3))

    pc, pw = parts(pred_xyxy)
    gc, gw = parts(gt_xyxy)
    return (pc - gc).abs().sum(1) + (pw - gw).abs().sum(1)
