"""Placement: choose where an object stands, as the paper does, by projecting a 3D ground point through K[R|t].

``sample_placement`` only *chooses* (returns a frozen, JSON-serialisable :class:`Placement`); rendering it is
another stage. Every rejected candidate keeps its reason in the returned :class:`PlacementReport`.
"""

from __future__ import annotations

import hashlib
import math
from collections import Counter, OrderedDict
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from aias_augment.analyse.ground import RAY_PARALLEL_EPS, GroundFitError, GroundPlane, depth_to_points, fit_ground_plane
from aias_augment.assets.asset import CATEGORY_HEIGHT_RANGE_M, Asset
from aias_augment.core.config import checked_config
from aias_augment.core.geometry import MIN_DEPTH, Intrinsics, project_points, transform_points
from aias_augment.plan.collision import CollisionConfig, OrientedBox, check_candidate


# Every field is checked at construction against its type hint and these bounds (config.checked_config).
@checked_config(
    {
        "max_tries": "[1, inf)",
        "min_box_height_px": "[0, inf)",
        "max_box_height_frac": "(0, inf)",
        "max_distance_m": "(0, inf]",
        "min_distance_m": "[0, inf)",
        "max_overlap_existing": "[0, 1]",
        "min_in_image_frac": "[0, 1]",
        "depth_tolerance_rel": "(0, inf)",
        "horizon_margin_px": "[0, inf)",
        "local_radius_m": "(0, inf)",
        "local_ground_band_m": "(0, inf)",
        "local_threshold_m": "(0, inf)",
        "local_max_tilt_deg": "[0, 90]",
        "local_min_inliers": "[3, inf)",
        "local_max_depth_m": "(0, inf]",
        "local_max_points": "[3, inf)",
        "local_support_radius_m": "(0, inf)",
        "local_support_min_points": "[0, inf)",
        "local_support_max_residual_m": "(0, inf)",
        "box_height_frac_range": "(0, 1] lo<=hi",
        "box_height_frac_samples": "(0, 1]",
        "box_height_jitter": "[0, inf)",
        "box_height_tolerance": "(0, inf)",
        "camera_height_range_m": "(0, inf) lo<=hi",
    },
    orders=["min_distance_m <= max_distance_m"],
)
@dataclass(frozen=True)
class PlacementConfig:
    max_tries: int = 60
    min_box_height_px: float = 12.0
    max_box_height_frac: float = 0.6  # of the image height
    max_distance_m: float = 60.0
    min_distance_m: float = 2.0
    max_overlap_existing: float = 0.3  # intersection / inserted-box area, against existing + earlier boxes
    min_in_image_frac: float = 0.9  # fraction of the projected box that must lie inside the image
    depth_tolerance_rel: float = 0.15  # |scene depth - plane depth| / plane depth for "this pixel is ground"
    horizon_margin_px: float = 8.0  # contact pixels must be this far below the horizon
    # Local ground refit around the chosen contact (needs measured points: ``points_in_cam`` or ``depth``). The
    # coarse (global) plane is only a first guess: roads are crowned and banked, sidewalks are kerb-high.
    local_refit: bool = True
    local_radius_m: float = 3.0  # refit on points within this horizontal distance of the coarse contact
    local_ground_band_m: float = 0.4  # ... and within this distance of the coarse plane (not a car trunk)
    local_threshold_m: float = 0.05  # RANSAC inlier distance of the local fit
    local_max_tilt_deg: float = 10.0  # local normal within this angle of the coarse normal
    local_min_inliers: int = 10
    local_max_depth_m: float = 40.0  # depth pixels farther than this are not used (stereo noise ~ z^2)
    local_max_points: int = 200_000  # random subset of the band points (speed)
    local_fallback: Literal["global", "reject"] = "global"  # too few points for a refit: coarse plane | reject
    # The local plane must agree with the measured points right under the object: median |residual| of the band
    # points within local_support_radius_m of the new contact <= local_support_max_residual_m. Otherwise (a kerb or a ramp
    # inside the 3 m window, where the bigger surface wins the RANSAC vote) the refit is retried with half the
    # radius, then a quarter. Fewer than local_support_min_points points there: no evidence, the plane is kept.
    local_support_radius_m: float = 1.0
    local_support_min_points: int = 5
    local_support_max_residual_m: float = 0.025  # half a kerb step; LiDAR/stereo noise (< ~3 cm sigma) passes
    # Pixel size of the inserted objects (what a detector learns from). By default a ground pixel is drawn uniformly
    # below the horizon, so sizes follow the scene's geometry. With a target, each object first draws a target box
    # height (as a fraction of the image height) from ``box_height_frac_samples`` (an empirical distribution, e.g.
    # the class's labelled boxes, jittered by ``box_height_jitter`` in log space) or uniformly from
    # ``box_height_frac_range``, and candidates are restricted to ground pixels whose predicted box height lies within
    # ``box_height_tolerance`` (relative) of it. A target the scene cannot host (ground too far or too near) falls back
    # to the 2 % of ground pixels nearest to it, and the report says so.
    box_height_frac_range: tuple[float, float] | None = None
    box_height_frac_samples: tuple[float, ...] = ()
    box_height_jitter: float = 0.1
    box_height_tolerance: float = 0.2
    # An image's existing boxes of the inserted kind (their labels name an inserted category through the taxonomy,
    # e.g. "cone" for traffic_cone, or are listed in ``size_reference_labels``) are the scene's own objects: when an
    # image has any, target box heights are drawn from theirs (jittered as above) instead of the samples/range
    # above, and an assumed-scale scene takes the scale at which objects of the category's mean height stand on
    # their bottom rows at their heights (:func:`scene_scale_from_boxes`), so an inserted object is as large as
    # the real ones on the same ground row. Images without such boxes are unaffected.
    sizes_from_existing: bool = True
    size_reference_labels: tuple[str, ...] = ()
    # An inserted object of a kind the image has labelled takes its height from one of those objects (their height
    # on the scene's ground, :func:`reference_heights_m`) times exp(N(0, reference_height_jitter)): the objects of one
    # site are mostly one model, and a same-row neighbour of another height would be a different size.
    reference_height_jitter: float = 0.06
    # A single photo's ground has no measured scale: its plane comes from a camera-height prior
    # (``GroundPlane.assumed_scale``), and a level road camera 1.65 m up cannot see a cone on the ground taller than
    # ~0.25 of the frame, while close-ups and product shots are full of them. With ``scene_scale_from_sizes`` and a
    # size target, each image first draws a reference target and a ground pixel that can host it at a camera height
    # inside ``camera_height_range_m``, and the whole scene is scaled about the camera centre to that height (the
    # one unknown a single photo leaves; every object of the image shares it, so they stay consistent with each
    # other, with the ground and with their shadows). Measured grounds (depth, LiDAR, poses) are never rescaled, and
    # without a size target nothing changes. On by default: on TraCon's dev split (2 real cone images + 60 inserted,
    # seeds 0 and 1) it raised AP50:95 from 0.191/0.089 to 0.207/0.130 (results/study_probe).
    scene_scale_from_sizes: bool = True
    camera_height_range_m: tuple[float, float] = (0.4, 4.0)


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


