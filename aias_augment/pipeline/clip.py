"""Video object insertion (the paper's video path): one object pose in WORLD coordinates for the whole clip.

``insert_into_clip`` chooses the contact point once, in the world: the ground under where the camera will be at
frame ``start + lookahead_frames`` (shifted sideways by ``lateral_offset_m`` so the object is beside the camera
path, not under it), or a ground pixel sampled in the first frame and lifted to the world. The point is projected
through K [R | t] of every frame (:func:`aias_augment.analyse.ground.project_world_point_track`). Per frame, when depth is
given, the ground is re-fitted locally around the projected contact (:func:`aias_augment.plan.placement.
refit_local_ground`); the median of those per-frame height offsets corrects the ONE world pose (per-frame poses
would jitter). The clip is planned once (:func:`plan_clip`: contact, yaw, world pose, per-frame camera pose of the
object, ground and lighting) and every frame goes through the image door's stages (:func:`apply_clip` ->
:func:`aias_augment.apply.stages.apply_plan`): rendered with that pose, shaded with the frame's estimate of ONE clip
lighting (same sun in the world, e.g. ``estimate_lighting_clip``; default a uniform ambient), layer stages with the
object's image motion, the image door's shadow stage (the ONE world pose and the ONE clip sun make it a fixed patch
of the world ground), composited against the frame's depth and annotated (COCO xywh of the visible part). With ``flow_refine`` the ground patch under the contact is tracked with KLT
(:mod:`aias_augment.plan.stabilize`) and each frame's object pose slides on its ground so the contact stays on the
tracked pixel: drifting poses (visual odometry) no longer make the object skate.

A toppling object (``topple_frames``) is knocked over during the clip: it turns about the edge of its base towards a
direction drawn in the plan and lands on its side (:func:`aias_augment.assets.deform.tipped`), the angle growing as
under a constant angular acceleration; each frame renders the turned object standing where it rests then.

A moving object (``speed_m_per_frame``) goes along its heading on the world ground from frame ``start`` on: its pose,
contact track and shadow move with it; the local refit is measured under each frame's contact, and flow refinement
(which tracks the ground under a standing object) is refused.

Several objects in one clip, kept apart, with the clip's lighting and harmonization: the clip door
:func:`aias_augment.pipeline.clip_objects.insert_objects_into_clip` (what ``aias-augment`` on a clip calls), built
on :func:`plan_clip` and :func:`apply_clip_objects`.

Poses: ``cams_from_world`` (N, 4, 4) OpenCV ``cam_from_world`` (KITTI poses inverted, DGP world poses, or
:func:`aias_augment.scenes.video.estimate_video_motion`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from aias_augment.analyse.exposure import ExposureMatch
from aias_augment.analyse.ground import GroundFitError, GroundPlane, project_world_point_track
from aias_augment.analyse.lighting.estimate import LightingEstimate
from aias_augment.assets.asset import Asset
from aias_augment.core.geometry import Intrinsics, check_rigid, invert_rigid, project_points, transform_points
from aias_augment.core.report import skipped
from aias_augment.pipeline.clip_motion import first_collision, object_boxes_in_world, travel_m
from aias_augment.pipeline.clip_motion import topple as fall
from aias_augment.pipeline.clip_plan import ClipPlan, VideoInsertionConfig
from aias_augment.plan.placement import (
    box_of_points,
    ground_band_points,
    object_pose_on_ground,
    refit_local_ground,
)
from aias_augment.plan.stabilize import refined_cam_from_object, track_contact_with_flow

__all__ = [
    "VideoInsertionConfig",
    "ClipInsertion",
    "ClipPlan",
    "apply_clip",
    "apply_clip_objects",
    "choose_world_contact",
    "first_collision",
    "insert_into_clip",
    "object_boxes_in_world",
    "travel_m",
    "plan_clip",
]


@dataclass
class ClipInsertion:
    frames: list[np.ndarray]  # (H, W, 3) uint8 per frame
    boxes_xywh: list[tuple | None]  # visible COCO box per frame (None: not visible)
    amodal_boxes_xywh: list[tuple | None]  # full projected silhouette box per frame
    contact_in_world: np.ndarray  # (3,) after the refit correction
    world_from_object: np.ndarray  # (4, 4) at frame ``start`` (a standing object: in every frame)
    contact_track_uv: np.ndarray  # (N, 2) projection of the contact in each frame, NaN behind the camera
    contact_visible: np.ndarray  # (N,) bool
    refit_offsets_m: list[float | None] = field(default_factory=list)  # per frame: local ground - world contact
    masks: list[np.ndarray | None] = field(default_factory=list)  # per frame: the object's visible soft alpha
    modules: dict[str, str] = field(default_factory=dict)
    contact_track_in_world: np.ndarray | None = None  # (N, 3) the contact per frame (a moving object moves it)
    visibilities: list[float | None] = field(default_factory=list)  # per frame: visible / amodal pixels

    def coco_annotations(self, category: str, first_image_id: int = 0) -> list[dict]:
        """One COCO annotation per frame where the object is visible (image_id = first_image_id + frame index)."""
        return [
            {
                "image_id": first_image_id + i,
                "category": category,
                "bbox": list(b),
                "area": float(b[2] * b[3]),
                "iscrowd": 0,
            }
            for i, b in enumerate(self.boxes_xywh)
            if b is not None
        ]


def _world_ground(ground_in_cam0: GroundPlane, cam0_from_world: np.ndarray) -> GroundPlane:
    return ground_in_cam0.transformed(invert_rigid(cam0_from_world))


def choose_world_contact(
    cams_from_world: np.ndarray,
    ground_in_cam0: GroundPlane,
    intrinsics: Intrinsics,
    rng: np.random.Generator,
    cfg: VideoInsertionConfig = VideoInsertionConfig(),
    start: int = 0,
) -> tuple[np.ndarray, GroundPlane]:
    """(contact point (3,), ground plane) in the world.

    "lookahead": the camera centre of frame j = start + T (clamped to the clip), moved lateral_offset_m along that
    camera's x axis and ahead_m along its z axis, dropped onto the ground as camera j sees it: ``ground_in_cam0``
    taken as camera-relative (a
    vehicle camera keeps its height and tilt over the road, while the road itself climbs and turns). "sampled": a
    random below-horizon pixel of frame ``start`` (2..40 m) lifted to its ground, then to the world.
    """
    poses = np.asarray(cams_from_world, float)
    if cfg.contact == "lookahead":
        j = min(start + cfg.lookahead_frames, len(poses) - 1)
        world_from_cam = invert_rigid(poses[j])
        world_ground = _world_ground(ground_in_cam0, poses[j])
        p = world_from_cam[:3, 3] + cfg.lateral_offset_m * world_from_cam[:3, 0] + cfg.ahead_m * world_from_cam[:3, 2]
        return world_ground.project_to_plane(p), world_ground
    world_ground = _world_ground(ground_in_cam0, poses[start])
    for _ in range(200):
        uv = np.array([rng.uniform(0, intrinsics.width), rng.uniform(intrinsics.cy, intrinsics.height)])
        p = ground_in_cam0.intersect_pixels(uv, intrinsics)
        if np.all(np.isfinite(p)) and 2.0 < np.linalg.norm(p) < 40.0:
            return transform_points(invert_rigid(poses[start]), p), world_ground
    raise ValueError("choose_world_contact: no ground pixel 2..40 m away in the first frame")


def plan_clip(
    frames,
    intrinsics: Intrinsics,
    cams_from_world,
    rng: np.random.Generator,
    cfg: VideoInsertionConfig = VideoInsertionConfig(),
    *,
    asset: Asset,
    ground_in_cam0: GroundPlane,
    depths=None,
    lighting: list[LightingEstimate] | None = None,
    start: int = 0,
    yaw_rad: float | None = None,
    layer_params: dict | None = None,
) -> ClipPlan:
    """Plan one object for the whole clip (see the module docstring and :func:`insert_into_clip`): every draw from
    ``rng`` happens here (in this order: contact, yaw, local refit, fall, flow tracking)."""
    poses = np.asarray(cams_from_world, dtype=np.float64)
    n = len(frames)
    _check_clip(frames, intrinsics, poses, depths, lighting, start)
    mods: dict[str, str] = {}
    contact_w, world_ground = choose_world_contact(poses, ground_in_cam0, intrinsics, rng, cfg, start)
    yaw = float(rng.uniform(-np.pi, np.pi)) if yaw_rad is None else float(yaw_rad)
    scale = 1.0 if cfg.height_m is None else cfg.height_m / max(asset.height_m, 1e-9)  # eps: degenerate asset
    obj = asset.scaled(scale) if scale != 1.0 else asset
    # A moving object goes along its heading (its x axis on the ground, which the yaw sets): step k frames from start.
    heading_w = (
        invert_rigid(poses[start])[:3, :3]
        @ object_pose_on_ground(transform_points(poses[start], contact_w), world_ground.transformed(poses[start]), yaw)[
            :3, 0
        ]
    )
    steps = travel_m(n, start, cfg)
    contact_w, offsets, mods["refit"] = _refit_contact(
        contact_w, world_ground, heading_w * steps[:, None], poses, intrinsics, depths, rng, cfg
    )

    # One world pose: object z = world up, yaw about it (reference axis: first camera's x on the ground).
    cam0_from_obj = object_pose_on_ground(
        transform_points(poses[start], contact_w), world_ground.transformed(poses[start]), yaw
    )
    world_from_object = invert_rigid(poses[start]) @ cam0_from_obj
    contacts_w = contact_w[None, :] + steps[:, None] * heading_w[None, :]
    frame_assets: list[Asset | None] = [None] * n
    object_from_frame = [np.eye(4)] * n
    topple = None
    if cfg.topple_frames:
        frame_assets, object_from_frame, topple = fall(obj, n, cfg, rng)
        contacts_w = np.array([contact_w + world_from_object[:3, :3] @ T[:3, 3] for T in object_from_frame])
        mods["motion"] = _motion_note(cfg, topple)
    if cfg.speed_m_per_frame == 0 and not cfg.topple_frames:
        track_uv, visible = project_world_point_track(contact_w, intrinsics, poses)
    else:
        tracks = [project_world_point_track(c, intrinsics, poses[i : i + 1]) for i, c in enumerate(contacts_w)]
        track_uv = np.concatenate([uv for uv, _ in tracks])
        visible = np.concatenate([v for _, v in tracks])
    if cfg.speed_m_per_frame:
        mods["motion"] = _motion_note(cfg, None)
    lights, mods["lighting"], mods["shadow"] = _clip_lights(frames, lighting, world_ground, poses, start, cfg)
    grounds = [world_ground.transformed(T) for T in poses]
    flow = None
    if cfg.flow_refine:
        flow = track_contact_with_flow(
            frames, track_uv, grounds, intrinsics, rng.spawn(1)[0], poses, start, cfg.flow_cfg
        )
        used = sum(st == "flow" for st in flow.status)
        mods["stabilize"] = f"KLT ground tracking: contact corrected in {used}/{n - 1} frames"
    else:
        mods["stabilize"] = skipped("poses trusted (flow_refine off)")
    # the object's pose in each frame: turned as it falls, moved along its heading
    worlds_from_object = [world_from_object @ object_from_frame[i] for i in range(n)]
    for i, world_from_object_i in enumerate(worlds_from_object):
        world_from_object_i[:3, 3] += steps[i] * heading_w
    cams_from_object = _cams_from_object(
        worlds_from_object, poses, [a or obj for a in frame_assets], intrinsics, flow, contact_w, grounds
    )
    if layer_params:
        mods["layers"] = ", ".join(f"{k} {v}" for k, v in layer_params.items())
    if flow is not None:  # the contact track the frames are rendered with
        track_uv = np.where(np.array([st == "flow" for st in flow.status])[:, None], flow.uv, track_uv)
    return ClipPlan(
        obj,
        yaw,
        contact_w,
        world_from_object,
        tuple(cams_from_object),
        tuple(grounds),
        tuple(lights),
        track_uv,
        visible,
        contacts_w,
        tuple(offsets),
        dict(layer_params or {}),
        mods,
        tuple(worlds_from_object),
        tuple(frame_assets),
        topple,
    )


def _motion_note(cfg: VideoInsertionConfig, topple: dict | None) -> str:
    """What the plan's ``motion`` note says: how the object falls (``topple``), or how it moves."""
    if topple is not None:
        return (
            f"knocked over towards {np.degrees(topple['azimuth']):.0f} deg of its x axis: falls from frame "
            f"{topple['start']}, lies on its side ({np.degrees(topple['rest_angle']):.0f} deg) from frame "
            f"{topple['start'] + topple['frames']}"
        )
    return f"moving {cfg.speed_m_per_frame:.3f} m per frame along its heading" + (
        f", standing {cfg.move_after_frames} frames, then reaching that speed over {cfg.accelerate_frames}"
        if cfg.move_after_frames or cfg.accelerate_frames
        else ""
    )


