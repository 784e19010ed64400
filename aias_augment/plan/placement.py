"""Placement: choose where an object stands, as the paper does, by projecting a 3D ground point through K[R|t].

``sample_placement`` only *chooses* (returns a frozen, JSON-serialisable :class:`Placement`); rendering it is
another stage. Every rejected candidate keeps its reason in the returned :class:`PlacementReport`.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from aias_augment.analyse.ground import RAY_PARALLEL_EPS, GroundFitError, GroundPlane
from aias_augment.assets.asset import CATEGORY_HEIGHT_RANGE_M, Asset
from aias_augment.core.geometry import MIN_DEPTH, Intrinsics, project_points, transform_points
from aias_augment.plan.box_size import (
    GROUND_CANDIDATES,
    candidates_for_box_height,
    draw_box_height_target,
    predicted_box_heights_px,
)
from aias_augment.plan.collision import CollisionConfig, OrientedBox, check_candidate
from aias_augment.plan.local_ground import UnevenGroundError, ground_band_points, refit_local_ground
from aias_augment.plan.placement_config import PlacementConfig
from aias_augment.plan.references import RowHeights
from aias_augment.plan.scene_scale import (
    reference_heights_m,
    scaled_ground,
    scene_scale_for_sizes,
    scene_scale_from_boxes,
)

__all__ = [
    "Placement",
    "PlacementConfig",
    "PlacementReport",
    "UnevenGroundError",
    "box_of_points",
    "draw_box_height_target",
    "ground_band_points",
    "object_pose_on_ground",
    "placement_at",
    "predicted_box_heights_px",
    "reference_heights_m",
    "refit_local_ground",
    "sample_placement",
    "scaled_ground",
    "scene_scale_for_sizes",
    "scene_scale_from_boxes",
]


@dataclass(frozen=True)
class Placement:
    """Everything needed to re-render one inserted object exactly (all in the frame's OpenCV camera frame)."""

    category: str
    asset_name: str
    asset_source: str
    scale: float  # applied to the canonical asset (metres -> metres)
    height_m: float
    yaw_rad: float
    contact_point_in_cam: tuple[float, float, float]
    contact_pixel: tuple[float, float]
    cam_from_object: tuple[tuple[float, ...], ...]
    amodal_box_xyxy: tuple[float, float, float, float]  # from the projected bounding-box corners
    ground_normal_in_cam: tuple[float, float, float]
    ground_d: float
    ground_source: str
    # Which plane the contact point and the orientation come from: "local" (refit around the contact), "global"
    # (the frame's plane: no measured points, refit off, or refit failed) and the inliers/rms of that plane.
    ground_used: str = "global"
    ground_num_inliers: int = 0
    ground_rms_m: float = 0.0
    # A procedural asset's draws (``Asset.meta``: generator, seed, shape, colours, bands...), so the record says
    # which object was made; empty for mesh assets.
    asset_meta: dict = field(default_factory=dict, hash=False)
    # A decoy is inserted like any object but not annotated (InsertionConfig.decoy_categories).
    decoy: bool = False
    # The scaled asset's axis-aligned bounds in the object frame, ((x0, y0, z0), (x1, y1, z1)) in metres (x the
    # heading, z up): the 3D box that 3D label exports (KITTI) write; () when not known.
    box_in_object_m: tuple = ()

    @property
    def cam_from_object_matrix(self) -> np.ndarray:
        return np.array(self.cam_from_object, dtype=np.float64)


@dataclass
class PlacementReport:
    tries: int = 0
    rejected: Counter = field(default_factory=Counter)
    chosen_because: str = ""
    local_refit_failed: int = 0  # candidates whose local refit failed (then the global plane or a rejection)
    target_box_height_px: float | None = None  # when the config sets a size target

    def to_dict(self) -> dict:
        return {
            "tries": self.tries,
            "rejected": dict(self.rejected),
            "chosen_because": self.chosen_because,
            "local_refit_failed": self.local_refit_failed,
            "target_box_height_px": self.target_box_height_px,
        }


def object_pose_on_ground(contact_point_in_cam: np.ndarray, ground: GroundPlane, yaw_rad: float) -> np.ndarray:
    """cam_from_object for an object standing at a ground point: object z = plane normal (up), yaw about it.

    Yaw 0 points the object x axis along the camera x axis projected onto the ground.
    """
    ux, uy, uz = (float(v) for v in ground.normal)
    # ref - (ref . up) up, ref = camera x (or the optical axis when camera x is vertical: rolled 90 deg)
    x0 = (1.0 - ux * ux, -ux * uy, -ux * uz)
    if math.sqrt(x0[0] ** 2 + x0[1] ** 2 + x0[2] ** 2) < 1e-6:
        x0 = (-uz * ux, -uz * uy, 1.0 - uz * uz)
    nrm = math.sqrt(x0[0] ** 2 + x0[1] ** 2 + x0[2] ** 2)
    x0 = (x0[0] / nrm, x0[1] / nrm, x0[2] / nrm)
    y0 = (uy * x0[2] - uz * x0[1], uz * x0[0] - ux * x0[2], ux * x0[1] - uy * x0[0])  # up x x0
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    x = (c * x0[0] + s * y0[0], c * x0[1] + s * y0[1], c * x0[2] + s * y0[2])
    y = (uy * x[2] - uz * x[1], uz * x[0] - ux * x[2], ux * x[1] - uy * x[0])  # up x x
    p = np.asarray(contact_point_in_cam, dtype=np.float64).reshape(3)
    return np.array([[x[0], y[0], ux, p[0]], [x[1], y[1], uy, p[1]], [x[2], y[2], uz, p[2]], [0.0, 0.0, 0.0, 1.0]])


def box_of_points(uv: np.ndarray) -> np.ndarray:
    return np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])


