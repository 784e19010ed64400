"""TraCon train photos that hold labelled cones, in a seeded order, and the colour of white cone sleeves in them: the
photo's own (from the labels) and an inserted object's (from its render), as linear RGB and as (R/G, B/G) chroma.
Shared by the lighting studies that compare inserted whites with real ones."""

from __future__ import annotations

import cv2
import numpy as np

from aias_augment.apply.render import render_object, srgb_to_linear
from aias_augment.core.config import data_root


def real_white_rgb(img: np.ndarray, boxes_xyxy: np.ndarray) -> np.ndarray | None:
    """Median linear RGB of the labelled cones' white sleeves: HSV S < 0.25, V in [0.55, 0.97], in the middle half of
    each box's width and its upper 85 % (the base excluded)."""
    hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV).astype(np.float32)
    s, v = hsv[..., 1] / 255.0, hsv[..., 2] / 255.0
    px = []
    for x0, y0, x1, y1 in boxes_xyxy.astype(int):
        w, h = x1 - x0, y1 - y0
        if w < 6 or h < 12:
            continue
        sl = (slice(max(y0, 0), max(y0 + int(0.85 * h), 0)), slice(max(x0 + w // 4, 0), max(x1 - w // 4, 0)))
        m = (s[sl] < 0.25) & (v[sl] > 0.55) & (v[sl] < 0.97)
        px.append(img[sl][m])
    px = np.concatenate(px) if px else np.zeros((0, 3), np.uint8)
    if len(px) < 20:
        return None
    return np.median(srgb_to_linear(px.astype(np.float32) / 255.0), axis=0)


def inserted_white_rgb(out: np.ndarray, plan, analysis) -> np.ndarray | None:
    wh = np.zeros(out.shape[:2], bool)
    for obj in plan.objects:
        L = render_object(obj.asset, obj.placement.cam_from_object_matrix, analysis.intrinsics, ssaa=1)
        a = L.albedo_linear
        w = (L.alpha > 0.99) & (a.min(-1) > 0.5) & ((a.max(-1) - a.min(-1)) / np.maximum(a.max(-1), 1e-6) < 0.15)
        wh |= cv2.erode(w.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    wh &= out.max(-1) < 250
    if wh.sum() < 10:
        return None
    return srgb_to_linear(out[wh].astype(np.float32) / 255.0).mean(0)


def labelled_cone_photos(seed: int):
    """TraCon train photos with labelled cones in a seeded order: (stem, RGB image at <= 640 px, cone boxes xyxy)."""
    root = data_root() / "tracon"
    stems = sorted(p.stem for p in (root / "labels/train").glob("*.txt") if p.stat().st_size > 0)
    for i in np.random.default_rng(seed).permutation(len(stems)):
        stem = stems[i]
        path = next((root / "images/train").glob(stem + ".*"), None)
        if path is None:
            continue
        img = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        s = min(1.0, 640 / max(img.shape[:2]))
        if s < 1:
            img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        H, W = img.shape[:2]
        lab = np.loadtxt(root / "labels/train" / f"{stem}.txt", ndmin=2)
        cx, cy, bw, bh = lab[:, 1] * W, lab[:, 2] * H, lab[:, 3] * W, lab[:, 4] * H
        yield stem, img, np.c_[cx - bw / 2, cy - bh / 2, cx + bw / 2, cy + bh / 2]


def chroma(rgb: np.ndarray) -> np.ndarray:
    return np.array([rgb[0] / max(rgb[1], 1e-6), rgb[2] / max(rgb[1], 1e-6)])
