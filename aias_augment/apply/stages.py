"""Step 3: carry out an :class:`InsertionPlan` on its frame: render, shade, shadow, composite, harmonize, annotate.

:func:`apply_plan` draws nothing (the harmonizer's generator is seeded from the plan): the same frame, analysis and
plan give the same bytes.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from aias_augment.analyse.analysis import SceneAnalysis
from aias_augment.analyse.lighting.estimate import LightingEstimate
from aias_augment.apply import composite as comp
from aias_augment.apply.annotate import ObjectAnnotation, annotate_in_window
from aias_augment.apply.layers import ObjectLayer, apply_layer_stages
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
from aias_augment.pipeline.config import InsertionConfig
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
    inserted objects nearer than it (None: no labelled boxes were given, or they could not be ordered)."""

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

    @property
    def cover(self) -> np.ndarray:
        """(H, W) float32: :attr:`cover_window` on the whole frame."""
        return _paste_window(self.image.shape[:2], self.window, self.cover_window)

    def object_cover(self, k: int) -> np.ndarray:
        """(H, W) float32: the visible coverage of the ``k``-th rendered object on the whole frame, in [0, 1]."""
        return _paste_window(self.image.shape[:2], self.window, np.clip(self.object_cover_windows[k], 0, 1))


def apply_plan(
    frame: Frame,
    analysis: SceneAnalysis,
    plan: InsertionPlan,
    cfg: InsertionConfig = InsertionConfig(),
    *,
    view_cache: ViewCache | None = None,
    motions_px: tuple | None = None,
    labelled_xywh: np.ndarray | None = None,
) -> AppliedPlan:
    """Render the plan's objects into ``frame.image`` (see the module docstring). ``cfg``: ssaa, render method,
    shadow and harmonization switches (the plan fixed everything random). ``view_cache``: where
    ``render_method="view_cache"`` keeps its views (None: the process-wide :func:`default_view_cache`).
    ``motions_px``: per object, its image motion during one frame interval ((2,) px) for the layer stages, or None
    (a still image; a clip frame passes its objects' motion). ``labelled_xywh``: (N, 4) COCO boxes of the frame's
    labelled objects, which occlude the inserted objects they stand in front of and are covered by those in front of
    them (:mod:`aias_augment.apply.occluders`; not in a naive paste, which places nothing on the ground).

    All float work happens inside one window: the union of the objects' and their shadows' render windows (the
    sRGB -> linear -> sRGB round trip is exact on uint8, so the pixels outside it are the input's)."""
    cfg = cfg.effective()
    img = frame.image
    depth = frame.depth
    h, w = img.shape[:2]
    if analysis.image_shape != (h, w):
        raise ValueError(f"analysis is for {analysis.image_shape}, frame is {(h, w)}")
    intr, lighting = analysis.intrinsics, analysis.lighting
    mods: dict = {}
    rendered, dropped = [], []
    n_cached = 0
    # the glossy coating reflects the estimated light: not in a render without lighting (ablation, naive paste)
    coating = Coating(cfg.coating_f0, cfg.coating_roughness) if cfg.lighting else Coating()
    labelled = None
    if labelled_xywh is not None and len(labelled_xywh):
        if cfg.placement:
            placements = [o.placement for o in plan.objects]
            labelled, mods["occlusion"] = image_occluders(img, labelled_xywh, analysis.ground, intr, placements)
        else:
            mods["occlusion"] = skipped("naive paste: objects pasted over the labelled ones")
    ldepth = None if labelled is None else labelled.depth

    def labelled_for(placement, arr):  # the labelled depths on the ground this object stands on
        return None if arr is None else arr * np.float32(ground_scale(analysis.ground, placement))

    for k, obj in enumerate(plan.objects):
        warped = None
        if cfg.render_method == "view_cache":
            warped = warp_from_view_cache(obj.asset, obj.cam_from_object, intr, view_cache)
            n_cached += warped is not None
        if warped is not None:
            roi, alpha, odepth = warped.roi, warped.alpha, warped.depth
        else:
            roi, rl = render_object_window(obj.asset, obj.cam_from_object, intr, ssaa=cfg.ssaa)
            alpha, odepth = rl.alpha, rl.depth
        if alpha.size == 0 or alpha.max() <= 0.5:
            dropped.append({"rejected": {"renders to no pixel": 1}})
            continue
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
        params = plan.layer_params[k] if k < len(plan.layer_params) else {}
        if params:
            motion = None if motions_px is None else motions_px[k]
            lay = apply_layer_stages(ObjectLayer(roi, alpha, odepth, shaded), params, (h, w), motion)
            roi, alpha, odepth, shaded = lay.roi, lay.alpha, lay.depth, lay.rgb
        rendered.append((obj, roi, alpha, odepth, shaded, params))
    if cfg.render_method == "view_cache":
        mods["render"] = (
            f"view cache: {n_cached} of {len(plan.objects)} objects warped from their view bin's "
            "render and relit (the others rendered in full: too near or too large for the cache)"
        )
    shadows = []
    if cfg.shadow and rendered:
        shadows = [
            _object_shadow_window(
                o.asset,
                o.cam_from_object,
                intr,
                lighting,
                depth,
                cfg.shadow_method,
                (cfg.contact_shadow_strength, cfg.contact_shadow_radius),
                labelled_depth=labelled_for(o.placement, ldepth),
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
    elif not cfg.shadow:
        mods["shadow"] = skipped("disabled (ablation or naive paste)")
    rois = [r for _, r, *_ in rendered] + [r for r, _ in shadows if r[2] > r[0] and r[3] > r[1]]
    if not rois:
        if not cfg.harmonize:
            mods["harmonize"] = skipped("disabled (ablation or naive paste)")
        none = None if labelled is None else np.ones(len(labelled.contact_z))
        return AppliedPlan(
            img.copy(),
            (),
            (),
            np.zeros((0, 0), np.float32),
            (0, 0, 0, 0),
            mods,
            tuple(dropped),
            labelled_visibility=none,
        )
    win = (min(r[0] for r in rois), min(r[1] for r in rois), max(r[2] for r in rois), max(r[3] for r in rois))
    X0, Y0, X1, Y1 = win
    wshape = (Y1 - Y0, X1 - X0)
    sdepth = None if depth is None else depth[Y0:Y1, X0:X1]
    swin = None if ldepth is None else ldepth[Y0:Y1, X0:X1]

    # Each object's coverage and depth placed in the common window (its shading stays in its own window).
    layers = [
        (obj, _in_window(wshape, win, roi, alpha), _in_window(wshape, win, roi, odepth), (roi, alpha, odepth, shaded))
        for obj, roi, alpha, odepth, shaded, _ in rendered
    ]

    bg = comp.to_linear(img[Y0:Y1, X0:X1])
    if len(shadows) > 1:
        ratio = np.ones(wshape, np.float32)
        for roi, r in shadows:
            ratio = np.minimum(ratio, _in_window(wshape, win, roi, r, fill=1.0))
        bg = comp.apply_shadow(bg, ratio)  # overlapping shadows of one sun do not darken twice: min, not product
    elif shadows:  # one shadow: applied in its window only (the ratio is 1 elsewhere: the same values)
        (sx0, sy0, sx1, sy1), r = shadows[0]
        if sx1 > sx0 and sy1 > sy0:
            sl = np.s_[sy0 - Y0 : sy1 - Y0, sx0 - X0 : sx1 - X0]
            bg[sl] = comp.apply_shadow(bg[sl], r)

    # Far to near by median object depth, so nearer objects are blended last; each blended in its own window
    # (its coverage is 0 elsewhere: the same values).
    def median_depth(i):
        _, alpha, odepth, _ = layers[i][3]
        return float(np.median(odepth[alpha > 0]))

    order = sorted(range(len(layers)), key=lambda i: -median_depth(i)) if len(layers) > 1 else [0]
    out = bg
    for i in order:
        (x0, y0, x1, y1), alpha, odepth, shaded = layers[i][3]
        sl = np.s_[y0 - Y0 : y1 - Y0, x0 - X0 : x1 - X0]
        a = alpha * _unhidden(odepth, sdepth, labelled_for(layers[i][0].placement, swin), sl)
        out[sl] = comp.alpha_over(out[sl], shaded, a)
    # Visible part of each object: not behind the scene, not behind nearer inserted objects.
    vis_alphas = []
    for i, (obj_i, a_i, d_i, _) in enumerate(layers):
        vis = a_i * _unhidden(d_i, sdepth, labelled_for(obj_i.placement, swin))
        for j, (_, a_j, d_j, _) in enumerate(layers):
            if j == i:
                continue
            nearer = (a_j > 0) & (d_j > 0) & ((d_i <= 0) | (d_j < d_i))
            vis = vis * np.where(nearer, 1.0 - a_j, 1.0)
        vis_alphas.append(vis)
    result = img.copy()
    result[Y0:Y1, X0:X1] = comp.to_uint8(out)
    full = (h, w)
    # The union of the objects' visible coverages: the one full-frame float layer (what hides existing boxes, and
    # the harmonizer's mask, whose context reaches outside the window); per object, only windows.
    cover_w = np.clip(np.maximum.reduce(vis_alphas), 0, 1).astype(np.float32, copy=False)

    if cfg.harmonize:
        before = result[Y0:Y1, X0:X1].copy() if cfg.harmonize_colour == "luminance" else None
        result, mods["harmonize"] = _harmonize(
            result,
            cover_w,
            cfg,
            np.random.default_rng(plan.harmonize_seed),
            within=win,
            mask_origin=(X0, Y0),
            in_place=True,
        )
        if before is not None:
            result[Y0:Y1, X0:X1] = keep_chromaticity(before, result[Y0:Y1, X0:X1])
            mods["harmonize"] += "; its luminance only (the lit object's chromaticity kept)"
        if cfg.camera_match:
            result, mods["camera_match"] = _camera_match(
                result, _paste_window(full, win, cover_w), cfg, img, plan.harmonize_seed
            )
    else:
        mods["harmonize"] = skipped("disabled (ablation or naive paste)")
    if analysis.monochrome:
        # A monochrome camera records luminance: the window's pixels (objects, shadows and the scene between them,
        # which is grey already and unchanged by this) as the camera's grey, R = G = B.
        grey = cv2.cvtColor(np.ascontiguousarray(result[Y0:Y1, X0:X1]), cv2.COLOR_RGB2GRAY)
        result[Y0:Y1, X0:X1] = grey[..., None]
        mods["colour"] = "luminance only: monochrome camera"

    annotations = [
        annotate_in_window(
            obj.placement.category, win, alpha, vis_w, full, decoy=obj.placement.decoy, box_margins=cfg.box_convention
        )
        for (obj, alpha, _, _), vis_w in zip(layers, vis_alphas)
    ]
    labelled_vis = None
    if labelled is not None:
        # each object's contact z on the labelled objects' ground
        object_z = [
            o.placement.contact_point_in_cam[2] / ground_scale(analysis.ground, o.placement) for o, *_ in layers
        ]
        labelled_vis = visibility_under_nearer(labelled_xywh, labelled.contact_z, vis_alphas, object_z, win[:2], full)
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
    )


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


def _paste_window(full: tuple, win: tuple, arr: np.ndarray) -> np.ndarray:
    out = np.zeros(full + arr.shape[2:], np.float32)
    out[win[1] : win[3], win[0] : win[2]] = arr
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


def keep_chromaticity(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """uint8 sRGB: each pixel of ``before`` scaled in linear light to the luminance of ``after`` (chromaticity of
    ``before``, brightness of ``after``); pixels ``after`` left unchanged stay byte-identical. A channel the scaling
    would push past white is clipped there."""
    changed = np.any(before != after, axis=-1)
    out = after.copy()
    if not changed.any():
        return out
    b, a = comp.to_linear(before[changed]), comp.to_linear(after[changed])
    w = np.array([0.2126, 0.7152, 0.0722], np.float32)
    lb, la = b @ w, a @ w
    scaled = b * (la / np.maximum(lb, 1e-6))[:, None]
    scaled = np.where((lb > 1e-6)[:, None], scaled, a)  # black before: nothing to scale, the harmonizer's pixel
    out[changed] = comp.to_uint8(scaled)
    return out


def _harmonize(
    image: np.ndarray,
    mask: np.ndarray,
    cfg: InsertionConfig,
    rng,
    within: tuple[int, int, int, int] | None = None,
    mask_box: tuple | None = None,
    *,
    mask_origin: tuple[int, int] = (0, 0),
    in_place: bool = False,
) -> tuple[np.ndarray, str]:
    """``mask``: the soft mask, placed at ``mask_origin`` (x, y) in ``image`` (0 elsewhere; by default the whole
    image's mask); ``within``: a window (x0, y0, x1, y1) known to hold every masked pixel (None: the whole image);
    ``mask_box``: the box (x0, y0, x1, y1) of the mask's non-zero pixels when the caller has it; ``in_place``: the
    fast harmonizer writes into ``image`` (the caller's own copy) instead of a new array."""
    H, W = image.shape[:2]
    ox, oy = mask_origin
    mh, mw = mask.shape
    windowed = (ox, oy, mh, mw) != (0, 0, H, W)

    def whole() -> np.ndarray:
        return _paste_window((H, W), (ox, oy, ox + mw, oy + mh), mask) if windowed else mask

    try:
        from aias_augment.apply.harmonize import harmonize
    except ImportError as e:  # the harmonization package is optional at this stage of the pipeline
        return image, skipped(f"harmonizer unavailable ({e})")
    try:
        if mask_box is None:
            mask_box = _nonzero_box(mask, None if windowed else within, mask_origin)
        win, model = (None, None) if mask_box is None else _harmonize_window(mask, cfg, within, mask_box, (H, W))
        if win is None:
            return (
                harmonize(
                    image, whole(), method=cfg.harmonize_method, rng=rng, test_time_views=cfg.harmonize_test_time_views
                ),
                f"harmonized ({cfg.harmonize_method})",
            )
        x0, y0, x1, y1 = win
        soft = np.zeros((y1 - y0, x1 - x0), np.float32)  # the mask's part in the window
        ix0, iy0, ix1, iy1 = max(x0, ox), max(y0, oy), min(x1, ox + mw), min(y1, oy + mh)
        if ix1 > ix0 and iy1 > iy0:
            soft[iy0 - y0 : iy1 - y0, ix0 - x0 : ix1 - x0] = mask[iy0 - oy : iy1 - oy, ix0 - ox : ix1 - ox]
        out = image if in_place else image.copy()
        # _harmonize_window returns a window for "fast" only: harmonize()'s fast path, blended on the mask only.
        from aias_augment.apply.harmonize.fast_infer import harmonize_fast_masked

        bx0, by0, bx1, by1 = mask_box
        harmonize_fast_masked(
            model,
            image[y0:y1, x0:x1],
            soft,
            tta=cfg.harmonize_test_time_views,
            box=(bx0 - x0, by0 - y0, bx1 - x0, by1 - y0),
            out=out[y0:y1, x0:x1],
        )
        return out, f"harmonized ({cfg.harmonize_method}, in the objects' context window)"
    except FileNotFoundError as e:
        return image, skipped(str(e))


def _camera_match(
    image: np.ndarray, mask: np.ndarray, cfg: InsertionConfig, source: np.ndarray, harmonize_seed: int
) -> tuple[np.ndarray, str]:
    """The camera-pipeline stage after the colour harmonizer (``cfg.camera_match``): blur, noise and JPEG matched to
    the surroundings; its noise from its own generator ``default_rng([harmonize_seed, 1])`` (the harmonizer's stream
    is left as it was)."""
    if cfg.harmonize_method == "camera":
        return image, skipped("the harmonizer is the camera pipeline already")
    from aias_augment.apply.harmonize.api import match_camera

    out, info = match_camera(image, mask, np.random.default_rng([harmonize_seed, 1]), source_rgb_uint8=source)
    jpeg = (
        f"JPEG q{info['jpeg_quality']} {'4:2:0' if info['chroma_420'] else '4:4:4'}"
        if info["jpeg_quality"]
        else "no JPEG trace in the source: not re-encoded"
    )
    return out, f"blur, noise, {jpeg} matched to the surroundings (after {cfg.harmonize_method})"


#: The fast harmonizer's files are looked at (two ``stat``) at most this often (s): a checkpoint replaced while a
#: process runs is read within this long.
FAST_MODEL_RECHECK_S = 1.0
_FAST_MODEL: dict = {}


def _nonzero_box(
    mask: np.ndarray, within: tuple[int, int, int, int] | None = None, origin: tuple[int, int] = (0, 0)
) -> tuple[int, int, int, int] | None:
    """(x0, y0, x1, y1), x1/y1 exclusive, of ``mask``'s non-zero pixels, scanned in ``within`` (mask pixels; None:
    all of it) and shifted by ``origin`` (where the mask lies in the image); None when none is non-zero."""
    sx0, sy0, sx1, sy1 = (0, 0, mask.shape[1], mask.shape[0]) if within is None else within
    x, y, bw, bh = cv2.boundingRect((mask[sy0:sy1, sx0:sx1] > 0).view(np.uint8))
    if bw == 0:
        return None
    x0, y0 = x + sx0 + origin[0], y + sy0 + origin[1]
    return x0, y0, x0 + bw, y0 + bh


def _fast_model_and_context():
    """(model, largest context factor) of the shipped fast harmonizer, or None when its checkpoint is missing.
    ``load_fast_np`` keys the model by the files' versions; the context is read from its config."""
    now = time.monotonic()
    got = _FAST_MODEL.get("m")
    if got is not None and now - got[0] < FAST_MODEL_RECHECK_S:
        return got[1]
    from aias_augment.apply.harmonize.api import DEFAULT_CHECKPOINTS
    from aias_augment.apply.harmonize.fast_infer import TTA_CONTEXTS, load_fast_np

    path = DEFAULT_CHECKPOINTS["fast"]
    try:
        model = load_fast_np(path)
    except FileNotFoundError:
        if not path.is_file():
            _FAST_MODEL.pop("m", None)
            return None  # harmonize() raises the missing-checkpoint error with its training command
        raise
    out = (model, max(TTA_CONTEXTS + (model.cfg.context,)))
    _FAST_MODEL["m"] = (now, out)
    return out


def _harmonize_window(
    mask: np.ndarray,
    cfg: InsertionConfig,
    within: tuple[int, int, int, int] | None = None,
    mask_box: tuple | None = None,
    image_hw: tuple[int, int] | None = None,
) -> tuple[tuple[int, int, int, int] | None, object]:
    """(window, model): the window (x0, y0, x1, y1) in which the "fast" harmonizer gives the same bytes as on the
    whole image, and its NumPy model; (None, None) for other methods (they use whole-image statistics or draw per
    pixel: they get the whole image) or when there is nothing to harmonize.

    The fast harmonizer changes only masked pixels, and reads, per connected component, a square context crop of
    side ``context x`` the component's longer side, centred on it and clipped to the image. Every component lies in
    the mask's box B, so every crop lies in B grown by ``max context / 2 x`` B's longer side: a window holding that
    (clipped to the image where the crops are clipped too) gives the same crops, the same predictions, the same
    pixels (``tests/aias_augment/apply/test_stages.py``). ``mask_box``: B when the caller has it (``mask`` is then
    not read); ``image_hw``: the image's size (default: the mask's)."""
    if cfg.harmonize_method != "fast":
        return None, None
    got = _fast_model_and_context()
    if got is None:
        return None, None
    model, ctx = got
    if mask_box is None:
        mask_box = _nonzero_box(mask, within)
        if mask_box is None:
            return None, None
    bx0, by0, bx1, by1 = mask_box
    grow = int(np.ceil(ctx / 2 * max(bx1 - bx0, by1 - by0))) + 2
    h, w = mask.shape if image_hw is None else image_hw
    return (max(0, bx0 - grow), max(0, by0 - grow), min(w, bx1 + grow), min(h, by1 + grow)), model