def ground_band_points(
    ground: GroundPlane,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    *,
    points_in_cam: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    cfg: PlacementConfig = PlacementConfig(),
) -> np.ndarray | None:
    """Measured points that may be ground: within ``cfg.local_ground_band_m`` of the coarse plane, (N, 3) or None.

    Source: ``points_in_cam`` (LiDAR / stereo points) when given, else ``depth`` pixels nearer than
    ``cfg.local_max_depth_m``. At most ``cfg.local_max_points`` points, drawn with ``rng``.
    """
    if points_in_cam is not None:
        pts = np.asarray(points_in_cam, dtype=np.float64).reshape(-1, 3)
        pts = pts[np.all(np.isfinite(pts), axis=1) & (pts[:, 2] < cfg.local_max_depth_m)]
    elif depth is not None:
        pts, _ = depth_to_points(depth, intrinsics, max_depth_m=cfg.local_max_depth_m)
    else:
        return None
    pts = pts[np.abs(ground.signed_distance(pts)) < cfg.local_ground_band_m]
    if len(pts) > cfg.local_max_points:
        pts = pts[rng.choice(len(pts), cfg.local_max_points, replace=False)]
    return pts


class UnevenGroundError(GroundFitError):
    """Measured points are under the contact, but no local plane agrees with them (kerb edge, ramp, clutter)."""


