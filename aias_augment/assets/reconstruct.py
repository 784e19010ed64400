"""An asset from posed photos of an object: its visual hull, cleaned, textured from the views, in metres.

1. :func:`visual_hull`: every view's silhouette becomes a signed distance (pixels to its boundary, positive
   outside, by OpenCV's distance transform), turned into metres at each voxel's depth (``d_px * z / f``). A point
   is inside the hull when it is inside every silhouette, so the field is the maximum over the views; its zero
   level, found by marching cubes (scikit-image), is the hull's surface with sub-voxel accuracy. The grid is first
   coarse over the box the caller gives, then fine over the occupied part.
2. Cleaned: the largest connected component, holes filled, oriented outward, resting on z = 0; with
   ``max_faces``, decimated by quadric error (``fast-simplification``, through trimesh) before texturing, so the
   colours are sampled on the vertices the asset keeps.
3. :func:`texture_from_views`: each vertex takes the colours of the views that see it (the hull's own depth,
   rendered by :mod:`aias_augment.apply.render`, decides visibility), weighted by how squarely each view faces it.
   With ``texture_px``, a UV atlas (``xatlas``) is baked instead: each texel's surface point is coloured the same
   way, so the colour detail no longer depends on how many vertices the (decimated) hull keeps.

Without poses, :func:`reconstruct_unposed` estimates them by structure from motion (:mod:`aias_augment.assets.sfm`)
and leaves out the views that the others contradict (:func:`consistent_views`: a mis-registered view would carve
the object away).

Poses in metres give a metric asset; otherwise ``height_m`` scales it. A visual hull cannot see concavities that
no silhouette shows (the inside of a bowl, a block's pits): with ``refine``, :func:`refine_photo_consistent` moves
its vertices inward to where the views agree on the surface's texture (a plane sweep along each normal scored by
normalised cross-correlation). Textureless surfaces give it nothing to match and stay where the hull put them.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from aias_augment.assets.asset import Asset, normalise_meshes
from aias_augment.assets.reconstruct_quality import check_height, check_hull
from aias_augment.assets.view_masks import View
from aias_augment.assets.view_masks import signed_distance_px as _signed_distance_px
from aias_augment.assets.views_file import read_views as _read_views_file
from aias_augment.core.config import checked_config
from aias_augment.core.geometry import Intrinsics


@checked_config(
    {
        "resolution": "[16, 512]",
        "coarse_resolution": "[8, 128]",
        "padding_voxels": "[1, 16]",
        "max_faces": "[100, inf)",
        "texture_px": "[16, 2048]",
        "refine_depth": "(0, 1]",
        "refine_patch_radius": "[1, 15]",
        "refine_top_views": "[1, 64]",
        "refine_min_ncc": "[-1, 1]",
        "refine_min_gain": "[0, 2]",
        "refine_min_std": "[0, inf)",
        "min_view_iou": "[0, 1]",
        "min_view_spread_deg": "[0, 180]",
        "max_reprojection_px": "(0, inf)",
        "size_slack": "[1, inf)",
    }
)
@dataclass(frozen=True)
class ReconstructConfig:
    resolution: int = 128  # voxels along the longest side of the occupied box
    coarse_resolution: int = 32  # first pass over the search box
    padding_voxels: int = 3
    # Quadric decimation of the cleaned hull to at most this many faces (None: marching cubes' own, ~10^5 at 128).
    max_faces: int | None = None
    # A texture atlas of this many texels a side baked from the views (xatlas UVs); None: vertex colours. At most
    # 2048: the bake's peak is about 215 bytes per texel (owner, barycentrics, surface points, colours, weights;
    # measured 0.86 GB above the process at 2048, 0.22 GB at 1024), so 4096 would take 3.6 GB and 8192 14 GB.
    texture_px: int | None = None
    # Photo-consistency refinement of the hull (refine_photo_consistent): off, or the deepest inward move searched
    # as a share of the hull's largest extent, the patch's half-side in pixels, the views averaged per depth, and the
    # score a move needs (NCC, and its gain over the hull's own surface).
    refine: bool = False
    refine_depth: float = 0.15
    refine_patch_radius: int = 3  # the patch is 2 r + 1 pixels a side
    refine_top_views: int = 2
    refine_min_ncc: float = 0.6
    refine_min_gain: float = 0.1
    refine_min_std: float = 4.0  # grey levels: flatter patches have nothing to match and stay
    # The quality a reconstruction must reach to be filed (aias_augment.assets.reconstruct_quality, where the bounds
    # are justified): each view's silhouette IoU, the spread of the views' directions, SfM's mean reprojection error,
    # and the slack around the category's height range.
    min_view_iou: float = 0.9
    min_view_spread_deg: float = 60.0
    max_reprojection_px: float = 2.0
    size_slack: float = 1.25


def _cleaned(mesh):
    """The largest connected component of ``mesh``, its holes filled, its faces oriented outward."""
    import trimesh

    parts = mesh.split(only_watertight=False)
    if len(parts) > 1:
        mesh = max(parts, key=lambda p: p.area)
    trimesh.repair.fill_holes(mesh)
    trimesh.repair.fix_normals(mesh)
    if mesh.is_watertight and mesh.volume < 0:  # outward: a closed surface encloses a positive volume
        mesh.invert()
    return mesh


def decimate(mesh, max_faces: int):
    """``mesh`` reduced to at most ``max_faces`` faces by quadric error (Garland-Heckbert, ``fast-simplification``),
    then cleaned like the hull. A closed hull stays closed: holes a collapse opens are filled. The decimator can
    stop short of its target or open the surface at one aggressiveness and not at another, so three are tried
    (7, its default, then 5 and 9), the first result that is closed and within budget kept. ``ValueError`` if none
    is: an open asset casts wrong shadows, and the budget is the caller's."""
    if len(mesh.faces) <= max_faces:
        return mesh
    tried = []
    for aggression in (7, 5, 9):
        out = _cleaned(mesh.simplify_quadric_decimation(face_count=int(max_faces), aggression=aggression))
        if (out.is_watertight or not mesh.is_watertight) and len(out.faces) <= max_faces:
            return out
        tried.append(f"{len(out.faces)} faces, {'closed' if out.is_watertight else 'open'}")
    raise ValueError(f"decimate: no closed hull within {max_faces} faces ({'; '.join(tried)}); allow more faces")


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
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


