"""Step 3: carry out an :class:`InsertionPlan` on its frame: render, shade, shadow, composite, harmonize, annotate.

:func:`apply_plan` draws nothing (the harmonizer's generator is seeded from the plan): the same frame, analysis and
plan give the same bytes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np

from aias_augment.analyse.analysis import SceneAnalysis
from aias_augment.analyse.instances import body_value
from aias_augment.analyse.lighting.estimate import LightingEstimate
from aias_augment.apply import composite as comp
from aias_augment.apply.annotate import ObjectAnnotation, annotate_in_window, mask_box_xywh
from aias_augment.apply.cone_raycast import raycast_cone
from aias_augment.apply.config import ApplyConfig, apply_config
from aias_augment.apply.frame_steps import frame_steps, frame_without_objects, paste_window
from aias_augment.apply.occluders import ground_scale, image_occluders, visibility_under_nearer
from aias_augment.apply.projected_shadow import projected_ground
from aias_augment.apply.render import render_ground_shadow, render_object_window
from aias_augment.apply.shading import Coating, object_coating, shade_object, shade_pixels, view_directions
from aias_augment.apply.shadows import (
    contact_occlusion_of,
    fill_nearest,
    occluder_distance_from_footprint,
    shadow_ratio_from_sun_sky,
    soften_shadow,
    sun_shadow_limits,
)
from aias_augment.apply.view_cache import ViewCache, warp_from_view_cache
from aias_augment.assets.asset import Asset
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics, invert_rigid, transform_points, unproject_points
from aias_augment.core.report import skipped
from aias_augment.core.srgb import srgb_to_linear
from aias_augment.core.stages import ObjectLayer, apply_layer_stages
from aias_augment.plan.insertion import InsertionPlan
from aias_augment.plan.placement import Placement

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class AppliedPlan:
    """The result of :func:`apply_plan`: the new image (H, W, 3) uint8, one annotation per object that rendered to a
    pixel (with its placement), ``cover_window`` float32 over ``window`` (x0, y0, x1, y1): the union of the objects'
    visible coverage (what hides existing boxes; 0 outside the window; :attr:`cover` is it on the whole frame), and
    per stage what was done ('shadow', 'harmonize') and which planned objects were dropped. ``layer_params``: the
    layer stages' parameters of the objects that rendered (aligned with ``placements``). ``object_cover_windows``:
    per rendered object, its own visible coverage over ``window`` (behind the scene and nearer objects removed).
    ``labelled_visibility``: per labelled box given to :func:`apply_plan`, the share of it not covered by the
    inserted objects nearer than it (None: no labelled boxes were given, or they could not be ordered).
    ``frame_params``: the frame stages' parameters (the plan's)."""

    image: np.ndarray
    placements: tuple[Placement, ...]
    annotations: tuple[ObjectAnnotation, ...]
    cover_window: np.ndarray
    window: tuple[int, int, int, int]
    modules: dict = field(default_factory=dict)
    dropped: tuple[dict, ...] = ()
    layer_params: tuple[dict, ...] = ()
    object_cover_windows: tuple[np.ndarray, ...] = ()
    labelled_visibility: np.ndarray | None = None
    frame_params: dict = field(default_factory=dict)

    @property
    def cover(self) -> np.ndarray:
        """(H, W) float32: :attr:`cover_window` on the whole frame."""
        return paste_window(self.image.shape[:2], self.window, self.cover_window)

    def object_cover(self, k: int) -> np.ndarray:
        """(H, W) float32: the visible coverage of the ``k``-th rendered object on the whole frame, in [0, 1]."""
        return paste_window(self.image.shape[:2], self.window, np.clip(self.object_cover_windows[k], 0, 1))


def apply_plan(
    frame: Frame,
    analysis: SceneAnalysis,
    plan: InsertionPlan,
    cfg: ApplyConfig = ApplyConfig(),
    *,
    view_cache: ViewCache | None = None,
    motions_px: tuple | None = None,
    labelled_xywh: np.ndarray | None = None,
) -> AppliedPlan:
    """Render the plan's objects into ``frame.image`` (see the module docstring). ``cfg``: the apply step's record
    (or a config that carries one: the door's ``InsertionConfig``): ssaa, render method, shadow and harmonization
    switches (the plan fixed everything random). ``view_cache``: where
    ``render_method="view_cache"`` keeps its views (None: the process-wide :func:`default_view_cache`).
    ``motions_px``: per object, its image motion during one frame interval ((2,) px) for the layer stages, or None
    (a still image; a clip frame passes its objects' motion). ``labelled_xywh``: (N, 4) COCO boxes of the frame's
    labelled objects, which occlude the inserted objects they stand in front of and are covered by those in front of
    them (:mod:`aias_augment.apply.occluders`; not in a naive paste, which places nothing on the ground).

    The steps, in order: each object rendered, shaded and put through its layer stages (the stage list,
    :mod:`aias_augment.core.stages`); the shadows; the composite, far to near; the harmonizer; the frame stages of
    the stage list; the camera's own stages (camera match, a monochrome camera's grey); the boxes. All float work
    happens inside one window: the union of the objects' and their shadows' render windows (the sRGB -> linear ->
    sRGB round trip is exact on uint8, so the pixels outside it are the input's, unless a frame stage changes them)."""
    cfg = apply_config(cfg)
    img = frame.image
    h, w = img.shape[:2]
    if analysis.image_shape != (h, w):
        raise ValueError(f"analysis is for {analysis.image_shape}, frame is {(h, w)}")
    mods: dict = {}
    occ = _labelled_occluders(img, analysis, plan, cfg, labelled_xywh, mods)
    rendered, dropped = _render_objects(analysis, plan, cfg, (h, w), view_cache, motions_px, mods)
    shadows = _shadow_windows(rendered, analysis, frame.depth, cfg, occ, mods)
    rois = [r for _, r, *_ in rendered] + [r for r, _ in shadows if r[2] > r[0] and r[3] > r[1]]
    if not rois:
        if not cfg.harmonize:
            mods["harmonize"] = skipped("disabled (ablation or naive paste)")
        none = None if occ.labelled is None else np.ones(len(occ.labelled.contact_z))
        image = frame_without_objects(img.copy(), plan.frame_params, analysis.monochrome)
        empty = np.zeros((0, 0), np.float32)
        return AppliedPlan(
            image,
            (),
            (),
            empty,
            (0, 0, 0, 0),
            mods,
            tuple(dropped),
            labelled_visibility=none,
            frame_params=dict(plan.frame_params),
        )
    win = (min(r[0] for r in rois), min(r[1] for r in rois), max(r[2] for r in rois), max(r[3] for r in rois))
    X0, Y0, X1, Y1 = win
    layers, out, vis_alphas = _composite(img, frame.depth, rendered, shadows, win, occ)
    result = img.copy()
    result[Y0:Y1, X0:X1] = comp.to_uint8(out)
    full = (h, w)
    # The union of the objects' visible coverages: the one full-frame float layer (what hides existing boxes, and
    # the harmonizer's mask, whose context reaches outside the window); per object, only windows.
    cover_w = np.clip(np.maximum.reduce(vis_alphas), 0, 1).astype(np.float32, copy=False)
    result = frame_steps(result, cover_w, win, img, analysis.monochrome, plan, cfg, mods)
    annotations = [
        annotate_in_window(
            obj.placement.category, win, alpha, vis_w, full, decoy=obj.placement.decoy, box_margins=cfg.box_convention
        )
        for (obj, alpha, _, _), vis_w in zip(layers, vis_alphas)
    ]
    labelled_vis = None
    if occ.labelled is not None:
        # each object's contact z on the labelled objects' ground
        object_z = [
            o.placement.contact_point_in_cam[2] / ground_scale(analysis.ground, o.placement) for o, *_ in layers
        ]
        labelled_vis = visibility_under_nearer(
            labelled_xywh, occ.labelled.contact_z, vis_alphas, object_z, win[:2], full
        )
    if any(cfg.box_convention):
        mods["boxes"] = "labelling convention: margins (left, top, right, bottom) {} of the label".format(
            list(cfg.box_convention)
        )
    return AppliedPlan(
        result,
        tuple(o.placement for o, _, _, _ in layers),
        tuple(annotations),
        cover_w,
        win,
        mods,
        tuple(dropped),
        tuple(p for *_, p in rendered),
        tuple(vis_alphas),
        labelled_vis,
        dict(plan.frame_params),
    )


@dataclass(frozen=True)
class _Occluders:
    """The frame's labelled objects as occluders (:func:`image_occluders`; None: none were given or ordered) and
    the ground they stand on."""

    labelled: object | None
    ground: object

    @property
    def depth(self) -> np.ndarray | None:
        return None if self.labelled is None else self.labelled.depth

    def depth_for(self, placement: Placement, arr: np.ndarray | None) -> np.ndarray | None:
        """The labelled depths ``arr`` on the ground ``placement`` stands on (None: none)."""
        return None if arr is None else arr * np.float32(ground_scale(self.ground, placement))


def _labelled_occluders(img, analysis: SceneAnalysis, plan: InsertionPlan, cfg, labelled_xywh, mods) -> _Occluders:
    labelled = None
    if labelled_xywh is not None and len(labelled_xywh):
        if cfg.placement:
            placements = [o.placement for o in plan.objects]
            labelled, mods["occlusion"] = image_occluders(
                img, labelled_xywh, analysis.ground, analysis.intrinsics, placements
            )
        else:
            mods["occlusion"] = skipped("naive paste: objects pasted over the labelled ones")
    return _Occluders(labelled, analysis.ground)


def _render_objects(
    analysis: SceneAnalysis, plan: InsertionPlan, cfg, shape: tuple[int, int], view_cache, motions_px, mods: dict
) -> tuple[list, list]:
    """Each planned object rendered (warped from its view-cache bin, or in full), shaded and put through its layer
    stages: per object that covers a pixel (object, roi, alpha, depth, shaded linear RGB, its layer parameters),
    and a report per object dropped."""
    intr = analysis.intrinsics
    # the glossy coating reflects the estimated light: not in a render without lighting (ablation, naive paste)
    coating = Coating(cfg.coating_f0, cfg.coating_roughness) if cfg.lighting else Coating()
    rendered, dropped, gains = [], [], []
    n_cached = n_cast = 0
    for k, obj in enumerate(plan.objects):
        warped = None
        if cfg.render_method == "raycast":
            warped = raycast_cone(obj.asset, obj.cam_from_object, intr)
            n_cast += warped is not None
        if warped is None and cfg.render_method in ("view_cache", "raycast"):
            warped = warp_from_view_cache(obj.asset, obj.cam_from_object, intr, view_cache)
            n_cached += warped is not None
        layer = _shaded_layer(obj, warped, intr, analysis.lighting, cfg, coating)
        if layer is None:
            dropped.append({"rejected": {"renders to no pixel": 1}})
            continue
        if cfg.cone_brightness == "labels" and cfg.lighting:
            layer, gain = _as_bright_as_its_look(layer, obj.asset.meta.get("look"))
            if gain is not None:
                gains.append(gain)
        params = plan.layer_params[k] if k < len(plan.layer_params) else {}
        if params:
            layer = apply_layer_stages(layer, params, shape, None if motions_px is None else motions_px[k])
        rendered.append((obj, layer.roi, layer.alpha, layer.depth, layer.rgb, params))
    if cfg.render_method == "raycast":
        mods["render"] = (
            f"ray cast: {n_cast} of {len(plan.objects)} objects (procedural cones); view cache: {n_cached} of "
            f"{len(plan.objects)} warped from their view bin's render (the others rendered in full)"
        )
    elif cfg.render_method == "view_cache":
        mods["render"] = (
            f"view cache: {n_cached} of {len(plan.objects)} objects warped from their view bin's "
            "render and relit (the others rendered in full: too near or too large for the cache)"
        )
    if gains:
        mods["brightness"] = (
            f"{len(gains)} of {len(plan.objects)} objects scaled to their labelled cone's body brightness (gain "
            f"{min(gains):.2f}-{max(gains):.2f})"
        )
    return rendered, dropped


#: The most a labelled cone's brightness scales a shaded one by (either way): beyond it the measurement (a few
#: pixels, a clipped body) is the likelier error than the light.
MAX_BRIGHTNESS_GAIN = 4.0


def _as_bright_as_its_look(layer: ObjectLayer, look: dict | None) -> tuple[ObjectLayer, float | None]:
    """``layer`` scaled so that its body's brightness (:func:`~aias_augment.analyse.instances.body_value` on what the
    layer shows, its covered pixels in sRGB) is ``look['body_value']``, the labelled cone's in the photo: the photo's
    own light and exposure on the same paint. Unchanged (gain None) without that value or a measurable body."""
    target = None if not look else look.get("body_value")
    if target is None:
        return layer, None
    covered = layer.alpha > 0.5
    box = mask_box_xywh(covered)
    if box is None or box[3] < 8:
        return layer, None
    x, y, w, h = box
    shown = comp.to_uint8(np.where(covered[..., None], layer.rgb, 0.0))
    now = body_value(shown, (x, y, x + w, y + h))
    if now is None:
        return layer, None
    ratio = float(srgb_to_linear(float(target), np.float64)) / float(srgb_to_linear(now, np.float64))
    gain = float(np.clip(ratio, 1 / MAX_BRIGHTNESS_GAIN, MAX_BRIGHTNESS_GAIN))
    return replace(layer, rgb=(layer.rgb * np.float32(gain)).astype(layer.rgb.dtype, copy=False)), gain


def _shaded_layer(obj, warped, intr: Intrinsics, lighting: LightingEstimate, cfg, coating: Coating):
    """One object's :class:`ObjectLayer`, shaded (from its view-cache ``warped`` render when there is one), or None
    when it renders to no pixel."""
    if warped is not None:
        roi, alpha, odepth = warped.roi, warped.alpha, warped.depth
    else:
        roi, rl = render_object_window(obj.asset, obj.cam_from_object, intr, ssaa=cfg.ssaa)
        alpha, odepth = rl.alpha, rl.depth
    if alpha.size == 0 or alpha.max() <= 0.5:
        return None
    view = view_directions(roi, intr) if coating.f0 > 0 else None
    parts = object_coating(obj.asset, obj.cam_from_object, roi, odepth, intr, coating)  # matte parts: none
    if warped is not None:  # shaded on its covered pixels only
        shaded = np.zeros(alpha.shape + (3,), np.float32)
        inside = warped.inside
        shaded[inside] = shade_pixels(
            warped.albedo, warped.normals, lighting, None, None if view is None else view[inside], parts.at(inside)
        )
    else:
        shaded = shade_object(rl.albedo_linear, rl.normals_in_cam, alpha > 0, lighting, view=view, coating=parts)
    return ObjectLayer(roi, alpha, odepth, shaded)


def _shadow_windows(rendered: list, analysis: SceneAnalysis, depth, cfg, occ: _Occluders, mods: dict) -> list:
    """Per rendered object, its shadow's (roi, ratio inside roi); empty with shadows off or nothing rendered."""
    if not cfg.shadow:
        mods["shadow"] = skipped("disabled (ablation or naive paste)")
        return []
    if not rendered:
        return []
    lighting = analysis.lighting
    shadows = [
        _object_shadow_window(
            o.asset,
            o.cam_from_object,
            analysis.intrinsics,
            lighting,
            depth,
            cfg.shadow_method,
            (cfg.contact_shadow_strength, cfg.contact_shadow_radius),
            labelled_depth=occ.depth_for(o.placement, occ.depth),
        )
        for o, *_ in rendered
    ]
    how = (
        "shadow catcher (ground patch with/without the object)"
        if cfg.shadow_method == "catcher"
        else "projected silhouette (triangles along the sun onto the ground)"
    )
    mods["shadow"] = (
        f"{how}, soft penumbra, contact occlusion"
        if lighting.dominant_sun
        else "contact occlusion only: no dominant sun"
    )
    return shadows


def _composite(img, depth, rendered: list, shadows: list, win: tuple, occ: _Occluders) -> tuple[list, np.ndarray, list]:
    """The shadows and objects composited in the window ``win``: (per object (object, coverage and depth in the
    window, its own (roi, alpha, depth, shaded)), the window's linear RGB, per object its visible coverage in the
    window: not behind the scene, a labelled object or a nearer inserted object)."""
    X0, Y0, X1, Y1 = win
    wshape = (Y1 - Y0, X1 - X0)
    sdepth = None if depth is None else depth[Y0:Y1, X0:X1]
    swin = None if occ.depth is None else occ.depth[Y0:Y1, X0:X1]
    # Each object's coverage and depth placed in the common window (its shading stays in its own window).
    layers = [
        (obj, _in_window(wshape, win, roi, alpha), _in_window(wshape, win, roi, odepth), (roi, alpha, odepth, shaded))
        for obj, roi, alpha, odepth, shaded, _ in rendered
    ]
    out = _shadowed(comp.to_linear(img[Y0:Y1, X0:X1]), shadows, win)

    # Far to near by median object depth, so nearer objects are blended last; each blended in its own window
    # (its coverage is 0 elsewhere: the same values).
    def median_depth(i):
        _, alpha, odepth, _ = layers[i][3]
        return float(np.median(odepth[alpha > 0]))

    order = sorted(range(len(layers)), key=lambda i: -median_depth(i)) if len(layers) > 1 else [0]
    for i in order:
        (x0, y0, x1, y1), alpha, odepth, shaded = layers[i][3]
        sl = np.s_[y0 - Y0 : y1 - Y0, x0 - X0 : x1 - X0]
        a = alpha * _unhidden(odepth, sdepth, occ.depth_for(layers[i][0].placement, swin), sl)
        out[sl] = comp.alpha_over(out[sl], shaded, a)
    # Visible part of each object: not behind the scene, not behind nearer inserted objects.
    vis_alphas = []
    for i, (obj_i, a_i, d_i, _) in enumerate(layers):
        vis = a_i * _unhidden(d_i, sdepth, occ.depth_for(obj_i.placement, swin))
        for j, (_, a_j, d_j, _) in enumerate(layers):
            if j == i:
                continue
            nearer = (a_j > 0) & (d_j > 0) & ((d_i <= 0) | (d_j < d_i))
            vis = vis * np.where(nearer, 1.0 - a_j, 1.0)
        vis_alphas.append(vis)
    return layers, out, vis_alphas


def _shadowed(bg: np.ndarray, shadows: list, win: tuple) -> np.ndarray:
    """The window's linear background ``bg`` under the objects' shadows ((roi, ratio) each)."""
    X0, Y0, X1, Y1 = win
    if len(shadows) > 1:
        ratio = np.ones((Y1 - Y0, X1 - X0), np.float32)
        for roi, r in shadows:
            ratio = np.minimum(ratio, _in_window(ratio.shape, win, roi, r, fill=1.0))
        bg = comp.apply_shadow(bg, ratio)  # overlapping shadows of one sun do not darken twice: min, not product
    elif shadows:  # one shadow: applied in its window only (the ratio is 1 elsewhere: the same values)
        (sx0, sy0, sx1, sy1), r = shadows[0]
        if sx1 > sx0 and sy1 > sy0:
            sl = np.s_[sy0 - Y0 : sy1 - Y0, sx0 - X0 : sx1 - X0]
            bg[sl] = comp.apply_shadow(bg[sl], r)
    return bg


def _unhidden(object_depth, scene_depth, labelled_depth, sl=np.s_[:, :]) -> np.ndarray | float:
    """Where an inserted surface of ``object_depth`` is not behind the scene (its measured depth, with the noise
    margin) nor behind a labelled object (its contact depth, exact: both stand on one ground plane); the depth maps
    are cut to ``sl``, None: nothing there occludes."""
    v = 1.0 if scene_depth is None else comp.visible_fraction_against_depth(object_depth, scene_depth[sl])
    if labelled_depth is not None:
        v = v * comp.visible_fraction_against_depth(object_depth, labelled_depth[sl], margin_rel=0.0)
    return v


def _in_window(wshape: tuple, win: tuple, roi: tuple, arr: np.ndarray, fill: float = 0.0) -> np.ndarray:
    """``arr`` (rendered in ``roi``) placed in the common window ``win`` (which contains roi)."""
    out = np.full(wshape + arr.shape[2:], fill, np.float32)
    x0, y0 = roi[0] - win[0], roi[1] - win[1]
    out[y0 : y0 + arr.shape[0], x0 : x0 + arr.shape[1]] = arr
    return out


def object_shadow_ratio(
    asset: Asset,
    cam_from_object: np.ndarray,
    intr: Intrinsics,
    lighting: LightingEstimate,
    scene_depth: np.ndarray | None,
) -> np.ndarray:
    """Multiplicative shadow ratio (H, W) of one object on the ground: sun visibility from the shadow catcher,
    strength from the sun/sky ratio, penumbra growing with the distance to the occluder, contact occlusion.
    Computed inside the window the catcher rendered (1 elsewhere)."""
    (x0, y0, x1, y1), ratio = _object_shadow_window(asset, cam_from_object, intr, lighting, scene_depth)
    out = np.ones((intr.height, intr.width), np.float32)
    out[y0:y1, x0:x1] = ratio
    return out


def _object_shadow_window(
    asset: Asset,
    cam_from_object: np.ndarray,
    intr: Intrinsics,
    lighting: LightingEstimate,
    scene_depth: np.ndarray | None,
    method: str = "catcher",
    contact: tuple[float, float] = (0.6, 0.25),
    labelled_depth: np.ndarray | None = None,
) -> tuple[tuple[int, int, int, int], np.ndarray]:
    """(roi, ratio inside roi) of :func:`object_shadow_ratio`; ``method``: "catcher" (GL) or "projected";
    ``contact``: the contact shadow's (strength, radius as a fraction of the object's height); ``labelled_depth``:
    the labelled objects' depth map (:mod:`aias_augment.apply.occluders`), which hides the shadow behind them."""
    R = cam_from_object[:3, :3]
    sun_cam = lighting.sun_direction_in_cam if lighting.dominant_sun else None
    # Below-horizon direction: the catcher then returns the ground geometry with full visibility.
    sun_obj = R.T @ sun_cam if sun_cam is not None else np.array([0.0, 0.0, -1.0])
    if method == "projected":
        sl, ground_xy = projected_ground(asset, cam_from_object, intr, sun_obj)
    else:
        sl, ground_xy = render_ground_shadow(asset, cam_from_object, intr, sun_obj, window=True), None
    x0, y0, x1, y1 = sl.roi
    gm = sl.ground_mask
    if not gm.any():
        return sl.roi, np.ones(gm.shape, np.float32)
    gdepth = sl.ground_depth
    if ground_xy is None:  # the catcher's ground points, from its depth
        vv, uu = np.nonzero(gm)
        pts_cam = unproject_points(np.stack([uu + x0, vv + y0], -1).astype(float), gdepth[gm], intr.K)
        ground_xy = transform_points(invert_rigid(cam_from_object), pts_cam)[:, :2]
    pts_obj = ground_xy
    lo, hi = asset.bounds_m
    # Horizontal distance from each ground point to the object's footprint rectangle.
    dx = np.maximum(np.maximum(lo[0] - pts_obj[:, 0], pts_obj[:, 0] - hi[0]), 0.0)
    dy = np.maximum(np.maximum(lo[1] - pts_obj[:, 1], pts_obj[:, 1] - hi[1]), 0.0)
    ao = np.ones(gm.shape, np.float32)  # off the ground patch: far from the object, no contact occlusion
    ao[gm] = contact_occlusion_of(np.hypot(dx, dy), asset.height_m, *contact)  # >= 0, finite: the ground points are
    # Without a sun the ratio is the contact occlusion alone ((a + 0 v) / 1).
    ratio = ao
    if sun_cam is not None:
        # As dark and as hard as the sun decision's confidence allows; never darker than that where the contact
        # occlusion alone (the shadow without a sun) is not.
        limits = sun_shadow_limits(lighting.confidence)
        r = limits.sun_sky_ratio(lighting.sun_sky_ratio)
        ratio = shadow_ratio_from_sun_sky(sl.visibility, r, ambient_occlusion=ao)
        elevation = float(np.arcsin(np.clip(sun_obj[2], -1.0, 1.0)))
        dist = np.full(gm.shape, np.nan)
        dist[gm] = occluder_distance_from_footprint(pts_obj[:, :2], asset.corners_m()[:, :2], elevation)
        ppm = np.where(gm, intr.fy / np.maximum(gdepth, 1e-3), 0.0)  # eps: no division by zero depth
        ratio = soften_shadow(ratio, dist, limits.angular_radius_rad, ppm, min_sigma_px=limits.min_sigma_px)
        ratio = np.maximum(ratio, np.minimum(ao, limits.darkest))
    # The real scene in front of the shadowed ground hides the shadow.
    win = np.s_[y0:y1, x0:x1]
    unoccluded = _unhidden(gdepth, scene_depth, None, win)
    if labelled_depth is not None:  # the penumbra reaches past the ground patch: the nearest patch pixel's ground
        unoccluded = unoccluded * _unhidden(fill_nearest(gdepth, gm), None, labelled_depth, win)
    return sl.roi, (1.0 - (1.0 - ratio) * unoccluded).astype(np.float32)
