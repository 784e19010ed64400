"""An insertion of the training-loop doors made again from its JSON record (``InsertionRecord.to_dict()``).

``ReplayCompose`` and ``Compose(save_applied_params=True)`` keep, as the transform's parameters, the record of the
insertion (placements, harmonizer seed, annotations, working resolution, mode): plain JSON, no image.
``InsertObjects(insertion=record)`` replays it on every call instead of drawing; AlbumentationsX's
``save_applied_params`` log (constructor arguments) holds the record under that name, so
``Compose.from_applied_transforms`` builds the transform that replays it. Replaying it
on the sample it was made from (same image, ``camera_k``, ``depth`` and ``scene``) renders the recorded plan again
(:func:`aias_augment.pipeline.replay.replay`: nothing is drawn) and gives the same bytes; the boxes and masks are the
record's own.
"""

from __future__ import annotations

import json
from collections.abc import Mapping

import numpy as np

from aias_augment.adapters.targets import labelled
from aias_augment.core.frame import Frame
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.scene_inputs import scene_meta
from aias_augment.pipeline.image import InsertionRecord
from aias_augment.pipeline.replay import default_asset_for, replay


def checked_record(record) -> dict | None:
    """``InsertObjects(insertion=...)`` checked at construction: None, ``{}`` (a call that left the image
    unchanged) or an ``InsertionRecord.to_dict()``, returned as its JSON form (tuples as lists), so that ``to_dict``
    / ``from_dict`` / ``save`` / ``load`` give it back equal."""
    if record is None:
        return None
    if not isinstance(record, Mapping):
        raise ValueError(f"insertion must be None or an InsertionRecord.to_dict() mapping, got {type(record).__name__}")
    try:
        as_json = json.loads(json.dumps(dict(record)))
        if as_json:
            InsertionRecord.from_dict(as_json)
    except (TypeError, ValueError, KeyError, AttributeError) as e:
        raise ValueError(
            f"insertion is not an insertion record (InsertionRecord.to_dict(), as ReplayCompose or "
            f"save_applied_params log it): {type(e).__name__}: {e}"
        ) from None
    return as_json


class ReplayedResult:
    """The fields of an :class:`~aias_augment.pipeline.image.InsertionResult` the doors read: ``image``,
    ``inserted_bboxes`` (K, 4) COCO xywh, ``inserted_labels``, ``keep_existing`` (N,) and ``record``."""

    __slots__ = ("image", "inserted_bboxes", "inserted_labels", "keep_existing", "record")

    def __init__(self, image, inserted_bboxes, inserted_labels, keep_existing, record):
        self.image, self.inserted_bboxes, self.inserted_labels = image, inserted_bboxes, inserted_labels
        self.keep_existing, self.record = keep_existing, record


def asset_lookup(bank):
    """``assets(placement)`` for :func:`replay`: the user's :class:`~aias_augment.assets.asset.PathAssets` file a
    placement names, else the default or procedural asset it was made from."""

    def find(p):
        if bank is not None and p.asset_source in bank.paths.get(p.category, ()):
            return bank._load(p.category, p.asset_source)
        return default_asset_for(p)

    return find


def replayed_result(
    record: dict, rgb: np.ndarray, data, cfg, bank, n_existing: int, min_visibility: float
) -> ReplayedResult:
    """``record`` applied again to ``rgb`` ((H, W, 3) uint8, the image as the insertion saw it) with the sample's
    ``camera_k``, ``depth`` and ``scene`` from ``data``; ``n_existing`` boxes came with the sample (the record's
    ``existing_visibility`` has one entry per box) and those below ``min_visibility`` are dropped."""
    vis = np.asarray(record.get("existing_visibility", ()), np.float64)
    if len(vis) != n_existing:
        raise ValueError(
            f"InsertObjects replay: the record was made with {len(vis)} existing boxes, the sample has {n_existing}"
        )
    h, w = rgb.shape[:2]
    k = data.get("camera_k")
    intrinsics = None if k is None else Intrinsics.from_matrix(np.asarray(k, np.float64), w, h)
    depth = data.get("depth")
    depth = None if depth is None else np.asarray(depth, np.float32)
    frame = Frame(rgb, intrinsics, depth=depth, meta=scene_meta(None, data.get("scene"), (h, w)))
    applied = replay(record, frame, cfg, assets=asset_lookup(bank))
    rec = InsertionRecord.from_dict(record)
    objects = labelled(rec.annotations)
    boxes = np.array([a.visible_box_xywh for a in objects], np.float64).reshape(-1, 4)
    return ReplayedResult(applied.image, boxes, [a.category for a in objects], vis >= min_visibility, rec)