def _support_residual_m(
    points: np.ndarray, plane: GroundPlane, contact_in_cam: np.ndarray, radius_m: float, min_points: int
) -> float | None:
    """Median |distance to plane| of the points within ``radius_m`` (along the plane) of the contact; None when
    fewer than ``min_points`` are there."""
    rel = points - contact_in_cam
    along = rel - (rel @ plane.normal)[:, None] * plane.normal
    near = points[np.einsum("ij,ij->i", along, along) < radius_m**2]
    if len(near) < min_points:
        return None
    return float(np.median(np.abs(plane.signed_distance(near))))


def refit_local_ground(
    band_points: np.ndarray,
    ground: GroundPlane,
    contact_in_cam: np.ndarray,
    rng: np.random.Generator,
    cfg: PlacementConfig = PlacementConfig(),
    pixel_uv: np.ndarray | None = None,
    intrinsics: Intrinsics | None = None,
) -> tuple[GroundPlane, np.ndarray]:
    """(local plane, contact on it): ground refit on ``band_points`` within ``cfg.local_radius_m`` (horizontally) of
    ``contact_in_cam``, normal within ``cfg.local_max_tilt_deg`` of the coarse ``ground``'s.

    The contact is re-intersected along ``pixel_uv``'s ray (given with ``intrinsics``), else projected onto the
    plane. A plane that disagrees with the points under the new contact (see ``local_support_radius_m``) is refit
    with half, then a quarter of the radius. Raises UnevenGroundError when planes were found but none agrees with
    the points under the contact, GroundFitError when there are too few points for a plane.
    """
    last_error, uneven = "no radius tried", None
    for radius in (cfg.local_radius_m, cfg.local_radius_m / 2, cfg.local_radius_m / 4):
        try:
            local = fit_ground_plane(
                band_points,
                rng,
                up_hint=ground.normal,
                max_tilt_deg=cfg.local_max_tilt_deg,
                threshold_m=cfg.local_threshold_m,
                local_center=contact_in_cam,
                local_radius_m=radius,
                min_inliers=cfg.local_min_inliers,
                source="local",
            )
        except GroundFitError as e:
            last_error = str(e)
            break  # a smaller window has even fewer points
        if pixel_uv is not None:
            contact = local.intersect_pixels(np.asarray(pixel_uv, float), intrinsics)
            if not np.all(np.isfinite(contact)):
                last_error = "the pixel's ray misses the local plane"
                continue
        else:
            contact = local.project_to_plane(np.asarray(contact_in_cam, float))
        res = _support_residual_m(band_points, local, contact, cfg.local_support_radius_m, cfg.local_support_min_points)
        if res is None or res <= cfg.local_support_max_residual_m:
            return local, contact
        uneven = f"local plane ({radius:.2g} m window) is {res:.3f} m off the points under the contact"
    if uneven is not None:
        raise UnevenGroundError(uneven)
    raise GroundFitError(last_error)


def draw_box_height_target(cfg: PlacementConfig, rng: np.random.Generator) -> float | None:
    """Target box height / image height for one object, or None when the config sets no target."""
    if cfg.box_height_frac_samples:
        base = cfg.box_height_frac_samples[int(rng.integers(len(cfg.box_height_frac_samples)))]
        return float(np.clip(base * np.exp(rng.normal(0.0, cfg.box_height_jitter)), 1e-3, 1.0))
    if cfg.box_height_frac_range is not None:
        return float(rng.uniform(*cfg.box_height_frac_range))
    return None


def predicted_box_heights_px(
    uv: np.ndarray, object_height_m: float, ground: GroundPlane, intrinsics: Intrinsics
) -> np.ndarray:
    """(N, 2) ground pixels -> (N,) image height in pixels of a vertical segment of ``object_height_m`` standing on
    the ground there (its base and top projected); nan where the ray misses the ground or the top is behind the
    camera. An object's box is about this high (a cone's box is its height; wide objects add a little)."""
    return _pred_scaled(uv, np.full(len(uv), float(object_height_m)), ground, intrinsics)


