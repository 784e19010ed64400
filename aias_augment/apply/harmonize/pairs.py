"""Training and evaluation pairs from real images (the iHarmony4 protocol).

A real object region (a box-labelled object segmented with GrabCut, or a random region of an unlabelled photo) is
perturbed in colour, exposure, noise and blur; the perturbed image is the *composite*, the untouched photo is the
*target*. A harmonizer that restores the target has learnt to undo appearance mismatch.

Choosing is split from doing: ``sample_perturbation(ranges, rng)`` returns a frozen ``Perturbation``;
``apply_perturbation`` is deterministic given it (its noise draws from the ``rng`` passed in).
"""

from __future__ import annotations

import json
import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.apply.harmonize.color import linear_to_srgb, luminance, srgb_to_linear, to_float, to_uint8
from aias_augment.apply.harmonize.regions import Box, context_box, resize
from aias_augment.core.image_io import read_image

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


@dataclass(frozen=True)
class PerturbRanges:
    """Ranges the appearance perturbation is drawn from (config ``perturb:``)."""

    exposure_stops_range: tuple[float, float] = (-1.0, 1.0)
    wb_log_sigma: float = 0.2  # per-channel gain = exp(N(0, sigma)), renormalised to unit geometric mean
    saturation_range: tuple[float, float] = (0.6, 1.5)
    gamma_range: tuple[float, float] = (0.8, 1.25)
    blur_probability: float = 0.3
    blur_sigma_px_range: tuple[float, float] = (0.5, 2.0)  # at the pair's resolution
    noise_probability: float = 0.3
    noise_sigma_range: tuple[float, float] = (0.005, 0.03)  # std at mid-grey, [0, 1] units


@dataclass(frozen=True)
class Perturbation:
    exposure_stops: float
    wb_gains: tuple[float, float, float]
    saturation: float
    gamma: float
    blur_sigma_px: float  # 0 = none
    noise_sigma: float  # 0 = none


def sample_perturbation(ranges: PerturbRanges, rng: np.random.Generator) -> Perturbation:
    gains = np.exp(rng.normal(0.0, ranges.wb_log_sigma, 3))
    gains /= np.exp(np.mean(np.log(gains)))
    blur = rng.uniform(*ranges.blur_sigma_px_range) if rng.random() < ranges.blur_probability else 0.0
    noise = rng.uniform(*ranges.noise_sigma_range) if rng.random() < ranges.noise_probability else 0.0
    return Perturbation(
        exposure_stops=float(rng.uniform(*ranges.exposure_stops_range)),
        wb_gains=tuple(float(g) for g in gains),
        saturation=float(rng.uniform(*ranges.saturation_range)),
        gamma=float(rng.uniform(*ranges.gamma_range)),
        blur_sigma_px=float(blur),
        noise_sigma=float(noise),
    )


def apply_perturbation(
    image_uint8: np.ndarray, mask: np.ndarray, p: Perturbation, rng: np.random.Generator
) -> np.ndarray:
    """Perturb the pixels under ``mask`` (float (H, W) in [0, 1]); returns a new uint8 image.

    Exposure and white balance act on linear light, saturation around linear luminance, gamma on the encoded values
    (a tone-curve mismatch), then blur and signal-dependent noise (variance grows linearly with the signal).
    """
    srgb = to_float(image_uint8)
    lin = srgb_to_linear(srgb) * (2.0**p.exposure_stops) * np.asarray(p.wb_gains, np.float32)
    y = luminance(lin)[..., None]
    lin = np.clip(y + p.saturation * (lin - y), 0.0, None)
    out = linear_to_srgb(lin) ** p.gamma
    if p.blur_sigma_px > 0:
        out = cv2.GaussianBlur(out, (0, 0), p.blur_sigma_px)
    if p.noise_sigma > 0:
        # sigma(x) = noise_sigma at x = 0.5, sqrt-proportional to the signal (shot noise) plus a read-noise floor.
        std = p.noise_sigma * np.sqrt((out + 0.05) / 0.55)
        out = out + std * rng.standard_normal(out.shape).astype(np.float32)
    m = mask[..., None].astype(np.float32)
    return to_uint8(m * np.clip(out, 0, 1) + (1 - m) * srgb)


