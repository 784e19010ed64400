"""The insertion pipeline for one image: scene -> placement -> lighting -> render -> composite -> harmonize -> annotate.

``insert_into_image`` is the functional core used by the albumentations transform, the offline CLI, the demo and
the detection study. Every stage records what it used and which modules it skipped and why, so any insertion can be
replayed from its :class:`InsertionRecord`.
"""
from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from . import composite as comp
from .annotate import ObjectAnnotation, annotate_object, box_visibility_under_cover
from .assets import CATEGORY_HEIGHT_RANGE_M, DEFAULT_ASSETS, Asset, default_asset
from .config import CONFIG_DIR, load_config
from .geometry import (Intrinsics, invert_rigid, make_rigid, project_points, transform_points,
                       unproject_points)
from .lighting.estimate import LightingEstimate, estimate_lighting
from .lighting.shading import shade_object
from .lighting.shadows import (contact_occlusion, occluder_distance_from_footprint, shadow_ratio_from_sun_sky,
                               soften_shadow)
from .ground import GroundFitError, GroundPlane, ground_plane_from_depth, prior_ground_plane
from .region import PlaceableRegion, below_horizon_mask, placeable_region
from .scenes.single_image import SingleImageConfig, estimate_camera_from_image
from .collision import OrientedBox
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
    harmonize_test_time_views: bool = True  # learnt harmonizers: average 6 views (False: 1 view, ~2-6x faster)
    asset_source: str = "default"        # "default": shared-data model per category, bank for others; "bank": all bank
    ssaa: int = 2                        # supersampling of the object render (edge quality vs time, cost ~ssaa^2)
    # Priors when the scene does not say.
    camera_height_m: float = 1.6
    estimate_camera: bool = True         # horizon/pitch/roll (and focal when unknown) from vanishing lines
    max_camera_pitch_deg: float = 25.0  # estimates beyond these bounds fall back to the level-camera prior
    max_camera_roll_deg: float = 10.0
    default_hfov_deg: float = 60.0
    naive_height_frac_range: tuple[float, float] = (0.05, 0.4)
    naive_height_frac_samples: tuple[float, ...] = ()   # when set, naive paste draws its heights from these instead
    placement_cfg: PlacementConfig = PlacementConfig()

    def __post_init__(self):
        if not self.categories:
            raise ValueError("InsertionConfig.categories must not be empty")
        if not (0 <= self.min_objects <= self.max_objects):
            raise ValueError(f"need 0 <= min_objects <= max_objects, got {self.min_objects}, {self.max_objects}")
        if self.ssaa < 1:
            raise ValueError("ssaa must be >= 1")
        if self.asset_source not in ("default", "bank"):
            raise ValueError(f"asset_source must be 'default' or 'bank', got {self.asset_source!r}")


