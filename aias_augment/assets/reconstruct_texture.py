"""A reconstructed hull coloured from the photos it was carved from (part 3 of :mod:`aias_augment.assets.reconstruct`).

:func:`texture_from_views` gives each vertex the colours of the views that see it (the hull's own depth, drawn by
the ``render`` callable passed in, decides visibility), weighted by how squarely each view faces it;
:func:`texture_atlas_from_views` bakes a UV atlas (``xatlas``) the same way, so the colour detail no longer depends
on how many vertices the (decimated) hull keeps.
"""

from __future__ import annotations

import cv2
import numpy as np

from aias_augment.assets.asset import Asset
from aias_augment.assets.rendering import RenderObject
from aias_augment.assets.view_masks import View

__all__ = ["sample_bilinear", "texture_atlas_from_views", "texture_from_views", "view_visibility"]


def sample_bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``img`` (H, W[, C]) sampled at (u, v) (pixel centres at integers; clamped to the image), bilinearly."""
    h, w = img.shape[:2]
    u = np.clip(u, 0, w - 1)
    v = np.clip(v, 0, h - 1)
    u0 = np.minimum(np.floor(u).astype(int), w - 2)
    v0 = np.minimum(np.floor(v).astype(int), h - 2)
    fu, fv = u - u0, v - v0
    if img.ndim == 3:
        fu, fv = fu[:, None], fv[:, None]
    top = img[v0, u0] * (1 - fu) + img[v0, u0 + 1] * fu
    bot = img[v0 + 1, u0] * (1 - fu) + img[v0 + 1, u0 + 1] * fu
    return top * (1 - fv) + bot * fv


def view_visibility(points, normals, mesh, views: list[View], ssaa: int = 1, *, render: RenderObject):
    """For each view, which of the surface points (``points``, ``normals``: (N, 3), object frame) it sees: in its
    image, facing it, inside its mask and in front of ``mesh``'s own depth as ``render`` draws it. Yields (view, u,
    v, seen, cos of the angle between the normal and the direction to the camera) per view."""
    import trimesh

    plain = Asset("hull", "object", (trimesh.Trimesh(mesh.vertices, mesh.faces, process=False),), "reconstruction")
    V, N = np.asarray(points, float), np.asarray(normals, float)
    for v in views:
        T = np.asarray(v.cam_from_object, float)
        pc = V @ T[:3, :3].T + T[:3, 3]
        K = v.intrinsics
        u = K.fx * pc[:, 0] / pc[:, 2] + K.cx
        w = K.fy * pc[:, 1] / pc[:, 2] + K.cy
        cam = -T[:3, :3].T @ T[:3, 3]
        to_cam = cam[None, :] - V
        to_cam /= np.linalg.norm(to_cam, axis=1, keepdims=True)
        cosang = np.einsum("ij,ij->i", N, to_cam)
        depth = render(plain, T, K, ssaa=ssaa, znear=0.01, zfar=1000.0, with_normals=False).depth
        h, wd = depth.shape
        ui, wi = np.round(u).astype(int), np.round(w).astype(int)
        ok = (cosang > 0.1) & (ui >= 0) & (ui < wd) & (wi >= 0) & (wi < h) & (pc[:, 2] > 0)
        d = np.zeros(len(V))
        d[ok] = depth[wi[ok], ui[ok]]
        ok &= (d > 0) & (np.abs(d - pc[:, 2]) < 0.01 * pc[:, 2] + 0.005)
        ok &= np.asarray(v.mask, bool)[np.clip(wi, 0, h - 1), np.clip(ui, 0, wd - 1)]
        yield v, u, w, ok, cosang


def _colours_from_views(points, normals, mesh, views: list[View], ssaa: int = 1, *, render: RenderObject):
    """Colour of each surface point (``points``, ``normals``: (N, 3), object frame) from the views that see it
    (:func:`_visibility`), weighted by cos^2 of the angle between the normal and the direction to the camera.
    Returns (N, 3) float sRGB colours and the (N,) mask of points some view saw."""
    V = np.asarray(points, float)
    acc = np.zeros((len(V), 3))
    wsum = np.zeros(len(V))
    for v, u, w, ok, cosang in view_visibility(points, normals, mesh, views, ssaa, render=render):
        if not ok.any():
            continue
        col = sample_bilinear(v.image_rgb.astype(np.float32), u[ok], w[ok])
        wgt = cosang[ok] ** 2
        acc[ok] += wgt[:, None] * col
        wsum[ok] += wgt
    seen = wsum > 0
    colours = np.full((len(V), 3), 128.0)
    colours[seen] = acc[seen] / wsum[seen, None]
    return colours, seen


def texture_from_views(mesh, views: list[View], ssaa: int = 1, *, render: RenderObject):
    """``mesh`` with vertex colours from the views that see each vertex (:func:`_colours_from_views`). The colour
    detail is the vertices' spacing: a decimated hull keeps its shape but blurs its colours (use
    :func:`texture_atlas_from_views` for those)."""
    import trimesh

    colours, seen = _colours_from_views(mesh.vertices, mesh.vertex_normals, mesh, views, ssaa, render=render)
    out = mesh.copy()
    out.visual = trimesh.visual.ColorVisuals(
        out, vertex_colors=np.c_[np.clip(colours + 0.5, 0, 255).astype(np.uint8), np.full(len(colours), 255, np.uint8)]
    )
    return out, float(seen.mean())


def _texel_samples(uv: np.ndarray, faces: np.ndarray, size: int):
    """Which face covers each texel of a ``size`` x ``size`` atlas (``uv`` per vertex, v up, as glTF reads it) and
    its barycentric weights there: (rows, cols, face index, (K, 3) weights) of the covered texels."""
    owner = np.full((size, size), -1, np.int32)
    px = np.stack([uv[:, 0] * size, (1.0 - uv[:, 1]) * size], axis=1)
    for f, tri in enumerate(faces):  # OpenCV draws the face's texels with its index
        cv2.fillConvexPoly(owner, np.round(px[tri] * 16).astype(np.int32), int(f), lineType=cv2.LINE_8, shift=4)
    rows, cols = np.nonzero(owner >= 0)
    fi = owner[rows, cols]
    a, b, c = (px[faces[fi, k]] for k in range(3))
    p = np.stack([cols + 0.5, rows + 0.5], axis=1)
    m = np.stack([b - a, c - a], axis=2)  # (K, 2, 2): columns are the edges
    det = m[:, 0, 0] * m[:, 1, 1] - m[:, 0, 1] * m[:, 1, 0]
    det = np.where(np.abs(det) < 1e-12, 1e-12, det)
    d = p - a
    l1 = (d[:, 0] * m[:, 1, 1] - d[:, 1] * m[:, 0, 1]) / det
    l2 = (m[:, 0, 0] * d[:, 1] - m[:, 1, 0] * d[:, 0]) / det
    bary = np.clip(np.stack([1 - l1 - l2, l1, l2], axis=1), 0.0, 1.0)  # texel centres just outside a drawn edge
    bary /= bary.sum(axis=1, keepdims=True)
    return rows, cols, fi, bary


def texture_atlas_from_views(mesh, views: list[View], size: int, ssaa: int = 1, *, render: RenderObject):
    """``mesh`` with a ``size`` x ``size`` texture baked from the views: a UV atlas by ``xatlas``, each covered
    texel's surface point coloured like a vertex (:func:`_colours_from_views`), every other texel (gutters between
    charts, and texels no view saw) given its nearest seen texel's colour so that filtering at chart edges draws no
    seam. The colour detail is the atlas's, not the vertices': a decimated hull keeps it."""
    import trimesh
    import xatlas
    from PIL import Image

    vmap, faces, uv = xatlas.parametrize(np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.uint32))
    verts = np.asarray(mesh.vertices, float)[vmap]
    rows, cols, fi, bary = _texel_samples(np.asarray(uv, float), faces, size)
    tri = verts[faces[fi]]  # (K, 3, 3)
    points = np.einsum("kj,kjd->kd", bary, tri)
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # xatlas keeps each face's winding
    normals = face_n / np.maximum(np.linalg.norm(face_n, axis=1, keepdims=True), 1e-12)
    colours, seen = _colours_from_views(points, normals, mesh, views, ssaa, render=render)
    img = np.zeros((size, size, 3), np.float32)
    valid = np.zeros((size, size), bool)
    img[rows[seen], cols[seen]] = colours[seen]
    valid[rows[seen], cols[seen]] = True
    if not valid.any():
        img[:] = 128.0
    else:  # nearest seen texel for the rest (OpenCV's distance transform, labelled by the nearest zero pixel)
        _, labels = cv2.distanceTransformWithLabels(
            (~valid).astype(np.uint8), cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL
        )
        vr, vc = np.nonzero(valid)
        lut = np.zeros((labels.max() + 1, 2), np.int64)
        lut[labels[vr, vc]] = np.stack([vr, vc], axis=1)
        src = lut[labels[~valid]]
        img[~valid] = img[src[:, 0], src[:, 1]]
    image = Image.fromarray(np.clip(img + 0.5, 0, 255).astype(np.uint8))
    out = trimesh.Trimesh(verts, faces, process=False)
    material = trimesh.visual.material.PBRMaterial(  # a plain image material would scale the texture by its grey
        baseColorTexture=image, baseColorFactor=[255, 255, 255, 255], metallicFactor=0.0, roughnessFactor=1.0
    )
    out.visual = trimesh.visual.TextureVisuals(uv=np.asarray(uv, float), material=material)
    covered_seen = float(seen.mean()) if len(seen) else 0.0
    return out, covered_seen