def _check_clip(frames, intrinsics: Intrinsics, poses: np.ndarray, depths, lighting, start: int) -> None:
    """One rigid 4x4 pose, depth map and lighting estimate per frame, frames (H, W, 3) uint8 of the intrinsics' size,
    ``start`` inside the clip: ``ValueError`` naming the first problem."""
    n = len(frames)
    if poses.shape != (n, 4, 4):
        raise ValueError(f"need one 4x4 cam_from_world per frame: {n} frames, poses {poses.shape}")
    for T in poses:
        check_rigid(T, "cam_from_world")
    if depths is not None and len(depths) != n:
        raise ValueError(f"{len(depths)} depth maps for {n} frames")
    if lighting is not None and len(lighting) != n:
        raise ValueError(f"{len(lighting)} lighting estimates for {n} frames")
    if not 0 <= start < n:
        raise ValueError(f"start {start} outside the clip of {n} frames")
    for f in frames:
        if np.asarray(f).shape != (intrinsics.height, intrinsics.width, 3) or np.asarray(f).dtype != np.uint8:
            raise ValueError("frames must be (H, W, 3) uint8 matching the intrinsics")


def _refit_contact(contact_w, world_ground, travel_w, poses, intrinsics, depths, rng, cfg: VideoInsertionConfig):
    """(contact, per-frame offsets, note): per frame with a depth map, the ground re-fitted locally around the
    projected contact (``travel_w``: (N, 3) how far the object has gone in each frame) and its signed offset along
    the world up; the median of those offsets moves the ONE world contact (per-frame poses would jitter)."""
    n = len(poses)
    offsets: list[float | None] = [None] * n
    if depths is None or not cfg.local_refit:
        return contact_w, offsets, skipped("no depth (or disabled); plane of the first frame")
    refit_rng = rng.spawn(1)[0]
    for i in range(n):
        if depths[i] is None:
            continue
        g_i = world_ground.transformed(poses[i])
        c_i = transform_points(poses[i], contact_w + travel_w[i])
        if c_i[2] <= 0.5:
            continue
        band = ground_band_points(
            g_i, intrinsics, refit_rng, depth=np.asarray(depths[i], np.float32), cfg=cfg.placement_cfg
        )
        try:
            local, _ = refit_local_ground(band, g_i, c_i, refit_rng, cfg.placement_cfg)
        except GroundFitError:
            continue
        offsets[i] = -float(local.signed_distance(c_i))  # > 0: the measured ground is above the contact
    measured = [o for o in offsets if o is not None]
    if not measured:
        return contact_w, offsets, "no frame had a local ground around the contact: plane of the first frame kept"
    shift = float(np.median(measured))
    note = f"local ground in {len(measured)}/{n} frames, median offset {shift * 100:.1f} cm applied"
    return contact_w + shift * world_ground.normal, offsets, note