def load_preset(name: str, **overrides) -> InsertionConfig:
    """``configs/presets/<name>.yaml`` (fast | balanced | accurate) with keyword overrides."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose from {PRESETS}")
    cfg = load_config(InsertionConfig, CONFIG_DIR / "presets" / f"{name}.yaml")
    return replace(cfg, **overrides) if overrides else cfg


@dataclass
class InsertionRecord:
    """What was done to one image: enough to replay it (placements are frozen records) and to debug it."""

    placements: list[Placement] = field(default_factory=list)
    annotations: list[ObjectAnnotation] = field(default_factory=list)
    lighting: LightingEstimate | None = None
    modules: dict[str, str] = field(default_factory=dict)   # stage -> what was used, or "skipped: why"
    placement_reports: list[dict] = field(default_factory=list)
    existing_visibility: list[float] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "placements": [asdict(p) for p in self.placements],
            "annotations": [a.to_dict() for a in self.annotations],
            "lighting": self.lighting.to_dict() if self.lighting else None,
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


def _scene_geometry(image: np.ndarray, intrinsics, depth, rng, cfg: InsertionConfig, modules: dict,
                    need_ground: bool) -> tuple[Intrinsics, GroundPlane | None]:
    """Camera and ground plane from what the scene offers: depth (RANSAC) > vanishing lines in the image (horizon,
    pitch, roll, focal when unknown) > priors (FOV, level camera at the configured height)."""
    h, w = image.shape[:2]
    if intrinsics is not None and not isinstance(intrinsics, Intrinsics):
        intrinsics = Intrinsics.from_matrix(np.asarray(intrinsics), w, h)
    modules["camera"] = "given" if intrinsics is not None else "unknown"
    if not need_ground:
        if intrinsics is None:
            modules["camera"] = f"prior: hfov {cfg.default_hfov_deg} deg (no placement: only the size matters)"
            intrinsics = Intrinsics.from_fov(w, h, cfg.default_hfov_deg)
        return intrinsics, None
    if depth is not None and intrinsics is not None:
        try:
            g = ground_plane_from_depth(depth, intrinsics, rng)
            modules["ground"] = f"RANSAC on depth ({g.inlier_ratio:.2f} inliers, rms {g.rms_m:.3f} m)"
            return intrinsics, g
        except GroundFitError as e:
            modules["ground"] = f"depth fit failed ({e}); "
    elif depth is not None:
        modules["ground"] = "depth ignored: no intrinsics to unproject it; "
    if cfg.estimate_camera:
        cam = estimate_camera_from_image(image, rng, intrinsics=intrinsics, cfg=SingleImageConfig(
            hfov_prior_deg=cfg.default_hfov_deg, camera_height_m=cfg.camera_height_m))
        pitch, roll = (np.degrees(x) for x in cam.ground.pitch_roll_rad())
        if abs(pitch) <= cfg.max_camera_pitch_deg and abs(roll) <= cfg.max_camera_roll_deg:
            if intrinsics is None:
                modules["camera"] = f"estimated: focal from {cam.focal_source}"
            modules["ground"] = modules.get("ground", "") + (
                f"horizon from {cam.horizon_source} (pitch {pitch:.1f}, roll {roll:.1f} deg), camera "
                f"{cfg.camera_height_m} m above the ground (prior)")
            return cam.intrinsics, cam.ground
        # A vanishing-line estimate outside what a road camera does is more likely wrong than the level prior.
        modules["ground"] = modules.get("ground", "") + (
            f"vanishing-line camera rejected (pitch {pitch:.0f}, roll {roll:.0f} deg beyond "
            f"{cfg.max_camera_pitch_deg}/{cfg.max_camera_roll_deg}); ")
    if intrinsics is None:
        modules["camera"] = f"prior: unknown camera, hfov {cfg.default_hfov_deg} deg, principal point at centre"
        intrinsics = Intrinsics.from_fov(w, h, cfg.default_hfov_deg)
    modules["ground"] = modules.get("ground", "") + f"prior: level camera {cfg.camera_height_m} m above the ground"
    return intrinsics, prior_ground_plane(cfg.camera_height_m)


def _scene_lighting(image, intr: Intrinsics, ground: GroundPlane, rng, cfg: InsertionConfig, meta: dict,
                    modules: dict) -> LightingEstimate:
    """Sun (kept apart, for shading and shadows) + SH ambient in the image's linear radiometric units."""
    if not cfg.lighting:
        # Ablation: no estimated lighting. The object is lit by a uniform ambient equal to the image's gray-world
        # irradiance (so it is neither black nor blown out), no sun.
        E = np.asarray(comp.ExposureMatch.from_image(image).irradiance_rgb)
        sh = np.zeros((9, 3))
        sh[0] = E / (np.pi * 0.886227)  # irradiance of a constant SH radiance L00*Y00 is pi * 0.886227 * L00
        modules["lighting"] = "skipped: disabled (ablation); uniform gray-world ambient, no sun"
        return LightingEstimate(None, np.zeros(3), sh, 0.0, False, 0.0, "none", ground.normal)
    est = estimate_lighting(image, intr, None, {**meta, "up_in_world": ground.normal}, rng=rng)
    if est.dominant_sun:
        modules["lighting"] = (f"sun from {est.source} (confidence {est.confidence:.2f}), sun/sky ratio "
                               f"{est.sun_sky_ratio:.2f}, SH ambient")
    else:
        modules["lighting"] = f"no dominant sun ({est.source}): environment (SH) light only"
    return est


