"""The working resolution: the analysis of a large frame on a <= ``max_pixels`` copy, lifted back to full size.

The bounded door (:func:`aias_augment.pipeline.bounded.insert_bounded`) and :func:`~.replay.replay` take the same
route through :meth:`WorkingResolution.analyse`, so a record that names its working resolution replays byte for byte:

1. the frame (image INTER_AREA; depth and image-shaped meta nearest) is resized to the working size and its K
   rescaled with it (:func:`rescale_intrinsics`, pixel-centre alignment: the one place intrinsics change size);
2. the scene analysis runs on that copy (through the scene cache);
3. the analysis is lifted to full size: metric quantities unchanged, the region mask resized nearest, the intrinsics
   the frame's own or the working copy's rescaled back.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from aias_augment.analyse.analysis import SceneAnalysis
from aias_augment.analyse.cache import SceneCache
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics
from aias_augment.pipeline.config import InsertionConfig

#: Default analysis bound (pixels): 2 MP, the size of a 1920x1080 frame (where the analysis was tuned).
ANALYSIS_MAX_PIXELS = 2_000_000


def working_size(width: int, height: int, max_pixels: int) -> tuple[int, int]:
    """(w, h) of the working image: the largest size with the aspect ratio kept and w * h <= max_pixels."""
    if width * height <= max_pixels:
        return width, height
    s = math.sqrt(max_pixels / (width * height))
    return max(1, int(width * s)), max(1, int(height * s))


def rescale_intrinsics(intr: Intrinsics, width: int, height: int) -> Intrinsics:
    """``intr`` (for its own image size) for an image of ``width`` x ``height`` (pixel-centre alignment)."""
    sx, sy = width / intr.width, height / intr.height
    return Intrinsics(
        intr.fx * sx, intr.fy * sy, (intr.cx + 0.5) * sx - 0.5, (intr.cy + 0.5) * sy - 0.5, int(width), int(height)
    )


def resize_nearest(a: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour resize of any dtype (labels, bool masks, depth with 0/NaN holes) to ``size`` (w, h)."""
    h, w = a.shape[:2]
    rows = np.minimum(((np.arange(size[1]) + 0.5) * h / size[1]).astype(np.intp), h - 1)
    cols = np.minimum(((np.arange(size[0]) + 0.5) * w / size[0]).astype(np.intp), w - 1)
    return np.ascontiguousarray(a[rows][:, cols])


def resize_like_image(v, h: int, w: int, size: tuple[int, int]):
    """Image-shaped meta arrays (masks, label maps) of an (h, w) image resized nearest to ``size``; anything else
    as is."""
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[:2] == (h, w):
        return resize_nearest(v, size)
    return v


@dataclass(frozen=True)
class WorkingResolution:
    """A frame of ``image_size`` (W, H) analysed and planned on its copy of ``analysis_size`` (w, h), the largest
    one within ``max_pixels``. Recorded in :class:`~aias_augment.pipeline.image.InsertionRecord` (``working_resolution``)."""

    image_size: tuple[int, int]
    analysis_size: tuple[int, int]
    max_pixels: int

    @classmethod
    def bound(cls, width: int, height: int, max_pixels: int) -> "WorkingResolution":
        return cls((int(width), int(height)), working_size(int(width), int(height), int(max_pixels)), int(max_pixels))

    @property
    def scale(self) -> tuple[float, float]:
        """(sx, sy): working copy pixels per full-size pixel."""
        return self.analysis_size[0] / self.image_size[0], self.analysis_size[1] / self.image_size[1]

    def to_dict(self) -> dict:
        return {
            "image_size": list(self.image_size),
            "analysis_size": list(self.analysis_size),
            "max_pixels": self.max_pixels,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "WorkingResolution":
        return cls(
            tuple(int(v) for v in d["image_size"]), tuple(int(v) for v in d["analysis_size"]), int(d["max_pixels"])
        )

    def working_frame(self, frame: Frame) -> Frame:
        """``frame`` (at :attr:`image_size`) resized to :attr:`analysis_size`: image INTER_AREA, depth and
        image-shaped meta nearest, K rescaled."""
        W, H = self.image_size
        if frame.image.shape[:2] != (H, W):
            raise ValueError(
                f"the working resolution is for a {W}x{H} frame, this one is "
                f"{frame.image.shape[1]}x{frame.image.shape[0]}"
            )
        w, h = self.analysis_size
        return Frame(
            cv2.resize(frame.image, (w, h), interpolation=cv2.INTER_AREA),
            None if frame.intrinsics is None else rescale_intrinsics(frame.intrinsics, w, h),
            depth=None if frame.depth is None else resize_nearest(frame.depth, (w, h)),
            meta={k: resize_like_image(v, H, W, (w, h)) for k, v in (frame.meta or {}).items()},
        )

    def analyse(
        self, frame: Frame, cfg: InsertionConfig, cache: SceneCache | None = None
    ) -> tuple[Frame, SceneAnalysis, SceneAnalysis]:
        """(working frame, its analysis, that analysis at full size) of ``frame``: the analysis of the working copy
        (through ``cache``) with its region mask resized back and the frame's intrinsics (or the working copy's,
        rescaled back)."""
        small = self.working_frame(frame)
        analysis_small = (cache if cache is not None else SceneCache(max_items=0)).get(small, cfg)
        W, H = self.image_size
        w, h = self.analysis_size
        full_intr = (
            frame.intrinsics if frame.intrinsics is not None else rescale_intrinsics(analysis_small.intrinsics, W, H)
        )
        region = analysis_small.region
        if region is not None:
            region = replace(region, mask=resize_like_image(np.asarray(region.mask, bool), h, w, (W, H)))
        modules = {
            **analysis_small.modules,
            "working_resolution": f"analysis and plan at {w}x{h} (<= {self.max_pixels / 1e6:g} MP), rendered at {W}x{H}",
        }
        analysis = replace(analysis_small, image_shape=(H, W), intrinsics=full_intr, region=region, modules=modules)
        return small, analysis_small, analysis