def _clip_lights(frames, lighting, world_ground, poses, start: int, cfg: VideoInsertionConfig):
    """(per-frame lighting, lighting note, shadow note): the estimates given, or a uniform grey-world ambient of
    frame ``start`` in every frame."""
    n = len(frames)
    if lighting is None:
        E = np.asarray(ExposureMatch.from_image(frames[start]).irradiance_rgb)
        sh = np.zeros((9, 3))
        sh[0] = E / (np.pi * 0.886227)  # constant SH radiance L00 Y00 has irradiance pi * 0.886227 * L00
        light0 = LightingEstimate(
            None, np.zeros(3), sh, 0.0, False, 0.0, "none", world_ground.transformed(poses[start]).normal
        )
        lights = [light0] * n
        light_note = "uniform grey-world ambient of the first frame (no sun)"
    else:
        lights = list(lighting)
        light_note = f"given per frame ({lights[start].source})"
    if not cfg.shadow:
        return lights, light_note, skipped("disabled")
    method = cfg.stages.shadow_method if cfg.stages else "catcher"
    shadow_note = (
        f"shadow {method} per frame (one world pose, one sun, confidence {lights[start].confidence:.2f})"
        if lights[start].dominant_sun
        else "contact occlusion only: no dominant sun"
    )
    return lights, light_note, shadow_note