def _view_distance(points: np.ndarray, v: View, sd: np.ndarray) -> np.ndarray:
    """(N,) signed distance in metres of ``points`` (object frame) to the silhouette of view ``v``."""
    T = np.asarray(v.cam_from_object, float)
    pc = points @ T[:3, :3].T + T[:3, 3]
    z = np.maximum(pc[:, 2], 1e-6)
    K = v.intrinsics
    u = K.fx * pc[:, 0] / z + K.cx
    w = K.fy * pc[:, 1] / z + K.cy
    h, wd = sd.shape
    uc, wc = np.clip(u, 0, wd - 1), np.clip(w, 0, h - 1)
    # bilinear sample, plus how far the point projects beyond the image (outside the silhouette there)
    val = _bilinear(sd, uc, wc) + np.hypot(u - uc, w - wc)
    d_m = val * z / K.fx
    d_m[pc[:, 2] <= 1e-6] = np.inf  # behind the camera: not seen, cannot be inside
    return d_m.astype(np.float32)


def _field(points: np.ndarray, views: list[View], sdfs: list[np.ndarray]) -> np.ndarray:
    """(N,) max over views of the signed distance in metres of ``points`` (object frame) to each silhouette."""
    out = np.full(len(points), -np.inf, np.float32)
    for v, sd in zip(views, sdfs):
        out = np.maximum(out, _view_distance(points, v, sd))
    return out


