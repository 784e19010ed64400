"""An analytic ray-cast scene for lighting tests: axis-aligned boxes on a flat ground under a sun and a uniform sky.

Independent of the code under test: it only knows geometry and Lambert's law. World = the gravity-aligned camera frame
(OpenCV: x right, y down, z forward), ground plane y = camera_height_m, camera at the origin looking along +z, pitched
down by ``pitch_deg``. A point with normal n receives ``sky x (1 + n_up) / 2 + sun x max(0, n . s) x visible``
(``visible``: the ray toward the sun misses every box) and shows ``albedo x that / pi``; sky pixels show a blue sky
brighter toward the horizon. Output: sRGB uint8.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.analyse.lighting.envmap import camera_ray_directions
from aias_augment.core.geometry import Intrinsics, rotation_about_axis
from aias_augment.core.hdr import linear_to_srgb


@dataclass(frozen=True)
class Box:
    lo: tuple[float, float, float]  # (x, y, z) min corner in the world (y down: the top has the smaller y)
    hi: tuple[float, float, float]
    albedo: tuple[float, float, float] = (0.5, 0.5, 0.5)
    stripe_m: float = 0.0  # > 0: horizontal darker stripes every stripe_m metres of height (floors, window rows)


def sun_direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Toward the sun in the world frame; azimuth atan2(forward, right) in degrees (0 = right, 90 = ahead)."""
    a, e = np.deg2rad(azimuth_deg), np.deg2rad(elevation_deg)
    return np.array([np.cos(e) * np.cos(a), -np.sin(e), np.cos(e) * np.sin(a)])


def _hit_boxes(origins: np.ndarray, dirs: np.ndarray, boxes: list[Box]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest box hit along each ray: distance (P,) (inf = none), box index (P,), outward normal (P, 3)."""
    P = len(dirs)
    best_t = np.full(P, np.inf)
    best_k = np.full(P, -1)
    best_n = np.zeros((P, 3))
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / dirs
        for k, b in enumerate(boxes):
            t1 = (np.asarray(b.lo) - origins) * inv
            t2 = (np.asarray(b.hi) - origins) * inv
            tmin = np.nanmax(np.minimum(t1, t2), axis=1)
            tmax = np.nanmin(np.maximum(t1, t2), axis=1)
            hit = (tmax >= tmin) & (tmin > 1e-6) & (tmin < best_t)
            axis = np.argmax(np.minimum(t1, t2), axis=1)
            n = np.zeros((P, 3))
            n[np.arange(P), axis] = -np.sign(dirs[np.arange(P), axis])
            best_t = np.where(hit, tmin, best_t)
            best_k = np.where(hit, k, best_k)
            best_n = np.where(hit[:, None], n, best_n)
    return best_t, best_k, best_n


def render(
    boxes: list[Box],
    sun_dir: np.ndarray,
    intrinsics: Intrinsics,
    camera_height_m: float = 1.65,
    pitch_deg: float = 0.0,
    sun_irradiance: float = 6.0,
    sky_irradiance: float = 1.0,
    ground_albedo: tuple[float, float, float] = (0.35, 0.33, 0.3),
    exposure: float = 1.6,
    rng: np.random.Generator | None = None,
    noise: float = 0.03,
) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) uint8 image and the cam_from_world rotation (3, 3) of the pitched camera."""
    s = np.asarray(sun_dir, dtype=np.float64) / np.linalg.norm(sun_dir)
    cam_from_world = rotation_about_axis(
        np.array([1.0, 0.0, 0.0]), np.deg2rad(pitch_deg)
    )  # pitch down: forward tilts to +y
    rays = camera_ray_directions(intrinsics).reshape(-1, 3) @ cam_from_world  # world = R^T cam
    P = len(rays)
    origin = np.zeros((P, 3))
    t_box, k_box, n_box = _hit_boxes(origin, rays, boxes)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = np.where(rays[:, 1] > 1e-9, camera_height_m / rays[:, 1], np.inf)
    ground = np.isfinite(t_ground) & (t_ground < t_box)
    on_box = np.isfinite(t_box) & ~ground
    t = np.where(ground, t_ground, np.where(on_box, t_box, 0.0))
    pts = rays * t[:, None]
    normal = np.where(ground[:, None], np.array([0.0, -1.0, 0.0]), n_box)
    albedo = np.tile(np.asarray(ground_albedo), (P, 1))
    for k, b in enumerate(boxes):
        sel = on_box & (k_box == k)
        a = np.tile(np.asarray(b.albedo), (int(sel.sum()), 1))
        if b.stripe_m > 0:
            height = camera_height_m - pts[sel, 1]
            a = a * np.where((height % b.stripe_m) < 0.25 * b.stripe_m, 0.45, 1.0)[:, None]
        albedo[sel] = a
    lit = ground | on_box
    shadow_t, _, _ = _hit_boxes(pts[lit] + 1e-4 * normal[lit], np.tile(s, (int(lit.sum()), 1)), boxes)
    visible = np.zeros(P, bool)
    visible[lit] = ~np.isfinite(shadow_t)
    n_up = -normal[:, 1]
    E = sky_irradiance * 0.5 * (1.0 + n_up) + sun_irradiance * np.maximum(normal @ s, 0.0) * visible
    rgb = albedo * E[:, None] / np.pi
    rng = np.random.default_rng(0) if rng is None else rng
    rgb = rgb * (1.0 + noise * rng.standard_normal((P, 1)))
    elev = np.clip(-rays[:, 1], 0.0, 1.0)
    sky = np.array([0.25, 0.45, 0.9]) * (0.6 + 0.4 * (1.0 - elev))[:, None] * 0.35
    rgb = np.where(lit[:, None], rgb, sky)
    img = np.round(linear_to_srgb(np.clip(rgb * exposure, 0.0, 1.0)) * 255.0).astype(np.uint8)
    return img.reshape(intrinsics.height, intrinsics.width, 3), cam_from_world
