"""Placement: choose where an object stands, as the paper does, by projecting a 3D ground point through K[R|t].

``sample_placement`` only *chooses* (returns a frozen, JSON-serialisable :class:`Placement`); rendering it is
another stage. Every rejected candidate keeps its reason in the returned :class:`PlacementReport`.
"""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from .assets import CATEGORY_HEIGHT_RANGE_M, Asset
from .collision import CollisionConfig, OrientedBox, check_candidate
from .geometry import Intrinsics, make_rigid, project_points, transform_points
from .ground import GroundPlane


@dataclass(frozen=True)
class PlacementConfig:
    max_tries: int = 60
    min_box_height_px: float = 12.0
    max_box_height_frac: float = 0.6        # of the image height
    max_distance_m: float = 60.0
    min_distance_m: float = 2.0
    max_overlap_existing: float = 0.3       # intersection / inserted-box area, against existing + earlier boxes
    min_in_image_frac: float = 0.9          # fraction of the projected box that must lie inside the image
    depth_tolerance_rel: float = 0.15       # |scene depth - plane depth| / plane depth for "this pixel is ground"
    horizon_margin_px: float = 8.0          # contact pixels must be this far below the horizon


@dataclass(frozen=True)
class Placement:
    """Everything needed to re-render one inserted object exactly (all in the frame's OpenCV camera frame)."""

    category: str
    asset_name: str
    asset_source: str
    scale: float                       # applied to the canonical asset (metres -> metres)
    height_m: float
    yaw_rad: float
    contact_point_in_cam: tuple[float, float, float]
    contact_pixel: tuple[float, float]
    cam_from_object: tuple[tuple[float, ...], ...]
    amodal_box_xyxy: tuple[float, float, float, float]  # from the projected bounding-box corners
    ground_normal_in_cam: tuple[float, float, float]
    ground_d: float
    ground_source: str

    @property
    def cam_from_object_matrix(self) -> np.ndarray:
        return np.array(self.cam_from_object, dtype=np.float64)


@dataclass
class PlacementReport:
    tries: int = 0
    rejected: Counter = field(default_factory=Counter)
    chosen_because: str = ""

    def to_dict(self) -> dict:
        return {"tries": self.tries, "rejected": dict(self.rejected), "chosen_because": self.chosen_because}


def object_pose_on_ground(contact_point_in_cam: np.ndarray, ground: GroundPlane, yaw_rad: float) -> np.ndarray:
    """cam_from_object for an object standing at a ground point: object z = plane normal (up), yaw about it.

    Yaw 0 points the object x axis along the camera x axis projected onto the ground.
    """
    up = ground.normal
    ref = np.array([1.0, 0.0, 0.0])
    x0 = ref - (ref @ up) * up
    if np.linalg.norm(x0) < 1e-6:  # camera x axis vertical (rolled 90 deg): use the optical axis instead
        ref = np.array([0.0, 0.0, 1.0])
        x0 = ref - (ref @ up) * up
    x0 /= np.linalg.norm(x0)
    y0 = np.cross(up, x0)
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    x = c * x0 + s * y0
    y = np.cross(up, x)
    return make_rigid(np.stack([x, y, up], axis=1), contact_point_in_cam)


def box_of_points(uv: np.ndarray) -> np.ndarray:
    return np.array([uv[:, 0].min(), uv[:, 1].min(), uv[:, 0].max(), uv[:, 1].max()])


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


def sample_placement(asset: Asset, ground: GroundPlane, intrinsics: Intrinsics, rng: np.random.Generator, *,
                     existing_boxes_xyxy: np.ndarray | None = None, depth: np.ndarray | None = None,
                     region_mask: np.ndarray | None = None, height_range_m: tuple[float, float] | None = None,
                     cfg: PlacementConfig = PlacementConfig(), points_in_cam: np.ndarray | None = None,
                     existing_objects: list | None = None,
                     collision_cfg=None) -> tuple[Placement | None, PlacementReport]:
    """Choose a ground point, scale and yaw for ``asset``; ``None`` (with reasons) when no candidate passes.

    Candidates: a pixel drawn uniformly in the ground region (below the horizon, inside ``region_mask`` when
    given), lifted to 3D by intersecting its ray with ``ground`` (the paper's Ax+By+Cz+D=0), then checked:
    distance range, scene depth agrees with the plane at that pixel (when depth is known), projected box inside
    the image, pixel size, overlap with existing boxes.
    """
    w, h = intrinsics.width, intrinsics.height
    existing = np.zeros((0, 4)) if existing_boxes_xyxy is None else np.asarray(existing_boxes_xyxy, float).reshape(-1, 4)
    hr = height_range_m or CATEGORY_HEIGHT_RANGE_M.get(asset.category, (asset.height_m, asset.height_m))
    report = PlacementReport()
    try:
        horizon = ground.horizon_line(intrinsics)
    except ValueError:
        horizon = None
    uu, vv = np.meshgrid(np.arange(w), np.arange(h))
    allowed = np.ones((h, w), bool)
    if horizon is not None:
        allowed &= horizon[0] * uu + horizon[1] * vv + horizon[2] > cfg.horizon_margin_px
    if region_mask is not None:
        allowed &= np.asarray(region_mask, bool)
    cand = np.flatnonzero(allowed)
    if len(cand) == 0:
        report.rejected["no ground pixels in view"] += 1
        return None, report
    for _ in range(cfg.max_tries):
        report.tries += 1
        idx = cand[rng.integers(len(cand))]
        v, u = divmod(int(idx), w)
        uv = np.array([u + rng.uniform(-0.5, 0.5), v + rng.uniform(-0.5, 0.5)])
        p = ground.intersect_pixels(uv, intrinsics)
        if not np.all(np.isfinite(p)):
            report.rejected["ray misses the ground"] += 1
            continue
        dist = float(np.linalg.norm(p))
        if not (cfg.min_distance_m <= dist <= cfg.max_distance_m):
            report.rejected["distance out of range"] += 1
            continue
        if depth is not None:
            d_scene = float(depth[v, u])
            if np.isfinite(d_scene) and d_scene > 0 and abs(d_scene - p[2]) > cfg.depth_tolerance_rel * p[2]:
                report.rejected["scene depth disagrees with the ground plane (not free ground)"] += 1
                continue
        target_h = rng.uniform(*hr)
        scale = target_h / max(asset.height_m, 1e-9)
        yaw = rng.uniform(-np.pi, np.pi)
        cam_from_object = object_pose_on_ground(p, ground, yaw)
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
            reason = check_candidate(box3d, ground, intrinsics, points_in_cam=points_in_cam,
                                     existing=existing_objects, depth=depth,
                                     cfg=collision_cfg if collision_cfg is not None else CollisionConfig())
            if reason is not None:
                report.rejected[reason.split(":")[0]] += 1
                continue
        report.chosen_because = (
            f"first candidate passing all checks (try {report.tries}): ground point at {dist:.1f} m, "
            f"box {bh:.0f} px high"
        )
        placement = Placement(
            category=asset.category, asset_name=asset.name, asset_source=asset.source, scale=float(scale),
            height_m=float(target_h), yaw_rad=float(yaw), contact_point_in_cam=tuple(map(float, p)),
            contact_pixel=(float(uv[0]), float(uv[1])),
            cam_from_object=tuple(tuple(map(float, r)) for r in cam_from_object),
            amodal_box_xyxy=tuple(map(float, box)), ground_normal_in_cam=tuple(map(float, ground.normal)),
            ground_d=float(ground.d), ground_source=ground.source,
        )
        return placement, report
    return None, report