def _support(field: np.ndarray, points: np.ndarray, ground_z: float | None) -> np.ndarray:
    """The hull cut by the support plane: nothing below z = ground_z (signed distance max(field, ground_z - z))."""
    return field if ground_z is None else np.maximum(field, (ground_z - points[:, 2]).astype(np.float32))


def _grid(lo: np.ndarray, hi: np.ndarray, n_long: int) -> tuple[np.ndarray, float, tuple[int, int, int]]:
    step = float(np.max(hi - lo)) / n_long
    shape = tuple(int(np.ceil((hi[i] - lo[i]) / step)) + 1 for i in range(3))
    axes = [lo[i] + step * np.arange(shape[i]) for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return pts, step, shape


def visual_hull(
    views: list[View],
    search_lo,
    search_hi,
    cfg: ReconstructConfig = ReconstructConfig(),
    ground_z: float | None = 0.0,
):
    """The visual hull of ``views`` inside the box [search_lo, search_hi] (object frame, metres) as a trimesh:
    largest component, holes filled, outward normals. ``ground_z``: the object stands on the plane z = ground_z of
    the poses' frame (a ground or turntable); no view from above can carve what lies under the object, the support
    plane does. None: no support plane."""
    import trimesh
    from skimage.measure import marching_cubes

    if len(views) < 2:
        raise ValueError("visual_hull needs at least two views")
    sdfs = [_signed_distance_px(v.mask) for v in views]
    lo, hi = np.asarray(search_lo, float), np.asarray(search_hi, float)
    pts, step, shape = _grid(lo, hi, cfg.coarse_resolution)
    inside = _support(_field(pts, views, sdfs), pts, ground_z) <= step  # generous: the fine grid loses nothing
    if not inside.any():
        raise ValueError("visual_hull: the silhouettes share no point inside the search box")
    occ = pts[inside]
    lo = np.maximum(occ.min(axis=0) - 2 * step, lo)
    hi = np.minimum(occ.max(axis=0) + 2 * step, hi)
    pts, step, shape = _grid(lo, hi, cfg.resolution)
    field = _support(_field(pts, views, sdfs), pts, ground_z).reshape(shape)
    pad = cfg.padding_voxels
    field = np.pad(field, pad, constant_values=np.float32(step * pad))  # closes the surface at the box's faces
    if not (field.min() < 0 < field.max()):
        raise ValueError("visual_hull: no surface in the fine grid")
    verts, faces, _, _ = marching_cubes(field, level=0.0, spacing=(step, step, step))
    verts = verts + lo - pad * step
    hull = _cleaned(trimesh.Trimesh(verts, faces, process=True))
    hull.metadata["voxel_m"] = float(step)
    return hull


def _visibility(points, normals, mesh, views: list[View], ssaa: int = 1):
    """For each view, which of the surface points (``points``, ``normals``: (N, 3), object frame) it sees: in its
    image, facing it, inside its mask and in front of ``mesh``'s own rendered depth. Yields (view, u, v, seen,
    cos of the angle between the normal and the direction to the camera) per view."""
    import trimesh

    from aias_augment.apply.render import render_object

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
        depth = render_object(plain, T, K, ssaa=ssaa, znear=0.01, zfar=1000.0, with_normals=False).depth
        h, wd = depth.shape
        ui, wi = np.round(u).astype(int), np.round(w).astype(int)
        ok = (cosang > 0.1) & (ui >= 0) & (ui < wd) & (wi >= 0) & (wi < h) & (pc[:, 2] > 0)
        d = np.zeros(len(V))
        d[ok] = depth[wi[ok], ui[ok]]
        ok &= (d > 0) & (np.abs(d - pc[:, 2]) < 0.01 * pc[:, 2] + 0.005)
        ok &= np.asarray(v.mask, bool)[np.clip(wi, 0, h - 1), np.clip(ui, 0, wd - 1)]
        yield v, u, w, ok, cosang


def _colours_from_views(points, normals, mesh, views: list[View], ssaa: int = 1):
    """Colour of each surface point (``points``, ``normals``: (N, 3), object frame) from the views that see it
    (:func:`_visibility`), weighted by cos^2 of the angle between the normal and the direction to the camera.
    Returns (N, 3) float sRGB colours and the (N,) mask of points some view saw."""
    V = np.asarray(points, float)
    acc = np.zeros((len(V), 3))
    wsum = np.zeros(len(V))
    for v, u, w, ok, cosang in _visibility(points, normals, mesh, views, ssaa):
        if not ok.any():
            continue
        col = _bilinear(v.image_rgb.astype(np.float32), u[ok], w[ok])
        wgt = cosang[ok] ** 2
        acc[ok] += wgt[:, None] * col
        wsum[ok] += wgt
    seen = wsum > 0
    colours = np.full((len(V), 3), 128.0)
    colours[seen] = acc[seen] / wsum[seen, None]
    return colours, seen


def texture_from_views(mesh, views: list[View], ssaa: int = 1):
    """``mesh`` with vertex colours from the views that see each vertex (:func:`_colours_from_views`). The colour
    detail is the vertices' spacing: a decimated hull keeps its shape but blurs its colours (use
    :func:`texture_atlas_from_views` for those)."""
    import trimesh

    colours, seen = _colours_from_views(mesh.vertices, mesh.vertex_normals, mesh, views, ssaa)
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


def texture_atlas_from_views(mesh, views: list[View], size: int, ssaa: int = 1):
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
    colours, seen = _colours_from_views(points, normals, mesh, views, ssaa)
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


def refine_photo_consistent(mesh, views: list[View], cfg: "ReconstructConfig", ssaa: int = 1):
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
    Returns (mesh, {"moved_share", "median_moved_m", "max_moved_m"})."""
    import trimesh

    V = np.asarray(mesh.vertices, float)
    N = np.asarray(mesh.vertex_normals, float)
    n_v = len(V)
    extent = float(np.max(V.max(axis=0) - V.min(axis=0)))
    grey = [cv2.cvtColor(v.image_rgb, cv2.COLOR_RGB2GRAY).astype(np.float32) for v in views]
    vis = [(ok, cosang) for _, _, _, ok, cosang in _visibility(V, N, mesh, views, ssaa)]
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
        ref_patch = _bilinear(grey[r], u.ravel(), w.ravel()).reshape(u.shape)
        textured = ref_patch[:, 0].std(axis=-1) >= cfg.refine_min_std  # the hull's own patch has texture to match
        scores = np.full((len(views), len(idx), len(depths)), np.nan, np.float32)
        for k, vk in enumerate(views):
            sel = seen[k, idx] & (k != r)
            if not sel.any():
                continue
            u, w, z = _project(pts[sel], vk)
            inside = (u >= 0) & (u <= vk.intrinsics.width - 1) & (w >= 0) & (w <= vk.intrinsics.height - 1) & (z > 0)
            patch = _bilinear(grey[k], u.ravel(), w.ravel()).reshape(u.shape)
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


def reconstruct(
    views: list[View],
    search_lo,
    search_hi,
    *,
    category: str,
    name: str = "reconstructed",
    height_m: float | None = None,
    ground_z: float | None = 0.0,
    cfg: ReconstructConfig = ReconstructConfig(),
) -> Asset:
    """A textured :class:`Asset` (canonical frame: metres, z up, on z = 0) from posed views of an object. The poses'
    units are kept unless ``height_m`` is given (then the asset is scaled to it). ``meta`` records the number of
    views, the grid, the share of vertices some view coloured and the quality measures.

    Before it is textured, the hull measures its own quality (:mod:`aias_augment.assets.reconstruct_quality`: every
    view's silhouette IoU, the views' spread) and the asset's height is checked against ``category``'s range:
    :class:`~aias_augment.assets.reconstruct_quality.ReconstructionRefused` names the bad views."""

    hull = visual_hull(views, search_lo, search_hi, cfg, ground_z)
    quality = check_hull(
        hull,
        views,
        hull.metadata["voxel_m"],
        cfg,
        agreement=lambda: view_agreement(views, search_lo, search_hi, ground_z),
    )
    height = hull.extents[2] if height_m is None else float(height_m)
    quality["height_range_m"] = check_height(float(height), category, cfg.size_slack)
    if cfg.max_faces is not None:
        hull = decimate(hull, cfg.max_faces)
    refined = None
    if cfg.refine:
        hull, refined = refine_photo_consistent(hull, views, cfg)
    if cfg.texture_px is None:
        textured, seen = texture_from_views(hull, views)
    else:
        textured, seen = texture_atlas_from_views(hull, views, cfg.texture_px)
    asset = Asset(
        name,
        category,
        normalise_meshes([textured], crease_deg=None),
        f"reconstruction from {len(views)} posed views",
        "",
        False,
        {
            "views": len(views),
            "resolution": cfg.resolution,
            "faces": len(hull.faces),
            "texture_px": cfg.texture_px,
            **({} if refined is None else {"refinement": refined}),
            "quality": quality,
            ("coloured_vertex_share" if cfg.texture_px is None else "coloured_texel_share"): round(seen, 4),
        },
    )
    if height_m is not None:
        asset = asset.scaled(float(height_m) / asset.height_m)
    return asset


def search_box(views: list[View]) -> tuple[np.ndarray, np.ndarray]:
    """A box that holds the object: centred where the views' optical axes pass closest (least squares), with a
    half-size of the largest silhouette's reach (its half-diagonal in pixels times depth over focal), doubled."""
    A = np.zeros((3, 3))
    b = np.zeros(3)
    reach = 0.0
    for v in views:
        T = np.asarray(v.cam_from_object, float)
        R, t = T[:3, :3], T[:3, 3]
        c = -R.T @ t
        d = R.T @ np.array([0.0, 0.0, 1.0])
        P = np.eye(3) - np.outer(d, d)
        A += P
        b += P @ c
    centre = np.linalg.lstsq(A, b, rcond=None)[0]
    for v in views:
        T = np.asarray(v.cam_from_object, float)
        z = float((T[:3, :3] @ centre + T[:3, 3])[2])
        ys, xs = np.nonzero(np.asarray(v.mask, bool))
        half_diag = 0.5 * float(np.hypot(xs.max() - xs.min() + 1, ys.max() - ys.min() + 1))
        reach = max(reach, half_diag * abs(z) / v.intrinsics.fx)
    return centre - 2 * reach, centre + 2 * reach


def read_views(path) -> tuple[list[tuple[np.ndarray, np.ndarray, Intrinsics, np.ndarray | None]], float | None]:
    """The photos of a views file as (image, mask, intrinsics, pose or None) and its ground z: see
    :func:`aias_augment.assets.views_file.read_views` (the format, the checks and the pixel bounds)."""

    return _read_views_file(path)


def load_views(path) -> tuple[list[View], float | None]:
    """Posed views of a views file (see :func:`read_views`); ValueError when the file has no poses."""
    photos, ground_z = read_views(path)
    if photos[0][3] is None:
        raise ValueError(f"{path}: the views have no cam_from_object (unposed: use reconstruct_unposed)")
    return [View(*p) for p in photos], ground_z


def _coarse_distances(views: list[View], search_lo, search_hi, ground_z, n_long: int):
    """(V, N) signed distances of an ``n_long`` grid over the box to each view's silhouette, and the grid step."""
    pts, step, _ = _grid(np.asarray(search_lo, float), np.asarray(search_hi, float), n_long)
    d = np.stack([_view_distance(pts, v, _signed_distance_px(v.mask)) for v in views])
    if ground_z is not None:
        d = np.maximum(d, (ground_z - pts[:, 2]).astype(np.float32))
    return d, step


def _agreement(d: np.ndarray, step: float, keep: list[int]) -> np.ndarray:
    out = np.full(len(d), np.nan)
    for j in keep:
        others = np.max(d[[k for k in keep if k != j]], axis=0) <= step
        out[j] = float(np.mean(d[j][others] <= step)) if others.any() else 0.0
    return out


def view_agreement(views: list[View], search_lo, search_hi, ground_z: float | None = 0.0, n_long: int = 32):
    """(V,) for each view, the share of the coarse hull of all the other views that projects inside its
    silhouette: 1.0 when it agrees with them."""
    d, step = _coarse_distances(views, search_lo, search_hi, ground_z, n_long)
    return _agreement(d, step, list(range(len(views))))


def consistent_views(
    views: list[View], search_lo, search_hi, ground_z: float | None = 0.0, min_agreement: float = 0.9, n_long: int = 32
) -> list[int]:
    """Indices of the views that agree with the others (:func:`view_agreement` at least ``min_agreement``). The
    worst view is left out and the check repeated, until every remaining view agrees (or two are left)."""
    d, step = _coarse_distances(views, search_lo, search_hi, ground_z, n_long)
    keep = list(range(len(views)))
    while len(keep) > 2:
        agreement = _agreement(d, step, keep)
        worst = keep[int(np.nanargmin(agreement[keep]))]
        if agreement[worst] >= min_agreement:
            break
        keep.remove(worst)
    return keep


def reconstruct_unposed(
    images_rgb: list[np.ndarray],
    masks: list[np.ndarray],
    intrinsics: Intrinsics,
    *,
    category: str,
    height_m: float,
    seed: int,
    name: str = "reconstructed",
    cfg: ReconstructConfig = ReconstructConfig(),
    workdir=None,
) -> Asset:
    """:func:`reconstruct` from photos without poses: the poses by structure from motion
    (:func:`aias_augment.assets.sfm.estimate_poses`), moved to the object's frame on the plane it stands on
    (:func:`~aias_augment.assets.sfm.ground_gauge`), then the visual hull of the registered views, scaled to
    ``height_m`` (SfM has no metric scale). ``meta`` adds the views registered and the model's reprojection error."""
    from aias_augment.assets.reconstruct_quality import check_reprojection
    from aias_augment.assets.sfm import estimate_poses, ground_gauge

    if len(images_rgb) != len(masks):
        raise ValueError(f"{len(images_rgb)} images but {len(masks)} masks")
    sfm = estimate_poses(images_rgb, intrinsics, seed, workdir)
    check_reprojection(sfm.mean_reprojection_error_px, cfg.max_reprojection_px)
    posed = [(img, m, T) for img, m, T in zip(images_rgb, masks, sfm.cams_from_world) if T is not None]
    if len(posed) < 2:
        raise ValueError(f"structure from motion registered {len(posed)} of {len(images_rgb)} views: need 2")
    model_views = [View(img, np.asarray(m, bool), intrinsics, T) for img, m, T in posed]
    lo, hi = search_box(model_views)
    object_from_model = ground_gauge(sfm, (lo + hi) / 2, np.random.default_rng(seed), float(np.max(hi - lo)) / 4)
    model_from_object = np.linalg.inv(object_from_model)
    views = [View(v.image_rgb, v.mask, intrinsics, v.cam_from_object @ model_from_object) for v in model_views]
    lo, hi = search_box(views)
    agree = consistent_views(views, lo, hi)
    views = [views[i] for i in agree]
    asset = reconstruct(views, lo, hi, category=category, name=name, height_m=height_m, ground_z=0.0, cfg=cfg)
    meta = {
        **asset.meta,
        "registered_views": len(posed),
        "consistent_views": len(views),
        "input_views": len(images_rgb),
        "sfm_points": int(len(sfm.points)),
        "sfm_reprojection_error_px": round(sfm.mean_reprojection_error_px, 4),
    }
    return Asset(
        asset.name,
        asset.category,
        asset.meshes,
        f"reconstruction from {len(posed)} of {len(images_rgb)} unposed views (SfM)",
        asset.licence,
        asset.procedural,
        meta,
    )
