"""An asset from posed photos of an object: its visual hull, cleaned, textured from the views, in metres.

1. :func:`visual_hull`: every view's silhouette becomes a signed distance (pixels to its boundary, positive
   outside, by OpenCV's distance transform), turned into metres at each voxel's depth (``d_px * z / f``). A point
   is inside the hull when it is inside every silhouette, so the field is the maximum over the views; its zero
   level, found by marching cubes (scikit-image), is the hull's surface with sub-voxel accuracy. The grid is first
   coarse over the box the caller gives, then fine over the occupied part.
2. Cleaned: the largest connected component, holes filled, oriented outward, resting on z = 0; with
   ``max_faces``, decimated by quadric error (``fast-simplification``, through trimesh) before texturing, so the
   colours are sampled on the vertices the asset keeps.
3. :func:`texture_from_views` (:mod:`aias_augment.assets.reconstruct_texture`): each vertex takes the colours of the
   views that see it (the hull's own depth, drawn by the ``render`` callable the caller passes, e.g.
   :func:`aias_augment.apply.render.render_object`, decides visibility), weighted by how squarely each view faces it.
   With ``texture_px``, a UV atlas (``xatlas``) is baked instead: each texel's surface point is coloured the same
   way, so the colour detail no longer depends on how many vertices the (decimated) hull keeps.

Without poses, :func:`reconstruct_unposed` estimates them by structure from motion (:mod:`aias_augment.assets.sfm`)
and leaves out the views that the others contradict (:func:`consistent_views`: a mis-registered view would carve
the object away).

Poses in metres give a metric asset; otherwise ``height_m`` scales it. A visual hull cannot see concavities that
no silhouette shows (the inside of a bowl, a block's pits): with ``refine``, :func:`refine_photo_consistent`
(:mod:`aias_augment.assets.reconstruct_refine`) moves
its vertices inward to where the views agree on the surface's texture (a plane sweep along each normal scored by
normalised cross-correlation). Textureless surfaces give it nothing to match and stay where the hull put them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.assets.asset import Asset, normalise_meshes
from aias_augment.assets.reconstruct_quality import check_height, check_hull
from aias_augment.assets.reconstruct_refine import refine_photo_consistent
from aias_augment.assets.reconstruct_texture import sample_bilinear, texture_atlas_from_views, texture_from_views
from aias_augment.assets.rendering import RenderObject
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
    val = sample_bilinear(sd, uc, wc) + np.hypot(u - uc, w - wc)
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
    render: RenderObject,
) -> Asset:
    """A textured :class:`Asset` (canonical frame: metres, z up, on z = 0) from posed views of an object. The poses'
    units are kept unless ``height_m`` is given (then the asset is scaled to it). ``meta`` records the number of
    views, the grid, the share of vertices some view coloured and the quality measures. ``render`` draws the hull
    for its quality check and its texture's visibility (:func:`aias_augment.apply.render.render_object`).

    Before it is textured, the hull measures its own quality (:mod:`aias_augment.assets.reconstruct_quality`: every
    view's silhouette IoU, the views' spread) and the asset's height is checked against ``category``'s range:
    :class:`~aias_augment.assets.reconstruct_quality.ReconstructionRefused` names the bad views."""

    hull = visual_hull(views, search_lo, search_hi, cfg, ground_z)
    quality = check_hull(
        hull,
        views,
        hull.metadata["voxel_m"],
        cfg,
        render=render,
        agreement=lambda: view_agreement(views, search_lo, search_hi, ground_z),
    )
    height = hull.extents[2] if height_m is None else float(height_m)
    quality["height_range_m"] = check_height(float(height), category, cfg.size_slack)
    if cfg.max_faces is not None:
        hull = decimate(hull, cfg.max_faces)
    refined = None
    if cfg.refine:
        hull, refined = refine_photo_consistent(hull, views, cfg, render=render)
    if cfg.texture_px is None:
        textured, seen = texture_from_views(hull, views, render=render)
    else:
        textured, seen = texture_atlas_from_views(hull, views, cfg.texture_px, render=render)
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
    render: RenderObject,
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
    asset = reconstruct(
        views, lo, hi, category=category, name=name, height_m=height_m, ground_z=0.0, cfg=cfg, render=render
    )
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
