"""The insertion variants and the warm-up of :class:`aias_augment.adapters.transform.InsertObjects`: what a call
does when the transform keeps at most K insertions per image (``variants_per_image``), and ``warm``, which computes
scene analyses, asset views and variants before training. A mixin of the transform: it reads the transform's
config, caches and counts."""

from __future__ import annotations

import logging
from dataclasses import replace
from types import MappingProxyType
from typing import Any

import numpy as np

from aias_augment.adapters import albu_compat as compat
from aias_augment.adapters.bbox_encoding import ENCODED_FORMATS, encode_boxes, xywh_from_internal
from aias_augment.adapters.boundary import SampleSkip, check_sample_targets, image_for_insertion
from aias_augment.adapters.variants import (
    Variant,
    VariantResult,
    plain_image_key,
    variant_key,
    variant_key_prefix,
    variant_rng,
)
from aias_augment.pipeline.bounded import ANALYSIS_MAX_PIXELS, insert_bounded

log = logging.getLogger("aias_augment.adapters.transform")

_NO_BOXES = np.zeros((0, 4))
_NO_BOXES.flags.writeable = False
_NO_TARGETS = MappingProxyType({})


def _same(image: np.ndarray) -> np.ndarray:
    """``restore`` of a uint8 RGB input (C-contiguous): the output is already in the input's form."""
    return image


def plan_labels(n: int, references: list | None) -> list:
    """The existing boxes' labels as the pipeline reads them: an inserted category for a box of that kind, else
    None (no kind); without references, the boxes' indices (the output's labels are not read back)."""
    return list(range(n)) if references is None else list(references)


