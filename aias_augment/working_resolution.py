"""A bounded working resolution for huge images: analyse and plan at <= ``max_pixels``, render at full size.

A 6000x4000 photo through :func:`aias_augment.pipeline.insert_into_image` costs minutes and gigabytes, almost all of
it in the scene analysis (camera from vanishing lines, region, lighting), whose result does not need 24 MP. Here:

1. the frame (image, depth, image-shaped meta) is resized to <= ``max_pixels`` (INTER_AREA; depth and masks
   nearest) and K scaled with it (pixel-centre alignment);
2. :func:`analyse_scene` (through the scene cache) and :func:`plan_insertion` run on that small frame: the plan's
   placements are metric (``cam_from_object`` in metres, the camera's own frame), so they do not depend on the pixel
   grid; their pixel fields (contact pixel, amodal box) are scaled back to full size for the record;
3. :func:`apply_plan` renders and composites the same plan into the full-size frame, with the analysis' intrinsics
   scaled back: objects and shadows are drawn at full resolution in their windows, every other pixel is the input's.

Images at or below ``max_pixels`` go through :func:`insert_into_image` unchanged (same bytes as before).
"""
from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np

from .geometry import Intrinsics
from .insertion.apply import apply_plan
from .insertion.cache import SceneCache
from .insertion.plan import PlannedObject, plan_insertion
from .pipeline import InsertionConfig, InsertionResult, assemble_result, insert_into_image
from .scene import Frame
from .scene_inputs import SceneInputs, scene_meta

#: Default analysis bound (pixels): 2 MP, the size of a 1920x1080 frame (where the analysis was tuned).
ANALYSIS_MAX_PIXELS = 2_000_000


def working_size(width: int, height: int, max_pixels: int) -> tuple[int, int]:
    """(w, h) of the working image: the largest size with the aspect ratio kept and w * h <= max_pixels."""
    if width * height <= max_pixels:
        return width, height
    s = math.sqrt(max_pixels / (width * height))
    return max(1, int(width * s)), max(1, int(height * s))


def _rescale_intrinsics(intr: Intrinsics, width: int, height: int) -> Intrinsics:
    """``intr`` (for its own image size) for an image of ``width`` x ``height`` (pixel-centre alignment)."""
    sx, sy = width / intr.width, height / intr.height
    return Intrinsics(intr.fx * sx, intr.fy * sy, (intr.cx + 0.5) * sx - 0.5, (intr.cy + 0.5) * sy - 0.5,
                      int(width), int(height))


def _resize_like_image(v, h: int, w: int, size: tuple[int, int]):
    """Image-shaped meta arrays (masks, label maps) resized nearest; anything else as is."""
    if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[:2] == (h, w):
        return _nearest(v, size)
    return v


def _nearest(a: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour resize of any dtype (labels, bool masks, depth with 0/NaN holes) to ``size`` (w, h)."""
    h, w = a.shape[:2]
    rows = np.minimum(((np.arange(size[1]) + 0.5) * h / size[1]).astype(np.intp), h - 1)
    cols = np.minimum(((np.arange(size[0]) + 0.5) * w / size[0]).astype(np.intp), w - 1)
    return np.ascontiguousarray(a[rows][:, cols])


def insert_bounded(image: np.ndarray, bboxes_xywh=None, labels=None, rng: np.random.Generator | None = None,
                   cfg: InsertionConfig = InsertionConfig(), *, intrinsics=None, depth=None, meta: dict | None = None,
                   min_visibility: float = 0.0, bank=None, n_objects: int | None = None,
                   scene_cache: SceneCache | None = None, max_pixels: int | None = ANALYSIS_MAX_PIXELS,
                   view_cache=None, scene: SceneInputs | None = None) -> InsertionResult:
    """:func:`insert_into_image` with the analysis and the plan at <= ``max_pixels`` (see the module docstring);
    same arguments, same result type, the result at the input's full size. ``max_pixels`` None: no bound."""
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8:
        raise ValueError(f"image must be (H, W, 3) uint8 RGB, got {img.shape} {img.dtype}")
    H, W = img.shape[:2]
    meta = scene_meta(meta, scene, (H, W))  # facts checked at full size, before they are resized
    if not max_pixels or H * W <= max_pixels:
        return insert_into_image(img, bboxes_xywh, labels, rng, cfg, intrinsics=intrinsics, depth=depth, meta=meta,
                                 min_visibility=min_visibility, bank=bank, n_objects=n_objects,
                                 scene_cache=scene_cache, view_cache=view_cache)
    if rng is None:
        raise ValueError("insert_bounded needs an explicit numpy Generator (rng) for reproducibility")
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

    w, h = working_size(W, H, max_pixels)
    sx, sy = w / W, h / H
    small = cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
    small_depth = None if depth is None else _nearest(depth, (w, h))
    small_meta = {k: _resize_like_image(v, H, W, (w, h)) for k, v in meta.items()}
    small_intr = None if intrinsics is None else _rescale_intrinsics(intrinsics, w, h)
    cache = scene_cache if scene_cache is not None else SceneCache(max_items=0)
    analysis_small = cache.get(Frame(small, small_intr, depth=small_depth, meta=small_meta), cfg)
    existing_xyxy = np.c_[boxes[:, :2], boxes[:, :2] + boxes[:, 2:]]
    scale4 = np.array([sx, sy, sx, sy])
    plan = plan_insertion(analysis_small, cfg, rng, existing_boxes_xyxy=existing_xyxy * scale4, depth=small_depth,
                          meta=small_meta, bank=bank, n_objects=n_objects)

    # The same analysis and plan at full size: metric quantities unchanged, pixel quantities scaled back.
    full_intr = intrinsics if intrinsics is not None else _rescale_intrinsics(analysis_small.intrinsics, W, H)
    region = analysis_small.region
    if region is not None:
        region = replace(region, mask=_resize_like_image(np.asarray(region.mask, bool), h, w, (W, H)))
    modules = {**analysis_small.modules,
               "working_resolution": f"analysis and plan at {w}x{h} (<= {max_pixels / 1e6:g} MP), rendered at {W}x{H}"}
    analysis = replace(analysis_small, image_shape=(H, W), intrinsics=full_intr, region=region, modules=modules)

    def full_px(p):
        cu, cv = p.contact_pixel
        x0, y0, x1, y1 = p.amodal_box_xyxy
        return replace(p, contact_pixel=((cu + 0.5) / sx - 0.5, (cv + 0.5) / sy - 0.5),
                       amodal_box_xyxy=(x0 / sx, y0 / sy, x1 / sx, y1 / sy))

    plan = replace(plan, objects=tuple(PlannedObject(full_px(o.placement), o.asset) for o in plan.objects))
    frame = Frame(img, full_intr, depth=depth, meta=meta)
    applied = apply_plan(frame, analysis, plan, cfg, view_cache=view_cache)

    return assemble_result(analysis, plan, applied, boxes, labels, min_visibility)