def placement_at(
    asset: Asset,
    cam_from_object: np.ndarray,
    intrinsics: Intrinsics,
    yaw_rad: float,
    ground: GroundPlane | None = None,
) -> Placement:
    """The record of ``asset`` (already scaled) at a pose chosen by the caller, not by the placement search: its
    amodal box from the projected bounding-box corners; with ``ground``, the contact point and pixel (the object's
    origin, on the ground) and the plane, else none (a paste without geometry)."""
    T = np.asarray(cam_from_object, float)
    uvc, _ = project_points(transform_points(T, asset.corners_m()), intrinsics.K)
    contact = T[:3, 3]
    if ground is None:
        pixel, normal, d, source = (float("nan"), float("nan")), (0.0, -1.0, 0.0), 0.0, "none"
    else:
        uv, _ = project_points(contact[None], intrinsics.K)
        pixel = (float(uv[0, 0]), float(uv[0, 1]))
        normal, d, source = tuple(map(float, ground.normal)), float(ground.d), ground.source
    return Placement(
        asset.category,
        asset.name,
        asset.source,
        float(asset.meta.get("scale", 1.0)),
        asset.height_m,
        float(yaw_rad),
        tuple(map(float, contact)),
        pixel,
        tuple(tuple(map(float, r)) for r in T),
        tuple(map(float, box_of_points(uvc))),
        normal,
        d,
        source,
        box_in_object_m=_bounds_tuple(asset.bounds_m),
    )


def _bounds_tuple(bounds_m) -> tuple:
    """(2, 3) bounds as the Placement's ``box_in_object_m``: ((x0, y0, z0), (x1, y1, z1))."""
    return tuple(tuple(map(float, row)) for row in np.asarray(bounds_m, float))


def _overlap_frac(box: np.ndarray, others: np.ndarray) -> float:
    """Largest intersection area of ``box`` with any of ``others`` (xyxy), over the smaller of the two areas."""
    if len(others) == 0:
        return 0.0
    ix = np.clip(np.minimum(box[2], others[:, 2]) - np.maximum(box[0], others[:, 0]), 0, None)
    iy = np.clip(np.minimum(box[3], others[:, 3]) - np.maximum(box[1], others[:, 1]), 0, None)
    inter = ix * iy
    area_b = max((box[2] - box[0]) * (box[3] - box[1]), 1e-9)
    area_o = np.maximum((others[:, 2] - others[:, 0]) * (others[:, 3] - others[:, 1]), 1e-9)
    return float(np.max(inter / np.minimum(area_b, area_o)))


