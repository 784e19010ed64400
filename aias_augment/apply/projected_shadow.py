"""The fast shadow: the object's silhouette projected along the sun onto its ground plane, without a GL call.

The sun visibility of a ground point is 0 inside the union of the object's triangles projected along the sun onto
z = 0 (object frame), 1 outside: each triangle that faces the sun is projected, mapped into the image and filled
(OpenCV, at 4x4 sub-pixels: the visibility at the edge is the pixel's uncovered fraction). The ground patch, its window and its z-depth are the shadow catcher's
(:func:`aias_augment.apply.render.render_ground_shadow`), computed analytically (ray-plane intersection per pixel). The
penumbra is added downstream (``soften_shadow``), as for the catcher.
"""

from __future__ import annotations

import cv2
import numpy as np

from aias_augment.apply.render import ShadowLayers, shadow_window, unit_sun
from aias_augment.assets.asset import Asset
from aias_augment.core.geometry import Intrinsics, check_rigid

#: A sun ray grazing the horizon is followed at most this far (m), as in the catcher's window.
MAX_SHADOW_REACH_M = 60.0
#: Sub-pixels per pixel side used to fill the projected triangles (coverage -> visibility at the shadow's edge).
SUPERSAMPLE = 4


def shadow_triangles(asset: Asset, sun_in_object: np.ndarray) -> np.ndarray:
    """(F, 3, 3) the asset's sun-facing triangles (all of them for an open mesh's two sides: a triangle facing away
    is skipped only when the mesh is watertight) projected along the unit sun onto z = 0, in the object frame."""
    out = []
    # A scaled asset's triangles are its root's times the scale (the same products as its own vertices): the root's
    # meshes keep trimesh's caches (triangles, watertightness), a per-sample scaled copy would recompute them.
    root, scale = (asset.render_root, float(asset.render_scale)) if asset.render_root is not None else (asset, 1.0)
    if len(root.meshes) != len(asset.meshes):
        root, scale = asset, 1.0
    from aias_augment.assets.bank.procedural import ConeMeshes  # trimesh: loaded with the meshes anyway

    meshes = root.meshes
    if isinstance(meshes, ConeMeshes):  # a family cone: its mesh's triangles, without building it (never watertight)
        parts = [(meshes.triangles(), False)]
    else:
        parts = [(np.asarray(m.triangles, np.float64), m.is_watertight) for m in meshes]
    for tri, watertight in parts:
        if len(tri) == 0:
            continue
        if scale != 1.0:
            tri = tri * scale
        if watertight:  # a closed surface's shadow is the shadow of its sun-facing half
            n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            tri = tri[n @ sun_in_object > 0]
        t = np.minimum(np.clip(tri[..., 2:3], 0.0, None) / sun_in_object[2], MAX_SHADOW_REACH_M)
        out.append(tri - t * sun_in_object)
    return np.concatenate(out) if out else np.zeros((0, 3, 3))


def projected_ground_shadow(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    sun_direction_in_object: np.ndarray,
    *,
    znear: float = 0.05,
) -> ShadowLayers:
    """:class:`ShadowLayers` of the window (as ``render_ground_shadow(..., window=True)``) with the projected
    silhouette as the sun visibility (0 in the shadow, 1 elsewhere)."""
    return projected_ground(asset, cam_from_object, intrinsics, sun_direction_in_object, znear=znear)[0]


def projected_ground(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    sun_direction_in_object: np.ndarray,
    *,
    znear: float = 0.05,
) -> tuple[ShadowLayers, np.ndarray]:
    """(:func:`projected_ground_shadow`'s layers, (N, 2) the object-frame x, y of the ground point seen by each pixel
    of the ground patch, in the row-major order of ``ground_mask``): the ray-plane intersection gives both."""
    T = check_rigid(cam_from_object, "cam_from_object")
    sun = unit_sun(sun_direction_in_object)
    roi, radius = shadow_window(asset, T, intrinsics, sun, znear)
    x0, y0, x1, y1 = roi
    if x1 <= x0 or y1 <= y0:
        z = np.zeros((0, 0), np.float32)
        return ShadowLayers(np.ones((0, 0), np.float32), np.zeros((0, 0), bool), z, (0, 0, 0, 0)), np.zeros((0, 2))
    K = intrinsics
    # The ray of pixel (u, v) is (a_u, b_v, 1) (z = 1: lambda is z-depth); everything linear in the ray is a sum of a
    # column term and a row term, so no (H, W, 3) array is built.
    a = ((np.arange(x0, x1, dtype=np.float64) - K.cx) / K.fx)[None, :]
    b = ((np.arange(y0, y1, dtype=np.float64) - K.cy) / K.fy)[:, None]
    R, t = T[:3, :3], T[:3, 3]
    n = R[:, 2]  # the ground's normal (object z) in the camera
    denom = a * n[0] + (b * n[1] + n[2])
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(np.abs(denom) > 1e-12, (n @ t) / denom, -1.0)
    hit = lam > znear
    tR = t @ R
    px = lam * (a * R[0, 0] + (b * R[1, 0] + R[2, 0])) - tR[0]  # R^T (lambda ray - t), x and y
    py = lam * (a * R[0, 1] + (b * R[1, 1] + R[2, 1])) - tR[1]
    on_patch = hit & (np.abs(px) <= radius) & (np.abs(py) <= radius)
    depth = np.where(on_patch, lam, 0.0).astype(np.float32)
    vis = np.ones(on_patch.shape, np.float32)
    if sun[2] > 0.02 and on_patch.any():
        tri = shadow_triangles(asset, sun).reshape(-1, 3) @ R.T + t  # on the ground, in the camera
        z = tri[:, 2].reshape(-1, 3)
        front = np.all(z > znear, axis=1)  # a triangle reaching behind the camera is skipped (the window is ahead)
        uv = (tri[:, :2] / np.maximum(tri[:, 2:3], znear) * [K.fx, K.fy] + [K.cx - x0, K.cy - y0]).reshape(-1, 3, 2)
        # Filled at SUPERSAMPLE x the resolution, then averaged: the coverage of each pixel (a soft, unbiased edge).
        ss = SUPERSAMPLE
        pts = np.round((ss * (uv[front] + 0.5) - 0.5) * 16).astype(np.int32)
        h, w = on_patch.shape
        mask = np.zeros((h * ss, w * ss), np.uint8)
        for p in pts:
            cv2.fillConvexPoly(mask, p, 1, lineType=cv2.LINE_8, shift=4)
        # each pixel's share of its ss x ss block (an area resize: exact sums of 0 and 1 times 1 / ss^2)
        cover = cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
        vis = np.where(on_patch, 1.0 - cover, 1.0).astype(np.float32)
    return ShadowLayers(vis, on_patch, depth, roi), np.stack([px[on_patch], py[on_patch]], -1)