def candidates_for_box_height(
    cand: np.ndarray,
    target_frac: float,
    object_height_m: float,
    ground: GroundPlane,
    intrinsics: Intrinsics,
    tolerance: float,
    pred: np.ndarray | None = None,
) -> tuple[np.ndarray, str]:
    """Flat pixel indices of ``cand`` whose predicted box height is within ``tolerance`` (relative) of
    ``target_frac * height``; when none is, the 2 % nearest to it (and a note saying so). ``pred``: the
    candidates' :func:`predicted_box_heights_px` when already known."""
    if pred is None:
        v, u = np.divmod(cand, intrinsics.width)
        pred = predicted_box_heights_px(np.c_[u, v].astype(np.float64), object_height_m, ground, intrinsics)
    target = target_frac * intrinsics.height
    rel = np.abs(pred / target - 1.0)
    rel[~np.isfinite(rel)] = np.inf
    ok = rel <= tolerance
    if ok.any():
        return cand[ok], f" (target {target:.0f} px)"
    finite = np.isfinite(rel)
    if not finite.any():
        return cand, f" (target {target:.0f} px: no ground pixel predicts a size, target ignored)"
    n = max(1, int(0.02 * finite.sum()))
    nearest = np.argsort(rel)[:n]
    return cand[nearest], f" (target {target:.0f} px not reachable in this scene: nearest sizes used)"