def _cams_from_object(worlds_from_object, poses, assets, intrinsics: Intrinsics, flow, contact_w, grounds) -> list:
    """Per frame the object's camera pose (slid on its ground to the tracked contact where flow tracking held), or
    None where it is behind the camera or off the frame."""
    cams = []
    for i, world_from_object_i in enumerate(worlds_from_object):
        cam_from_object = poses[i] @ world_from_object_i
        if flow is not None and flow.status[i] == "flow":
            cam_from_object = refined_cam_from_object(
                cam_from_object, transform_points(poses[i], contact_w), flow.uv[i], grounds[i], intrinsics
            )
        uvc, z = project_points(transform_points(cam_from_object, assets[i].corners_m()), intrinsics.K)
        in_front = not np.any(z <= 0.05) and np.all(np.isfinite(uvc))
        b = box_of_points(uvc) if in_front else None
        on_frame = b is not None and b[2] >= 0 and b[3] >= 0 and b[0] <= intrinsics.width and b[1] <= intrinsics.height
        cams.append(cam_from_object if on_frame else None)
    return cams


def apply_clip(
    frames, intrinsics: Intrinsics, plan: ClipPlan, cfg: VideoInsertionConfig = VideoInsertionConfig(), depths=None
) -> ClipInsertion:
    """One planned object through every frame: :func:`apply_clip_objects` with one plan."""
    return apply_clip_objects(frames, intrinsics, [plan], cfg, depths)[0]


