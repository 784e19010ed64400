"""Equirectangular environment maps: conventions, sampling, perspective views and assembly from posed frames.

Convention (the same as Blender/Cycles' world equirectangular mapping, so Blender HDRIs load with their intended
orientation):
- The *env frame* is right-handed and z-up: +x is the direction at the centre column, +y the direction a quarter of
  the width to the LEFT of the centre (u = 0.25), +z the zenith.
- Pixel (row, col) of an (H, W) map has its centre at azimuth ``phi = pi * (1 - 2 (col + 0.5) / W)`` (counter-clockwise
  about +z from +x, in (-pi, pi]) and elevation ``el = pi * (0.5 - (row + 0.5) / H)``; row 0 is the zenith side.
- direction = (cos el cos phi, cos el sin phi, sin el).
- Radiance is linear float32 RGB. How the env frame sits in a scene is carried by ``world_from_env`` (3x3 rotation).

Cameras looking into a map use the OpenCV convention (x right, y down, z forward); ``cam_from_env`` is a 3x3 rotation.
"""

from __future__ import annotations

import functools
from typing import Callable, Sequence

import cv2
import numpy as np
from scipy import ndimage

from aias_augment.core.envmap import EnvironmentMap, check_rotation
from aias_augment.core.geometry import Intrinsics, check_shape

__all__ = [
    "EnvironmentMap",
    "pixel_directions",
    "direction_to_pixel",
    "direction_to_azimuth_elevation",
    "azimuth_elevation_to_direction",
    "pixel_solid_angles",
    "sample_envmap",
    "cam_from_env_look",
    "camera_ray_directions",
    "render_perspective",
    "assemble_envmap",
]


def azimuth_elevation_to_direction(azimuth_rad, elevation_rad) -> np.ndarray:
    """(*,), (*,) -> unit (*, 3) in the env frame."""
    az, el = np.broadcast_arrays(np.asarray(azimuth_rad, dtype=np.float64), np.asarray(elevation_rad, dtype=np.float64))
    ce = np.cos(el)
    return np.stack([ce * np.cos(az), ce * np.sin(az), np.sin(el)], axis=-1)


