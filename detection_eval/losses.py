"""YOLOX losses on SimOTA positives: IoU loss (1 - IoU^2), objectness BCE on all anchors, class BCE with IoU-aware
targets on positives; each normalised by the number of positives and weighted by ``LossConfig``."""
from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from .boxes import aligned_iou
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


def detection_loss(decoded: torch.Tensor, anchor_centers: torch.Tensor, anchor_strides: torch.Tensor,
                   targets: Targets, assigner: AssignerConfig, weights: LossConfig) -> dict[str, torch.Tensor]:
    """``decoded`` (B, A, 5 + C): xyxy boxes, objectness logit, class logits."""
    batch, num_anchors = decoded.shape[:2]
    num_classes = decoded.shape[-1] - 5
    boxes, obj_logit, cls_logit = decoded[..., :4], decoded[..., 4], decoded[..., 5:]
    obj_targets = torch.zeros(batch, num_anchors, dtype=decoded.dtype, device=decoded.device)
    fg_boxes, fg_gt_boxes, fg_cls_logits, fg_cls_targets = [], [], [], []
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
        fg_cls_logits.append(cls_logit[b, a.fg_mask])
        fg_cls_targets.append(F.one_hot(gt_labels[gt_idx].long(), num_classes).to(decoded.dtype)
                              * a.matched_iou[a.fg_mask, None])
    num_fg = sum(len(x) for x in fg_boxes)
    norm = float(max(num_fg, 1))
    loss_obj = F.binary_cross_entropy_with_logits(obj_logit, obj_targets, reduction="sum") / norm
    if num_fg:
        iou = aligned_iou(torch.cat(fg_boxes), torch.cat(fg_gt_boxes))
        loss_iou = (1 - iou.pow(2)).sum() / norm
        loss_cls = F.binary_cross_entropy_with_logits(torch.cat(fg_cls_logits), torch.cat(fg_cls_targets),
                                                      reduction="sum") / norm
    else:  # keep the graph connected so backward works on images without objects
        loss_iou = boxes.sum() * 0.0
        loss_cls = cls_logit.sum() * 0.0
    total = weights.iou_weight * loss_iou + weights.obj_weight * loss_obj + weights.cls_weight * loss_cls
    return {"loss": total, "iou": loss_iou.detach(), "obj": loss_obj.detach(), "cls": loss_cls.detach(),
            "num_fg": torch.tensor(float(num_fg))}
