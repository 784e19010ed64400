"""The insertion pipeline for one image: scene -> placement -> lighting -> render -> composite -> harmonize -> annotate.

``insert_into_image`` is the image door, used by the albumentations transform, the offline CLI, the demo and the
detection study (with ``max_pixels``, a huge image is analysed and planned on a smaller copy:
:mod:`aias_augment.pipeline.bounded`): a thin wrapper over the three steps of :mod:`aias_augment.analyse`, :mod:`aias_augment.plan` and :mod:`aias_augment.apply` (``analyse_scene`` ->
``plan_insertion`` -> ``apply_plan``). Every stage records what it used and which modules it skipped and why, so any
insertion can be replayed from its :class:`InsertionRecord`.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from aias_augment.analyse.analysis import scene_geometry, scene_lighting  # noqa: F401  (old names, kept importable)
from aias_augment.analyse.cache import SceneCache
from aias_augment.analyse.lighting.estimate import LightingEstimate
from aias_augment.apply.annotate import ObjectAnnotation, box_visibility_under_cover
from aias_augment.apply.stages import apply_plan
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.report import notes_from_dict, skipped_stages
from aias_augment.core.scene_inputs import SceneInputs, scene_meta
from aias_augment.pipeline.config import PRESETS, InsertionConfig, load_preset  # noqa: F401
from aias_augment.pipeline.replay import placement_from_dict
from aias_augment.pipeline.working import WorkingResolution
from aias_augment.plan.insertion import PlannedObject, plan_insertion
from aias_augment.plan.looks import labelled_cone_looks
from aias_augment.plan.placement import Placement

log = logging.getLogger(__name__)


@dataclass
class InsertionRecord:
    """What was done to one image: enough to replay it (placements are frozen records) and to debug it."""

    placements: list[Placement] = field(default_factory=list)
    annotations: list[ObjectAnnotation] = field(default_factory=list)
    lighting: LightingEstimate | None = None
    modules: dict[str, str] = field(default_factory=dict)  # stage -> its StageNote (what was used, or skipped: why)
    placement_reports: list[dict] = field(default_factory=list)
    existing_visibility: list[float] = field(default_factory=list)
    harmonize_seed: int | None = None  # the plan's harmonizer seed (with the placements: enough to replay)
    # the analysis and plan ran on a smaller copy of the image (the bounded door); None: on the image itself
    working_resolution: WorkingResolution | None = None
    # per placement, the layer stages' parameters drawn in the plan (aias_augment.core.stages)
    layer_params: list[dict] = field(default_factory=list)
    # how the image was made: "pipeline" or "naive_paste" (InsertionConfig.naive_share draws it per image)
    mode: str = "pipeline"
    # the 3x3 intrinsics of the output image (OpenCV pixels), which 3D label exports write beside their labels
    camera_K: tuple | None = None
    # the input's labelled boxes (COCO xywh, output pixels) that occluded by depth order (replay passes them again)
    labelled_boxes_xywh: list = field(default_factory=list)
    # the frame stages' parameters drawn in the plan (aias_augment.core.stages); written only when a frame stage ran
    frame_params: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        out = {
            "mode": self.mode,
            "harmonize_seed": self.harmonize_seed,
            "working_resolution": None if self.working_resolution is None else self.working_resolution.to_dict(),
            "placements": [asdict(p) for p in self.placements],
            "annotations": [a.to_dict() for a in self.annotations],
            "lighting": self.lighting.to_dict() if self.lighting else None,
            "modules": dict(self.modules),
            "skipped_stages": skipped_stages(self.modules),
            "placement_reports": self.placement_reports,
            "existing_visibility": self.existing_visibility,
            "layer_params": self.layer_params,
            "camera_K": None if self.camera_K is None else [list(r) for r in self.camera_K],
            "labelled_boxes_xywh": [list(map(float, b)) for b in self.labelled_boxes_xywh],
        }
        if self.frame_params:
            out["frame_params"] = dict(self.frame_params)
        return out

    @classmethod
    def from_dict(cls, d: dict) -> "InsertionRecord":
        """The record :meth:`to_dict` wrote (e.g. read back from JSON): ``from_dict(r.to_dict()).to_dict()`` equals
        ``r.to_dict()``. A record without ``working_resolution`` (written before it was recorded) was analysed on
        the image itself; one without ``mode`` was made as its run's config says."""
        wr = d.get("working_resolution")
        return cls(
            [placement_from_dict(p) for p in d["placements"]],
            [ObjectAnnotation.from_dict(a) for a in d["annotations"]],
            None if d["lighting"] is None else LightingEstimate.from_dict(d["lighting"]),
            notes_from_dict(d["modules"], d.get("skipped_stages", ())),
            list(d["placement_reports"]),
            list(d["existing_visibility"]),
            d["harmonize_seed"],
            None if wr is None else WorkingResolution.from_dict(wr),
            [dict(x) for x in d.get("layer_params", ())],
            d.get("mode", "pipeline"),
            None if d.get("camera_K") is None else tuple(tuple(map(float, r)) for r in d["camera_K"]),
            [list(map(float, b)) for b in d.get("labelled_boxes_xywh", ())],
            dict(d.get("frame_params", {})),
        )