class WarmVariants:
    """``warm`` and the variant calls of :class:`~aias_augment.adapters.transform.InsertObjects`."""

    def warm(
        self, images, camera_ks=None, depths=None, view_plans: int = 0, variants: bool = False, bboxes=None
    ) -> dict:
        """Analyse ``images`` (an iterable of what the transform will be called with: arrays in any input format it
        accepts) into the scene cache before training, so that no call pays a first analysis: with ``scene_cache``
        (a folder) every DataLoader worker and later run reads them; without, only this process's LRU holds them.
        ``camera_ks`` / ``depths``: per image, as the ``camera_k`` / ``depth`` targets (None: none).
        ``view_plans``: with the fast preset, also draw that many plans per image (on generators of their own, so
        from the planner's own distribution of assets and poses) and render the views their objects use into the
        view cache (``scene_cache/views`` with a folder: every worker reads them; else this process's), so that
        the calls find most views cached. Only images of at most 2 MP (larger ones are analysed, their views not).

        Each image goes through the call's own path (:func:`aias_augment.pipeline.bounded.insert_bounded` with
        the scene cache, on a generator of its own), so the cached analysis is the one the call looks up (same
        frame, same key); the insertion it makes is discarded and the transform's generator, counts and records
        are untouched: warming changes when the analysis (and a view) is computed, never what a call returns.
        ``variants``: with ``variants_per_image`` K, also compute each image's K variants (into this process's
        variant cache and, with ``scene_cache``, its folder), so that calls only paste them; ``bboxes``: per image,
        the boxes the calls will carry, as they pass them: in the Compose's bbox format (COCO xywh for a transform
        outside a Compose with ``bbox_params``). A variant is made for its image's boxes (None: no boxes), so they go
        through the Compose's own conversion here as in a call (to albumentations' float32 boxes, clipped or
        filtered as its ``BboxParams`` say, and back): warm's keys are the calls' keys bit for bit.
        Returns ``{"images", "analysed", "already_cached", "skipped", "views_rendered", "views_cached",
        "variants_computed", "variants_cached", "boxes_refused"}`` (boxes_refused: images whose boxes the Compose's
        processor refuses, as it would in a call; logged, no variants made for them)."""
        if variants and not self.variants_per_image:
            raise ValueError("warm(variants=True) needs InsertObjects(variants_per_image=K)")
        out = {
            "images": 0,
            "analysed": 0,
            "already_cached": 0,
            "skipped": 0,
            "views_rendered": 0,
            "views_cached": 0,
            "variants_computed": 0,
            "variants_cached": 0,
            "boxes_refused": 0,
        }
        cache = self._scene_cache
        for i, image in enumerate(images):
            out["images"] += 1
            k = None if camera_ks is None else camera_ks[i]
            d = None if depths is None else depths[i]
            try:
                rgb, _, _ = image_for_insertion(image)
                h, w = rgb.shape[:2]
                check_sample_targets({"camera_k": k, "depth": d}, h, w)
            except SampleSkip:
                out["skipped"] += 1
                continue
            before = cache.misses
            try:
                insert_bounded(
                    rgb,
                    None,
                    None,
                    np.random.default_rng(i),
                    replace(self.config, naive_share=0.0),  # the pipeline's analysis (a naive paste needs little)
                    intrinsics=k,
                    depth=d,
                    bank=self._bank,
                    scene_cache=cache,
                    n_objects=0,
                )
            except Exception as e:  # as in a call: an odd image is skipped, not fatal
                log.warning("warm: image %d skipped (%s)", i, e)
                out["skipped"] += 1
                continue
            out["analysed" if cache.misses > before else "already_cached"] += 1
            if view_plans and self.config.render_method in ("view_cache", "raycast") and h * w <= ANALYSIS_MAX_PIXELS:
                self._warm_views(rgb, k, d, view_plans, i, out)
            if variants:
                try:
                    boxes = np.zeros((0, 4)) if bboxes is None else self._boxes_as_called(bboxes[i], h, w)
                except ValueError as e:  # boxes the Compose would refuse in a call too
                    log.warning("warm: no variants for image %d: its boxes are refused (%s)", i, e)
                    out["boxes_refused"] += 1
                    continue
                for j in range(self.variants_per_image):
                    m0 = self._variants.misses
                    try:
                        self._variant(rgb, boxes, 0.0, {"camera_k": k, "depth": d}, j=j)
                    except Exception as e:  # as in a call
                        log.warning("warm: variant %d of image %d not made (%s)", j, i, e)
                        continue
                    out["variants_computed" if self._variants.misses > m0 else "variants_cached"] += 1
        return out

    def _warm_views(self, rgb, k, d, view_plans: int, i: int, out: dict) -> None:
        from aias_augment.apply.cone_raycast import cone_shape
        from aias_augment.apply.view_cache import default_view_cache, render_from_view_cache
        from aias_augment.core.frame import Frame
        from aias_augment.core.geometry import Intrinsics
        from aias_augment.plan.insertion import plan_insertion

        h, w = rgb.shape[:2]
        intr = None if k is None else Intrinsics.from_matrix(np.asarray(k, float), w, h)
        depth = None if d is None else np.asarray(d, np.float32)
        analysis = self._scene_cache.get(Frame(rgb, intr, depth=depth, meta={}), self.config)
        vc = self._view_cache if self._view_cache is not None else default_view_cache()
        for j in range(view_plans):
            plan = plan_insertion(analysis, self.config, np.random.default_rng([i, j, 1]), depth=depth, bank=self._bank)
            for o in plan.objects:
                if self.config.render_method == "raycast" and cone_shape(o.asset) is not None:
                    continue  # ray-cast at its pose in every call: no view to render
                m0 = vc.misses
                if render_from_view_cache(o.asset, o.cam_from_object, analysis.intrinsics, vc) is not None:
                    out["views_rendered" if vc.misses > m0 else "views_cached"] += 1

    def _variant(
        self,
        rgb: np.ndarray,
        existing_xywh: np.ndarray,
        min_vis: float,
        data,
        j: int | None = None,
        key: str | None = None,
        references=None,
        rng: np.random.Generator | None = None,
    ):
        """Variant ``j`` (None: drawn with the call's generator) of this sample, computed on a miss. ``key``: the
        sample's :func:`variant_key` when the caller has it (and found it missing: it is not looked up again).
        ``references``: per existing box, the inserted category it is an object of (its label is the one the
        inserted boxes get), else None."""
        if j is None:
            j = int(rng.integers(self.variants_per_image))
        # Boxes to 1e-3 px, in the key and in the insertion alike: the Compose's normalise/denormalise round trip
        # (or warm's raw boxes) must find the same variant, and the variant is made from exactly what its key says.
        if len(existing_xywh):
            existing_xywh = np.round(np.asarray(existing_xywh, np.float64).reshape(-1, 4), 3)
        v = None
        if key is None:
            key = variant_key(
                rgb,
                camera_k=data.get("camera_k"),
                depth=data.get("depth"),
                scene=data.get("scene"),
                existing_xywh=existing_xywh,
                references=None if references is None else [r is not None for r in references],
                prefix=self._key_prefix(),
            )
            v = self._variants.get(key, j)
        labels = plan_labels(len(existing_xywh), references)
        if v is None:
            full = insert_bounded(
                rgb,
                existing_xywh,
                labels,
                variant_rng(self.variants_seed, j, key),
                self.config,
                intrinsics=data.get("camera_k"),
                depth=data.get("depth"),
                bank=self._bank,
                scene_cache=self._scene_cache,
                view_cache=self._view_cache,
                scene=data.get("scene"),
            )
            v = Variant.from_result(rgb, full)
            h, w = rgb.shape[:2]
            for fmt in () if compat.IS_X else ENCODED_FORMATS:  # the new boxes as a 2.0.8 Compose encodes them
                v.encoded[(h, w, fmt)] = encode_boxes(v.inserted_bboxes, h, w, fmt)
            self._variants.put(key, j, v)
        return v.result(rgb, existing_xywh, labels, min_vis)

    def _key_prefix(self):
        """The variant keys' fixed part (config, assets, seed): :func:`variant_key_prefix`, made on first use."""
        if self._variant_prefix is None:
            self._variant_prefix = variant_key_prefix(self.config, self.assets, self.variants_seed)
        return self._variant_prefix

    def _plain_variant(self, rgb: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
        """A variant call on a uint8 RGB image (the training loop's usual input) without existing boxes, K, depth
        or scene facts: what :meth:`_general_params` does for it (the image passes the boundary as it is and
        ``restore`` is the identity), in fewer steps: a draw, the key, a lookup, a copy with the window pasted."""
        j = int(rng.integers(self.variants_per_image))
        try:
            key = plain_image_key(rgb, self._key_prefix())
            v = self._variants.get(key, j)
            res = (
                self._variant(rgb, _NO_BOXES, 0.0, _NO_TARGETS, j=j, key=key)
                if v is None
                else v.result(rgb, _NO_BOXES, ())
            )
        except Exception as e:  # one odd image must not stop an epoch: skip it, count it, say why
            self.counts.skip(e, log)
            return {"insert_result": None, "restore": _same}
        self.last_record = res.variant if isinstance(res, VariantResult) else res.record
        n = len(res.inserted_labels)
        self.counts.result(n, None if n else res.record.to_dict(), log)
        return {"insert_result": res, "restore": _same}

    def _boxes_as_called(self, boxes, h: int, w: int) -> np.ndarray:
        """COCO xywh pixels of ``boxes`` (the Compose's bbox format; COCO xywh without a bbox processor) as a call
        reads them: through the processor's own ``check_and_convert`` (float32 albumentations boxes, clip and
        filter as configured; the Compose's preprocess) and :func:`xywh_from_internal`."""
        b = np.asarray(boxes, np.float64).reshape(-1, 4)
        if len(b) == 0:
            return np.zeros((0, 4))
        proc = self._bbox_processor()
        internal = (
            proc.check_and_convert(b, compat.shape_arg((h, w)), direction="to")
            if proc is not None
            else compat.to_albumentations(b, "coco", (h, w))
        )
        return xywh_from_internal(internal, h, w)
