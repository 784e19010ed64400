"""Copy-paste of the user's own real instances (Simple Copy-Paste, Ghiasi et al. CVPR 2021): the baseline a detection
team would pick instead of 3D insertion. Masks come from the boxes (GrabCut, :func:`aias_augment.assets.bank.lift.cut_out`:
box-only data has no segments); each instance is pasted at a random position and size, flipped at random, with its
soft alpha, and its new box is the pasted mask's box."""

from __future__ import annotations

import numpy as np

from aias_augment.assets.bank.lift import Cutout


def _resize_cutout(cut: Cutout, height_px: int) -> tuple[np.ndarray, np.ndarray]:
    """(rgb, alpha) of the cutout's mask box resized to ``height_px`` rows (aspect kept)."""
    import cv2

    x0, y0, x1, y1 = cut.mask_box
    rgb, alpha = cut.rgb[y0:y1, x0:x1], cut.alpha[y0:y1, x0:x1]
    h = max(2, int(height_px))
    w = max(2, int(round((x1 - x0) * h / (y1 - y0))))
    interp = cv2.INTER_AREA if h < (y1 - y0) else cv2.INTER_LINEAR
    return cv2.resize(rgb, (w, h), interpolation=interp), cv2.resize(alpha, (w, h), interpolation=interp)


def paste_instances(
    background: np.ndarray,
    cutouts: list[Cutout],
    rng: np.random.Generator,
    height_fracs,
    n_objects: int,
    max_tries: int = 20,
    max_overlap: float = 0.3,
):
    """Paste ``n_objects`` cutouts drawn from ``cutouts`` into ``background`` (H, W, 3 uint8); heights (as a fraction
    of the image height) drawn from ``height_fracs``, positions uniform with the object wholly inside the image and
    overlapping earlier pastes by at most ``max_overlap`` of its box. Returns (image, boxes_xyxy (N, 4))."""
    if not cutouts:
        raise ValueError("no cutouts to paste")
    fracs = np.asarray([f for f in height_fracs if 0 < f <= 1], np.float64)
    if not len(fracs):
        raise ValueError("height_fracs holds no fraction in (0, 1]")
    img = background.astype(np.float32)
    H, W = background.shape[:2]
    boxes: list[np.ndarray] = []
    for _ in range(n_objects):
        cut = cutouts[int(rng.integers(len(cutouts)))]
        h_px = int(round(float(fracs[int(rng.integers(len(fracs)))]) * H))
        flip = bool(rng.random() < 0.5)
        rgb, alpha = _resize_cutout(cut, min(max(h_px, 8), H - 2))
        if flip:
            rgb, alpha = rgb[:, ::-1], alpha[:, ::-1]
        h, w = alpha.shape
        if w >= W - 2:
            continue
        for _try in range(max_tries):
            x0, y0 = int(rng.integers(0, W - w + 1)), int(rng.integers(0, H - h + 1))
            box = np.array([x0, y0, x0 + w, y0 + h], np.float64)
            if all(_inter(box, b) / (w * h) <= max_overlap for b in boxes):
                break
        else:
            continue
        a = alpha[..., None]
        img[y0 : y0 + h, x0 : x0 + w] = a * rgb + (1 - a) * img[y0 : y0 + h, x0 : x0 + w]
        ys, xs = np.nonzero(alpha >= 0.5)
        if len(xs):
            boxes.append(np.array([x0 + xs.min(), y0 + ys.min(), x0 + xs.max() + 1, y0 + ys.max() + 1], np.float64))
    out = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return out, (np.array(boxes) if boxes else np.zeros((0, 4)))


def _inter(a, b) -> float:
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
