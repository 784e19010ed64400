"""Shading of an inserted object: SH ambient plus a shadowed directional sun, Lambertian.

Output is linear radiance in the units of the lighting estimate: ``albedo / pi * (E_sh(n) + E_sun max(0, n.l) v)``
with ``E_sh`` the SH irradiance (``sh``), ``E_sun`` the sun's normal-incidence irradiance, ``l`` the sun direction and
``v`` the per-pixel sun visibility (self-shadowing from the renderer; 1 when not given). The 1/pi makes a white
surface under a uniform sky of radiance L show exactly L. Indoor / no dominant sun: ambient only.
"""
from __future__ import annotations

import numpy as np

from .estimate import LightingEstimate
from .sh import sh_irradiance

__all__ = ["shade_object", "irradiance_at_normals"]


def irradiance_at_normals(normals_in_cam: np.ndarray, lighting: LightingEstimate,
                          sun_visibility: np.ndarray | None = None) -> np.ndarray:
    """Total irradiance (*, 3) at unit normals (*, 3) in the camera frame."""
    n = np.asarray(normals_in_cam, dtype=np.float64)
    E = sh_irradiance(lighting.ambient_sh, n)
    if lighting.dominant_sun and lighting.sun_direction_in_cam is not None:
        cos = np.maximum(n @ lighting.sun_direction_in_cam, 0.0)
        if sun_visibility is not None:
            cos = cos * np.clip(np.asarray(sun_visibility, dtype=np.float64), 0.0, 1.0)
        E = E + cos[..., None] * lighting.sun_irradiance_rgb
    return E


def shade_object(albedo_linear: np.ndarray, normals_in_cam: np.ndarray, mask: np.ndarray, lighting: LightingEstimate,
                 sun_visibility: np.ndarray | None = None) -> np.ndarray:
    """Linear RGB (H, W, 3) float32 of the object (0 outside ``mask``). Normals need not be exactly unit (renormalised);
    zero normals inside the mask get ambient from the up direction rather than NaN."""
    albedo = np.asarray(albedo_linear, dtype=np.float64)
    n = np.asarray(normals_in_cam, dtype=np.float64)
    m = np.asarray(mask, bool)
    if albedo.ndim != 3 or albedo.shape[2] != 3 or n.shape != albedo.shape or m.shape != albedo.shape[:2]:
        raise ValueError(f"shade_object: albedo {albedo.shape}, normals {n.shape}, mask {m.shape} must match (H, W, 3)")
    if sun_visibility is not None and np.asarray(sun_visibility).shape != m.shape:
        raise ValueError(f"shade_object: sun_visibility must be {m.shape}")
    if not (np.all(np.isfinite(albedo[m])) and np.all(np.isfinite(n[m]))):
        raise ValueError("shade_object: albedo or normals contain NaN or Inf inside the mask")
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(length > 1e-6, n / np.maximum(length, 1e-6), lighting.up_in_cam)  # eps: degenerate normals
    out = np.zeros_like(albedo)
    vis = None if sun_visibility is None else np.asarray(sun_visibility, dtype=np.float64)[m]
    E = irradiance_at_normals(n[m], lighting, vis)
    out[m] = np.clip(albedo[m], 0.0, None) * E / np.pi
    return np.nan_to_num(out, nan=0.0, posinf=0.0).astype(np.float32)
