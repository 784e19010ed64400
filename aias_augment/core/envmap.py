"""An environment map: linear equirectangular radiance and its orientation in the scene's world frame (a scene fact
a caller may give; the lighting analysis reads its sun and ambient from it)."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from aias_augment.core.geometry import check_shape

log = logging.getLogger(__name__)
# The lighting drawn from a map (its sun, its spherical harmonics) costs ~O(pixels^1.4): 1024 rows take ~5 s and
# 0.5 GB, 2048 rows 35 s and 1.5 GB. 1024 rows (0.18 deg a pixel) still resolve the sun's 0.5 deg disc.
MAX_ENVMAP_HEIGHT = 1024


def check_rotation(R: np.ndarray, name: str) -> np.ndarray:
    """``R`` as a float64 3x3 proper rotation, else a ValueError naming ``name``."""
    R = check_shape(np.asarray(R, dtype=np.float64), (3, 3), name)
    if not np.all(np.isfinite(R)) or not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise ValueError(f"{name}: not a proper 3x3 rotation")
    return R


@dataclass(frozen=True)
class EnvironmentMap:
    """Linear equirectangular radiance (H, W=2H, 3) plus its orientation in the scene's world frame."""

    radiance: np.ndarray
    world_from_env: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self):
        r = np.asarray(self.radiance)
        if r.ndim != 3 or r.shape[2] != 3 or r.shape[1] != 2 * r.shape[0] or r.shape[0] < 2:
            raise ValueError(f"EnvironmentMap: radiance must be (H, 2H, 3) with H >= 2, got {r.shape}")
        if not np.all(np.isfinite(r)):
            raise ValueError("EnvironmentMap: radiance contains NaN or Inf")
        if np.any(r < 0):
            raise ValueError("EnvironmentMap: radiance must be >= 0 (clip compression noise before building it)")
        object.__setattr__(self, "radiance", r.astype(np.float32, copy=False))
        object.__setattr__(self, "world_from_env", check_rotation(self.world_from_env, "world_from_env"))

    @property
    def shape(self) -> tuple[int, int]:
        return self.radiance.shape[:2]

    @classmethod
    def from_file(
        cls, path, world_from_env: np.ndarray | None = None, max_height: int = MAX_ENVMAP_HEIGHT
    ) -> "EnvironmentMap":
        """The map in an EXR / Radiance file: its size checked from the header (at most
        :data:`~aias_augment.core.hdr.MAX_HDR_PIXELS`, 8192x4096, else ``ImageTooLarge``), then averaged down
        (``cv2.INTER_AREA``: the radiance integrated over each new pixel, so the sun's power is kept) to at most
        ``max_height`` rows."""
        from aias_augment.core.hdr import read_hdr_image

        rgb = read_hdr_image(path)
        if rgb.shape[1] != 2 * rgb.shape[0]:
            raise ValueError(
                f"{path}: not equirectangular (expected width = 2 x height, got {rgb.shape[1]}x{rgb.shape[0]})"
            )
        if rgb.shape[0] > max_height:
            log.info("%s: %dx%d averaged down to %dx%d", path, rgb.shape[1], rgb.shape[0], 2 * max_height, max_height)
            rgb = cv2.resize(rgb, (2 * max_height, max_height), interpolation=cv2.INTER_AREA)
        return cls(rgb, np.eye(3) if world_from_env is None else world_from_env)
