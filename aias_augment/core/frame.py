"""The per-frame scene record every stage reads: image, camera, optional depth and semantics."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aias_augment.core.geometry import Intrinsics, check_rigid


@dataclass
class Frame:
    """One image of a scene.

    image: (H, W, 3) uint8 RGB.
    intrinsics: pinhole camera, or None when unknown (placement then uses priors).
    cam_from_world: (4, 4) OpenCV camera pose, or None (the camera frame is then the world frame).
    depth: (H, W) float32 z-depth in metres; 0 or non-finite = unknown.
    semantic: (H, W) integer label map, or None.
    meta: free-form metadata (source path, timestamp, GPS, ...).
    """

    image: np.ndarray
    intrinsics: Intrinsics | None = None
    cam_from_world: np.ndarray | None = None
    depth: np.ndarray | None = None
    semantic: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        img = np.asarray(self.image)
        if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
            raise ValueError(f"Frame.image must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
        h, w = img.shape[:2]
        if self.intrinsics is not None and (self.intrinsics.width, self.intrinsics.height) != (w, h):
            raise ValueError(
                f"Frame: intrinsics are for {self.intrinsics.width}x{self.intrinsics.height}, image is {w}x{h}"
            )
        if self.cam_from_world is not None:
            self.cam_from_world = check_rigid(self.cam_from_world, "cam_from_world")
        if self.depth is not None:
            d = np.asarray(self.depth, dtype=np.float32)
            if d.shape != (h, w):
                raise ValueError(f"Frame.depth must be {(h, w)}, got {d.shape}")
            self.depth = d
        if self.semantic is not None and np.asarray(self.semantic).shape != (h, w):
            raise ValueError(f"Frame.semantic must be {(h, w)}, got {np.asarray(self.semantic).shape}")

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return self.image.shape[1], self.image.shape[0]

    @property
    def valid_depth(self) -> np.ndarray | None:
        if self.depth is None:
            return None
        return np.isfinite(self.depth) & (self.depth > 0)


def changed_pixels(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels where two (H, W, C) images differ in any channel (channel planes OR-ed: a
    reduction over a short last axis loops per pixel, ~10x slower)."""
    d = np.asarray(a) != np.asarray(b)
    out = d[..., 0].copy()
    for c in range(1, d.shape[-1]):
        out |= d[..., c]
    return out