def apply_clip_objects(
    frames, intrinsics: Intrinsics, plans, cfg: VideoInsertionConfig = VideoInsertionConfig(), depths=None
) -> list[ClipInsertion]:
    """Several planned objects (each its own :func:`plan_clip`: track, asset, appearance) through every frame, each
    frame through the image door's stages (:func:`aias_augment.apply.stages.apply_plan`: render, shade, layer stages
    with each object's image motion, shadows, composite far to near against the frame's depth and each other,
    annotate) with the plans' poses, the frame's ground and lighting of the first plan. Harmonization is the clip's
    own (one transform for the clip, :func:`aias_augment.apply.harmonize.harmonize_clip`), not per frame.

    Returns one :class:`ClipInsertion` per plan; their ``frames`` are the same list (every object drawn in it),
    ``boxes``/``masks`` each object's own visible part. ``depths``: per frame None or an (H, W) z-depth map (0:
    unknown) of the scene, in front of which nothing inserted is drawn (e.g. labelled objects,
    :func:`aias_augment.pipeline.clip_occluders.occluder_depths`)."""
    from aias_augment.analyse.analysis import SceneAnalysis
    from aias_augment.apply.stages import apply_plan  # lazy: the apply step imports the renderer
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.config import InsertionConfig
    from aias_augment.plan.insertion import InsertionPlan, PlannedObject
    from aias_augment.plan.placement import placement_at

    plans = list(plans)
    if not plans:
        raise ValueError("apply_clip_objects: need at least one plan")
    for plan in plans:
        if len(frames) != len(plan.cams_from_object):
            raise ValueError(f"{len(frames)} frames for a plan of {len(plan.cams_from_object)}")
    stages_cfg = replace(
        cfg.stages or InsertionConfig(),
        ssaa=cfg.ssaa,
        shadow=cfg.shadow,
        harmonize=False,
        render_method="full",
    )
    shape = (intrinsics.height, intrinsics.width)
    out_frames = []
    boxes = [[] for _ in plans]
    amodal = [[] for _ in plans]
    masks = [[] for _ in plans]
    visibilities = [[] for _ in plans]
    for i, img in enumerate(frames):
        img = np.asarray(img)
        live = [k for k, plan in enumerate(plans) if plan.cams_from_object[i] is not None]
        placements = {
            k: placement_at(
                plans[k].asset_at(i), plans[k].cams_from_object[i], intrinsics, plans[k].yaw_rad, plans[k].grounds[i]
            )
            for k in live
        }
        res = None
        if live:
            analysis = SceneAnalysis(
                f"clip-frame-{i}", shape, intrinsics, plans[0].grounds[i], None, plans[0].lights[i]
            )
            frame_plan = InsertionPlan(
                tuple(PlannedObject(placements[k], plans[k].asset_at(i)) for k in live),
                0,
                len(live),
                layer_params=tuple(plans[k].layer_params for k in live),
            )
            depth = None if depths is None or depths[i] is None else np.asarray(depths[i], np.float32)
            res = apply_plan(
                Frame(img, intrinsics, depth=depth),
                analysis,
                frame_plan,
                stages_cfg,
                motions_px=tuple(_image_motion(plans[k].contact_track_uv, i) for k in live),
            )
        out_frames.append(img.copy() if res is None else res.image)
        rendered = {} if res is None else {id(pl): j for j, pl in enumerate(res.placements)}
        for k in range(len(plans)):
            j = rendered.get(id(placements[k])) if k in placements else None
            if j is None:
                boxes[k].append(None), amodal[k].append(None), masks[k].append(None), visibilities[k].append(None)
                continue
            ann = res.annotations[j]
            boxes[k].append(ann.visible_box_xywh)
            amodal[k].append(ann.amodal_box_xywh)
            masks[k].append(res.object_cover(j))
            visibilities[k].append(float(ann.visibility))
    return [
        ClipInsertion(
            out_frames,
            boxes[k],
            amodal[k],
            plan.contact_in_world,
            plan.world_from_object,
            plan.contact_track_uv,
            plan.contact_visible,
            list(plan.refit_offsets_m),
            masks[k],
            dict(plan.modules),
            plan.contact_track_in_world,
            visibilities[k],
        )
        for k, plan in enumerate(plans)
    ]


