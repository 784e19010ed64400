"""Depth from a rectified stereo pair (OpenCV semi-global block matching).

Convention: ``left`` and ``right`` are a rectified pair (epipolar lines are image rows), the right camera sits
``baseline_m`` metres to the right of the left one (KITTI: P1[0, 3] = -fx * baseline). Depth is the z-depth of
the LEFT camera: ``z = fx * baseline / disparity``.
"""

from __future__ import annotations

import cv2
import numpy as np

from aias_augment.core.geometry import Intrinsics

__all__ = ["stereo_disparity", "stereo_depth", "disparity_to_depth"]

#: Disparities (pixels) below this are treated as invalid: depth would exceed fx * baseline / 0.5 (about 760 m on
#: KITTI) and the SGBM sub-pixel estimate carries no information there.
MIN_DISPARITY_PX = 0.5


def _to_grey(image: np.ndarray, name: str) -> np.ndarray:
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise ValueError(f"{name}: expected uint8 image, got {img.dtype}")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    if img.ndim == 3 and img.shape[2] == 1:
        return img[..., 0]
    raise ValueError(f"{name}: expected (H, W) grey or (H, W, 3) RGB, got shape {img.shape}")


def stereo_disparity(
    left, right, *, num_disparities: int = 128, block_size: int = 5, wls_lambda: float | None = None
) -> np.ndarray:
    """Left-view disparity (H, W) float32 in pixels, 0 where invalid (occluded, textureless, out of range).

    SGBM 3-way with the usual smoothness penalties P1 = 8 * bs^2, P2 = 32 * bs^2, a left-right consistency check
    (``disp12MaxDiff = 1``) and speckle filtering. ``wls_lambda`` (e.g. 8000) adds the ximgproc WLS filter, which
    fills holes: use it for pictures, not for measurement (filled values are interpolated, not measured).
    """
    left_g, right_g = _to_grey(left, "left"), _to_grey(right, "right")
    if left_g.shape != right_g.shape:
        raise ValueError(f"stereo pair shapes differ: {left_g.shape} vs {right_g.shape}")
    if num_disparities <= 0 or num_disparities % 16:
        raise ValueError(f"num_disparities must be a positive multiple of 16, got {num_disparities}")
    if block_size < 1 or block_size % 2 == 0:
        raise ValueError(f"block_size must be a positive odd number, got {block_size}")
    if left_g.shape[1] <= num_disparities:
        raise ValueError(f"image width {left_g.shape[1]} must exceed num_disparities {num_disparities}")
    matcher = cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=num_disparities,
        blockSize=block_size,
        P1=8 * block_size**2,
        P2=32 * block_size**2,
        disp12MaxDiff=1,
        uniquenessRatio=10,
        speckleWindowSize=100,
        speckleRange=2,
        preFilterCap=63,
        mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY,
    )
    raw = matcher.compute(left_g, right_g)  # int16, fixed point with 4 fractional bits
    if wls_lambda is not None:
        right_matcher = cv2.ximgproc.createRightMatcher(matcher)
        raw_right = right_matcher.compute(right_g, left_g)
        wls = cv2.ximgproc.createDisparityWLSFilter(matcher)
        wls.setLambda(float(wls_lambda))
        wls.setSigmaColor(1.5)
        raw = wls.filter(raw, left_g, disparity_map_right=raw_right)
    disp = raw.astype(np.float32) / 16.0
    disp[~(disp >= MIN_DISPARITY_PX)] = 0.0
    return disp


def disparity_to_depth(disparity: np.ndarray, fx: float, baseline_m: float) -> np.ndarray:
    """z = fx * baseline / disparity; 0 where the disparity is below :data:`MIN_DISPARITY_PX` (no division there)."""
    if not (np.isfinite(baseline_m) and baseline_m > 0):
        raise ValueError(f"baseline_m must be positive, got {baseline_m}")
    if not (np.isfinite(fx) and fx > 0):
        raise ValueError(f"fx must be positive, got {fx}")
    disp = np.asarray(disparity, dtype=np.float32)
    valid = np.isfinite(disp) & (disp >= MIN_DISPARITY_PX)
    depth = np.zeros(disp.shape, np.float32)
    depth[valid] = np.float32(fx * baseline_m) / disp[valid]
    return depth


def stereo_depth(
    left,
    right,
    intrinsics: Intrinsics,
    baseline_m: float,
    *,
    num_disparities: int = 128,
    block_size: int = 5,
    wls_lambda: float | None = None,
) -> np.ndarray:
    """Float32 (H, W) z-depth in metres of the left camera for a rectified pair (grey or RGB uint8); 0 = invalid."""
    h, w = np.asarray(left).shape[:2]
    if (intrinsics.width, intrinsics.height) != (w, h):
        raise ValueError(f"intrinsics are for {intrinsics.width}x{intrinsics.height}, images are {w}x{h}")
    disp = stereo_disparity(left, right, num_disparities=num_disparities, block_size=block_size, wls_lambda=wls_lambda)
    return disparity_to_depth(disp, intrinsics.fx, baseline_m)
