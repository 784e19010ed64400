"""YOLOX-style detector: backbone -> PAFPN neck -> decoupled anchor-free head.

``Detector.forward(images, targets)`` returns a loss dict in training and decoded predictions in eval. Images are
RGB float in [0, 1], (B, 3, S, S) with S a multiple of 32. Decoded predictions are (B, A, 5 + C): xyxy box in input
pixels, objectness probability, class probabilities.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
import torchvision
from torch import nn

from .backbones import IMAGENET_MEAN, IMAGENET_STD, BaseConv, CSPLayer, build_backbone, conv_cls
from .config import DetectorConfig, InferenceConfig
from .losses import Targets, detection_loss

STRIDES = (8, 16, 32)
LEVELS = ("p3", "p4", "p5")
MAX_LOG_WH = 10.0  # exp() of the size regression is clamped here: e^10 strides is far larger than any image


class PAFPN(nn.Module):
    """YOLOX's path-aggregation FPN over (p3, p4, p5). Backbone channels are first mapped to the neck's
    ``(256, 512, 1024) * width`` by 1x1 convs when they differ (pretrained backbones)."""

    def __init__(self, in_channels: dict[str, int], depth: float, width: float, depthwise: bool = False):
        super().__init__()
        c3, c4, c5 = (int(c * width) for c in (256, 512, 1024))
        n = max(round(3 * depth), 1)
        Conv = conv_cls(depthwise)
        self.adapt = nn.ModuleDict(
            {
                name: (nn.Identity() if in_channels[name] == c else BaseConv(in_channels[name], c, 1, 1))
                for name, c in zip(LEVELS, (c3, c4, c5))
            }
        )
        self.lateral_conv0 = BaseConv(c5, c4, 1, 1)
        self.C3_p4 = CSPLayer(2 * c4, c4, n, False, depthwise=depthwise)
        self.reduce_conv1 = BaseConv(c4, c3, 1, 1)
        self.C3_p3 = CSPLayer(2 * c3, c3, n, False, depthwise=depthwise)
        self.bu_conv2 = Conv(c3, c3, 3, 2)
        self.C3_n3 = CSPLayer(2 * c3, c4, n, False, depthwise=depthwise)
        self.bu_conv1 = Conv(c4, c4, 3, 2)
        self.C3_n4 = CSPLayer(2 * c4, c5, n, False, depthwise=depthwise)
        self.out_channels = (c3, c4, c5)

    def forward(self, feats: dict[str, torch.Tensor]) -> list[torch.Tensor]:
        x3, x4, x5 = (self.adapt[name](feats[name]) for name in LEVELS)
        fpn_out0 = self.lateral_conv0(x5)
        f = self.C3_p4(torch.cat([F.interpolate(fpn_out0, size=x4.shape[-2:], mode="nearest"), x4], 1))
        fpn_out1 = self.reduce_conv1(f)
        pan_out2 = self.C3_p3(torch.cat([F.interpolate(fpn_out1, size=x3.shape[-2:], mode="nearest"), x3], 1))
        pan_out1 = self.C3_n3(torch.cat([self.bu_conv2(pan_out2), fpn_out1], 1))
        pan_out0 = self.C3_n4(torch.cat([self.bu_conv1(pan_out1), fpn_out0], 1))
        return [pan_out2, pan_out1, pan_out0]


class LevelSharedConv(nn.Module):
    """A 3x3 conv whose weights all levels share, with a BatchNorm per level (EfficientDet's shared head: the levels'
    statistics differ, so one BatchNorm cannot serve them all), then SiLU."""

    def __init__(self, channels: int, num_levels: int):
        super().__init__()
        self.conv = nn.Conv2d(channels, channels, 3, 1, 1, bias=False)
        self.bns = nn.ModuleList([nn.BatchNorm2d(channels, eps=1e-3, momentum=0.1) for _ in range(num_levels)])
        self.act = nn.SiLU(inplace=True)

    def forward(self, x: torch.Tensor, level: int) -> torch.Tensor:
        return self.act(self.bns[level](self.conv(x)))


class DecoupledHead(nn.Module):
    """Per level: 1x1 stem, then a classification branch and a regression branch (box + objectness).

    ``shared``: the branches' 3x3 convs and the prediction convs are shared by all levels (BatchNorm per level), as in
    RetinaNet/FCOS; every level's positives then train the same weights, 3x the samples per weight in a short run.
    Sizes are predicted in strides (``exp(raw) * stride``), so one regressor serves every level."""

    def __init__(
        self,
        in_channels: tuple[int, ...],
        num_classes: int,
        width: float,
        depthwise: bool,
        prior_prob: float,
        shared: bool = False,
    ):
        super().__init__()
        hidden = int(256 * width)
        Conv = conv_cls(depthwise)
        levels = len(in_channels)
        self.shared = shared
        if shared and depthwise:
            raise ValueError("a shared head is built from full 3x3 convs: depthwise must be false")
        self.stems = nn.ModuleList([BaseConv(c, hidden, 1, 1) for c in in_channels])
        if shared:
            self.cls_convs = nn.ModuleList([LevelSharedConv(hidden, levels) for _ in range(2)])
            self.reg_convs = nn.ModuleList([LevelSharedConv(hidden, levels) for _ in range(2)])
        else:
            self.cls_convs = nn.ModuleList(
                [nn.Sequential(Conv(hidden, hidden, 3), Conv(hidden, hidden, 3)) for _ in in_channels]
            )
            self.reg_convs = nn.ModuleList(
                [nn.Sequential(Conv(hidden, hidden, 3), Conv(hidden, hidden, 3)) for _ in in_channels]
            )
        n_pred = 1 if shared else levels
        self.cls_preds = nn.ModuleList([nn.Conv2d(hidden, num_classes, 1) for _ in range(n_pred)])
        self.reg_preds = nn.ModuleList([nn.Conv2d(hidden, 4, 1) for _ in range(n_pred)])
        self.obj_preds = nn.ModuleList([nn.Conv2d(hidden, 1, 1) for _ in range(n_pred)])
        bias = -math.log((1 - prior_prob) / prior_prob)
        for conv in list(self.cls_preds) + list(self.obj_preds):
            nn.init.constant_(conv.bias, bias)

    def forward(self, feats: list[torch.Tensor]) -> list[torch.Tensor]:
        """Returns per level raw (B, 4 + 1 + C, H, W): box regression, objectness logit, class logits."""
        outs = []
        for i, x in enumerate(feats):
            x = self.stems[i](x)
            if self.shared:
                c = r = x
                for conv in self.cls_convs:
                    c = conv(c, i)
                for conv in self.reg_convs:
                    r = conv(r, i)
                j = 0
            else:
                c, r, j = self.cls_convs[i](x), self.reg_convs[i](x), i
            outs.append(torch.cat([self.reg_preds[j](r), self.obj_preds[j](r), self.cls_preds[j](c)], 1))
        return outs


def anchor_grid(shapes: list[tuple[int, int]], strides, device, dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """Anchor points (cell corners, YOLOX convention) in grid units and their strides: (A, 2), (A,)."""
    grids, stride_list = [], []
    for (h, w), s in zip(shapes, strides):
        yv, xv = torch.meshgrid(
            torch.arange(h, device=device, dtype=dtype), torch.arange(w, device=device, dtype=dtype), indexing="ij"
        )
        grids.append(torch.stack([xv, yv], -1).reshape(-1, 2))
        stride_list.append(torch.full((h * w,), float(s), device=device, dtype=dtype))
    return torch.cat(grids), torch.cat(stride_list)


def decode_outputs(raw: list[torch.Tensor], strides=STRIDES):
    """Raw head maps -> (B, A, 4 + 1 + C) with xyxy boxes in pixels and *logits* for objectness and classes;
    also returns anchor centres (A, 2) in pixels and strides (A,)."""
    shapes = [tuple(r.shape[-2:]) for r in raw]
    flat = torch.cat([r.flatten(2).transpose(1, 2) for r in raw], 1)  # (B, A, 5 + C)
    grid, stride = anchor_grid(shapes, strides, flat.device, flat.dtype)
    centre = (flat[..., :2] + grid) * stride[:, None]
    wh = torch.exp(flat[..., 2:4].clamp(max=MAX_LOG_WH)) * stride[:, None]
    boxes = torch.cat([centre - wh / 2, centre + wh / 2], -1)
    anchor_centers = (grid + 0.5) * stride[:, None]
    return torch.cat([boxes, flat[..., 4:]], -1), anchor_centers, stride


class Detector(nn.Module):
    def __init__(self, cfg: DetectorConfig):
        super().__init__()
        m = cfg.model
        self.cfg = cfg
        self.backbone = build_backbone(
            m.backbone, m.depth, m.width, m.depthwise, m.pretrained, m.frozen_blocks, m.backbone_bn
        )
        self.neck = PAFPN(self.backbone.out_channels, m.depth, m.width, m.depthwise)
        self.head = DecoupledHead(
            self.neck.out_channels, m.num_classes, m.width, m.depthwise, m.prior_prob, m.shared_head
        )
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1), persistent=False)

    @classmethod
    def from_config(cls, cfg: DetectorConfig) -> "Detector":
        return cls(cfg)

    def raw_outputs(self, images: torch.Tensor) -> list[torch.Tensor]:
        if images.ndim != 4 or images.shape[1] != 3 or images.shape[-1] % 32 or images.shape[-2] % 32:
            raise ValueError(f"images must be (B, 3, H, W) with H, W multiples of 32, got {tuple(images.shape)}")
        return self.head(self.neck(self.backbone((images - self.mean) / self.std)))

    def forward(self, images: torch.Tensor, targets: Targets | None = None):
        decoded, centers, strides = decode_outputs(self.raw_outputs(images))
        if self.training:
            if targets is None:
                raise ValueError("training forward needs targets")
            return detection_loss(decoded, centers, strides, targets, self.cfg.assigner, self.cfg.loss)
        return torch.cat([decoded[..., :4], decoded[..., 4:].sigmoid()], -1)


def postprocess(decoded: torch.Tensor, cfg: InferenceConfig) -> list[dict[str, torch.Tensor]]:
    """(B, A, 5 + C) eval output -> per image ``{"boxes": (N, 4) xyxy, "scores": (N,), "labels": (N,)}`` after
    score threshold (obj * cls) and class-wise NMS, best ``max_detections`` kept."""
    results = []
    for pred in decoded:
        scores_all = pred[:, 4:5] * pred[:, 5:]  # (A, C)
        scores, labels = scores_all.max(1)
        keep = scores > cfg.score_threshold
        boxes, scores, labels = pred[keep, :4], scores[keep], labels[keep]
        keep = torchvision.ops.batched_nms(boxes, scores, labels, cfg.nms_iou)[: cfg.max_detections]
        results.append({"boxes": boxes[keep], "scores": scores[keep], "labels": labels[keep]})
    return results