@dataclass
class InsertionResult:
    image: np.ndarray  # (H, W, 3) uint8
    bboxes: np.ndarray  # (M, 4) COCO xywh: kept existing boxes then inserted ones
    labels: list  # matching labels (existing labels kept, inserted = category names)
    inserted_bboxes: np.ndarray  # (K, 4) xywh of the inserted objects' visible parts
    inserted_labels: list[str]
    keep_existing: np.ndarray  # (N,) bool: existing boxes that stay visible enough
    record: InsertionRecord


def insert_into_image(
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
    view_cache=None,
    scene: SceneInputs | None = None,
    max_pixels: int | None = None,
) -> InsertionResult:
    """Insert 1..k objects into ``image`` and return the new image, boxes and a replayable record.

    image: (H, W, 3) uint8 RGB. bboxes_xywh: (N, 4) COCO boxes already in the image, labels their labels.
    intrinsics: Intrinsics or 3x3 K (None: FOV prior). depth: (H, W) metres (0/NaN unknown) or None.
    min_visibility: existing boxes whose visible fraction under the inserted objects drops below it are dropped.
    scene: typed scene facts (:class:`~aias_augment.core.scene_inputs.SceneInputs`: placeable mask, measured points,
        existing 3D boxes, position/time/orientation for the sun, ...), checked against the image before anything
        runs. meta: the same facts as a dict (its keys are SceneInputs' field names, e.g. 'placeable_mask',
        'lidar_points_in_cam', 'lat'/'lon'/'utc') plus free-form provenance the pipeline carries but does not
        read; a misspelt fact name raises. Facts come from one of the two.
    scene_cache: where the scene analysis is looked up / kept (None: computed for this call only). The analysis
        draws from its own fixed-seed generator, so ``rng`` only drives the plan (objects, placements, harmonizer).
    view_cache: the :class:`~aias_augment.apply.view_cache.ViewCache` of ``render_method="view_cache"`` (None:
        the process-wide one); like the scene cache it changes when views are rendered, never the pixels.
    max_pixels: an image above this many pixels is analysed and planned on a copy of at most ``max_pixels`` and
        rendered at full size (:func:`_insert_at_working_resolution`, recorded as ``working_resolution``); None:
        the whole analysis at the image's size. :func:`aias_augment.pipeline.bounded.insert_bounded` is this door
        with the default bound.
    """
    require_rng(rng, "insert_into_image")
    inputs = DoorInputs.checked(image, bboxes_xywh, labels, depth, intrinsics, meta, scene)
    cfg = cfg.for_image(rng)  # naive_share: this image a naive paste or a pipeline insertion
    h, w = inputs.image.shape[:2]
    plan_kw = dict(bank=bank, n_objects=n_objects, cone_looks=_cone_looks(inputs, cfg))
    if max_pixels and h * w > max_pixels:
        working = WorkingResolution.bound(w, h, max_pixels)
        return _insert_at_working_resolution(
            inputs, working, rng, cfg, scene_cache, view_cache, min_visibility, plan_kw
        )
    frame = Frame(inputs.image, inputs.intrinsics, depth=inputs.depth, meta=inputs.meta)
    cache = scene_cache if scene_cache is not None else SceneCache(max_items=0)
    analysis = cache.get(frame, cfg)
    plan = plan_insertion(
        analysis,
        cfg,
        rng,
        existing_boxes_xyxy=inputs.boxes_xyxy,
        existing_labels=inputs.labels,
        depth=inputs.depth,
        meta=inputs.meta,
        labelled_ground=_labelled_ground(inputs.image, inputs.boxes_xyxy, cfg),
        **plan_kw,
    )
    applied = apply_plan(frame, analysis, plan, cfg, view_cache=view_cache, labelled_xywh=inputs.boxes)
    return assemble_result(analysis, plan, applied, inputs.boxes, inputs.labels, min_visibility, mode=cfg.mode)


