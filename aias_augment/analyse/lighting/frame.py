"""One frame made ready for the lighting estimate (:class:`FrameContext`): the image checked, the up vector, a small
analysis copy and its linear radiance, and the lit/shadow measurement on the ground region (or on a fallback box
where the region shows no cast shadows). A clip's frames share the first camera's up."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from aias_augment.analyse.lighting.config import LightingConfig
from aias_augment.analyse.lighting.envmap import camera_ray_directions
from aias_augment.analyse.lighting.ratio import LitShadowMeasurement, ground_region_mask, measure_lit_shadow
from aias_augment.analyse.lighting.solar_position import rotation_of
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.hdr import InverseToneMapParams, inverse_tone_map, srgb_to_linear

__all__ = [
    "FrameContext",
    "check_image",
    "fallback_measurement_ok",
    "measured",
    "prepare_clip",
    "prepare_frame",
    "up_vectors",
]


@dataclass
class FrameContext:
    """Everything about one frame that the sun evidence and the final estimate need."""

    img: np.ndarray
    meta: dict
    K: Intrinsics
    known_camera: bool
    R_cw: np.ndarray
    up_in_world: np.ndarray
    up_in_cam: np.ndarray
    indoor: bool
    small: np.ndarray
    K_small: Intrinsics
    linear_small: np.ndarray
    region: np.ndarray | None
    measurement: LitShadowMeasurement | None
    n_above_small: int  # pixels of the analysis copy more than 2 deg above the horizon
    #: the region ``measurement`` was taken on: ``region``, or a fallback box (``LightingConfig.fallback_ground_boxes_m``)
    measurement_region: np.ndarray | None = None


def check_image(image_rgb_uint8) -> np.ndarray:
    img = np.asarray(image_rgb_uint8)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"estimate_lighting: image must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
    if img.shape[0] < 8 or img.shape[1] < 8:
        raise ValueError(f"estimate_lighting: image too small ({img.shape[1]}x{img.shape[0]})")
    return img


def up_vectors(R_cw: np.ndarray, meta: dict) -> tuple[np.ndarray, np.ndarray]:
    if "up_in_world" in meta:
        up_in_world = np.asarray(meta["up_in_world"], dtype=np.float64).reshape(3)
    else:
        up_in_world = R_cw.T @ np.array([0.0, -1.0, 0.0])
    n = np.linalg.norm(up_in_world)
    if not np.isfinite(n) or n < 1e-9:
        raise ValueError(f"estimate_lighting: invalid up_in_world {up_in_world}")
    up_in_world = up_in_world / n
    return up_in_world, R_cw @ up_in_world


def _downscale(img: np.ndarray, K: Intrinsics, max_width: int) -> tuple[np.ndarray, Intrinsics]:
    """Area-resample an image (and its intrinsics) so that it is at most ``max_width`` wide."""
    import cv2

    h, w = img.shape[:2]
    if w <= max_width:
        return img, K
    s = max_width / w
    K2 = K.scaled(s)
    return cv2.resize(img, (K2.width, K2.height), interpolation=cv2.INTER_AREA), K2


def prepare_frame(
    img: np.ndarray,
    intrinsics: Intrinsics | None,
    R_cw: np.ndarray,
    meta: dict,
    config: LightingConfig,
    measure: bool = True,
) -> FrameContext:
    """The frame's context; with ``measure`` False without the lit/shadow measurement (see :func:`measured`), which
    only a sun's strength and direction read."""
    h, w = img.shape[:2]
    up_in_world, up_in_cam = up_vectors(R_cw, meta)
    known_camera = intrinsics is not None
    K = intrinsics if known_camera else Intrinsics.from_fov(w, h, config.prior_hfov_deg)
    if (K.width, K.height) != (w, h):
        raise ValueError(f"estimate_lighting: intrinsics are for {K.width}x{K.height}, image is {w}x{h}")
    small, K_small = _downscale(img, K, config.analysis_width)
    linear_small = inverse_tone_map(small, InverseToneMapParams())
    region = meta.get("ground_mask")
    if region is None:
        region = ground_region_mask(
            K, up_in_cam, config.camera_height_m, config.ground_lateral_range_m, config.ground_forward_range_m
        )
    region = np.asarray(region, bool)
    if region.shape != (h, w):
        raise ValueError(f"estimate_lighting: ground_mask must be {(h, w)}, got {region.shape}")
    n_above = int(np.sum(camera_ray_directions(K_small) @ up_in_cam > np.sin(np.deg2rad(2.0))))
    ctx = FrameContext(
        img,
        meta,
        K,
        known_camera,
        R_cw,
        up_in_world,
        up_in_cam,
        bool(meta.get("indoor", False)),
        small,
        K_small,
        linear_small,
        region,
        None,
        n_above,
        region,
    )
    return measured(ctx, config) if measure else ctx


def measured(ctx: FrameContext, config: LightingConfig) -> FrameContext:
    """``ctx`` with the lit/shadow measurement for the sun's strength: on the ground region at full resolution (thin
    cast shadows matter), or on the first fallback ground box that shows cast shadows where the region does not."""
    linear = srgb_to_linear(ctx.img)
    measurement = measure_lit_shadow(linear, ctx.region)
    measurement_region = ctx.region
    if not (measurement is not None and measurement.dominant_sun):
        for lateral, forward in config.fallback_ground_boxes_m:
            box = ground_region_mask(ctx.K, ctx.up_in_cam, config.camera_height_m, tuple(lateral), tuple(forward))
            m = measure_lit_shadow(linear, box)
            if fallback_measurement_ok(m, config):
                measurement, measurement_region = m, box
                break
    return replace(ctx, measurement=measurement, measurement_region=measurement_region)


def fallback_measurement_ok(m: LitShadowMeasurement | None, config: LightingConfig) -> bool:
    """Whether a fallback ground box's lit/shadow split counts as cast shadows (see
    ``LightingConfig.fallback_min_separation``)."""
    return bool(
        m is not None
        and m.dominant_sun
        and m.separation >= config.fallback_min_separation
        and 0.02 <= m.shadow_fraction <= config.fallback_max_shadow_fraction
        and m.sun_sky_ratio <= config.max_direct_to_diffuse_ratio
    )


def prepare_clip(images, intrinsics, cams_from_world, metas, config: LightingConfig, measure: bool = True):
    """Frame contexts of a clip and its world up (``metas[0]['up_in_world']`` or the first camera's -y); ``measure``
    as in :func:`prepare_frame`."""
    n = len(images)
    if n == 0 or len(cams_from_world) != n:
        raise ValueError("estimate_lighting_clip: need one pose per image and at least one image")
    Ks = list(intrinsics) if isinstance(intrinsics, (list, tuple)) else [intrinsics] * n
    ms = [dict(m or {}) for m in metas] if isinstance(metas, (list, tuple)) else [dict(metas or {})] * n
    if len(Ks) != n or len(ms) != n:
        raise ValueError("estimate_lighting_clip: intrinsics and metas must match the number of images")
    R0 = rotation_of(cams_from_world[0])
    up_in_world, _ = up_vectors(R0, ms[0])
    for m in ms:
        m.setdefault("up_in_world", up_in_world)
    ctxs = [
        prepare_frame(check_image(img), K, rotation_of(T), m, config, measure)
        for img, K, T, m in zip(images, Ks, cams_from_world, ms)
    ]
    return ctxs, up_in_world
