"""Frames of scene clips: a folder of images, a video file, or a single image, as (FrameRef, BGR uint8) pairs."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from aias_augment.core import image_io
from aias_augment.scenes.retrieval.index import FrameRef

log = logging.getLogger(__name__)

__all__ = ["IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "iter_frames", "read_image"]

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".ppm", ".pgm"}
VIDEO_SUFFIXES = {".avi", ".mp4", ".mov", ".mkv", ".webm", ".m4v"}


def read_image(path: str | Path) -> np.ndarray:
    """(H, W, 3) uint8 BGR (as the video frames), upright, by the package's reader; 16-bit images are refused
    (they are depth maps, not frames)."""
    return np.ascontiguousarray(image_io.read_image(path, allow_16bit=False)[..., ::-1])


def iter_frames(
    path: str | Path, *, every: int = 1, clip: str | None = None, pattern: str = "*", max_frames: int | None = None
) -> Iterator[tuple[FrameRef, np.ndarray]]:
    """Frames of a clip: every ``every``-th image of a folder (sorted by name, ``pattern`` glob) or of a video."""
    path = Path(path)
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    clip = clip or (path.stem if path.is_file() else path.name)
    n = 0
    if path.is_dir():
        files = sorted(p for p in path.glob(pattern) if p.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"{path}: no images matching {pattern!r}")
        for p in files[::every]:
            if max_frames is not None and n >= max_frames:
                return
            yield FrameRef(clip, p.relative_to(path).as_posix()), read_image(p)
            n += 1
    elif path.suffix.lower() in VIDEO_SUFFIXES:
        cap = cv2.VideoCapture(str(path))
        if not cap.isOpened():
            raise ValueError(f"cannot open video {path}")
        i = 0
        try:
            while max_frames is None or n < max_frames:
                ok, frame = cap.read()
                if not ok:
                    break
                if i % every == 0:
                    yield FrameRef(clip, f"{path.name}#{i:05d}"), frame
                    n += 1
                i += 1
        finally:
            cap.release()
    elif path.suffix.lower() in IMAGE_SUFFIXES:
        yield FrameRef(clip, path.name), read_image(path)
    else:
        raise ValueError(f"{path}: not a folder of images, a video or an image")
