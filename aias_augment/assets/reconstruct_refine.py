"""Photo-consistency refinement of a visual hull: its vertices moved inward to where the views agree on the
surface's texture (a plane sweep along each normal scored by normalised cross-correlation). A visual hull cannot see
concavities that no silhouette shows; textureless surfaces give the sweep nothing to match and stay where the hull
put them.
"""

from __future__ import annotations

import cv2
import numpy as np

from aias_augment.assets.reconstruct_texture import sample_bilinear, view_visibility
from aias_augment.assets.rendering import RenderObject
from aias_augment.assets.view_masks import View

__all__ = ["refine_photo_consistent"]


def _project(points: np.ndarray, v: View) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixel coordinates (u, v) and depth of ``points`` (..., 3) in view ``v``."""
    T = np.asarray(v.cam_from_object, float)
    pc = points @ T[:3, :3].T + T[:3, 3]
    z = np.maximum(pc[..., 2], 1e-9)
    K = v.intrinsics
    return K.fx * pc[..., 0] / z + K.cx, K.fy * pc[..., 1] / z + K.cy, pc[..., 2]


def _ncc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation of patches along the last axis (NaN where either patch is flat)."""
    a = a - a.mean(axis=-1, keepdims=True)
    b = b - b.mean(axis=-1, keepdims=True)
    den = np.sqrt((a * a).sum(axis=-1) * (b * b).sum(axis=-1))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 1e-6, (a * b).sum(axis=-1) / den, np.nan)


def refine_photo_consistent(mesh, views: list[View], cfg, ssaa: int = 1, *, render: RenderObject):
    """The hull's vertices moved inward along their normals to where the views agree on the surface's texture: a
    plane sweep per vertex. A visual hull holds the object, so the surface lies at or inside it; for each depth d
    in [0, ``refine_depth`` x the hull's largest extent], a square patch (2 ``refine_patch_radius`` + 1 samples a
    side) on the plane through v - d n, tangent to the hull, one pixel of the vertex's reference view (the one
    facing it most squarely) per sample, is projected into every view that sees the vertex and compared with the reference's patch by
    normalised cross-correlation; the depth's score is the mean of its ``refine_top_views`` best views (a view
    that sees the hull's surface there may not see the object's, e.g. the bottom of a hole seen from the side).
    A vertex moves to its best depth when that score is at least ``refine_min_ncc`` and beats the hull's own (d = 0)
    by ``refine_min_gain``; patches flatter than ``refine_min_std`` grey levels (no texture to match) stay. The
    displacements are then smoothed by a median over each vertex's ring, twice, so lone outliers go. Same faces: a closed hull stays closed.
    ``cfg``: a :class:`~aias_augment.assets.reconstruct.ReconstructConfig`; ``render`` draws the hull's depth for
    the visibility. Returns (mesh, {"moved_share", "median_moved_m", "max_moved_m"})."""
    import trimesh

    V = np.asarray(mesh.vertices, float)
    N = np.asarray(mesh.vertex_normals, float)
    n_v = len(V)
    extent = float(np.max(V.max(axis=0) - V.min(axis=0)))
    grey = [cv2.cvtColor(v.image_rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) for v in views]
    vis = [(ok, cosang) for _, _, _, ok, cosang in view_visibility(V, N, mesh, views, ssaa, render=render)]
    seen = np.stack([ok for ok, _ in vis])  # (views, vertices)
    facing = np.where(seen, np.stack([c for _, c in vis]), -np.inf)
    ref = np.argmax(facing, axis=0)
    # tangent frame of each vertex
    helper = np.where(np.abs(N[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    t1 = np.cross(N, helper)
    t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-12)
    t2 = np.cross(N, t1)
    half = cfg.refine_patch_radius
    ab = np.stack(np.meshgrid(np.arange(-half, half + 1), np.arange(-half, half + 1)), -1).reshape(-1, 2)  # (P, 2)
    step = extent / cfg.resolution / 2  # half a voxel of the hull's grid
    depths = np.arange(0.0, cfg.refine_depth * extent + 1e-12, step)  # (D,)
    best = np.zeros(n_v)
    owned = [np.nonzero((ref == r) & (seen.sum(axis=0) >= 2))[0] for r in range(len(views))]
    for r, idx in ((r, c) for r, own in enumerate(owned) for c in np.array_split(own, max(1, -(-len(own) // 1024)))):
        if not len(idx):
            continue
        vr = views[r]
        _, _, z = _project(V[idx], vr)
        px = z / vr.intrinsics.fx  # metres per pixel at the vertex in its reference view
        offs = ab[None, :, 0:1] * t1[idx, None] + ab[None, :, 1:2] * t2[idx, None]  # (n, P, 3)
        pts = (V[idx, None, None] - depths[None, :, None, None] * N[idx, None, None]) + (px[:, None, None] * offs)[
            :, None
        ]  # (n, D, P, 3)
        u, w, _ = _project(pts, vr)
        ref_patch = sample_bilinear(grey[r], u.ravel(), w.ravel()).reshape(u.shape)
        textured = ref_patch[:, 0].std(axis=-1) >= cfg.refine_min_std  # the hull's own patch has texture to match
        scores = np.full((len(views), len(idx), len(depths)), np.nan, np.float32)
        for k, vk in enumerate(views):
            sel = seen[k, idx] & (k != r)
            if not sel.any():
                continue
            u, w, z = _project(pts[sel], vk)
            inside = (u >= 0) & (u <= vk.intrinsics.width - 1) & (w >= 0) & (w <= vk.intrinsics.height - 1) & (z > 0)
            patch = sample_bilinear(grey[k], u.ravel(), w.ravel()).reshape(u.shape)
            ncc = _ncc(ref_patch[sel], patch)
            ncc[~inside.all(axis=-1)] = np.nan
            scores[k, sel] = ncc
        top = np.sort(np.where(np.isnan(scores), -np.inf, scores), axis=0)[::-1][: cfg.refine_top_views]  # (t, n, D)
        score = np.where(np.isfinite(top).all(axis=0), top.mean(axis=0), np.nan)
        k_best = np.argmax(np.where(np.isnan(score), -np.inf, score), axis=1)
        s_best = score[np.arange(len(idx)), k_best]
        s_zero = np.where(np.isnan(score[:, 0]), -1.0, score[:, 0])
        move = textured & (s_best >= cfg.refine_min_ncc) & (s_best - s_zero >= cfg.refine_min_gain)
        best[idx[move]] = depths[k_best[move]]
    # median over each vertex's one-ring (with itself), twice
    nbrs = mesh.vertex_neighbors
    for _ in range(2):
        best = np.array([np.median(np.r_[best[i], best[nbrs[i]]]) for i in range(n_v)])
    out = trimesh.Trimesh(V - best[:, None] * N, np.asarray(mesh.faces), process=False)
    moved = best > 0
    return out, {
        "moved_share": round(float(moved.mean()), 4),
        "median_moved_m": round(float(np.median(best[moved])), 5) if moved.any() else 0.0,
        "max_moved_m": round(float(best.max()), 5),
    }