def object_shadow_ratio(asset: Asset, cam_from_object: np.ndarray, intr: Intrinsics, lighting: LightingEstimate,
                        scene_depth: np.ndarray | None) -> np.ndarray:
    """Multiplicative shadow ratio (H, W) of one object on the ground: sun visibility from the shadow catcher,
    strength from the sun/sky ratio, penumbra growing with the distance to the occluder, contact occlusion.
    Computed inside the window the catcher rendered (1 elsewhere)."""
    R = cam_from_object[:3, :3]
    sun_cam = lighting.sun_direction_in_cam if lighting.dominant_sun else None
    # Below-horizon direction: the catcher then returns the ground geometry with full visibility.
    sun_obj = R.T @ sun_cam if sun_cam is not None else np.array([0.0, 0.0, -1.0])
    sl = render_ground_shadow(asset, cam_from_object, intr, sun_obj)
    out = np.ones((intr.height, intr.width), np.float32)
    x0, y0, x1, y1 = sl.roi
    gm = sl.ground_mask[y0:y1, x0:x1]
    if not gm.any():
        return out
    gdepth = sl.ground_depth[y0:y1, x0:x1]
    vv, uu = np.nonzero(gm)
    pts_cam = unproject_points(np.stack([uu + x0, vv + y0], -1).astype(float), gdepth[gm], intr.K)
    pts_obj = transform_points(invert_rigid(cam_from_object), pts_cam)
    lo, hi = asset.bounds_m
    # Horizontal distance from each ground point to the object's footprint rectangle.
    dx = np.maximum(np.maximum(lo[0] - pts_obj[:, 0], pts_obj[:, 0] - hi[0]), 0.0)
    dy = np.maximum(np.maximum(lo[1] - pts_obj[:, 1], pts_obj[:, 1] - hi[1]), 0.0)
    rho = np.full(gm.shape, 1e6)  # off the ground patch: far from the object, no contact occlusion
    rho[gm] = np.hypot(dx, dy)
    ao = contact_occlusion(rho, asset.height_m)
    ratio = shadow_ratio_from_sun_sky(sl.visibility[y0:y1, x0:x1], lighting.sun_sky_ratio if sun_cam is not None
                                      else 0.0, ambient_occlusion=ao)
    if sun_cam is not None:
        elevation = float(np.arcsin(np.clip(sun_obj[2], -1.0, 1.0)))
        dist = np.full(gm.shape, np.nan)
        dist[gm] = occluder_distance_from_footprint(pts_obj[:, :2], asset.corners_m()[:, :2], elevation)
        ppm = np.where(gm, intr.fy / np.maximum(gdepth, 1e-3), 0.0)  # eps: no division by zero depth
        ratio = soften_shadow(ratio, dist, pixels_per_metre=ppm)
    # The real scene in front of the shadowed ground hides the shadow.
    sd = None if scene_depth is None else scene_depth[y0:y1, x0:x1]
    unoccluded = comp.visible_fraction_against_depth(gdepth, sd)
    out[y0:y1, x0:x1] = 1.0 - (1.0 - ratio) * unoccluded
    return out


_object_shadow = object_shadow_ratio  # the name scripts/eval_lighting_kitti.py uses


def _naive_pose(asset: Asset, intr: Intrinsics, rng, cfg: InsertionConfig) -> tuple[np.ndarray, float]:
    """Random 2D position and size with no scene geometry: the object stands upright facing the camera at the
    depth that gives the sampled pixel height, centred on a random pixel."""
    if cfg.naive_height_frac_samples:   # the same empirical size distribution the placement targets use
        base = cfg.naive_height_frac_samples[int(rng.integers(len(cfg.naive_height_frac_samples)))]
        h_px = float(np.clip(base * np.exp(rng.normal(0.0, cfg.placement_cfg.box_height_jitter)), 1e-3, 1.0)) * \
            intr.height
    else:
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


def _choose_asset(category: str, rng, cfg: InsertionConfig, bank=None) -> Asset:
    """The caller's asset source, else the shared-data default of the category (asset_source "default"), else the
    asset bank (``aias_augment.bank``: sweethome3d catalogs, gazebo models, procedural debris), real-size jittered."""
    if bank is not None:
        return bank.sample(category, rng)
    if cfg.asset_source == "default" and category in DEFAULT_ASSETS:
        return default_asset(category)
    from .bank import get_bank  # lazy: the bank catalog is only read when a category needs it
    return get_bank().sample(category, rng)


