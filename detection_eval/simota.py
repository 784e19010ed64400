"""SimOTA label assignment (YOLOX, Ge et al. 2021, sec. 2.2), as a pure function of one image's predictions.

Steps: (1) candidate anchors lie inside a gt box or within ``center_radius`` strides of its centre; (2) the cost of
pairing gt i with anchor j is ``cls_w * BCE(cls_prob, onehot) + iou_w * -log(IoU) + outside_cost * [not in box and
centre region]``; (3) each gt gets ``k = max(1, floor(sum of its top-``candidate_topk`` IoUs))`` anchors of lowest cost
(raised to ``min_k``, at most the gt's anchors inside both box and centre region, when ``min_k > 1``);
(4) an anchor claimed by several gts keeps the one of lowest cost. No gradients flow through the assignment.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from .boxes import box_iou
from .config import AssignerConfig

LOG_EPS = 1e-8  # inside -log(IoU) so IoU 0 gives a large finite cost


@dataclass(frozen=True)
class Assignment:
    fg_mask: torch.Tensor  # (A,) bool: anchor is a positive
    matched_gt: torch.Tensor  # (A,) long: index of the gt for positives, -1 elsewhere
    matched_iou: torch.Tensor  # (A,) float: IoU of the prediction with its gt for positives, 0 elsewhere

    @property
    def num_fg(self) -> int:
        return int(self.fg_mask.sum())


def candidate_masks(
    gt_boxes_xyxy: torch.Tensor, anchor_centers: torch.Tensor, anchor_strides: torch.Tensor, center_radius: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Returns ``(in_box (G, A), in_center (G, A))``: anchor centre strictly inside the gt box; inside the square of
    half-side ``center_radius * stride`` around the gt centre."""
    x, y = anchor_centers[None, :, 0], anchor_centers[None, :, 1]
    g = gt_boxes_xyxy[:, None, :]
    in_box = (x > g[..., 0]) & (x < g[..., 2]) & (y > g[..., 1]) & (y < g[..., 3])
    cx, cy = (g[..., 0] + g[..., 2]) / 2, (g[..., 1] + g[..., 3]) / 2
    r = center_radius * anchor_strides[None, :]
    in_center = (x > cx - r) & (x < cx + r) & (y > cy - r) & (y < cy + r)
    return in_box, in_center


def dynamic_k(ious: torch.Tensor, candidate_topk: int) -> torch.Tensor:
    """(G, A') IoUs of candidates -> (G,) long: ``max(1, floor(sum of the top-k IoUs))``."""
    k = min(candidate_topk, ious.shape[1])
    if k == 0:
        return torch.ones(ious.shape[0], dtype=torch.long, device=ious.device)
    return torch.topk(ious, k, dim=1).values.sum(1).floor().long().clamp(min=1)


@torch.no_grad()
def simota_assign(
    gt_boxes_xyxy: torch.Tensor,
    gt_classes: torch.Tensor,
    pred_boxes_xyxy: torch.Tensor,
    pred_cls_prob: torch.Tensor,
    anchor_centers: torch.Tensor,
    anchor_strides: torch.Tensor,
    cfg: AssignerConfig = AssignerConfig(),
) -> Assignment:
    """Assign anchors of one image to its gts.

    Shapes: gt_boxes_xyxy (G, 4), gt_classes (G,) long, pred_boxes_xyxy (A, 4), pred_cls_prob (A, C) joint
    probability (sqrt(obj * cls) in YOLOX), anchor_centers (A, 2), anchor_strides (A,). ``G == 0`` gives no positives.
    """
    num_anchors = pred_boxes_xyxy.shape[0]
    device = pred_boxes_xyxy.device
    fg_mask = torch.zeros(num_anchors, dtype=torch.bool, device=device)
    matched_gt = torch.full((num_anchors,), -1, dtype=torch.long, device=device)
    matched_iou = torch.zeros(num_anchors, dtype=pred_boxes_xyxy.dtype, device=device)
    num_gt = gt_boxes_xyxy.shape[0]
    if num_gt == 0:
        return Assignment(fg_mask, matched_gt, matched_iou)
    if gt_classes.shape != (num_gt,):
        raise ValueError(f"gt_classes must have shape ({num_gt},), got {tuple(gt_classes.shape)}")

    in_box, in_center = candidate_masks(gt_boxes_xyxy, anchor_centers, anchor_strides, cfg.center_radius)
    candidate = (in_box | in_center).any(0)  # (A,)
    cand_idx = candidate.nonzero(as_tuple=True)[0]
    if cand_idx.numel() == 0:
        return Assignment(fg_mask, matched_gt, matched_iou)
    in_both = (in_box & in_center)[:, cand_idx]  # (G, A')

    ious = box_iou(gt_boxes_xyxy, pred_boxes_xyxy[cand_idx])  # (G, A')
    iou_cost = -torch.log(ious + LOG_EPS)
    probs = pred_cls_prob[cand_idx].float().clamp(1e-6, 1 - 1e-6)  # (A', C)
    onehot = F.one_hot(gt_classes.long(), probs.shape[1]).float()  # (G, C)
    cls_cost = F.binary_cross_entropy(
        probs[None].expand(num_gt, -1, -1), onehot[:, None].expand(-1, probs.shape[0], -1), reduction="none"
    ).sum(-1)  # (G, A')
    cost = cfg.cls_cost_weight * cls_cost + cfg.iou_cost_weight * iou_cost + cfg.outside_cost * (~in_both).float()

    ks = dynamic_k(ious, cfg.candidate_topk)
    if cfg.min_k > 1:
        ks = torch.maximum(ks, in_both.sum(1).clamp(max=cfg.min_k))
    matching = torch.zeros_like(cost, dtype=torch.bool)
    for g in range(num_gt):
        k = min(int(ks[g]), cost.shape[1])
        matching[g, torch.topk(cost[g], k, largest=False).indices] = True
    multi = matching.sum(0) > 1
    if multi.any():
        best = cost[:, multi].argmin(0)
        matching[:, multi] = False
        matching[best, multi.nonzero(as_tuple=True)[0]] = True

    assigned = matching.any(0)  # (A',)
    gt_of = matching.float().argmax(0)  # (A',) valid where assigned
    sel = cand_idx[assigned]
    fg_mask[sel] = True
    matched_gt[sel] = gt_of[assigned]
    matched_iou[sel] = ious[gt_of[assigned], assigned.nonzero(as_tuple=True)[0]].to(matched_iou.dtype)
    return Assignment(fg_mask, matched_gt, matched_iou)