def require_rng(rng, door: str) -> None:
    """The doors draw only from a Generator passed in: a missing one is refused, naming the door."""
    if rng is None:
        raise ValueError(f"{door} needs an explicit numpy Generator (rng) for reproducibility")


@dataclass(frozen=True)
class DoorInputs:
    """One image's inputs as the door checked them (:meth:`checked`): the image (H, W, 3) uint8, its labelled
    boxes (N, 4) COCO xywh and their labels, depth (H, W) float32 or None, intrinsics for (W, H) or None, and the
    scene facts checked against the image (:func:`~aias_augment.core.scene_inputs.scene_meta`)."""

    image: np.ndarray
    boxes: np.ndarray
    labels: list
    depth: np.ndarray | None
    intrinsics: Intrinsics | None
    meta: dict

    @classmethod
    def checked(cls, image, bboxes_xywh, labels, depth, intrinsics, meta, scene) -> "DoorInputs":
        """Every input checked against the image (``ValueError`` naming the first problem) before anything runs."""
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
        if intrinsics is not None and not isinstance(intrinsics, Intrinsics):
            intrinsics = Intrinsics.from_matrix(np.asarray(intrinsics), w, h)
        return cls(img, boxes, labels, depth, intrinsics, scene_meta(meta, scene, (h, w)))

    @property
    def boxes_xyxy(self) -> np.ndarray:
        return np.c_[self.boxes[:, :2], self.boxes[:, :2] + self.boxes[:, 2:]]


def _insert_at_working_resolution(
    inputs: DoorInputs, working: WorkingResolution, rng, cfg, scene_cache, view_cache, min_visibility, plan_kw
) -> InsertionResult:
    """The door's route for an image above its ``max_pixels``: the analysis and the plan on the working copy
    (:meth:`WorkingResolution.analyse`), the plan's pixel fields scaled back to full size (its metric ones do not
    depend on the pixel grid), and :func:`apply_plan` rendering it into the full-size frame."""
    frame = Frame(inputs.image, inputs.intrinsics, depth=inputs.depth, meta=inputs.meta)
    small, analysis_small, analysis = working.analyse(frame, cfg, scene_cache)
    sx, sy = working.scale
    boxes_small = inputs.boxes_xyxy * np.array([sx, sy, sx, sy])
    plan = plan_insertion(
        analysis_small,
        cfg,
        rng,
        existing_boxes_xyxy=boxes_small,
        existing_labels=inputs.labels,
        depth=small.depth,
        meta=small.meta,
        labelled_ground=_labelled_ground(small.image, boxes_small, cfg),
        **plan_kw,
    )

    def full_px(p):
        cu, cv = p.contact_pixel
        x0, y0, x1, y1 = p.amodal_box_xyxy
        return replace(
            p,
            contact_pixel=((cu + 0.5) / sx - 0.5, (cv + 0.5) / sy - 0.5),
            amodal_box_xyxy=(x0 / sx, y0 / sy, x1 / sx, y1 / sy),
        )

    plan = replace(plan, objects=tuple(PlannedObject(full_px(o.placement), o.asset) for o in plan.objects))
    frame = Frame(inputs.image, analysis.intrinsics, depth=inputs.depth, meta=inputs.meta)
    applied = apply_plan(frame, analysis, plan, cfg, view_cache=view_cache, labelled_xywh=inputs.boxes)
    return assemble_result(
        analysis, plan, applied, inputs.boxes, inputs.labels, min_visibility, working_resolution=working, mode=cfg.mode
    )


