"""The insertion pipeline for one image: scene -> placement -> lighting -> render -> composite -> harmonize -> annotate.

``insert_into_image`` is the functional core used by the albumentations transform, the offline CLI, the demo and
the detection study. Every stage records what it used and which modules it skipped and why, so any insertion can be
replayed from its :class:`InsertionRecord`.
"""
from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from . import composite as comp
from .annotate import ObjectAnnotation, annotate_object, box_visibility_under_cover
from .assets import CATEGORY_HEIGHT_RANGE_M, Asset, default_asset
from .config import CONFIG_DIR, from_dict, load_config
from .geometry import Intrinsics, check_finite, make_rigid, project_points, transform_points
from .ground import GroundFitError, GroundPlane, ground_plane_from_depth, prior_ground_plane
from .placement import Placement, PlacementConfig, box_of_points, sample_placement
from .render import render_ground_shadow, render_object

log = logging.getLogger(__name__)

PRESETS = ("fast", "balanced", "accurate")


@dataclass(frozen=True)
class InsertionConfig:
    categories: tuple[str, ...] = ("traffic_cone",)
    min_objects: int = 1
    max_objects: int = 3
    # Stages (ablation switches). naive_paste=True is 3D Copy-Paste's "random insertion": a plain render pasted at a
    # random position and scale, no geometry, lighting, shadow or harmonization.
    placement: bool = True
    shadow: bool = True
    lighting: bool = True
    harmonize: bool = True
    naive_paste: bool = False
    harmonize_method: str = "camera"
    ssaa: int = 2                        # supersampling of the object render (edge quality vs time, cost ~ssaa^2)
    # Priors when the scene does not say.
    camera_height_m: float = 1.6
    default_hfov_deg: float = 60.0
    sun_elevation_deg_range: tuple[float, float] = (25.0, 60.0)
    sun_sky_ratio: float = 2.5           # sun / sky irradiance on the ground (sunny day ~2-5, overcast ~0)
    naive_height_frac_range: tuple[float, float] = (0.05, 0.4)
    placement_cfg: PlacementConfig = PlacementConfig()

    def __post_init__(self):
        if not self.categories:
            raise ValueError("InsertionConfig.categories must not be empty")
        if not (0 <= self.min_objects <= self.max_objects):
            raise ValueError(f"need 0 <= min_objects <= max_objects, got {self.min_objects}, {self.max_objects}")
        if self.ssaa < 1:
            raise ValueError("ssaa must be >= 1")


