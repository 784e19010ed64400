"""Box conversions, IoU and letterboxing. Boxes are pixel coordinates; ``xyxy`` = (x0, y0, x1, y1), ``xywh`` = COCO
(x0, y0, w, h), ``cxcywh`` = centre and size. Functions take any batch shape ``(*, 4)``."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch

IOU_EPS = 1e-7  # added to union areas so empty boxes give IoU 0, not NaN

PAD_VALUE = 114  # YOLOX letterbox grey


def xywh_to_xyxy(b):
    return _cat(b[..., :2], b[..., :2] + b[..., 2:4])


def xyxy_to_xywh(b):
    return _cat(b[..., :2], b[..., 2:4] - b[..., :2])


def cxcywh_to_xyxy(b):
    half = b[..., 2:4] / 2
    return _cat(b[..., :2] - half, b[..., :2] + half)


def xyxy_to_cxcywh(b):
    return _cat((b[..., :2] + b[..., 2:4]) / 2, b[..., 2:4] - b[..., :2])


def _cat(a, b):
    return torch.cat([a, b], dim=-1) if isinstance(a, torch.Tensor) else np.concatenate([a, b], axis=-1)


def box_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Pairwise IoU of xyxy boxes: (N, 4), (M, 4) -> (N, M)."""
    lt = torch.maximum(a[:, None, :2], b[None, :, :2])
    rb = torch.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = (rb - lt).clamp(min=0).prod(-1)
    area_a = (a[:, 2:] - a[:, :2]).clamp(min=0).prod(-1)
    area_b = (b[:, 2:] - b[:, :2]).clamp(min=0).prod(-1)
    return inter / (area_a[:, None] + area_b[None, :] - inter + IOU_EPS)


def aligned_iou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """IoU of matching rows of xyxy boxes: (*, 4), (*, 4) -> (*)."""
    lt = torch.maximum(a[..., :2], b[..., :2])
    rb = torch.minimum(a[..., 2:], b[..., 2:])
    inter = (rb - lt).clamp(min=0).prod(-1)
    area_a = (a[..., 2:] - a[..., :2]).clamp(min=0).prod(-1)
    area_b = (b[..., 2:] - b[..., :2]).clamp(min=0).prod(-1)
    return inter / (area_a + area_b - inter + IOU_EPS)


def aligned_giou(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Generalised IoU (Rezatofighi et al. 2019) of matching rows: ``IoU - (hull - union) / hull`` with ``hull`` the
    smallest box enclosing both; in [-1, 1], and < 0 (with a gradient) when the boxes do not overlap. (*, 4) -> (*)."""
    lt = torch.maximum(a[..., :2], b[..., :2])
    rb = torch.minimum(a[..., 2:], b[..., 2:])
    inter = (rb - lt).clamp(min=0).prod(-1)
    area_a = (a[..., 2:] - a[..., :2]).clamp(min=0).prod(-1)
    area_b = (b[..., 2:] - b[..., :2]).clamp(min=0).prod(-1)
    union = area_a + area_b - inter + IOU_EPS
    hull = (torch.maximum(a[..., 2:], b[..., 2:]) - torch.minimum(a[..., :2], b[..., :2])).clamp(min=0).prod(-1)
    return inter / union - (hull - union) / (hull + IOU_EPS)


@dataclass(frozen=True)
class Letterbox:
    """Maps original image pixels to the letterboxed square: ``x_lb = x * scale + pad_x``."""

    scale: float
    pad_x: float
    pad_y: float
    size: int

    def boxes_to_letterbox(self, boxes_xyxy: np.ndarray) -> np.ndarray:
        offset = np.array([self.pad_x, self.pad_y, self.pad_x, self.pad_y], dtype=np.float64)
        return np.asarray(boxes_xyxy, dtype=np.float64) * self.scale + offset

    def boxes_from_letterbox(self, boxes_xyxy):
        """Inverse of ``boxes_to_letterbox`` (numpy or torch)."""
        offset = [self.pad_x, self.pad_y, self.pad_x, self.pad_y]
        if isinstance(boxes_xyxy, torch.Tensor):
            offset = torch.tensor(offset, dtype=boxes_xyxy.dtype, device=boxes_xyxy.device)
        else:
            offset = np.asarray(offset, dtype=np.float64)
        return (boxes_xyxy - offset) / self.scale


def letterbox_params(height: int, width: int, size: int, center: bool = True) -> Letterbox:
    """Scale the longer side to ``size`` keeping aspect; pad the rest (centred or at the bottom/right)."""
    if height <= 0 or width <= 0 or size <= 0:
        raise ValueError(f"letterbox needs positive sizes, got {height}x{width} -> {size}")
    scale = min(size / height, size / width)
    new_w, new_h = round(width * scale), round(height * scale)
    pad_x = (size - new_w) // 2 if center else 0
    pad_y = (size - new_h) // 2 if center else 0
    return Letterbox(scale=scale, pad_x=float(pad_x), pad_y=float(pad_y), size=size)


def letterbox_image(image: np.ndarray, size: int, center: bool = True) -> tuple[np.ndarray, Letterbox]:
    """Resize ``image`` (H, W, 3) uint8 into a ``size`` x ``size`` canvas; returns the canvas and its mapping."""
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) image, got shape {image.shape}")
    h, w = image.shape[:2]
    lb = letterbox_params(h, w, size, center)
    new_w, new_h = round(w * lb.scale), round(h * lb.scale)
    interp = cv2.INTER_AREA if lb.scale < 1 else cv2.INTER_LINEAR
    resized = cv2.resize(image, (new_w, new_h), interpolation=interp)
    canvas = np.full((size, size, 3), PAD_VALUE, dtype=np.uint8)
    x0, y0 = int(lb.pad_x), int(lb.pad_y)
    canvas[y0 : y0 + new_h, x0 : x0 + new_w] = resized
    return canvas, lb