def insert_into_image(image: np.ndarray, bboxes_xywh=None, labels=None, rng: np.random.Generator | None = None,
                      cfg: InsertionConfig = InsertionConfig(), *, intrinsics=None, depth=None,
                      meta: dict | None = None, min_visibility: float = 0.0, bank=None,
                      n_objects: int | None = None) -> InsertionResult:
    """Insert 1..k objects into ``image`` and return the new image, boxes and a replayable record.

    image: (H, W, 3) uint8 RGB. bboxes_xywh: (N, 4) COCO boxes already in the image, labels their labels.
    intrinsics: Intrinsics or 3x3 K (None: FOV prior). depth: (H, W) metres (0/NaN unknown) or None.
    min_visibility: existing boxes whose visible fraction under the inserted objects drops below it are dropped.
    meta: optional scene facts: 'placeable_mask' ((H, W) bool, where objects may stand), 'semantic' (label map for
        the placeable region), 'lidar_points_in_cam' / 'boxes_in_cam' (3D collision checks), lighting keys of
        :func:`aias_augment.lighting.estimate_lighting` ('lat', 'lon', 'utc', 'indoor', ...).
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
    intr, ground = _scene_geometry(img, intrinsics, depth, rng, cfg, mods, need_ground=cfg.placement)
    if not cfg.placement:
        mods["placement"] = "skipped: disabled (ablation or naive paste); random 2D position and size"
    region = None
    if cfg.placement:
        if meta.get("placeable_mask") is not None:  # the caller says where objects may stand (e.g. road pixels)
            m = np.asarray(meta["placeable_mask"], bool)
            if m.shape != (h, w):
                raise ValueError(f"meta['placeable_mask'] must be {(h, w)}, got {m.shape}")
            region = PlaceableRegion(m & below_horizon_mask(ground, intr), "given", float(m.mean()))
        else:
            region = placeable_region(intr, ground, depth=depth, semantic=meta.get("semantic"))
        mods["region"] = f"{region.evidence} ({100 * region.fraction:.0f}% of the image placeable)"
        if region.evidence != "prior:below_horizon" and "ground_mask" not in meta:
            meta = {**meta, "ground_mask": region.mask}  # lit/shadowed ground for the sun/sky ratio
    lighting = _scene_lighting(img, intr, ground or prior_ground_plane(cfg.camera_height_m), rng, cfg, meta, mods)
    record.lighting = lighting
    k = int(n_objects if n_objects is not None else rng.integers(cfg.min_objects, cfg.max_objects + 1))

    existing_xyxy = np.c_[boxes[:, :2], boxes[:, :2] + boxes[:, 2:]]
    taken = [b for b in existing_xyxy]
    # DGP-style 3D scene info (meta "lidar_points_in_cam" (N, 3), "boxes_in_cam" [OrientedBox]): candidates must not
    # intersect LiDAR clusters, existing 3D boxes, or the objects inserted before them.
    scene_points = meta.get("lidar_points_in_cam")
    boxes_3d = list(meta.get("boxes_in_cam") or [])
    if cfg.placement and (scene_points is not None or boxes_3d):
        mods["collision"] = (f"3D checks: {0 if scene_points is None else len(scene_points)} scene points, "
                             f"{len(boxes_3d)} existing 3D boxes, earlier insertions")
    layers = []   # (placement, asset, RenderLayers, shaded_linear)
    for _ in range(k):
        category = cfg.categories[int(rng.integers(len(cfg.categories)))]
        base = _choose_asset(category, rng, cfg, bank)
        if cfg.placement:
            placement, report = sample_placement(base, ground, intr, rng, existing_boxes_xyxy=np.array(taken),
                                                 depth=depth, cfg=cfg.placement_cfg, region_mask=region.mask,
                                                 height_range_m=CATEGORY_HEIGHT_RANGE_M.get(category),
                                                 points_in_cam=scene_points,
                                                 existing_objects=boxes_3d if "collision" in mods else None)
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
        shaded = shade_object(rl.albedo_linear, rl.normals_in_cam, rl.alpha > 0, lighting)
        layers.append((placement, asset, rl, shaded, cam_from_object))
        taken.append(np.array(placement.amodal_box_xyxy))
        if cfg.placement and "collision" in mods:
            boxes_3d.append(OrientedBox.standing_on_ground(cam_from_object, tuple(asset.extents_m), category))
        record.placements.append(placement)

    # Composite far to near.
    bg = comp.to_linear(img)
    if cfg.shadow and layers:
        ratio = np.ones((h, w), np.float32)
        for placement, asset, rl, _, cam_from_object in layers:
            ratio = np.minimum(ratio, object_shadow_ratio(asset, cam_from_object, intr, lighting, depth))
        bg = comp.apply_shadow(bg, ratio)  # overlapping shadows of one sun do not darken twice: min, not product
        mods["shadow"] = ("shadow catcher (ground patch with/without the object), soft penumbra, contact occlusion"
                          if lighting.dominant_sun else "contact occlusion only: no dominant sun")
    elif not cfg.shadow:
        mods["shadow"] = "skipped: disabled (ablation or naive paste)"

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
        return (harmonize(image, mask, method=cfg.harmonize_method, rng=rng,
                          test_time_views=cfg.harmonize_test_time_views), f"harmonized ({cfg.harmonize_method})")
    except FileNotFoundError as e:
        return image, f"skipped: {e}"
