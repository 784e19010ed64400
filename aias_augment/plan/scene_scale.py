"""The scale of a scene whose ground has no measured scale (a single photo's camera-height prior): the factor
about the camera centre at which a size target stands on visible ground, or at which the image's own labelled
objects are their real height; and the height of the object each labelled box shows."""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.core.geometry import Intrinsics
from aias_augment.plan.box_size import GROUND_CANDIDATES, box_heights_at_pixels
from aias_augment.plan.placement_config import PlacementConfig
from aias_augment.plan.references import whole_box_mask

__all__ = ["reference_heights_m", "scaled_ground", "scene_scale_for_sizes", "scene_scale_from_boxes"]


def scene_scale_for_sizes(
    ground: GroundPlane,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    cfg: PlacementConfig,
    object_height_m: float,
    target_frac: float,
    region_mask: np.ndarray | None = None,
) -> tuple[float, str]:
    """Factor ``k`` by which to scale an assumed-scale scene about the camera centre (the camera height becomes
    ``k * ground.d``) so that an object of box height ``target_frac`` (of the image height) stands on a ground
    pixel drawn uniformly among those that can host it with the camera height inside
    ``cfg.camera_height_range_m``; ``(1.0, reason)`` when the scene is not rescaled. Given the largest target of
    an image, its smaller ones fit farther away. Scaling the scene by ``k`` shows an object of height ``h`` as the
    unscaled scene shows one of ``h / k``, which gives each pixel's ``k`` by a fixed-point iteration on the
    predicted box heights."""
    if not ground.assumed_scale:
        return 1.0, f"measured ground ({ground.source}): its scale is kept"
    cand = GROUND_CANDIDATES.get(ground, intrinsics, region_mask, cfg.horizon_margin_px)["cand"]
    if len(cand) == 0 or not (ground.d > 0):
        return 1.0, "no ground in view: scale kept"
    cand = cand[:: max(1, len(cand) // 4096)]
    v, u = np.divmod(cand, intrinsics.width)
    uv = np.c_[u, v].astype(np.float64)
    target = target_frac * intrinsics.height
    k = _scales_for_heights(uv, np.full(len(uv), target), object_height_m, ground, intrinsics)
    if np.isnan(k).all():
        return 1.0, f"target {target:.0f} px: no ground pixel predicts a size, scale kept"
    heights = k * ground.d
    lo, hi = cfg.camera_height_range_m
    ok = np.flatnonzero((heights >= lo) & (heights <= hi))
    if len(ok) == 0:
        near = float(heights[np.nanargmin(np.abs(np.log(heights / np.sqrt(lo * hi))))])
        kk = float(np.clip(near, lo, hi)) / ground.d  # the nearest plausible height: the target is not met
        return kk, (f"target {target:.0f} px needs a camera height outside {lo}-{hi} m: {kk * ground.d:.2f} m used")
    i = ok[int(rng.integers(len(ok)))]
    return float(k[i]), (
        f"camera {heights[i]:.2f} m above the ground (assumed {ground.d:.2f} m) so that a "
        f"{target:.0f} px target stands on visible ground"
    )


def scene_scale_from_boxes(
    ground: GroundPlane,
    intrinsics: Intrinsics,
    boxes_xyxy: np.ndarray,
    object_height_m: float | np.ndarray,
    cfg: PlacementConfig,
) -> tuple[float | None, str]:
    """Factor ``k`` by which to scale an assumed-scale scene about the camera centre so that objects of
    ``object_height_m`` (one for all, or (N,): each box's kind's height) standing on the ground at the bottom centres
    of ``boxes_xyxy`` (the scene's own objects of the inserted kinds) are as tall in the image as those boxes: the
    median over the boxes of the per-box factor,
    the camera height ``k * ground.d`` kept inside ``cfg.camera_height_range_m``. Boxes cut by the frame's top or
    bottom edge (their height or base unknown) and bases above the horizon give none. ``(None, reason)`` when no
    box gives a factor; ``(1.0, reason)`` for a measured ground."""
    if not ground.assumed_scale:
        return 1.0, f"measured ground ({ground.source}): its scale is kept"
    b = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    heights = np.broadcast_to(np.asarray(object_height_m, float), (len(b),))
    h_px = b[:, 3] - b[:, 1]
    inside = whole_box_mask(b, intrinsics)
    if not inside.any() or not (ground.d > 0):
        return None, f"none of {len(b)} reference boxes is whole in the frame"
    b, h_px, heights = b[inside], h_px[inside], heights[inside]
    uv = np.c_[(b[:, 0] + b[:, 2]) / 2, b[:, 3]]
    k = _scales_for_heights(uv, h_px, heights, ground, intrinsics)
    object_height_m = float(np.mean(heights))
    k = k[np.isfinite(k)]
    if len(k) == 0:
        return None, f"no reference box stands on the visible ground ({len(b)} whole in the frame)"
    lo, hi = cfg.camera_height_range_m
    height = float(np.median(k)) * ground.d
    kk = float(np.clip(height, lo, hi)) / ground.d
    clipped = "" if lo <= height <= hi else f" (the boxes ask for {height:.2f} m, outside {lo}-{hi} m)"
    return kk, (
        f"camera {kk * ground.d:.2f} m above the ground (assumed {ground.d:.2f} m): {object_height_m:.2f} m objects "
        f"on the bottom rows of the image's {len(k)} reference boxes are their height (median of their scales){clipped}"
    )


def reference_heights_m(ground: GroundPlane, intrinsics: Intrinsics, boxes_xyxy: np.ndarray) -> np.ndarray:
    """(N,) height in metres of the upright object whose box is each of ``boxes_xyxy`` (N, 4), standing on ``ground``
    at the box's bottom centre: the height whose projection (:func:`predicted_box_heights_px`) is the box's height.
    nan for a box cut by the frame's top or bottom edge or whose base is not on the visible ground."""
    b = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    out = np.full(len(b), np.nan)
    ok = whole_box_mask(b, intrinsics)
    if ok.any() and ground.d > 0:
        uv = np.c_[(b[ok, 0] + b[ok, 2]) / 2, b[ok, 3]]
        out[ok] = 1.0 / _scales_for_heights(uv, b[ok, 3] - b[ok, 1], np.ones(int(ok.sum())), ground, intrinsics)
    return out


def _scales_for_heights(
    uv: np.ndarray, target_px: np.ndarray, object_height_m, ground: GroundPlane, intrinsics: Intrinsics
) -> np.ndarray:
    """Per ground pixel, the scene scale ``k`` at which an object of ``object_height_m`` (scalar or one per pixel)
    standing there is
    ``target_px`` tall (nan where none). Scaling the scene by ``k`` shows an object of height ``h`` as the unscaled
    scene shows one of ``h / k``: a fixed-point iteration on the predicted heights, nearly proportional to 1 / k, so
    a few steps converge."""
    k = np.ones(len(uv))
    for _ in range(4):
        pred = box_heights_at_pixels(uv, object_height_m / k, ground, intrinsics)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = k * pred / target_px
        k[~(np.isfinite(k) & (k > 0))] = np.nan
    return k


def scaled_ground(ground: GroundPlane, k: float) -> GroundPlane:
    """``ground`` with the scene scaled by ``k`` about the camera centre (same normal, camera height ``k * d``)."""
    if k == 1.0:
        return ground
    return GroundPlane(
        ground.normal,
        ground.d * k,
        f"{ground.source}:scaled",
        ground.inlier_ratio,
        ground.rms_m,
        ground.num_inliers,
        ground.assumed_scale,
    )
