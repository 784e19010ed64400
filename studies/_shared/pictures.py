"""How the studies write their pictures: JPEG at quality 85, at most 1200 px on a side (larger pictures are shrunk
with area averaging), so that a committed result stays small and every picture opens in a browser."""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np

JPEG_QUALITY = 85
MAX_SIDE = 1200


def fit_max_side(image: np.ndarray, max_side: int = MAX_SIDE) -> np.ndarray:
    """``image`` shrunk so that its longer side is at most ``max_side`` (unchanged when it already is)."""
    scale = max_side / max(image.shape[:2])
    if scale >= 1:
        return image
    size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def write_jpeg(path: str | Path, bgr: np.ndarray) -> None:
    """Write a BGR (or grey) uint8 picture as a JPEG of at most ``MAX_SIDE`` px on a side."""
    if Path(path).suffix.lower() not in (".jpg", ".jpeg"):
        raise ValueError(f"write_jpeg writes .jpg files, got {path}: name the picture .jpg")
    if not cv2.imwrite(str(path), fit_max_side(bgr), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]):
        raise OSError(f"could not write {path}")


def save_figure_jpeg(fig, path: str | Path, dpi: int) -> None:
    """A matplotlib figure rendered at ``dpi`` and written with :func:`write_jpeg`."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    write_jpeg(path, cv2.imdecode(np.frombuffer(buf.getvalue(), np.uint8), cv2.IMREAD_COLOR))