def load_preset(name: str, **overrides) -> InsertionConfig:
    """``configs/presets/<name>.yaml`` (fast | balanced | accurate) with keyword overrides."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose from {PRESETS}")
    cfg = load_config(InsertionConfig, CONFIG_DIR / "presets" / f"{name}.yaml")
    return replace(cfg, **overrides) if overrides else cfg


@dataclass(frozen=True)
class LightingUsed:
    sun_direction_in_cam: tuple[float, float, float] | None
    irradiance_rgb: tuple[float, float, float]
    sun_sky_ratio: float
    source: str


@dataclass
class InsertionRecord:
    """What was done to one image: enough to replay it (placements are frozen records) and to debug it."""

    placements: list[Placement] = field(default_factory=list)
    annotations: list[ObjectAnnotation] = field(default_factory=list)
    lighting: LightingUsed | None = None
    modules: dict[str, str] = field(default_factory=dict)   # stage -> what was used, or "skipped: why"
    placement_reports: list[dict] = field(default_factory=list)
    existing_visibility: list[float] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "placements": [asdict(p) for p in self.placements],
            "annotations": [a.to_dict() for a in self.annotations],
            "lighting": asdict(self.lighting) if self.lighting else None,
            "modules": self.modules,
            "placement_reports": self.placement_reports,
            "existing_visibility": self.existing_visibility,
        }


@dataclass
class InsertionResult:
    image: np.ndarray                 # (H, W, 3) uint8
    bboxes: np.ndarray                # (M, 4) COCO xywh: kept existing boxes then inserted ones
    labels: list                      # matching labels (existing labels kept, inserted = category names)
    inserted_bboxes: np.ndarray       # (K, 4) xywh of the inserted objects' visible parts
    inserted_labels: list[str]
    keep_existing: np.ndarray         # (N,) bool: existing boxes that stay visible enough
    record: InsertionRecord


def _scene_camera(image: np.ndarray, intrinsics: Intrinsics | np.ndarray | None, cfg: InsertionConfig,
                  modules: dict) -> Intrinsics:
    h, w = image.shape[:2]
    if intrinsics is None:
        modules["camera"] = f"prior: unknown camera, hfov {cfg.default_hfov_deg} deg, principal point at centre"
        return Intrinsics.from_fov(w, h, cfg.default_hfov_deg)
    if not isinstance(intrinsics, Intrinsics):
        intrinsics = Intrinsics.from_matrix(np.asarray(intrinsics), w, h)
    modules["camera"] = "given"
    return intrinsics


def _scene_ground(depth, intr: Intrinsics, rng, cfg: InsertionConfig, modules: dict) -> GroundPlane:
    if depth is not None:
        try:
            g = ground_plane_from_depth(depth, intr, rng)
            modules["ground"] = f"RANSAC on depth ({g.inlier_ratio:.2f} inliers, rms {g.rms_m:.3f} m)"
            return g
        except GroundFitError as e:
            modules["ground"] = f"prior: depth fit failed ({e})"
    else:
        modules["ground"] = f"prior: no depth, camera {cfg.camera_height_m} m above level ground"
    return prior_ground_plane(cfg.camera_height_m)


def _scene_lighting(image, ground: GroundPlane, rng, cfg: InsertionConfig, meta: dict, modules: dict) -> LightingUsed:
    exposure = comp.ExposureMatch.from_image(image)
    if not cfg.lighting:
        modules["lighting"] = "skipped: disabled (ablation); flat unlit albedo"
        return LightingUsed(None, (1.0, 1.0, 1.0), 0.0, "none")
    sun = meta.get("sun_direction_in_cam")
    if sun is not None:
        sun = check_finite(np.asarray(sun, float).reshape(3), "sun_direction_in_cam")
        sun = sun / np.linalg.norm(sun)
        source = "metadata"
    else:
        # Prior: sun above the ground plane at a random elevation and azimuth (recorded for replay).
        elev = np.deg2rad(rng.uniform(*cfg.sun_elevation_deg_range))
        az = rng.uniform(-np.pi, np.pi)
        up = ground.normal
        e1 = np.cross(up, [0.0, 0.0, 1.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(up, e1)
        sun = np.cos(elev) * (np.cos(az) * e1 + np.sin(az) * e2) + np.sin(elev) * up
        source = "prior (random elevation/azimuth)"
    modules["lighting"] = f"sun from {source}; exposure/white balance from gray-world"
    return LightingUsed(tuple(map(float, sun)), exposure.irradiance_rgb, float(cfg.sun_sky_ratio), source)


def _shade(albedo: np.ndarray, normals: np.ndarray, lighting: LightingUsed, ground: GroundPlane) -> np.ndarray:
    """Lambertian: albedo * (E_sky + E_sun * max(0, n.l)); E split so that a horizontal surface in the sun receives
    the measured total irradiance."""
    E = np.asarray(lighting.irradiance_rgb, np.float32)
    if lighting.sun_direction_in_cam is None:
        return albedo * E
    sun = np.asarray(lighting.sun_direction_in_cam, np.float32)
    r = lighting.sun_sky_ratio
    cos_ground = max(float(sun @ ground.normal), 0.1)  # eps: a grazing sun must not blow up the normal irradiance
    e_sky = E / (1.0 + r)
    e_sun = E * r / (1.0 + r) / cos_ground
    ndotl = np.clip(normals @ sun, 0.0, None)[..., None]
    # Sky light reaching a surface tilted away from the zenith: (1 + n.up) / 2 (uniform sky, no ground bounce).
    sky_vis = (0.5 * (1.0 + normals @ ground.normal.astype(np.float32)))[..., None]
    return albedo * (e_sky * (0.3 + 0.7 * sky_vis) + e_sun * ndotl)


def _naive_pose(asset: Asset, intr: Intrinsics, rng, cfg: InsertionConfig) -> tuple[np.ndarray, float]:
    """Random 2D position and size with no scene geometry: the object stands upright facing the camera at the
    depth that gives the sampled pixel height, centred on a random pixel."""
    h_px = rng.uniform(*cfg.naive_height_frac_range) * intr.height
    z = intr.fy * asset.height_m / h_px
    u = rng.uniform(0.1, 0.9) * intr.width
    v = rng.uniform(0.1, 0.9) * intr.height
    yaw = rng.uniform(-np.pi, np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    R_up = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # object z (up) -> camera -y
    R_yaw = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    centre_cam = np.array([(u - intr.cx) * z / intr.fx, (v - intr.cy) * z / intr.fy, z])
    t = centre_cam - R_up @ R_yaw @ np.array([0, 0, asset.height_m / 2])
    return make_rigid(R_up @ R_yaw, t), yaw


def _choose_asset(category: str, rng, bank=None) -> Asset:
    if bank is not None:
        return bank.sample(category, rng)
    return default_asset(category)


def insert_into_image(image: np.ndarray, bboxes_xywh=None, labels=None, rng: np.random.Generator | None = None,
                      cfg: InsertionConfig = InsertionConfig(), *, intrinsics=None, depth=None,
                      meta: dict | None = None, min_visibility: float = 0.0, bank=None,
                      n_objects: int | None = None) -> InsertionResult:
    """Insert 1..k objects into ``image`` and return the new image, boxes and a replayable record.

    image: (H, W, 3) uint8 RGB. bboxes_xywh: (N, 4) COCO boxes already in the image, labels their labels.
    intrinsics: Intrinsics or 3x3 K (None: FOV prior). depth: (H, W) metres (0/NaN unknown) or None.
    min_visibility: existing boxes whose visible fraction under the inserted objects drops below it are dropped.
    """
    if rng is None:
        raise ValueError("insert_into_image needs an explicit numpy Generator (rng) for reproducibility")
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
    h, w = img.shape[:2]
    boxes = np.zeros((0, 4)) if bboxes_xywh is None else np.asarray(bboxes_xywh, float).reshape(-1, 4)
    labels = [] if labels is None else list(labels)
    if len(labels) != len(boxes):
        raise ValueError(f"{len(boxes)} boxes but {len(labels)} labels")
    if depth is not None:
        depth = np.asarray(depth, np.float32)
        if depth.shape != (h, w):
            raise ValueError(f"depth must be {(h, w)}, got {depth.shape}")
    meta = meta or {}
    record = InsertionRecord()
    mods = record.modules
    if cfg.naive_paste:
        cfg = replace(cfg, placement=False, shadow=False, lighting=False, harmonize=False)
        mods["mode"] = "naive paste: random position/scale, no geometry/lighting/shadow/harmonization"
    intr = _scene_camera(img, intrinsics, cfg, mods)
    ground = _scene_ground(depth, intr, rng, cfg, mods) if cfg.placement else None
    if not cfg.placement:
        mods["placement"] = "skipped: disabled (ablation or naive paste); random 2D position and size"
    lighting = _scene_lighting(img, ground or prior_ground_plane(cfg.camera_height_m), rng, cfg, meta, mods)
    k = int(n_objects if n_objects is not None else rng.integers(cfg.min_objects, cfg.max_objects + 1))

    existing_xyxy = np.c_[boxes[:, :2], boxes[:, :2] + boxes[:, 2:]]
    taken = [b for b in existing_xyxy]
    layers = []   # (placement, asset, RenderLayers, shaded_linear)
    for _ in range(k):
        category = cfg.categories[int(rng.integers(len(cfg.categories)))]
        base = _choose_asset(category, rng, bank)
        if cfg.placement:
            placement, report = sample_placement(base, ground, intr, rng, existing_boxes_xyxy=np.array(taken),
                                                 depth=depth, cfg=cfg.placement_cfg,
                                                 height_range_m=CATEGORY_HEIGHT_RANGE_M.get(category))
            record.placement_reports.append(report.to_dict())
            if placement is None:
                log.info("no valid placement for %s: %s", category, dict(report.rejected))
                continue
            asset = base.scaled(placement.scale)
            cam_from_object = placement.cam_from_object_matrix
        else:
            hr = CATEGORY_HEIGHT_RANGE_M.get(category, (base.height_m, base.height_m))
            asset = base.scaled(rng.uniform(*hr) / base.height_m)
            cam_from_object, yaw = _naive_pose(asset, intr, rng, cfg)
            uvc, _ = project_points(transform_points(cam_from_object, asset.corners_m()), intr.K)
            placement = Placement(category, asset.name, asset.source, float(asset.meta.get("scale", 1.0)),
                                  asset.height_m, float(yaw), tuple(map(float, cam_from_object[:3, 3])),
                                  (float("nan"), float("nan")),
                                  tuple(tuple(map(float, r)) for r in cam_from_object),
                                  tuple(map(float, box_of_points(uvc))), (0.0, -1.0, 0.0), 0.0, "none")
        rl = render_object(asset, cam_from_object, intr, ssaa=cfg.ssaa)
        if rl.alpha.max() <= 0.5:
            record.placement_reports.append({"rejected": {"renders to no pixel": 1}})
            continue
        shaded = _shade(rl.albedo_linear, rl.normals_in_cam, lighting,
                        ground or prior_ground_plane(cfg.camera_height_m))
        layers.append((placement, asset, rl, shaded, cam_from_object))
        taken.append(np.array(placement.amodal_box_xyxy))
        record.placements.append(placement)

    # Composite far to near.
    bg = comp.to_linear(img)
    if cfg.shadow and lighting.sun_direction_in_cam is not None and layers:
        ratio = np.ones((h, w), np.float32)
        for placement, asset, rl, _, cam_from_object in layers:
            sun_in_obj = cam_from_object[:3, :3].T @ np.asarray(lighting.sun_direction_in_cam)
            sl = render_ground_shadow(asset, cam_from_object, intr, sun_in_obj)
            unoccluded = comp.visible_fraction_against_depth(sl.ground_depth, depth)
            shadow_strength = lighting.sun_sky_ratio / (1.0 + lighting.sun_sky_ratio)
            r_i = 1.0 - shadow_strength * (1.0 - sl.visibility) * unoccluded
            ratio = np.minimum(ratio, r_i)  # overlapping shadows of one sun do not darken twice
        bg = comp.apply_shadow(bg, ratio)
        mods["shadow"] = "shadow catcher: ground patch rendered with/without the object, differential ratio"
    elif not cfg.shadow:
        mods["shadow"] = "skipped: disabled (ablation or naive paste)"
    else:
        mods["shadow"] = "skipped: no sun direction"

    # Far to near by median object depth, so nearer objects are blended last.
    order = sorted(range(len(layers)), key=lambda i: -float(np.median(layers[i][2].depth[layers[i][2].alpha > 0])))
    out = bg
    vis_alphas = []
    for i in order:
        _, _, rl, shaded, _ = layers[i]
        vis = rl.alpha * comp.visible_fraction_against_depth(rl.depth, depth)
        out = comp.alpha_over(out, shaded, vis)
    # Visible part of each object: not behind the scene, not behind nearer inserted objects.
    for i in range(len(layers)):
        rl_i = layers[i][2]
        vis = rl_i.alpha * comp.visible_fraction_against_depth(rl_i.depth, depth)
        for j in range(len(layers)):
            rl_j = layers[j][2]
            if j == i:
                continue
            nearer = (rl_j.alpha > 0) & (rl_j.depth > 0) & ((rl_i.depth <= 0) | (rl_j.depth < rl_i.depth))
            vis = vis * np.where(nearer, 1.0 - rl_j.alpha, 1.0)
        vis_alphas.append(vis)
    result = comp.to_uint8(out)

    if cfg.harmonize and layers:
        union = np.clip(np.maximum.reduce(vis_alphas), 0, 1).astype(np.float32)
        result, mods["harmonize"] = _harmonize(result, union, cfg, rng)
    elif not cfg.harmonize:
        mods["harmonize"] = "skipped: disabled (ablation or naive paste)"

    inserted_boxes, inserted_labels = [], []
    cover = np.zeros((h, w), np.float32)
    for (placement, asset, rl, _, _), vis in zip(layers, vis_alphas):
        ann = annotate_object(placement.category, rl.alpha, vis)
        record.annotations.append(ann)
        cover = np.maximum(cover, vis)
        if ann.visible_box_xywh is not None:
            inserted_boxes.append(ann.visible_box_xywh)
            inserted_labels.append(placement.category)
    existing_vis = box_visibility_under_cover(existing_xyxy, cover)
    keep = existing_vis >= min_visibility
    record.existing_visibility = existing_vis.tolist()
    ins = np.array(inserted_boxes, float).reshape(-1, 4)
    all_boxes = np.concatenate([boxes[keep], ins], axis=0)
    all_labels = [l for l, k_ in zip(labels, keep) if k_] + inserted_labels
    return InsertionResult(result, all_boxes, all_labels, ins, inserted_labels, keep, record)


def _harmonize(image: np.ndarray, mask: np.ndarray, cfg: InsertionConfig, rng) -> tuple[np.ndarray, str]:
    try:
        from .harmonize import harmonize
    except ImportError as e:  # the harmonization package is optional at this stage of the pipeline
        return image, f"skipped: harmonizer unavailable ({e})"
    try:
        return harmonize(image, mask, method=cfg.harmonize_method, rng=rng), f"harmonized ({cfg.harmonize_method})"
    except FileNotFoundError as e:
        return image, f"skipped: {e}"