def _ground_point(ground: GroundPlane, uv: np.ndarray, K: tuple) -> np.ndarray | None:
    """``ground.intersect_pixels`` of one pixel in scalar arithmetic (the same operations): the ground point (3,) in
    the camera frame, or None where that gives NaN (horizon, sky, behind the camera). ``K``: fx, fy, cx, cy, skew."""
    fx, fy, cx, cy, skew = K
    u, v = float(uv[0]), float(uv[1])
    y = (v - cy) / fy
    x = (u - cx - skew * y) / fx
    nx, ny, nz = (float(c) for c in ground.normal)
    denom = x * nx + y * ny + nz
    if not abs(denom) > RAY_PARALLEL_EPS:
        return None
    t = -float(ground.d) / denom
    if not t > 0 or not t > MIN_DEPTH:  # z = t (the ray's z is 1)
        return None
    return np.array([x * t, y * t, t])


def _child_generator(rng: np.random.Generator) -> np.random.Generator:
    """Independent child of ``rng`` that leaves ``rng``'s stream untouched (SeedSequence spawn; deterministic).
    A generator without a seed sequence gives one draw instead."""
    try:
        return rng.spawn(1)[0]
    except (TypeError, ValueError, AttributeError):
        return np.random.default_rng(rng.integers(2**63))


