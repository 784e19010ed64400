"""``InsertObjects``: the albumentations adapter over :func:`aias_augment.pipeline.image.insert_into_image`.

Use it inside ``A.Compose(..., bbox_params=A.BboxParams(format="coco", label_fields=[...]), seed=...)``. Optional
per-sample targets: ``camera_k`` (3x3 intrinsics of the image as passed in), ``depth`` ((H, W) metres, 0/NaN =
unknown) and ``scene`` (:class:`aias_augment.core.scene_inputs.SceneInputs`: e.g. a road mask where objects may stand;
a bad one is a counted skip like any odd sample). Inserted boxes are appended with their label (``category_ids[name]`` or the category name); existing
boxes whose visible fraction under the inserted objects falls below the Compose's ``min_visibility`` are dropped.
Every target of a Compose (:mod:`aias_augment.adapters.targets`): instance ``masks`` stay in step with the boxes
(hidden parts removed, the inserted objects' masks appended in the order of their boxes); the semantic ``mask`` gets
``mask_values[category]`` on the inserted pixels; keypoints under an inserted object are hidden ones (removed when
``KeypointParams(remove_invisible=True)``, the default); boxes in any ``BboxParams`` format. ``ReplayCompose`` and
``Compose(save_applied_params=True)`` keep the insertion's JSON record as its parameters
(:mod:`aias_augment.adapters.record_replay`): ``ReplayCompose.replay`` of it, JSON round trip or not, gives the same
bytes, as does ``InsertObjects(insertion=record)`` (AlbumentationsX's ``Compose.from_applied_transforms``). Put it first in the pipeline: later geometric transforms do not update ``camera_k``/``depth``.

Inputs (:func:`aias_augment.adapters.boundary.image_for_insertion`): grey, RGB or RGBA; uint8; uint16 (converted to 8 bit by
``round(v / 257)`` for the insertion, inserted pixels written back as ``v * 257``); float in [0, 1] (``round(v * 255)``,
written back as ``v / 255``). Pixels the insertion does not touch are returned bit for bit. A float image with NaN/Inf
or values outside [0, 1], ``depth`` without ``camera_k`` or another odd sample is left unchanged and counted by reason
in ``transform.counts`` (as is a call that placed nothing, with why); it never stops an epoch. Images above 2 MP are
analysed and planned at 2 MP and rendered at full size (:mod:`aias_augment.pipeline.bounded`).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import albumentations as A
import numpy as np

from aias_augment.adapters import albu_compat as compat
from aias_augment.adapters import record_replay, targets
from aias_augment.adapters.bbox_encoding import (
    encode_boxes,
    encoded_labels,
    internal_from_xywh,
    pad_columns,
    xywh_from_internal,
)
from aias_augment.adapters.boundary import (
    SampleSkip,
    TransformCounts,
    check_categories,
    check_sample_targets,
    image_for_insertion,
)
from aias_augment.adapters.transform_warm import WarmVariants, plan_labels
from aias_augment.adapters.variants import Variant, VariantCache, VariantResult
from aias_augment.analyse.cache import SceneCache
from aias_augment.apply.view_cache import ViewCache
from aias_augment.assets.asset import PathAssets
from aias_augment.pipeline.bounded import insert_bounded
from aias_augment.pipeline.image import PRESETS, InsertionConfig, load_preset

log = logging.getLogger(__name__)

#: This thread's insertions between a transform's sampling step and its apply step, by ``id(transform)``: the
#: result (image, boxes, masks) stays out of the parameters albumentations keeps, which hold only the JSON record.
_LIVE = threading.local()


def _hand_over(transform, live: dict) -> None:
    if not hasattr(_LIVE, "calls"):
        _LIVE.calls = {}
    _LIVE.calls[id(transform)] = live


def _take(transform) -> dict | None:
    return getattr(_LIVE, "calls", {}).pop(id(transform), None)


class InsertObjects(WarmVariants, A.DualTransform):
    """Insert 3D objects photorealistically and append their COCO boxes.

    Args:
        categories: object categories to insert (default asset bank: see ``aias_augment.assets.asset.DEFAULT_ASSETS``).
        max_objects / min_objects: number of objects per image, drawn uniformly.
        preset: "fast" | "balanced" | "accurate" (configs/presets/*.yaml).
        category_ids: label written for each category (e.g. {"traffic_cone": 3}); default: the category name.
        assets: your own meshes, {"category": ["path.obj", ...]}.
        config_overrides: any :class:`InsertionConfig` field (e.g. {"shadow": False}); a nested config as a mapping
            of some of its fields updates the preset's (e.g. {"placement_cfg": {"max_tries": 30}}). Every value is
            checked here: a wrong type or a value out of range raises, naming the field.
        scene_cache: a folder for scene analyses (camera, ground, region, lighting) shared by all workers and runs;
            None: only the in-process cache. Either way an image seen again (same bytes, K, depth) is not analysed
            again: the analysis is cached by content in an LRU of ``scene_cache_items`` entries in each process.
            With a folder, the fast preset's asset views are kept in ``scene_cache/views`` too (by asset content
            and view bin): a view one worker rendered is read by the others. See :meth:`warm`.
        variants_per_image: None (default): a new insertion per call. K: each image gets at most K insertions
            over training, each computed once and then pasted (~0.1 ms instead of ~20 ms): a call draws which of
            the K it gets (see :mod:`aias_augment.adapters.variants`; kept in memory and, with ``scene_cache``,
            in ``scene_cache/variants`` for every worker and run). Trades variety for speed;
            ``warm(images, variants=True)`` computes them all before training.
        variants_seed: the seed of the variants' own plans (a variant is a function of the sample, this and its
            index; the Compose seed picks which variant a call gets).
        mask_values: the value of each category's pixels in a semantic ``mask`` target (e.g. {"traffic_cone": 3});
            needed when the Compose is called with a ``mask``.
        insertion: None (default): each call draws a new insertion. An insertion record
            (``InsertionRecord.to_dict()``, as ``ReplayCompose``, ``save_applied_params`` and ``last_record`` give
            it): each call replays it on the sample instead of drawing (the sample it was made from gives the same
            bytes); ``{}``: the record of a call that left the image unchanged. AlbumentationsX's
            ``save_applied_params`` log holds it under this name, so ``Compose.from_applied_transforms`` replays it.
        p: probability of applying.

    Attributes:
        counts: :class:`aias_augment.adapters.boundary.TransformCounts` of this process (``counts.to_dict()``: calls,
            inserted, objects, skipped by reason, nothing_inserted by reason, converted by conversion).
        skipped: the number of images left unchanged (all reasons).
    """

    _targets = compat.TARGETS

    def __init__(
        self,
        categories: tuple[str, ...] | list[str] = ("traffic_cone",),
        max_objects: int = 3,
        min_objects: int = 1,
        preset: str = "balanced",
        category_ids: dict[str, Any] | None = None,
        assets: dict[str, list[str]] | None = None,
        config_overrides: dict[str, Any] | None = None,
        scene_cache: str | None = None,
        scene_cache_items: int = 128,
        variants_per_image: int | None = None,
        variants_seed: int = 0,
        mask_values: dict[str, float] | None = None,
        insertion: dict[str, Any] | None = None,
        p: float = 0.5,
    ):
        super().__init__(p=p)
        if variants_per_image is not None and (
            isinstance(variants_per_image, bool)
            or int(variants_per_image) != variants_per_image
            or variants_per_image < 1
        ):
            raise ValueError(f"variants_per_image must be None or an integer >= 1, got {variants_per_image!r}")
        self.variants_per_image = None if variants_per_image is None else int(variants_per_image)
        self.variants_seed = int(variants_seed)
        if preset not in PRESETS:
            raise ValueError(f"preset must be one of {PRESETS}, got {preset!r}")
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"p must be in [0, 1], got {p}")
        self.categories = tuple(categories)
        if not self.categories:
            raise ValueError("categories must not be empty")
        if any(c not in (assets or {}) for c in self.categories):  # unknown categories: InputError now
            check_categories([c for c in self.categories if c not in (assets or {})])
        self.max_objects = int(max_objects)
        self.min_objects = int(min_objects)
        self.preset = preset
        self.category_ids = dict(category_ids) if category_ids else None
        self.assets = assets
        self.config_overrides = dict(config_overrides or {})
        # Validates everything now: unknown override keys and wrong types raise TypeError, values out of range
        # ValueError, each naming the field (config.checked_config).
        self.config: InsertionConfig = load_preset(
            preset,
            categories=self.categories,
            max_objects=self.max_objects,
            min_objects=self.min_objects,
            **self.config_overrides,
        )
        if self.category_ids is not None:
            missing = set(self.categories) - set(self.category_ids)
            if missing:
                raise ValueError(f"category_ids lacks {sorted(missing)}")
        self.mask_values = _checked_mask_values(mask_values, self.categories)
        self.insertion = record_replay.checked_record(insertion)
        self._bank = PathAssets(assets) if assets else None
        self.scene_cache = None if scene_cache is None else str(scene_cache)
        self.scene_cache_items = int(scene_cache_items)
        self._scene_cache = SceneCache(self.scene_cache_items, self.scene_cache)
        # The view cache of the fast preset: on disk beside the scene analyses when there is a folder; else the
        # process-wide one (shared by every transform of the process).
        self._view_cache = None if scene_cache is None else ViewCache(directory=Path(scene_cache) / "views")
        self._variants = VariantCache(directory=None if scene_cache is None else Path(scene_cache) / "variants")
        self._variant_prefix = None  # hash of config, assets and seed (made on first use; not picklable)
        self.counts = TransformCounts()  # calls, insertions, skips and empty calls by reason (this process)
        self.last_record = None  # InsertionRecord of the latest call in this process (for debugging/replay)

    @property
    def skipped(self) -> int:
        """Images left unchanged because the sample was refused or insertion failed (``counts.skipped``: why)."""
        return self.counts.total_skipped

    @property
    def targets_as_params(self) -> list[str]:
        return ["image"]

    def get_transform_init_args_names(self) -> tuple[str, ...]:
        return (
            "categories",
            "max_objects",
            "min_objects",
            "preset",
            "category_ids",
            "assets",
            "config_overrides",
            "scene_cache",
            "scene_cache_items",
            "variants_per_image",
            "variants_seed",
            "mask_values",
            "insertion",
        )

    # -- choosing and doing: the pipeline renders here because boxes, masks and image all depend on it ----------
    def _params_for_call(self, params: dict[str, Any], data: dict[str, Any]) -> dict[str, Any]:
        """albumentations 2.0.8's ``get_params_dependent_on_data``: runs the insertion (handed to this call's
        ``apply_*``). The parameters albumentations keeps are JSON: ``{"insertion": record dict or {} (image left
        unchanged)}`` when the Compose records parameters (``ReplayCompose``, ``save_applied_params=True``), else
        none (a record costs a dict per call)."""
        live = self._insert(data, self.random_generator)
        _hand_over(self, live)
        if not (self.deterministic or "applied_transforms" in data):
            return {}
        return {"insertion": _record_of(live)}

    def sample_parameters(self, params, data, targets, sampling):
        """AlbumentationsX's sampling hook: the insertion on the invocation's generator (handed to this call's
        ``apply_*``). The parameters it returns are JSON, as on 2.0.8: the record when the call is recorded
        (``ReplayCompose``, ``save_applied_params``, a direct call), else none."""
        from albumentations.core.transform_params import SampledParams

        live = self._insert(data, sampling.random_generator)
        _hand_over(self, live)
        if not (self.deterministic or isinstance(sampling.applied_overrides, dict)):
            return SampledParams(params={})
        record = _record_of(live)
        sampling.applied_overrides["insertion"] = record  # the save_applied_params log: constructor arguments
        return SampledParams(params={"insertion": record})

    def _insert(self, data: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
        if self.insertion is not None:  # replay the constructor's record: nothing is drawn
            return self._replayed({"insertion": self.insertion}, data)
        if self.variants_per_image:
            img = data["image"]
            boxes = data.get("bboxes")
            if (
                type(img) is np.ndarray
                and img.dtype == np.uint8
                and img.ndim == 3
                and img.shape[2] == 3
                and img.size
                and img.flags.c_contiguous
                and (boxes is None or len(boxes) == 0)
                and data.get("camera_k") is None
                and data.get("depth") is None
                and data.get("scene") is None
            ):
                return self._plain_variant(img, rng)
        return self._general_params(data, rng)

    def _general_params(self, data: dict[str, Any], rng: np.random.Generator) -> dict[str, Any]:
        try:  # the sample's boundary: dtype/range/shape of the image, camera_k and depth (SampleSkip: counted)
            rgb, restore, conversion = image_for_insertion(data["image"])
            h, w = rgb.shape[:2]
            check_sample_targets(data, h, w)
        except SampleSkip as e:
            self.counts.skip(e, log)
            return {"insert_result": None, "restore": None}
        if conversion:
            self.counts.convert(conversion)
        boxes_internal = data.get("bboxes")
        n_existing = 0 if boxes_internal is None else len(boxes_internal)
        existing_xywh = np.zeros((0, 4)) if not n_existing else xywh_from_internal(boxes_internal, h, w)
        min_vis = 0.0
        proc = self._bbox_processor()
        if proc is not None:
            min_vis = float(proc.params.min_visibility)
        references = self._references(boxes_internal, proc) if n_existing else None
        try:
            if self.variants_per_image:
                res = self._variant(rgb, existing_xywh, min_vis, data, references=references, rng=rng)
            else:
                res = insert_bounded(
                    rgb,
                    existing_xywh,
                    plan_labels(n_existing, references),
                    rng,
                    self.config,
                    intrinsics=data.get("camera_k"),
                    depth=data.get("depth"),
                    min_visibility=min_vis,
                    bank=self._bank,
                    scene_cache=self._scene_cache,
                    view_cache=self._view_cache,
                    scene=data.get("scene"),
                )
        except Exception as e:  # one odd image must not stop an epoch: skip it, count it, say why
            self.counts.skip(e, log)
            return {"insert_result": None, "restore": restore}
        self.last_record = res.variant if isinstance(res, VariantResult) else res.record
        self.counts.result(len(res.inserted_labels), None if res.inserted_labels else res.record.to_dict(), log)
        return {"insert_result": res, "restore": restore}

    @property
    def last_record(self):
        """The InsertionRecord of the latest call in this process (for debugging/replay; None before any)."""
        r = self._last_record
        return r.record if isinstance(r, Variant) else r

    @last_record.setter
    def last_record(self, value) -> None:
        self._last_record = value  # a record, or the variant whose record it is (unpickled when read)

    def __getstate__(self):
        # Per-call state (render results, the restore closure) is not part of the transform.
        state = self.__dict__.copy()
        state["params"] = {}
        state["_variant_prefix"] = None
        state["_last_record"] = None
        return state

    def _bbox_processor(self):
        try:
            return self.get_processor("bboxes")
        except (AttributeError, KeyError):
            return None

    def apply_with_params(self, params, *args: Any, **kwargs: Any) -> dict[str, Any]:
        """Applies this call's insertion to every target; parameters without it (``ReplayCompose.replay``, or a
        record kept from ``save_applied_params``) are replayed from their ``"insertion"`` record first.
        ``params``: a mapping (2.0.8) or AlbumentationsX's ``SampledParams``."""
        given = params if isinstance(params, Mapping) else params.params
        live = _take(self)
        if live is None or self.replay_mode:
            live = self._replayed(given, kwargs)
        res = live["insert_result"]
        call = {**given, **live, **self._call_extras(res, kwargs)}
        if compat.IS_X:
            from albumentations.core.transform_params import SampledParams

            return super().apply_with_params(SampledParams(params=call), *args, **kwargs)
        out = super().apply_with_params(call, *args, **kwargs)
        masks = kwargs.get("masks")
        if res is not None and isinstance(masks, (list, tuple)) and not masks:  # 2.0.8 skips an empty list
            out["masks"] = list(self._new_masks(res, call["new_kept"]).astype(np.uint8))
        return out

    def _call_extras(self, res, data) -> dict[str, Any]:
        """``new_kept``, with instance masks: which inserted boxes the Compose's ``BboxParams`` keep, so that their
        masks go with them (boxes alone are filtered by the Compose itself)."""
        if res is None or data.get("masks") is None:
            return {}
        h, w = res.image.shape[:2]
        rows = internal_from_xywh(res.inserted_bboxes, h, w)
        return {"new_kept": compat.kept_rows(rows, (h, w), self._bbox_processor())}

    def _replayed(self, params: dict[str, Any], data: dict[str, Any]) -> dict[str, Any]:
        if "insertion" not in params:
            raise ValueError(
                "InsertObjects: these parameters hold no insertion record; record them with ReplayCompose or "
                "Compose(save_applied_params=True)"
            )
        rgb, restore, _ = image_for_insertion(data["image"])
        record = params["insertion"]
        if not record:  # None or {}: the recorded call left the image unchanged
            return {"insert_result": None, "restore": restore}
        boxes = data.get("bboxes")
        proc = self._bbox_processor()
        res = record_replay.replayed_result(
            record,
            rgb,
            data,
            self.config,
            self._bank,
            0 if boxes is None else len(boxes),
            0.0 if proc is None else float(proc.params.min_visibility),
        )
        return {"insert_result": res, "restore": restore}

    def apply(self, img: np.ndarray, insert_result=None, restore=None, **params: Any) -> np.ndarray:
        if insert_result is None:
            return img
        return restore(insert_result.image)

    def apply_to_mask(self, mask: np.ndarray, insert_result=None, **params: Any) -> np.ndarray:
        if self.mask_values is None:
            raise ValueError(
                "InsertObjects: a semantic mask target needs mask_values={category: value}, the value of the "
                f"inserted objects' pixels in it (categories {list(self.categories)})"
            )
        if insert_result is None:
            return mask
        return targets.paint_semantic(mask, insert_result.record.annotations, self.mask_values)

    def apply_to_masks(self, masks: np.ndarray, insert_result=None, new_kept=None, **params: Any) -> np.ndarray:
        if insert_result is None:
            return masks
        if len(masks) == 0:  # AlbumentationsX passes no masks on (2.0.8 skips them: see apply_with_params)
            new = self._new_masks(insert_result, new_kept)
            return new.astype(masks.dtype) if isinstance(masks, np.ndarray) else list(new.astype(np.uint8))
        hw = insert_result.image.shape[:2]
        hidden = targets.cover(insert_result.record.annotations, hw)
        return targets.instance_masks_after(
            masks, insert_result.keep_existing, self._new_masks(insert_result, new_kept), hidden
        )

    @staticmethod
    def _new_masks(res, new_kept) -> np.ndarray:
        """(K', H, W) bool: the masks of the inserted boxes the Compose keeps, in their order."""
        new = targets.inserted_masks(res.record.annotations, res.image.shape[:2])
        if len(new) != len(res.inserted_bboxes):
            raise RuntimeError(f"{len(new)} inserted masks for {len(res.inserted_bboxes)} inserted boxes")
        return new if new_kept is None else new[new_kept]

    def apply_to_keypoints(self, keypoints: np.ndarray, insert_result=None, **params: Any) -> np.ndarray:
        if insert_result is None:
            return keypoints
        proc = self.get_processor("keypoints")
        remove = True if proc is None else bool(proc.params.remove_invisible)
        hidden = targets.cover(insert_result.record.annotations, insert_result.image.shape[:2])
        return targets.keypoints_after(keypoints, hidden, remove)

    def apply_to_bboxes(self, bboxes: np.ndarray, insert_result=None, new_kept=None, **params: Any) -> np.ndarray:
        if insert_result is None or (len(insert_result.inserted_labels) == 0 and insert_result.keep_existing.all()):
            return bboxes
        kept = bboxes[insert_result.keep_existing] if len(bboxes) else bboxes
        if len(insert_result.inserted_labels) == 0:
            return kept
        new_rows = self._encode_new_boxes(insert_result, bboxes, params["shape"])
        if new_kept is not None:
            new_rows = new_rows[new_kept]
        if len(kept) == 0:
            return new_rows
        return np.concatenate([kept, new_rows.astype(kept.dtype)], axis=0)

    def _encode_new_boxes(self, res, bboxes: np.ndarray, shape) -> np.ndarray:
        """Run the new boxes through the Compose bbox processor (as albumentations' Mosaic does) so that their labels
        are encoded by the same label manager the Compose will use to decode them, even when the image had no box.

        With the processor's defaults (``clip`` and ``filter_invalid_bboxes`` off) and a COCO / Pascal VOC / YOLO
        format, the boxes' round trip (to the user's format and back, in float32) is :func:`encode_boxes`, kept
        per variant, image size and format (a variant's boxes come again and again), and only the labels go
        through the processor's label manager (``process_field``, as its ``preprocess`` calls it): the same rows,
        byte for byte (tested against ``preprocess``). Anything else, or a box the processor's check would look
        at twice, goes through ``preprocess`` itself."""
        h, w = shape[:2]
        proc = self._bbox_processor()
        label_fields = None if proc is None else proc.params.label_fields
        if label_fields:
            values = [self._label_for(c, proc, label_fields[0]) for c in res.inserted_labels]
            p = proc.params
            if compat.encodes_like_2_0_8(p):
                memo = getattr(getattr(res, "variant", None), "encoded", None)
                mk = (h, w, p.format)
                geo = None if memo is None else memo.get(mk)
                if geo is None:
                    geo = encode_boxes(res.inserted_bboxes, h, w, p.format)
                    if memo is not None:
                        memo[mk] = geo
                elif type(geo) is bytes:  # as stored
                    geo = memo[mk] = np.frombuffer(geo, np.float32).reshape(-1, 4)
                if geo is not False:  # False: a box the processor's check must see (it may raise)
                    # the labels' columns promoted as preprocess's hstack promotes them, then float32
                    rows = np.hstack((geo, *encoded_labels(proc.label_manager, label_fields, values)))
                    return pad_columns(rows.astype(np.float32, copy=False), bboxes)
            return pad_columns(self._preprocess_new_boxes(res, proc, values, label_fields, h, w), bboxes)
        return internal_from_xywh(res.inserted_bboxes, h, w)

    @staticmethod
    def _preprocess_new_boxes(res, proc, values: list, label_fields, h: int, w: int) -> np.ndarray:
        """The new boxes through ``proc.preprocess`` (the Compose's own conversion, checks and label encoding)."""
        # to the user's format by the processor itself (any format, "albumentations" included), then back
        user_fmt = proc.check_and_convert(
            internal_from_xywh(res.inserted_bboxes, h, w), compat.shape_arg((h, w)), direction="from"
        )
        temp = {"image": np.zeros((h, w, 1), np.uint8), "bboxes": user_fmt}
        for f in label_fields:
            temp[f] = list(values)
        compat.preprocess(proc, temp)
        return temp["bboxes"]

    def _references(self, boxes_internal, proc) -> list | None:
        """Per existing box, the inserted category whose label (as the inserted boxes get it, encoded by the
        Compose's first label field) the box carries, else None: the image's own objects of the inserted kind,
        which set the inserted objects' sizes (``placement_cfg.sizes_from_existing``). None without label fields."""
        if proc is None or not proc.params.label_fields or not self.config.placement_cfg.sizes_from_existing:
            return None
        field = proc.params.label_fields[0]
        meta = proc.label_manager.metadata.get("bboxes", {}).get(field)
        if meta is None:
            return None
        codes = {}
        for c in self.config.categories:
            try:
                value = self._label_for(c, proc, field)
            except (KeyError, ValueError):
                continue
            if meta.is_numerical:
                codes[float(value)] = c
            elif meta.encoder is not None and value in meta.encoder.classes_:
                codes[float(meta.encoder.classes_[value])] = c
        column = np.asarray(boxes_internal)[:, 4] if np.asarray(boxes_internal).shape[1] > 4 else ()
        out = [codes.get(float(x)) for x in column]
        return out if any(r is not None for r in out) else None

    def _label_for(self, category: str, proc, field: str):
        if self.category_ids is not None:
            return self.category_ids[category]
        meta = proc.label_manager.metadata.get("bboxes", {}).get(field)
        if meta is not None and meta.is_numerical:
            raise ValueError(
                f"InsertObjects: the label field {field!r} holds numbers; pass category_ids="
                f"{{{category!r}: <id>}} so inserted boxes get numeric labels"
            )
        return category


def _record_of(live: dict) -> dict:
    """The JSON record of a call's insertion (``{}``: the image was left unchanged)."""
    res = live["insert_result"]
    return {} if res is None else res.record.to_dict()


def _checked_mask_values(values, categories: tuple[str, ...]) -> dict[str, float] | None:
    """``mask_values`` as given, checked: a finite number for every category and for no other."""
    if values is None:
        return None
    values = dict(values)
    missing, extra = set(categories) - set(values), set(values) - set(categories)
    if missing or extra:
        raise ValueError(
            f"mask_values must give a value for each category {list(categories)}: missing {sorted(missing)}, "
            f"unknown {sorted(extra)}"
        )
    for c, v in values.items():
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) or not np.isfinite(v):
            raise ValueError(f"mask_values[{c!r}] must be a finite number, got {v!r}")
    return values


# The sampling hook of each line: albumentations 2.0.8 calls ``get_params_dependent_on_data``; AlbumentationsX
# calls ``sample_parameters`` and refuses a class that defines the former in its body, so it is attached here, for
# the 2.0.8 line only.
if not compat.IS_X:
    InsertObjects.get_params_dependent_on_data = InsertObjects._params_for_call