def insert_into_clip(
    frames,
    intrinsics: Intrinsics,
    cams_from_world,
    rng: np.random.Generator,
    cfg: VideoInsertionConfig = VideoInsertionConfig(),
    *,
    asset: Asset,
    ground_in_cam0: GroundPlane,
    depths=None,
    lighting: list[LightingEstimate] | None = None,
    start: int = 0,
    yaw_rad: float | None = None,
    layer_params: dict | None = None,
) -> ClipInsertion:
    """Insert ``asset`` into every frame with one world pose (see module docstring): :func:`plan_clip` once, then
    :func:`apply_clip`.

    frames: N (H, W, 3) uint8 RGB. cams_from_world: (N, 4, 4). ground_in_cam0: ground of frame ``start`` in its
    camera. depths: None or N (H, W) z-depth maps (0 = unknown): per-frame refit and occlusion. lighting: None
    (uniform grey-world ambient of frame ``start``, no sun) or N per-frame estimates of ONE clip lighting, e.g.
    :func:`aias_augment.analyse.lighting.estimate.estimate_lighting_clip`. layer_params: the object's layer stages
    and their parameters (:func:`aias_augment.core.stages.draw_layer_params`), applied in every frame with the
    object's image motion there (the contact track's central difference, px per frame).
    """
    plan = plan_clip(
        frames,
        intrinsics,
        cams_from_world,
        rng,
        cfg,
        asset=asset,
        ground_in_cam0=ground_in_cam0,
        depths=depths,
        lighting=lighting,
        start=start,
        yaw_rad=yaw_rad,
        layer_params=layer_params,
    )
    return apply_clip(frames, intrinsics, plan, cfg, depths)


def _image_motion(track_uv: np.ndarray, i: int) -> np.ndarray | None:
    """The contact's image motion at frame ``i`` (px per frame): central difference of the track, one-sided at the
    ends; None where a neighbour is behind the camera or the clip has one frame."""
    lo, hi = max(i - 1, 0), min(i + 1, len(track_uv) - 1)
    if hi == lo:
        return None
    d = (np.asarray(track_uv[hi], float) - np.asarray(track_uv[lo], float)) / (hi - lo)
    return d if np.all(np.isfinite(d)) else None
