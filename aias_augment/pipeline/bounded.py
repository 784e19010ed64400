"""A bounded working resolution for huge images: analyse and plan at <= ``max_pixels``, render at full size.

A 6000x4000 photo analysed at its own size costs minutes and gigabytes, almost all of it in the scene analysis
(camera from vanishing lines, region, lighting), whose result does not need 24 MP. The image door with
``max_pixels`` (:func:`aias_augment.pipeline.image.insert_into_image`; :func:`insert_bounded` is that door with the
default bound) therefore takes this route:

1. the frame (image, depth, image-shaped meta) is resized to <= ``max_pixels`` (INTER_AREA; depth and masks
   nearest) and K scaled with it (pixel-centre alignment): :class:`~aias_augment.pipeline.working.WorkingResolution`,
   which the record keeps (``working_resolution``) so that :func:`~aias_augment.pipeline.replay.replay` takes the
   same route;
2. :func:`analyse_scene` (through the scene cache) and :func:`plan_insertion` run on that small frame: the plan's
   placements are metric (``cam_from_object`` in metres, the camera's own frame), so they do not depend on the pixel
   grid; their pixel fields (contact pixel, amodal box) are scaled back to full size for the record;
3. :func:`apply_plan` renders and composites the same plan into the full-size frame, with the analysis' intrinsics
   scaled back: objects and shadows are drawn at full resolution in their windows, every other pixel is the input's.

Images at or below ``max_pixels`` take the door's plain route (same bytes as without a bound). The inputs are
checked once, by the door (:class:`~aias_augment.pipeline.image.DoorInputs`), whichever route they take.
"""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.cache import SceneCache
from aias_augment.core.scene_inputs import SceneInputs
from aias_augment.pipeline.image import InsertionConfig, InsertionResult, insert_into_image, require_rng
from aias_augment.pipeline.working import ANALYSIS_MAX_PIXELS, WorkingResolution, working_size  # noqa: F401  (public here)


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
    require_rng(rng, "insert_bounded")
    return insert_into_image(
        image,
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
        scene=scene,
        max_pixels=max_pixels,
    )