def scene_scale_for_sizes(
    ground: GroundPlane,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    cfg: PlacementConfig,
    object_height_m: float,
    target_frac: float,
    region_mask: np.ndarray | None = None,
) -> tuple[float, str]:
    """Factor ``k`` by which to scale an assumed-scale scene about the camera centre (the camera height becomes
    ``k * ground.d``) so that an object of box height ``target_frac`` (of the image height) stands on a ground
    pixel drawn uniformly among those that can host it with the camera height inside
    ``cfg.camera_height_range_m``; ``(1.0, reason)`` when the scene is not rescaled. Given the largest target of
    an image, its smaller ones fit farther away. Scaling the scene by ``k`` shows an object of height ``h`` as the
    unscaled scene shows one of ``h / k``, which gives each pixel's ``k`` by a fixed-point iteration on the
    predicted box heights."""
    if not ground.assumed_scale:
        return 1.0, f"measured ground ({ground.source}): its scale is kept"
    cand = _GROUND_CANDIDATES.get(ground, intrinsics, region_mask, cfg.horizon_margin_px)["cand"]
    if len(cand) == 0 or not (ground.d > 0):
        return 1.0, "no ground in view: scale kept"
    cand = cand[:: max(1, len(cand) // 4096)]
    v, u = np.divmod(cand, intrinsics.width)
    uv = np.c_[u, v].astype(np.float64)
    target = target_frac * intrinsics.height
    k = _scales_for_heights(uv, np.full(len(uv), target), object_height_m, ground, intrinsics)
    if np.isnan(k).all():
        return 1.0, f"target {target:.0f} px: no ground pixel predicts a size, scale kept"
    heights = k * ground.d
    lo, hi = cfg.camera_height_range_m
    ok = np.flatnonzero((heights >= lo) & (heights <= hi))
    if len(ok) == 0:
        near = float(heights[np.nanargmin(np.abs(np.log(heights / np.sqrt(lo * hi))))])
        kk = float(np.clip(near, lo, hi)) / ground.d  # the nearest plausible height: the target is not met
        return kk, (f"target {target:.0f} px needs a camera height outside {lo}-{hi} m: {kk * ground.d:.2f} m used")
    i = ok[int(rng.integers(len(ok)))]
    return float(k[i]), (
        f"camera {heights[i]:.2f} m above the ground (assumed {ground.d:.2f} m) so that a "
        f"{target:.0f} px target stands on visible ground"
    )


def scene_scale_from_boxes(
    ground: GroundPlane,
    intrinsics: Intrinsics,
    boxes_xyxy: np.ndarray,
    object_height_m: float | np.ndarray,
    cfg: PlacementConfig,
) -> tuple[float | None, str]:
    """Factor ``k`` by which to scale an assumed-scale scene about the camera centre so that objects of
    ``object_height_m`` (one for all, or (N,): each box's kind's height) standing on the ground at the bottom centres
    of ``boxes_xyxy`` (the scene's own objects of the inserted kinds) are as tall in the image as those boxes: the
    median over the boxes of the per-box factor,
    the camera height ``k * ground.d`` kept inside ``cfg.camera_height_range_m``. Boxes cut by the frame's top or
    bottom edge (their height or base unknown) and bases above the horizon give none. ``(None, reason)`` when no
    box gives a factor; ``(1.0, reason)`` for a measured ground."""
    if not ground.assumed_scale:
        return 1.0, f"measured ground ({ground.source}): its scale is kept"
    b = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    heights = np.broadcast_to(np.asarray(object_height_m, float), (len(b),))
    h_px = b[:, 3] - b[:, 1]
    inside = _whole_boxes(b, intrinsics)
    if not inside.any() or not (ground.d > 0):
        return None, f"none of {len(b)} reference boxes is whole in the frame"
    b, h_px, heights = b[inside], h_px[inside], heights[inside]
    uv = np.c_[(b[:, 0] + b[:, 2]) / 2, b[:, 3]]
    k = _scales_for_heights(uv, h_px, heights, ground, intrinsics)
    object_height_m = float(np.mean(heights))
    k = k[np.isfinite(k)]
    if len(k) == 0:
        return None, f"no reference box stands on the visible ground ({len(b)} whole in the frame)"
    lo, hi = cfg.camera_height_range_m
    height = float(np.median(k)) * ground.d
    kk = float(np.clip(height, lo, hi)) / ground.d
    clipped = "" if lo <= height <= hi else f" (the boxes ask for {height:.2f} m, outside {lo}-{hi} m)"
    return kk, (
        f"camera {kk * ground.d:.2f} m above the ground (assumed {ground.d:.2f} m): {object_height_m:.2f} m objects "
        f"on the bottom rows of the image's {len(k)} reference boxes are their height (median of their scales){clipped}"
    )


def _whole_boxes(b: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(N,) bool: boxes (N, 4) xyxy not cut by the frame's top or bottom edge (height and base seen), >= 4 px tall."""
    return (b[:, 1] > 1.0) & (b[:, 3] < intrinsics.height - 2.0) & (b[:, 3] - b[:, 1] >= 4.0)


def reference_heights_m(ground: GroundPlane, intrinsics: Intrinsics, boxes_xyxy: np.ndarray) -> np.ndarray:
    """(N,) height in metres of the upright object whose box is each of ``boxes_xyxy`` (N, 4), standing on ``ground``
    at the box's bottom centre: the height whose projection (:func:`predicted_box_heights_px`) is the box's height.
    nan for a box cut by the frame's top or bottom edge or whose base is not on the visible ground."""
    b = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    out = np.full(len(b), np.nan)
    ok = _whole_boxes(b, intrinsics)
    if ok.any() and ground.d > 0:
        uv = np.c_[(b[ok, 0] + b[ok, 2]) / 2, b[ok, 3]]
        out[ok] = 1.0 / _scales_for_heights(uv, b[ok, 3] - b[ok, 1], np.ones(int(ok.sum())), ground, intrinsics)
    return out


def _scales_for_heights(
    uv: np.ndarray, target_px: np.ndarray, object_height_m, ground: GroundPlane, intrinsics: Intrinsics
) -> np.ndarray:
    """Per ground pixel, the scene scale ``k`` at which an object of ``object_height_m`` (scalar or one per pixel)
    standing there is
    ``target_px`` tall (nan where none). Scaling the scene by ``k`` shows an object of height ``h`` as the unscaled
    scene shows one of ``h / k``: a fixed-point iteration on the predicted heights, nearly proportional to 1 / k, so
    a few steps converge."""
    k = np.ones(len(uv))
    for _ in range(4):
        pred = _pred_scaled(uv, object_height_m / k, ground, intrinsics)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = k * pred / target_px
        k[~(np.isfinite(k) & (k > 0))] = np.nan
    return k


def _pred_scaled(uv: np.ndarray, heights_m: np.ndarray, ground: GroundPlane, intrinsics: Intrinsics) -> np.ndarray:
    """:func:`predicted_box_heights_px` with one object height per pixel."""
    return _pred_from_bases(ground.intersect_pixels(uv, intrinsics), heights_m, ground, intrinsics)


def _pred_from_bases(
    base: np.ndarray, heights_m: np.ndarray, ground: GroundPlane, intrinsics: Intrinsics
) -> np.ndarray:
    """(N,) image heights of vertical segments of ``heights_m`` (N,) standing at the ground points ``base`` (N, 3)."""
    top = base + heights_m[:, None] * ground.normal[None, :]
    out = np.full(len(base), np.nan)
    ok = np.all(np.isfinite(base), axis=1) & np.isfinite(heights_m) & (base[:, 2] > 0.05) & (top[:, 2] > 0.05)
    if ok.any():
        ub, _ = project_points(base[ok], intrinsics.K)
        ut, _ = project_points(top[ok], intrinsics.K)
        out[ok] = np.abs(ub[:, 1] - ut[:, 1])
    return out


def scaled_ground(ground: GroundPlane, k: float) -> GroundPlane:
    """``ground`` with the scene scaled by ``k`` about the camera centre (same normal, camera height ``k * d``)."""
    if k == 1.0:
        return ground
    return GroundPlane(
        ground.normal,
        ground.d * k,
        f"{ground.source}:scaled",
        ground.inlier_ratio,
        ground.rms_m,
        ground.num_inliers,
        ground.assumed_scale,
    )


class _GroundCandidates:
    """The candidate contact pixels of a scene (below the horizon margin, inside the region) and their predicted
    box heights per object height, for the last few scenes. Planning on the same analysis again (a training loop's
    next epoch) then skips the full-frame pixel grid. Keyed by the plane, the intrinsics, the margin and the
    region's bytes (a digest, so a mask changed in place is a new key): the arrays are those a fresh computation
    gives, so the draws and results are the same with or without a hit."""

    def __init__(self, max_entries: int = 32):
        self.max_entries = max_entries
        self._entries: OrderedDict = OrderedDict()
        self._digests: OrderedDict = OrderedDict()  # id -> (mask, digest) of read-only masks that own their data

    def _region_digest(self, region_mask) -> tuple:
        m = region_mask
        # A read-only array that owns its memory (PlaceableRegion's mask) cannot change: digested once.
        frozen = isinstance(m, np.ndarray) and not m.flags.writeable and m.base is None
        if frozen:
            got = self._digests.get(id(m))
            if got is not None and got[0] is m:
                return got[1]
        a = np.ascontiguousarray(np.asarray(m, bool))
        digest = (a.shape, hashlib.blake2b(np.packbits(a).tobytes(), digest_size=16).digest())
        if frozen:
            self._digests[id(m)] = (m, digest)
            while len(self._digests) > self.max_entries:
                self._digests.popitem(last=False)
        return digest

    def _key(self, ground: GroundPlane, intrinsics: Intrinsics, region_mask, margin: float) -> tuple:
        region = None if region_mask is None else self._region_digest(region_mask)
        return (
            tuple(np.asarray(ground.normal, float).tolist()),
            float(ground.d),
            intrinsics.width,
            intrinsics.height,
            float(intrinsics.fx),
            float(intrinsics.fy),
            float(intrinsics.cx),
            float(intrinsics.cy),
            float(margin),
            region,
        )

    def get(self, ground: GroundPlane, intrinsics: Intrinsics, region_mask, margin: float) -> dict:
        key = self._key(ground, intrinsics, region_mask, margin)
        entry = self._entries.get(key)
        if entry is None:
            w, h = intrinsics.width, intrinsics.height
            try:
                horizon = ground.horizon_line(intrinsics)
            except ValueError:
                horizon = None
            allowed = np.ones((h, w), bool)
            if horizon is not None:
                uu, vv = np.meshgrid(np.arange(w), np.arange(h))
                allowed &= horizon[0] * uu + horizon[1] * vv + horizon[2] > margin
            if region_mask is not None:
                allowed &= np.asarray(region_mask, bool)
            cand = np.flatnonzero(allowed)
            cand.setflags(write=False)
            entry = {"cand": cand, "pred": {}}
            self._entries[key] = entry
            while len(self._entries) > self.max_entries:
                self._entries.popitem(last=False)
        else:
            self._entries.move_to_end(key)
        return entry

    def predicted(self, entry: dict, object_height_m: float, ground: GroundPlane, intrinsics: Intrinsics) -> np.ndarray:
        """The candidates' :func:`predicted_box_heights_px` for ``object_height_m``: their ground points are kept
        (heights are continuous draws: one projection per call, from the same points a fresh computation gives)."""
        base = entry["pred"].get("base")
        if base is None:
            v, u = np.divmod(entry["cand"], intrinsics.width)
            base = ground.intersect_pixels(np.c_[u, v].astype(np.float64), intrinsics)
            base.setflags(write=False)
            entry["pred"]["base"] = base
        return _pred_from_bases(base, np.full(len(base), float(object_height_m)), ground, intrinsics)


_GROUND_CANDIDATES = _GroundCandidates()


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

    Height: ``object_height_m`` when given, else drawn uniformly from ``height_range_m`` (the category's range);
    with a box-height target it is drawn once, before the candidates are chosen for it.
    """
    w, h = intrinsics.width, intrinsics.height
    K = (
        float(intrinsics.fx),
        float(intrinsics.fy),
        float(intrinsics.cx),
        float(intrinsics.cy),
        float(intrinsics.K[0, 1]),
    )
    existing = (
        np.zeros((0, 4)) if existing_boxes_xyxy is None else np.asarray(existing_boxes_xyxy, float).reshape(-1, 4)
    )
    hr = height_range_m or CATEGORY_HEIGHT_RANGE_M.get(
        asset.category, (asset.reference_height_m, asset.reference_height_m)
    )
    report = PlacementReport()
    entry = _GROUND_CANDIDATES.get(ground, intrinsics, region_mask, cfg.horizon_margin_px)
    cand = entry["cand"]
    if len(cand) == 0:
        report.rejected["no ground pixels in view"] += 1
        return None, report
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
            pred=_GROUND_CANDIDATES.predicted(entry, fixed_h, ground, intrinsics),
        )
        report.target_box_height_px = target_frac * h
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
            try:
                local, p_local = refit_local_ground(band, ground, p, refit_rng, cfg, pixel_uv=uv, intrinsics=intrinsics)
                plane, used, p = local, "local", p_local
                dist = float(np.linalg.norm(p))
            except UnevenGroundError:
                # Points are there but the ground under the object is not one plane: do not stand it there.
                report.rejected["uneven ground under the contact point"] += 1
                continue
            except GroundFitError:
                report.local_refit_failed += 1
                if cfg.local_fallback == "reject":
                    report.rejected["no local ground around the contact point"] += 1
                    continue
        if depth is not None:
            d_scene = float(depth[v, u])
            if np.isfinite(d_scene) and d_scene > 0 and abs(d_scene - p[2]) > cfg.depth_tolerance_rel * p[2]:
                report.rejected["scene depth disagrees with the ground plane (not free ground)"] += 1
                continue
        target_h = rng.uniform(*hr) if fixed_h is None else fixed_h
        scale = target_h / max(asset.reference_height_m, 1e-9)
        yaw = rng.uniform(-np.pi, np.pi)
        cam_from_object = object_pose_on_ground(p, plane, yaw)
        corners = transform_points(cam_from_object, asset.corners_m() * scale)
        uvc, z = project_points(corners, intrinsics.K)
        if np.any(z <= 0.05) or not np.all(np.isfinite(uvc)):
            report.rejected["object crosses the camera plane"] += 1
            continue
        box = box_of_points(uvc)
        bw, bh = box[2] - box[0], box[3] - box[1]
        inside = (min(box[2], w - 0.5) - max(box[0], -0.5)) * (min(box[3], h - 0.5) - max(box[1], -0.5))
        if bw <= 0 or bh <= 0 or inside / (bw * bh) < cfg.min_in_image_frac or box[2] < 0 or box[3] < 0:
            report.rejected["projected box leaves the image"] += 1
            continue
        if bh < cfg.min_box_height_px:
            report.rejected["too small in the image"] += 1
            continue
        if bh > cfg.max_box_height_frac * h:
            report.rejected["too large in the image"] += 1
            continue
        if _overlap_frac(box, existing) > cfg.max_overlap_existing:
            report.rejected["overlaps an existing box"] += 1
            continue
        if points_in_cam is not None or existing_objects:
            # 3D checks (collision.py): LiDAR/stereo points inside the object's box above the ground, existing
            # 3D boxes (OrientedBox), depth occlusion. Reasons read "key: detail"; the report counts by key.
            box3d = OrientedBox.standing_on_ground(cam_from_object, tuple(asset.extents_m * scale), asset.category)
            reason = check_candidate(
                box3d,
                plane,
                intrinsics,
                points_in_cam=points_in_cam,
                existing=existing_objects,
                depth=depth,
                cfg=collision_cfg if collision_cfg is not None else CollisionConfig(),
            )
            if reason is not None:
                report.rejected[reason.kind] += 1
                continue
        report.chosen_because = (
            f"first candidate passing all checks (try {report.tries}): ground point at {dist:.1f} m on the "
            f"{used} plane, box {bh:.0f} px high{size_note}"
        )
        placement = Placement(
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
        return placement, report
    return None, report
