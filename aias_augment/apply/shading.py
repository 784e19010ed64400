"""Shading of an inserted object: SH ambient plus a shadowed directional sun, Lambertian, with an optional glossy
dielectric coating (:class:`Coating`: road plastics, painted metal).

Output is linear radiance in the units of the lighting estimate: ``albedo / pi * (E_sh(n) + E_sun max(0, n.l) v)``
with ``E_sh`` the SH irradiance (``sh``), ``E_sun`` the sun's normal-incidence irradiance, ``l`` the sun direction and
``v`` the per-pixel sun visibility (self-shadowing from the renderer; 1 when not given). The 1/pi makes a white
surface under a uniform sky of radiance L show exactly L. Indoor / no dominant sun: ambient only.

Fluorescent orange: road-safety orange (cones, barrels, vests) is daylight-fluorescent paint or plastic: it
absorbs blue-green light and re-emits it as orange, so its luminance factor (about 0.3-0.45, ASTM D4956 / EN 471
orange) exceeds what any non-fluorescent surface of that saturation can reflect (sRGB (255, 72, 18) reflects 0.26 at
most). A texture cannot store reflectance above 1, so albedos of that colour (hue 0-35 deg, saturation >= 0.8, value
>= 0.5, measured on the sRGB-encoded albedo) get the luminance gain of :func:`fluorescent_gain` in
:func:`shade_object`, the one shading function every render path calls; no channel is lifted above 1 (white's
response), so e.g. (208, 64, 16) paint becomes (255, 80, 23)-like while (255, 72, 18) gains little.

Coating: a dielectric's reflection at its surface, colourless, with Schlick's Fresnel term from ``f0`` (0.04 for
plastics and paint, refractive index about 1.5). Of the sun, a GGX microfacet lobe (Smith-Schlick visibility, Walter
et al. 2007): ``F D G / (4 n.v) E_sun v``. Of the sky, the SH ambient seen in the mirror direction r: its irradiance
E_sh(r) / pi is the cosine-weighted mean radiance around r, the reflection of a rough surface. The diffuse part keeps
``1 - F`` of the light. Needs the direction toward the camera at each pixel (:func:`view_directions`).

Materials per part: an asset whose ``meta["parts"]`` lists parts as height bands of its canonical frame (``z_m``
(lo, hi) in the unscaled asset's metres, a ``material`` of :data:`MATERIALS`; ``meta["material"]`` for the rest)
gets the coating per pixel (:func:`part_coating`): the config's coating where the material is glossy (with the
material's roughness), none where it is matte (a rubber base: its grazing Fresnel would mirror the sky). The part of
a pixel is read from the surface point it sees (depth unprojected into the object frame), so the full render and
the view cache's warp take it the same way. A deformed variant (``meta`` "deformation" or "tipped") has moved its
surface off those bands: it keeps the uniform coating.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.analyse.lighting.estimate import LightingEstimate
from aias_augment.analyse.lighting.sh import sh_irradiance
from aias_augment.core.geometry import norm3
from aias_augment.core.srgb import linear_to_srgb

__all__ = [
    "Coating",
    "PixelCoating",
    "SurfaceMaterial",
    "MATERIALS",
    "part_coating",
    "object_coating",
    "points_in_object",
    "shade_object",
    "shade_pixels",
    "irradiance_at_normals",
    "fluorescent_gain",
    "view_directions",
    "FLUORESCENT_GAIN",
]

#: Luminance gain of a fully fluorescent-orange albedo: (255, 72, 18) reflects 0.26; x 1.6 = 0.41, mid-range of the
#: daylight-fluorescent orange luminance factors (0.3-0.45). Read at call time (1.0: off, as the realism report's
#: "fixes off" arm sets it).
FLUORESCENT_GAIN = 1.6


@dataclass(frozen=True)
class Coating:
    """A glossy dielectric surface layer: ``f0`` the reflectance at normal incidence (0: none, matte Lambertian;
    0.04: plastic), ``roughness`` the GGX perceptual roughness (alpha = roughness^2)."""

    f0: float = 0.0
    roughness: float = 0.4

    def __post_init__(self):
        if not (0.0 <= self.f0 <= 0.2 and 0.05 <= self.roughness <= 1.0):
            raise ValueError(f"Coating: f0 in [0, 0.2] and roughness in [0.05, 1], got {self}")

    @property
    def any(self) -> bool:
        return self.f0 > 0

    def at(self, mask: np.ndarray) -> "Coating":
        """The coating of the pixels ``mask`` selects: the same everywhere."""
        return self


@dataclass(frozen=True, eq=False)
class PixelCoating:
    """A coating per pixel: ``f0`` and ``roughness`` arrays of one shape ((H, W) over a window, or (N,) over a list
    of pixels), each pixel's values in :class:`Coating`'s ranges (f0 0: matte there)."""

    f0: np.ndarray
    roughness: np.ndarray

    @property
    def any(self) -> bool:
        return bool(np.any(self.f0 > 0))

    def at(self, mask: np.ndarray) -> "PixelCoating":
        """(N,) arrays of the pixels ``mask`` (H, W) selects."""
        m = np.asarray(mask, bool)
        return PixelCoating(self.f0[m], self.roughness[m])


@dataclass(frozen=True)
class SurfaceMaterial:
    """How a part's surface takes the config's coating: ``glossy`` (the coating's f0) or matte (none), with its own
    GGX ``roughness`` (None: the config's)."""

    glossy: bool
    roughness: float | None = None


#: Surface materials that asset parts name (``meta["parts"][i]["material"]``, ``meta["material"]``).
MATERIALS: dict[str, SurfaceMaterial] = {
    "glossy_plastic": SurfaceMaterial(True),
    # retroreflective sheeting: glass beads or prisms sealed under a smooth acrylic film (index ~1.49: f0 0.04)
    "retroreflective": SurfaceMaterial(True, 0.25),
    "matte_rubber": SurfaceMaterial(False),
}

#: A pixel's surface point is taken to lie in a part's height band within this fraction of the asset's height: the
#: view cache's warp shows a view from up to half a bin away, which moves a point by ~1 % of the object's size.
PART_BAND_TOLERANCE = 0.015


def points_in_object(
    roi: tuple[int, int, int, int], depth: np.ndarray, intrinsics, cam_from_object: np.ndarray
) -> np.ndarray:
    """(h, w, 3) the surface point seen at each pixel centre of the window ``roi`` (x0, y0, x1, y1) at z-depth
    ``depth`` (h, w) metres, in the object frame of ``cam_from_object`` (4x4 rigid)."""
    x0, y0, x1, y1 = roi
    u, v = np.meshgrid(np.arange(x0, x1, dtype=np.float64), np.arange(y0, y1, dtype=np.float64))
    z = np.asarray(depth, np.float64)
    p = np.stack([(u - intrinsics.cx) / intrinsics.fx * z, (v - intrinsics.cy) / intrinsics.fy * z, z], -1)
    T = np.asarray(cam_from_object, np.float64)
    return (p - T[:3, 3]) @ T[:3, :3]  # R^T (p - t), row-wise


def object_coating(asset, cam_from_object: np.ndarray, roi, depth: np.ndarray, intrinsics, coating: Coating):
    """:func:`part_coating` over the render window ``roi`` of ``asset`` (its ``depth`` (h, w) z-depth, 0 where
    uncovered) at ``cam_from_object``: ``coating`` itself for an asset without parts."""
    if not asset.meta.get("parts") or not coating.any:
        return coating
    return part_coating(asset.meta, coating, points_in_object(roi, depth, intrinsics, cam_from_object))


def part_coating(meta: dict, coating: Coating, points_obj: np.ndarray) -> Coating | PixelCoating:
    """The coating at surface points ``points_obj`` (*, 3) of an asset with ``meta`` (see the module docstring):
    ``coating`` itself when the asset names no parts, is deformed, or ``coating`` is none; else a
    :class:`PixelCoating` of shape ``points_obj.shape[:-1]``. Parts are taken in their listed order (the first band
    holding a point wins); a name outside :data:`MATERIALS` is an error."""
    parts = meta.get("parts")
    if not parts or not coating.any or "deformation" in meta or "tipped" in meta:
        return coating

    def material(name):
        if name not in MATERIALS:
            raise ValueError(f"asset material {name!r} is not one of {sorted(MATERIALS)}")
        return MATERIALS[name]

    scale = float(meta.get("scale", 1.0))
    z = np.asarray(points_obj, np.float64)[..., 2] / scale  # the unscaled asset's heights, as the bands are
    tol = PART_BAND_TOLERANCE * float(meta.get("height_m", np.ptp(z) if z.size else 0.0))
    rest = material(meta.get("material", "glossy_plastic"))
    f0 = np.full(z.shape, coating.f0 if rest.glossy else 0.0)
    rough = np.full(z.shape, coating.roughness if rest.roughness is None else rest.roughness)
    free = np.ones(z.shape, bool)
    for part in parts:
        mat = material(part["material"])
        lo, hi = part["z_m"]
        m = free & (z >= lo - tol) & (z <= hi + tol)
        f0[m] = coating.f0 if mat.glossy else 0.0
        rough[m] = coating.roughness if mat.roughness is None else mat.roughness
        free &= ~m
    return PixelCoating(f0, rough)


def view_directions(roi: tuple[int, int, int, int], intrinsics) -> np.ndarray:
    """(h, w, 3) unit vectors in the camera frame from the surface seen at each pixel centre of the window ``roi``
    (x0, y0, x1, y1) toward the camera: minus the pixel's ray."""
    x0, y0, x1, y1 = roi
    u, v = np.meshgrid(np.arange(x0, x1) + 0.5, np.arange(y0, y1) + 0.5)
    ray = np.stack([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones_like(u)], -1)
    return -ray / norm3(ray, keepdims=True)


def _coating_radiance(n, view, lighting: LightingEstimate, sun_visibility, coating: Coating | PixelCoating):
    """(Fresnel weight (N,), reflected radiance (N, 3)) of ``coating`` (one, or (N,) per pixel) at unit normals
    ``n`` seen from ``view``."""
    v = np.asarray(view, dtype=np.float64)
    ndv = np.clip(np.einsum("ij,ij->i", n, v), 1e-3, 1.0)
    coated = np.asarray(coating.f0) > 0  # f0 0 is no coating at all, not a grazing-only one
    fresnel = np.where(coated, coating.f0 + (1.0 - coating.f0) * (1.0 - ndv) ** 5, 0.0)
    mirror = 2.0 * ndv[:, None] * n - v
    out = fresnel[:, None] * sh_irradiance(lighting.ambient_sh, mirror) / np.pi
    if lighting.dominant_sun and lighting.sun_direction_in_cam is not None:
        sun = np.asarray(lighting.sun_direction_in_cam, dtype=np.float64)
        ndl = np.einsum("ij,j->i", n, sun)
        half = sun + v
        half /= np.maximum(norm3(half, keepdims=True), 1e-9)
        ndh = np.clip(np.einsum("ij,ij->i", n, half), 0.0, 1.0)
        vdh = np.clip(np.einsum("ij,ij->i", v, half), 0.0, 1.0)
        a2 = coating.roughness**4
        d = a2 / (np.pi * (ndh**2 * (a2 - 1.0) + 1.0) ** 2)
        k = coating.roughness**2 / 2.0
        g = ndl / (ndl * (1.0 - k) + k) * ndv / (ndv * (1.0 - k) + k)
        f = coating.f0 + (1.0 - coating.f0) * (1.0 - vdh) ** 5
        lobe = np.where((ndl > 0) & coated, f * d * g / (4.0 * ndv), 0.0)
        if sun_visibility is not None:
            lobe = lobe * np.clip(np.asarray(sun_visibility, dtype=np.float64), 0.0, 1.0)
        out = out + lobe[:, None] * np.asarray(lighting.sun_irradiance_rgb, dtype=np.float64)
    return fresnel, out


def irradiance_at_normals(
    normals_in_cam: np.ndarray, lighting: LightingEstimate, sun_visibility: np.ndarray | None = None
) -> np.ndarray:
    """Total irradiance (*, 3) at unit normals (*, 3) in the camera frame."""
    n = np.asarray(normals_in_cam, dtype=np.float64)
    E = sh_irradiance(lighting.ambient_sh, n)
    if lighting.dominant_sun and lighting.sun_direction_in_cam is not None:
        cos = np.maximum(n @ lighting.sun_direction_in_cam, 0.0)
        if sun_visibility is not None:
            cos = cos * np.clip(np.asarray(sun_visibility, dtype=np.float64), 0.0, 1.0)
        E = E + cos[..., None] * lighting.sun_irradiance_rgb
    return E


def fluorescent_gain(albedo_linear: np.ndarray, gain: float = FLUORESCENT_GAIN) -> np.ndarray:
    """(*,) multiplicative gain per albedo (*, 3) linear: ``1 + (gain - 1) w`` with w in [0, 1] the weight of
    daylight-fluorescent orange: full for sRGB hue 0-30 deg, saturation >= 0.9 and value >= 0.6, fading linearly to 0 at
    hue 35 deg, saturation 0.8 and value 0.5. Every other colour (whites, greys, blues, dark or pale oranges): 1."""
    a = np.clip(np.asarray(albedo_linear, dtype=np.float64), 0.0, 1.0)
    c = linear_to_srgb(a, dtype=np.float64)
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    mx, mn = c.max(-1), c.min(-1)
    sat = np.where(mx > 1e-6, (mx - mn) / np.maximum(mx, 1e-6), 0.0)  # eps: black albedo
    hue = 60.0 * (g - b) / np.maximum(mx - mn, 1e-6)  # valid where red is the max
    w = (
        (r >= mx)
        * np.clip((35.0 - hue) / 5.0, 0, 1)
        * (hue >= 0)
        * np.clip((sat - 0.8) / 0.1, 0, 1)
        * np.clip((mx - 0.5) / 0.1, 0, 1)
    )
    return 1.0 + (gain - 1.0) * w


def shade_object(
    albedo_linear: np.ndarray,
    normals_in_cam: np.ndarray,
    mask: np.ndarray,
    lighting: LightingEstimate,
    sun_visibility: np.ndarray | None = None,
    view: np.ndarray | None = None,
    coating: Coating | PixelCoating = Coating(),
) -> np.ndarray:
    """Linear RGB (H, W, 3) float32 of the object (0 outside ``mask``). Normals need not be exactly unit (renormalised);
    zero normals inside the mask get ambient from the up direction rather than NaN. ``view`` (H, W, 3): the
    directions toward the camera (:func:`view_directions`), needed by a ``coating`` with ``f0`` above 0; a
    :class:`PixelCoating` is (H, W)."""
    albedo = np.asarray(albedo_linear, dtype=np.float64)
    n = np.asarray(normals_in_cam, dtype=np.float64)
    m = np.asarray(mask, bool)
    if albedo.ndim != 3 or albedo.shape[2] != 3 or n.shape != albedo.shape or m.shape != albedo.shape[:2]:
        raise ValueError(f"shade_object: albedo {albedo.shape}, normals {n.shape}, mask {m.shape} must match (H, W, 3)")
    if sun_visibility is not None and np.asarray(sun_visibility).shape != m.shape:
        raise ValueError(f"shade_object: sun_visibility must be {m.shape}")
    if not (np.all(np.isfinite(albedo[m])) and np.all(np.isfinite(n[m]))):
        raise ValueError("shade_object: albedo or normals contain NaN or Inf inside the mask")
    out = np.zeros(albedo.shape, np.float32)
    out[m] = shade_pixels(
        albedo[m],
        n[m],
        lighting,
        None if sun_visibility is None else np.asarray(sun_visibility, dtype=np.float64)[m],
        None if view is None else np.asarray(view, dtype=np.float64)[m],
        coating.at(m),
    )
    return out


def shade_pixels(
    albedo_linear: np.ndarray,
    normals_in_cam: np.ndarray,
    lighting: LightingEstimate,
    sun_visibility: np.ndarray | None = None,
    view: np.ndarray | None = None,
    coating: Coating | PixelCoating = Coating(),
) -> np.ndarray:
    """:func:`shade_object` on a list of pixels: albedo (N, 3), normals (N, 3) (renormalised; a zero normal gets
    the up direction), sun visibility (N,) or None, directions toward the camera (N, 3) or None, a
    :class:`PixelCoating` (N,) or one :class:`Coating` -> (N, 3) float32
    linear radiance (non-finite results as 0). The caller checks finiteness (``shade_object`` does)."""
    n = np.asarray(normals_in_cam, dtype=np.float64)
    length = np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    n = np.where(length > 1e-6, n / np.maximum(length, 1e-6), lighting.up_in_cam)  # eps: degenerate normals
    E = irradiance_at_normals(n, lighting, sun_visibility)
    a = np.clip(np.asarray(albedo_linear, dtype=np.float64), 0.0, None)
    # the gain never lifts a channel above white's response (albedo 1): the saturation guard on white holds for it
    a = np.minimum(a * fluorescent_gain(a, FLUORESCENT_GAIN)[:, None], np.maximum(a, 1.0))
    out = a * E / np.pi
    if coating.any:
        if view is None:
            raise ValueError("shade_pixels: a coating needs the view directions")
        fresnel, reflected = _coating_radiance(n, view, lighting, sun_visibility, coating)
        out = out * (1.0 - fresnel)[:, None] + reflected
    return np.nan_to_num(out, nan=0.0, posinf=0.0).astype(np.float32)