def direction_to_azimuth_elevation(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(*, 3) (any non-zero length) -> azimuth in (-pi, pi], elevation in [-pi/2, pi/2]; zero vectors give (0, 0)."""
    d = check_shape(directions, ("*", 3), "directions").astype(np.float64)
    n = np.linalg.norm(d, axis=-1)
    z = np.clip(d[..., 2] / np.maximum(n, 1e-300), -1.0, 1.0)  # eps: only matters for zero vectors
    return np.arctan2(d[..., 1], d[..., 0]), np.arcsin(z)


def pixel_directions(height: int, width: int | None = None) -> np.ndarray:
    """Unit directions of pixel centres, (H, W, 3) float64 in the env frame."""
    width = 2 * height if width is None else width
    phi = np.pi * (1.0 - 2.0 * (np.arange(width) + 0.5) / width)
    el = np.pi * (0.5 - (np.arange(height) + 0.5) / height)
    return azimuth_elevation_to_direction(phi[None, :], el[:, None])


def direction_to_pixel(directions: np.ndarray, height: int, width: int | None = None) -> np.ndarray:
    """Continuous pixel coordinates (col, row), (*, 3) -> (*, 2), such that integer values are pixel centres.

    col is in [-0.5, W - 0.5) (wrapping), row in [-0.5, H - 0.5].
    """
    width = 2 * height if width is None else width
    az, el = direction_to_azimuth_elevation(directions)
    col = ((1.0 - az / np.pi) / 2.0 * width - 0.5) % width
    col = np.where(col >= width - 0.5, col - width, col)
    row = (0.5 - el / np.pi) * height - 0.5
    return np.stack([col, row], axis=-1)


def pixel_solid_angles(height: int, width: int | None = None) -> np.ndarray:
    """Exact solid angle (sr) of each pixel, (H, 1): (2 pi / W) * (sin el_top - sin el_bottom). Sums to 4 pi."""
    width = 2 * height if width is None else width
    edges = np.pi * (0.5 - np.arange(height + 1) / height)
    return ((2.0 * np.pi / width) * (np.sin(edges[:-1]) - np.sin(edges[1:])))[:, None]


def sample_envmap(radiance: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Bilinear lookup (wrapping in azimuth, clamped at the poles), (*, 3) directions -> (*, C) values."""
    radiance = np.asarray(radiance)
    h, w = radiance.shape[:2]
    pix = direction_to_pixel(directions, h, w)
    col, row = pix[..., 0], np.clip(pix[..., 1], 0.0, h - 1.0)
    c0 = np.floor(col).astype(np.int64)
    r0 = np.floor(row).astype(np.int64)
    fc = (col - c0)[..., None]
    fr = (row - r0)[..., None]
    r1 = np.minimum(r0 + 1, h - 1)
    c0w, c1w = c0 % w, (c0 + 1) % w
    top = radiance[r0, c0w] * (1 - fc) + radiance[r0, c1w] * fc
    bot = radiance[r1, c0w] * (1 - fc) + radiance[r1, c1w] * fc
    return (top * (1 - fr) + bot * fr).astype(radiance.dtype, copy=False)


def cam_from_env_look(yaw_rad: float, pitch_rad: float = 0.0, roll_rad: float = 0.0) -> np.ndarray:
    """Rotation (3, 3) of an OpenCV camera that looks toward env azimuth ``yaw`` and elevation ``pitch`` (level roll 0).

    Rows are the camera axes in env coordinates: x = right, y = down, z = forward. Positive roll turns the image
    clockwise as seen by the viewer. Pitch must stay within +-89 deg (the horizon defines "right").
    """
    if abs(pitch_rad) > np.deg2rad(89.0):
        raise ValueError(f"pitch must be within +-89 deg, got {np.rad2deg(pitch_rad):.1f}")
    fwd = azimuth_elevation_to_direction(yaw_rad, pitch_rad)
    right = np.cross(fwd, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(fwd, right)
    c, s = np.cos(roll_rad), np.sin(roll_rad)
    right, down = c * right - s * down, s * right + c * down
    return np.stack([right, down, fwd], axis=0)


def camera_ray_directions(intrinsics: Intrinsics) -> np.ndarray:
    """Unit ray directions of every pixel centre in the OpenCV camera frame, (H, W, 3), read-only: one analysis
    asks for the same camera's rays several times (sky, ambient, ground boxes, side cues), so the last few cameras'
    rays are kept (a pure function of the intrinsics)."""
    return _camera_rays(
        float(intrinsics.fx),
        float(intrinsics.fy),
        float(intrinsics.cx),
        float(intrinsics.cy),
        int(intrinsics.width),
        int(intrinsics.height),
    )


@functools.lru_cache(maxsize=8)
def _camera_rays(fx: float, fy: float, cx: float, cy: float, width: int, height: int) -> np.ndarray:
    intrinsics = Intrinsics(fx, fy, cx, cy, width, height)
    u = np.arange(intrinsics.width, dtype=np.float64)
    v = np.arange(intrinsics.height, dtype=np.float64)
    x = (u[None, :] - intrinsics.cx) / intrinsics.fx
    y = (v[:, None] - intrinsics.cy) / intrinsics.fy
    d = np.stack(np.broadcast_arrays(x, y, np.ones_like(x * y)), axis=-1)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    d.flags.writeable = False
    return d


def render_perspective(radiance: np.ndarray, intrinsics: Intrinsics, cam_from_env: np.ndarray) -> np.ndarray:
    """A pinhole view into an equirectangular map (bilinear), (h, w, 3) float32 radiance."""
    R = check_rotation(cam_from_env, "cam_from_env")
    rays_in_env = camera_ray_directions(intrinsics) @ R  # R^T applied to row vectors
    return sample_envmap(np.asarray(radiance, dtype=np.float32), rays_in_env)


# Above this pre-blur sigma (image pixels) the frame is area-averaged down first, so that the blur kernel stays
# under ~2 * 4 * _MAX_BLUR_SIGMA_PX taps whatever the focal length says (fx = 1e7 would ask for millions).
_MAX_BLUR_SIGMA_PX = 32.0


def _area_reduced(img: np.ndarray, sigma_px: float) -> tuple[np.ndarray, float]:
    """``img`` area-averaged by ``f = sigma_px / 8`` (INTER_AREA: every source pixel counted once) when
    ``sigma_px`` exceeds ``_MAX_BLUR_SIGMA_PX``, and ``f`` (1.0 when unchanged). The remaining blur is
    ``sigma_px / f`` = 8 reduced pixels; a frame smaller than one reduced pixel becomes its mean."""
    if not sigma_px > _MAX_BLUR_SIGMA_PX:
        return img, 1.0
    f = sigma_px / 8.0
    h, w = img.shape[:2]
    size = (max(1, int(round(w / f))), max(1, int(round(h / f))))
    if size == (1, 1):
        return np.broadcast_to(
            img.reshape(-1, img.shape[2]).mean(axis=0, dtype=np.float64).astype(np.float32), (1, 1, img.shape[2])
        ).copy(), f
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA), f


def assemble_envmap(
    frames_linear: Sequence[np.ndarray],
    intrinsics: Sequence[Intrinsics],
    cams_from_env: Sequence[np.ndarray],
    height: int = 64,
    fill: Callable[[np.ndarray], np.ndarray] | np.ndarray | None = None,
    edge_weight_px: float = 8.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Equirectangular radiance (height, 2 height, 3) from posed linear frames, plus the (height, 2 height) coverage.

    Every map pixel looks through each frame (OpenCV pinhole, ``cam_from_env`` rotation only: the environment is at
    infinity) and averages the frames that see it, weighted by the distance to the image border (feathered seams).
    Directions no frame saw take ``fill``: a callable mapping unit directions (N, 3) -> radiance (N, 3), a full map of
    the same size, or None (zeros). Each frame is area-averaged down to about the map's angular resolution first so
    that the lookup does not alias.
    """
    if not (len(frames_linear) == len(intrinsics) == len(cams_from_env)) or len(frames_linear) == 0:
        raise ValueError("assemble_envmap: need the same non-zero number of frames, intrinsics and poses")
    if height < 2:
        raise ValueError(f"assemble_envmap: height must be >= 2, got {height}")
    width = 2 * height
    dirs = pixel_directions(height, width).reshape(-1, 3)
    acc = np.zeros((dirs.shape[0], 3), dtype=np.float64)
    wsum = np.zeros(dirs.shape[0], dtype=np.float64)
    map_pixel_rad = np.pi / height
    for img, K, R in zip(frames_linear, intrinsics, cams_from_env):
        img = np.asarray(img, dtype=np.float32)
        if img.shape != (K.height, K.width, 3):
            raise ValueError(f"assemble_envmap: frame {img.shape} does not match intrinsics {K.width}x{K.height}")
        R = check_rotation(R, "cam_from_env")
        # Pre-blur to the map's resolution: sigma ~ half a map pixel expressed in image pixels.
        sigma_px = 0.5 * map_pixel_rad * K.fx
        img, reduced_by = _area_reduced(img, sigma_px)  # long focal lengths: area-average first (bounded cost)
        sigma_px /= reduced_by
        if sigma_px > 0.7:
            # scipy's gaussian_filter(mode="nearest", truncate 4) as one OpenCV call (same kernel, replicated
            # border; ~10x faster on a full frame): half of the radius is int(4 sigma + 0.5)
            r = int(4.0 * sigma_px + 0.5)
            img = cv2.GaussianBlur(
                img, (2 * r + 1, 2 * r + 1), sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REPLICATE
            )
        d_cam = dirs @ R.T
        z = d_cam[:, 2]
        front = z > 1e-6  # rays behind or on the camera plane are not seen
        zs = np.where(front, z, 1.0)
        u = K.fx * d_cam[:, 0] / zs + K.cx
        v = K.fy * d_cam[:, 1] / zs + K.cy
        inside = front & (u >= 0) & (u <= K.width - 1) & (v >= 0) & (v <= K.height - 1)
        if not inside.any():
            continue
        ui, vi = u[inside], v[inside]
        ur, vr = (ui + 0.5) * img.shape[1] / K.width - 0.5, (vi + 0.5) * img.shape[0] / K.height - 0.5
        vals = ndimage.map_coordinates(
            img, [np.repeat(vr, 3), np.repeat(ur, 3), np.tile([0, 1, 2], ui.size)], order=1, mode="nearest"
        ).reshape(-1, 3)
        border = np.minimum.reduce([ui, vi, K.width - 1 - ui, K.height - 1 - vi])
        w = np.clip((border + 1.0) / edge_weight_px, 1e-3, 1.0)
        acc[inside] += w[:, None] * vals
        wsum[inside] += w
    seen = wsum > 0
    out = np.zeros_like(acc)
    out[seen] = acc[seen] / wsum[seen, None]
    if fill is not None and (~seen).any():
        if callable(fill):
            out[~seen] = np.asarray(fill(dirs[~seen]), dtype=np.float64).reshape(-1, 3)
        else:
            f = np.asarray(fill, dtype=np.float64)
            if f.shape != (height, width, 3):
                raise ValueError(f"assemble_envmap: fill map must be {(height, width, 3)}, got {f.shape}")
            out[~seen] = f.reshape(-1, 3)[~seen]
    out = np.clip(np.nan_to_num(out, nan=0.0, posinf=0.0), 0.0, None)
    return out.reshape(height, width, 3).astype(np.float32), seen.reshape(height, width)