def _candidate_pixels(ground, intrinsics, rng, region_mask, hr, cfg, object_height_m, row_heights, report, within):
    """(flat candidate pixel indices, a note on the size target, the object's height when drawn once) for
    :func:`sample_placement`, or None (counted in ``report``) when no ground pixel is in view. With a size target
    the object's height is drawn once and the candidates are the pixels where it has that size (its size on each row
    from ``row_heights`` when given; rows where that is under ``cfg.min_box_height_px`` are no candidates)."""
    entry = GROUND_CANDIDATES.get(ground, intrinsics, region_mask, cfg.horizon_margin_px)
    cand = entry["cand"]
    if within is not None:  # both ascending: the candidates among them, as a mask of them would give
        at = np.minimum(np.searchsorted(cand, within), max(len(cand) - 1, 0))
        cand = within[cand[at] == within] if len(cand) else cand
    rows_pred = None
    if row_heights is not None and len(cand):
        rows_pred = row_heights.at(cand // intrinsics.width)
        keep = rows_pred >= cfg.min_box_height_px
        cand, rows_pred = cand[keep], rows_pred[keep]
    if len(cand) == 0:
        report.rejected["no ground pixels in view"] += 1
        return None
    size_note = ""
    fixed_h = None if object_height_m is None else float(object_height_m)
    target_frac = draw_box_height_target(cfg, rng)
    if target_frac is not None:
        # the object's own height, drawn once: the candidates are the pixels where this object has the target size
        fixed_h = float(rng.uniform(*hr)) if fixed_h is None else fixed_h
        cand, size_note = candidates_for_box_height(
            cand,
            target_frac,
            fixed_h,
            ground,
            intrinsics,
            cfg.box_height_tolerance,
            pred=rows_pred
            if rows_pred is not None or within is not None
            else GROUND_CANDIDATES.predicted(entry, fixed_h, ground, intrinsics),
        )
        report.target_box_height_px = target_frac * intrinsics.height
    return cand, size_note, fixed_h


#: A row-sized object keeps within this factor of the height it was drawn at (beyond it the site is refused: the
#: labelled boxes' line and the ground disagree there by more than any camera estimate should).
ROW_RESCALE_LIMIT = 10.0


def _projected_at_scale(asset, scale, cam_from_object, intrinsics, row_heights: RowHeights | None):
    """(scale, corners projected (8, 2), their depths) of ``asset`` at ``cam_from_object``, or (None, reason). With
    ``row_heights`` the object is rescaled about its contact point until its mask-tight box (its outline's,
    :meth:`~aias_augment.assets.asset.Asset.outline_m`) is the line's height on the box's own bottom row
    (fixed-point steps: the bottom row moves a little with the scale); without, ``scale`` is kept."""
    start = scale
    for step in range(4):
        corners = transform_points(cam_from_object, asset.corners_m() * scale)
        uvc, z = project_points(corners, intrinsics.K)
        if np.any(z <= 0.05) or not np.all(np.isfinite(uvc)):
            return None, "object crosses the camera plane"
        if row_heights is None:
            break
        # the mask-tight box, as labelled boxes are: the outline's, not the bounding box's (a cone's is ~7 % taller)
        box = box_of_points(
            project_points(transform_points(cam_from_object, asset.outline_m() * scale), intrinsics.K)[0]
        )
        target, bh = float(row_heights.at(box[3])), float(box[3] - box[1])
        if not (target > 0 and bh > 0):
            return None, "the labelled objects' size line gives no height on this row"
        if abs(target / bh - 1.0) < 0.005 or step == 3:
            break
        scale *= target / bh
        if not (1.0 / ROW_RESCALE_LIMIT <= scale / start <= ROW_RESCALE_LIMIT):
            return None, "the labelled objects' size on this row is out of the object's reach"
    return scale, (uvc, z)


def _box_rejection(box: np.ndarray, w: int, h: int, existing: np.ndarray, cfg: PlacementConfig) -> str | None:
    """Why a projected amodal box (xyxy) is refused in a ``w`` x ``h`` image with ``existing`` boxes, or None."""
    bw, bh = box[2] - box[0], box[3] - box[1]
    inside = (min(box[2], w - 0.5) - max(box[0], -0.5)) * (min(box[3], h - 0.5) - max(box[1], -0.5))
    if bw <= 0 or bh <= 0 or inside / (bw * bh) < cfg.min_in_image_frac or box[2] < 0 or box[3] < 0:
        return "projected box leaves the image"
    if bh < cfg.min_box_height_px:
        return "too small in the image"
    if bh > cfg.max_box_height_frac * h:
        return "too large in the image"
    if _overlap_frac(box, existing) > cfg.max_overlap_existing:
        return "overlaps an existing box"
    return None


def thin_structure_in_front(box: np.ndarray, segments: np.ndarray) -> str | None:
    """Why a site whose projected box (xyxy, the object's base on its bottom edge) is refused because of the scene's
    thin structures (``segments`` (N, 4), :func:`aias_augment.analyse.thin_structures.thin_structure_segments`), or
    None. A segment is clipped to the box above its lowest tenth (where the ground under the base shows): a
    near-vertical one inside it for a quarter of the box's height whose lower end reaches the base row or below
    stands on nearer ground (a pole in front); any other crossing the box for 60 % of its width may be nearer (a
    rail: its foot is not seen)."""
    x0, y0, x1, y1 = (float(v) for v in box)
    bw, bh = x1 - x0, y1 - y0
    if len(segments) == 0 or bw <= 0 or bh <= 0:
        return None
    s = np.asarray(segments, np.float64)
    px, py = s[:, 0], s[:, 1]
    dx, dy = s[:, 2] - px, s[:, 3] - py
    t0, t1 = np.zeros(len(s)), np.ones(len(s))
    ok = np.ones(len(s), bool)
    for pk, qk in ((-dx, px - x0), (dx, x1 - px), (-dy, py - y0), (dy, (y1 - 0.1 * bh) - py)):  # Liang-Barsky
        ok &= ~((pk == 0) & (qk < 0))
        with np.errstate(divide="ignore", invalid="ignore"):
            r = qk / pk
        t0 = np.where(pk < 0, np.maximum(t0, r), t0)
        t1 = np.where(pk > 0, np.minimum(t1, r), t1)
    inside = np.where(ok & (t1 > t0), (t1 - t0) * np.hypot(dx, dy), 0.0)
    vertical = np.abs(dy) > 2.0 * np.abs(dx)
    foot = np.maximum(py, s[:, 3])
    if np.any(vertical & (inside >= max(4.0, 0.25 * bh)) & (foot >= y1 - 0.05 * bh)):
        return "a pole (thin structure) stands in front"
    if np.any(~vertical & (inside >= max(4.0, 0.6 * bw))):
        return "a rail (thin structure) crosses the object"
    return None


def _local_plane(band, ground, p, refit_rng, cfg, uv, intrinsics, report):
    """(plane, "local" or "global", contact point) for a candidate contact ``p`` at pixel ``uv``: the ground refit
    on ``band`` around it, or the coarse ``ground`` when the refit finds too few points (``cfg.local_fallback``
    "global"); None, counted in ``report``, when the candidate is refused."""
    try:
        local, p_local = refit_local_ground(band, ground, p, refit_rng, cfg, pixel_uv=uv, intrinsics=intrinsics)
    except UnevenGroundError:
        # Points are there but the ground under the object is not one plane: do not stand it there.
        report.rejected["uneven ground under the contact point"] += 1
        return None
    except GroundFitError:
        report.local_refit_failed += 1
        if cfg.local_fallback == "reject":
            report.rejected["no local ground around the contact point"] += 1
            return None
        return ground, "global", p
    return local, "local", p_local


def _intrinsics_tuple(intrinsics: Intrinsics) -> tuple:
    """(fx, fy, cx, cy, skew) as floats, for :func:`_ground_point`."""
    return (
        float(intrinsics.fx),
        float(intrinsics.fy),
        float(intrinsics.cx),
        float(intrinsics.cy),
        float(intrinsics.K[0, 1]),
    )


def _refit_points(ground, intrinsics, rng, points_in_cam, depth, cfg: PlacementConfig):
    """(generator for the local refits, the measured points near the coarse plane), or (None, None) without
    measured points or with ``cfg.local_refit`` off."""
    # A child generator for the refits, so that how many points the scene has does not change the draws of
    # pixels, heights and yaws from ``rng`` (same seed -> same candidates with or without measured points).
    # (Made only when there are measured points to refit on: a spawn leaves the draws from ``rng`` unchanged.)
    measured = points_in_cam is not None or depth is not None
    refit_rng = _child_generator(rng) if cfg.local_refit and measured else None
    band = (
        ground_band_points(ground, intrinsics, refit_rng, points_in_cam=points_in_cam, depth=depth, cfg=cfg)
        if refit_rng is not None
        else None
    )
    return refit_rng, band


def _collision_kind(box3d, plane, intrinsics, points_in_cam, existing_objects, depth, collision_cfg) -> str | None:
    """The 3D checks of :mod:`.collision` (LiDAR/stereo points inside the object's box above the ground, existing 3D
    boxes, depth occlusion): the reason's key ("key: detail" reasons are counted by key), or None when it passes."""
    found = check_candidate(
        box3d,
        plane,
        intrinsics,
        points_in_cam=points_in_cam,
        existing=existing_objects,
        depth=depth,
        cfg=collision_cfg if collision_cfg is not None else CollisionConfig(),
    )
    return None if found is None else found.kind


def _placement_record(asset, scale, target_h, yaw, p, uv, cam_from_object, box, plane, used) -> Placement:
    return Placement(
        category=asset.category,
        asset_name=asset.name,
        asset_source=asset.source,
        scale=float(scale),
        height_m=float(target_h),
        yaw_rad=float(yaw),
        contact_point_in_cam=tuple(map(float, p)),
        contact_pixel=(float(uv[0]), float(uv[1])),
        cam_from_object=tuple(tuple(map(float, r)) for r in cam_from_object),
        amodal_box_xyxy=tuple(map(float, box)),
        ground_normal_in_cam=tuple(map(float, plane.normal)),
        ground_d=float(plane.d),
        ground_source=plane.source,
        ground_used=used,
        ground_num_inliers=int(plane.num_inliers),
        ground_rms_m=float(plane.rms_m),
        box_in_object_m=_bounds_tuple(asset.bounds_m * scale),
    )


def sample_placement(
    asset: Asset,
    ground: GroundPlane,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    *,
    existing_boxes_xyxy: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    region_mask: np.ndarray | None = None,
    height_range_m: tuple[float, float] | None = None,
    cfg: PlacementConfig = PlacementConfig(),
    points_in_cam: np.ndarray | None = None,
    existing_objects: list | None = None,
    collision_cfg=None,
    object_height_m: float | None = None,
    thin_segments: np.ndarray | None = None,
    row_heights: RowHeights | None = None,
    within_pixels: np.ndarray | None = None,
) -> tuple[Placement | None, PlacementReport]:
    """Choose a ground point, scale and yaw for ``asset``; ``None`` (with reasons) when no candidate passes.

    Candidates: a pixel drawn uniformly in the ground region (below the horizon, inside ``region_mask`` when
    given), lifted to 3D by intersecting its ray with ``ground`` (the paper's Ax+By+Cz+D=0). When measured
    points are known (``points_in_cam``, else ``depth``) and ``cfg.local_refit``: the ground is refitted on the
    points within ``cfg.local_radius_m`` of that point and ``cfg.local_ground_band_m`` of ``ground``, the pixel's
    ray is re-intersected with the local plane and the object is oriented by the local normal (the Placement
    records ``ground_used``). Then checked: distance range, scene depth agrees with the plane at that pixel (when
    depth is known), projected box inside the image, pixel size, overlap with existing boxes, and the 3D checks
    of :mod:`.collision` when ``points_in_cam`` or ``existing_objects`` (OrientedBox list) are given.

    ``thin_segments``: the scene's poles and rails (:func:`thin_structure_in_front` refuses sites behind them).

    Height: ``object_height_m`` when given, else drawn uniformly from ``height_range_m`` (the category's range);
    with a box-height target it is drawn once, before the candidates are chosen for it. ``row_heights``: the box
    height the object must have on each bottom row (the image's labelled objects of its kind): the object is
    rescaled about its contact point to it before the checks, and its height is what that scale gives.
    ``within_pixels``: ascending flat pixel indices (``v * W + u``) the candidates must also be among (a site an
    arrangement gives), the same candidates as a region mask of those pixels alone.
    """
    w, h = intrinsics.width, intrinsics.height
    K = _intrinsics_tuple(intrinsics)
    existing = (
        np.zeros((0, 4)) if existing_boxes_xyxy is None else np.asarray(existing_boxes_xyxy, float).reshape(-1, 4)
    )
    hr = height_range_m or CATEGORY_HEIGHT_RANGE_M.get(
        asset.category, (asset.reference_height_m, asset.reference_height_m)
    )
    report = PlacementReport()
    chosen = _candidate_pixels(
        ground, intrinsics, rng, region_mask, hr, cfg, object_height_m, row_heights, report, within_pixels
    )
    if chosen is None:
        return None, report
    cand, size_note, fixed_h = chosen
    refit_rng, band = _refit_points(ground, intrinsics, rng, points_in_cam, depth, cfg)
    for _ in range(cfg.max_tries):
        report.tries += 1
        idx = cand[rng.integers(len(cand))]
        v, u = divmod(int(idx), w)
        uv = np.array([u + rng.uniform(-0.5, 0.5), v + rng.uniform(-0.5, 0.5)])
        p = _ground_point(ground, uv, K)
        if p is None:
            report.rejected["ray misses the ground"] += 1
            continue
        dist = math.sqrt(float(p @ p))
        if not (cfg.min_distance_m <= dist <= cfg.max_distance_m):
            report.rejected["distance out of range"] += 1
            continue
        plane, used = ground, "global"
        if band is not None:
            refit = _local_plane(band, ground, p, refit_rng, cfg, uv, intrinsics, report)
            if refit is None:
                continue
            plane, used, p = refit
            if used == "local":
                dist = float(np.linalg.norm(p))
        if depth is not None:
            d_scene = float(depth[v, u])
            if np.isfinite(d_scene) and d_scene > 0 and abs(d_scene - p[2]) > cfg.depth_tolerance_rel * p[2]:
                report.rejected["scene depth disagrees with the ground plane (not free ground)"] += 1
                continue
        target_h = rng.uniform(*hr) if fixed_h is None else fixed_h
        scale = target_h / max(asset.reference_height_m, 1e-9)
        yaw = rng.uniform(-np.pi, np.pi)
        cam_from_object = object_pose_on_ground(p, plane, yaw)
        scale, got = _projected_at_scale(asset, scale, cam_from_object, intrinsics, row_heights)
        if scale is None:
            report.rejected[got] += 1
            continue
        uvc, z = got
        if row_heights is not None:  # the height the row's scale gives
            target_h = scale * asset.reference_height_m
        box = box_of_points(uvc)
        bh = box[3] - box[1]
        reason = _box_rejection(box, w, h, existing, cfg)
        if reason is None and thin_segments is not None:
            reason = thin_structure_in_front(box, thin_segments)
        if reason is None and (points_in_cam is not None or existing_objects):
            box3d = OrientedBox.standing_on_ground(cam_from_object, tuple(asset.extents_m * scale), asset.category)
            reason = _collision_kind(box3d, plane, intrinsics, points_in_cam, existing_objects, depth, collision_cfg)
        if reason is not None:
            report.rejected[reason] += 1
            continue
        report.chosen_because = (
            f"first candidate passing all checks (try {report.tries}): ground point at {dist:.1f} m on the "
            f"{used} plane, box {bh:.0f} px high{size_note}"
        )
        return _placement_record(asset, scale, target_h, yaw, p, uv, cam_from_object, box, plane, used), report
    return None, report