def assemble_result(
    analysis,
    plan,
    applied,
    boxes: np.ndarray,
    labels: list,
    min_visibility: float,
    *,
    working_resolution: WorkingResolution | None = None,
    mode: str = "pipeline",
) -> InsertionResult:
    """The result of one insertion from its three steps' records: the inserted objects' visible boxes appended to the
    input boxes that stay visible enough under what was drawn over them (``boxes`` xywh, in the output's pixels; when
    ``applied`` ordered them by depth, only the inserted objects nearer than a box count, else all of them).
    ``working_resolution``: the smaller copy the analysis and plan ran on (recorded for replay), None: the image.
    ``mode``: how the image was made (:attr:`InsertionConfig.mode` of its config after ``for_image``)."""
    record = InsertionRecord(
        list(applied.placements),
        list(applied.annotations),
        analysis.lighting,
        {**analysis.modules, **plan.modules, **applied.modules},
        list(plan.placement_reports) + list(applied.dropped),
        harmonize_seed=plan.harmonize_seed,
        working_resolution=working_resolution,
        layer_params=list(applied.layer_params),
        frame_params=dict(applied.frame_params),
        mode=mode,
        camera_K=tuple(tuple(map(float, r)) for r in analysis.intrinsics.K),
    )
    inserted_boxes, inserted_labels = [], []
    for placement, ann in zip(applied.placements, applied.annotations):
        if ann.visible_box_xywh is not None and not placement.decoy:
            inserted_boxes.append(ann.visible_box_xywh)
            inserted_labels.append(placement.category)
    if applied.labelled_visibility is not None:
        existing_vis = np.asarray(applied.labelled_visibility, float)
        record.labelled_boxes_xywh = boxes.tolist()
    else:
        existing_xyxy = np.c_[boxes[:, :2], boxes[:, :2] + boxes[:, 2:]]
        existing_vis = box_visibility_under_cover(
            existing_xyxy, applied.cover_window, applied.window[:2], applied.image.shape[:2]
        )
    keep = existing_vis >= min_visibility
    record.existing_visibility = existing_vis.tolist()
    ins = np.array(inserted_boxes, float).reshape(-1, 4)
    all_boxes = np.concatenate([boxes[keep], ins], axis=0)
    all_labels = [lab for lab, k in zip(labels, keep) if k] + inserted_labels
    return InsertionResult(applied.image, all_boxes, all_labels, ins, inserted_labels, keep, record)


def _labelled_ground(image: np.ndarray, boxes_xyxy: np.ndarray, cfg: InsertionConfig):
    """The ground the image's labelled objects stand on, by its look, where a row of them is continued
    (``arrangement: row``): the row's sites are on it (:func:`aias_augment.analyse.instances.labelled_ground`)."""
    if cfg.arrangement != "row" or not cfg.placement or not len(boxes_xyxy):
        return None
    from aias_augment.analyse.instances import labelled_ground

    return labelled_ground(image, boxes_xyxy)


def _cone_looks(inputs: DoorInputs, cfg: InsertionConfig) -> tuple:
    """The looks of the image's labelled cones (full size), for inserted cones to be drawn like them: only with
    ``cone_look: labels``, cones among the categories and a placement (a naive paste keeps the family's variety)."""
    if cfg.cone_look != "labels" or "traffic_cone" not in cfg.categories or not cfg.placement or not len(inputs.boxes):
        return ()
    return labelled_cone_looks(inputs.image, inputs.boxes_xyxy, inputs.labels)
