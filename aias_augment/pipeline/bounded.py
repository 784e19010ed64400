"""A bounded working resolution for huge images: analyse and plan at <= ``max_pixels``, render at full size.

A 6000x4000 photo through :func:`aias_augment.pipeline.image.insert_into_image` costs minutes and gigabytes, almost all of
it in the scene analysis (camera from vanishing lines, region, lighting), whose result does not need 24 MP. Here:

1. the frame (image, depth, image-shaped meta) is resized to <= ``max_pixels`` (INTER_AREA; depth and masks
   nearest) and K scaled with it (pixel-centre alignment): :class:`~aias_augment.pipeline.working.WorkingResolution`,
   which the record keeps (``working_resolution``) so that :func:`~aias_augment.pipeline.replay.replay` takes the
   same route;
2. :func:`analyse_scene` (through the scene cache) and :func:`plan_insertion` run on that small frame: the plan's
   placements are metric (``cam_from_object`` in metres, the camera's own frame), so they do not depend on the pixel
   grid; their pixel fields (contact pixel, amodal box) are scaled back to full size for the record;
3. :func:`apply_plan` renders and composites the same plan into the full-size frame, with the analysis' intrinsics
   scaled back: objects and shadows are drawn at full resolution in their windows, every other pixel is the input's.

Images at or below ``max_pixels`` go through :func:`insert_into_image` unchanged (same bytes as before).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from aias_augment.analyse.cache import SceneCache
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.scene_inputs import SceneInputs, scene_meta
from aias_augment.pipeline.image import InsertionConfig, InsertionResult, assemble_result, insert_into_image
from aias_augment.pipeline.working import ANALYSIS_MAX_PIXELS, WorkingResolution, working_size  # noqa: F401  (public here)
from aias_augment.plan.insertion import PlannedObject, plan_insertion


def insert_bounded(
    image: np.ndarray,
    bboxes_xywh=None,
    labels=None,
    rng: np.random.Generator | None = None,
    cfg: InsertionConfig = InsertionConfig(),
    *,
    intrinsics=None,
    depth=None,
    meta: dict | None = None,
    min_visibility: float = 0.0,
    bank=None,
    n_objects: int | None = None,
    scene_cache: SceneCache | None = None,
    max_pixels: int | None = ANALYSIS_MAX_PIXELS,
    view_cache=None,
    scene: SceneInputs | None = None,
) -> InsertionResult:
    """:func:`insert_into_image` with the analysis and the plan at <= ``max_pixels`` (see the module docstring);
    same arguments, same result type, the result at the input's full size. ``max_pixels`` None: no bound."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
    H, W = img.shape[:2]
    meta = scene_meta(meta, scene, (H, W))  # facts checked at full size, before they are resized
    if not max_pixels or H * W <= max_pixels:
        return insert_into_image(
            img,
            bboxes_xywh,
            labels,
            rng,
            cfg,
            intrinsics=intrinsics,
            depth=depth,
            meta=meta,
            min_visibility=min_visibility,
            bank=bank,
            n_objects=n_objects,
            scene_cache=scene_cache,
            view_cache=view_cache,
        )
    if rng is None:
        raise ValueError("insert_bounded needs an explicit numpy Generator (rng) for reproducibility")
    cfg = cfg.for_image(rng)  # naive_share: as insert_into_image draws it (the small route draws it there)
    boxes = np.zeros((0, 4)) if bboxes_xywh is None else np.asarray(bboxes_xywh, float).reshape(-1, 4)
    labels = [] if labels is None else list(labels)
    if len(labels) != len(boxes):
        raise ValueError(f"{len(boxes)} boxes but {len(labels)} labels")
    if depth is not None:
        depth = np.asarray(depth, np.float32)
        if depth.shape != (H, W):
            raise ValueError(f"depth must be {(H, W)}, got {depth.shape}")
    if intrinsics is not None and not isinstance(intrinsics, Intrinsics):
        intrinsics = Intrinsics.from_matrix(np.asarray(intrinsics), W, H)
    meta = dict(meta or {})

    frame = Frame(img, intrinsics, depth=depth, meta=meta)
    working = WorkingResolution.bound(W, H, max_pixels)
    small, analysis_small, analysis = working.analyse(frame, cfg, scene_cache)
    sx, sy = working.scale
    existing_xyxy = np.c_[boxes[:, :2], boxes[:, :2] + boxes[:, 2:]]
    scale4 = np.array([sx, sy, sx, sy])
    plan = plan_insertion(
        analysis_small,
        cfg,
        rng,
        existing_boxes_xyxy=existing_xyxy * scale4,
        existing_labels=labels,
        depth=small.depth,
        meta=small.meta,
        bank=bank,
        n_objects=n_objects,
    )

    # The same plan at full size: metric quantities unchanged, pixel quantities scaled back.
    def full_px(p):
        cu, cv = p.contact_pixel
        x0, y0, x1, y1 = p.amodal_box_xyxy
        return replace(
            p,
            contact_pixel=((cu + 0.5) / sx - 0.5, (cv + 0.5) / sy - 0.5),
            amodal_box_xyxy=(x0 / sx, y0 / sy, x1 / sx, y1 / sy),
        )

    plan = replace(plan, objects=tuple(PlannedObject(full_px(o.placement), o.asset) for o in plan.objects))
    frame = Frame(img, analysis.intrinsics, depth=depth, meta=meta)
    applied = apply_plan(frame, analysis, plan, cfg, view_cache=view_cache, labelled_xywh=boxes)
    return assemble_result(
        analysis, plan, applied, boxes, labels, min_visibility, working_resolution=working, mode=cfg.mode
    )