# ---------------------------------------------------------------------------------------------------- labelled images
def read_image_rgb(path: str | Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB, upright, by the package's reader."""
    return read_image(path)


def read_yolo_boxes(label_path: str | Path, width: int, height: int) -> list[Box]:
    """YOLO txt (class cx cy w h, normalised) -> pixel boxes; a missing or empty file means no object."""
    p = Path(label_path)
    if not p.exists():
        return []
    boxes = []
    for line_no, line in enumerate(p.read_text().splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) < 5:
            raise ValueError(f"{p}:{line_no}: expected 'class cx cy w h', got {line!r}")
        cx, cy, bw, bh = (float(v) for v in parts[1:5])
        x0, y0 = (cx - bw / 2) * width, (cy - bh / 2) * height
        x1, y1 = (cx + bw / 2) * width, (cy + bh / 2) * height
        boxes.append(_clip_box((x0, y0, x1, y1), width, height))
    return [b for b in boxes if b is not None]


def read_coco_boxes(coco_json: str | Path) -> dict[str, list[Box]]:
    """COCO json -> {file_name: [pixel boxes]} (bbox is x, y, w, h); images without annotations map to []."""
    data = json.loads(Path(coco_json).read_text())
    images = {im["id"]: im for im in data["images"]}
    out: dict[str, list[Box]] = {im["file_name"]: [] for im in data["images"]}
    for ann in data.get("annotations", []):
        im = images[ann["image_id"]]
        x, y, w, h = ann["bbox"]
        b = _clip_box((x, y, x + w, y + h), im["width"], im["height"])
        if b is not None:
            out[im["file_name"]].append(b)
    return out


def _clip_box(box, width: int, height: int) -> Box | None:
    x0, y0, x1, y1 = box
    x0, y0 = int(np.clip(round(x0), 0, width)), int(np.clip(round(y0), 0, height))
    x1, y1 = int(np.clip(round(x1), 0, width)), int(np.clip(round(y1), 0, height))
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None


def labelled_images(images_dir: str | Path, labels: str | Path) -> list[tuple[Path, list[Box] | None]]:
    """[(image path, boxes)] for a folder of images with a YOLO label folder or a COCO json.

    Boxes are None when the image size must be read first (YOLO); ``load_boxes`` resolves them.
    """
    images_dir, labels = Path(images_dir), Path(labels)
    paths = sorted(p for p in images_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not paths:
        raise ValueError(f"no images in {images_dir}")
    if labels.is_file() and labels.suffix == ".json":
        coco = read_coco_boxes(labels)
        return [(p, coco[p.name]) for p in paths if p.name in coco]
    if not labels.is_dir():
        raise ValueError(f"labels must be a YOLO label folder or a COCO .json, got {labels}")
    return [(p, None) for p in paths]


def load_boxes(image_path: Path, boxes: list[Box] | None, labels: Path, image_hw: tuple[int, int]) -> list[Box]:
    if boxes is not None:
        return boxes
    return read_yolo_boxes(Path(labels) / (image_path.stem + ".txt"), image_hw[1], image_hw[0])


# ------------------------------------------------------------------------------------------------------ object masks
def grabcut_mask(image_rgb: np.ndarray, box: Box, iterations: int = 3, work_px: int = 256) -> np.ndarray | None:
    """Object mask from its box with GrabCut, run on a context crop shrunk to ``work_px``; None if implausible.

    Implausible = the segment covers < 15% or > 95% of the box (GrabCut failed or the box is the object).
    Returns a full-image bool mask (largest connected component, holes filled).
    """
    h, w = image_rgb.shape[:2]
    x0, y0, x1, y1 = box
    if min(x1 - x0, y1 - y0) < 4:
        return None
    cx0, cy0, cx1, cy1 = context_box(box, (h, w), 1.6)
    crop = image_rgb[cy0:cy1, cx0:cx1]
    scale = min(1.0, work_px / max(crop.shape[:2]))
    small = cv2.resize(crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale < 1 else crop
    sh, sw = small.shape[:2]
    rx0, ry0 = int((x0 - cx0) * scale), int((y0 - cy0) * scale)
    rx1, ry1 = min(sw, int(np.ceil((x1 - cx0) * scale))), min(sh, int(np.ceil((y1 - cy0) * scale)))
    rect = (rx0, ry0, max(rx1 - rx0, 2), max(ry1 - ry0, 2))
    gc = np.zeros((sh, sw), np.uint8)
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    try:
        cv2.grabCut(cv2.cvtColor(small, cv2.COLOR_RGB2BGR), gc, rect, bgd, fgd, iterations, cv2.GC_INIT_WITH_RECT)
    except cv2.error:
        return None
    fg = ((gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    if n < 2:
        return None
    fg = (labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))).astype(np.uint8)
    contours, _ = cv2.findContours(fg, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    fg = cv2.drawContours(np.zeros_like(fg), contours, -1, 1, thickness=cv2.FILLED)
    full = cv2.resize(fg, (cx1 - cx0, cy1 - cy0), interpolation=cv2.INTER_NEAREST)
    out = np.zeros((h, w), bool)
    out[cy0:cy1, cx0:cx1] = full.astype(bool)
    frac = out[y0:y1, x0:x1].mean()
    return out if 0.15 <= frac <= 0.95 else None


def random_region_mask(image_hw: tuple[int, int], rng: np.random.Generator, size_frac_range=(0.08, 0.3)) -> np.ndarray:
    """A random blob (convex polygon of 5-9 vertices) for photos without labelled objects."""
    h, w = image_hw
    size = rng.uniform(*size_frac_range) * min(h, w)
    cx, cy = rng.uniform(size / 2, w - size / 2), rng.uniform(size / 2, h - size / 2)
    n = int(rng.integers(5, 10))
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = size / 2 * rng.uniform(0.5, 1.0, n)
    aspect = rng.uniform(0.5, 2.0)
    pts = np.stack([cx + rad * np.cos(ang) * aspect**0.5, cy + rad * np.sin(ang) / aspect**0.5], 1)
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(pts).astype(np.int32)], 1)
    return mask.astype(bool)


def object_crop(image_rgb: np.ndarray, mask_bool: np.ndarray, box: Box, context: float, size_px: int):
    """(crop uint8 (S, S, 3), mask float32 (S, S)) of the object's context box resized to ``size_px``."""
    x0, y0, x1, y1 = context_box(box, image_rgb.shape[:2], context)
    crop = resize(image_rgb[y0:y1, x0:x1], (size_px, size_px))
    m = cv2.resize(mask_bool[y0:y1, x0:x1].astype(np.float32), (size_px, size_px), interpolation=cv2.INTER_AREA)
    return crop, (m > 0.5).astype(np.float32)


def cover_resize(image_rgb: np.ndarray, size_wh: tuple[int, int]) -> tuple[np.ndarray, float, int, int]:
    """Scale so the image covers ``size_wh`` then centre-crop; returns (image, scale, x offset, y offset)."""
    h, w = image_rgb.shape[:2]
    tw, th = size_wh
    s = max(tw / w, th / h)
    nw, nh = max(tw, int(round(w * s))), max(th, int(round(h * s)))
    big = resize(image_rgb, (nw, nh))
    ox, oy = (nw - tw) // 2, (nh - th) // 2
    return big[oy : oy + th, ox : ox + tw].copy(), s, ox, oy


def asdict_perturbation(p: Perturbation) -> dict:
    return asdict(p)
