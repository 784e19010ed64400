"""Every place where the two albumentations lines differ, for the adapter: albumentations 2.0.8 (MIT, the pinned
dependency) and AlbumentationsX (AGPL; never a dependency of this project: supported when the user has installed it,
and then imported under the same name ``albumentations``).

The differences the transform meets:

- sampling: 2.0.8 calls ``get_params_dependent_on_data(params, data)`` and keeps what it returns as the transform's
  ``params``; AlbumentationsX calls ``sample_parameters(params, data, targets, sampling)``, which returns
  ``SampledParams``, and refuses a class that defines the 2.0.8 hook in its body;
- ``BboxParams``: the format is ``format`` (2.0.8) or ``coord_format`` (X); clipping on input ``clip`` or
  ``clip_bboxes_on_input``; X boxes carry a ``bbox_type`` ("hbb" here) that its bbox functions take as an argument;
- the bbox filter: 2.0.8's ``filter_bboxes`` returns the kept rows; X's processor says which rows it keeps
  (``filter_with_keep_mask``), with its own clipping (``clip_after_transform``);
- the bbox conversion arithmetic differs between the lines, so the bit-exact shortcut of
  :func:`aias_augment.adapters.bbox_encoding.encode_boxes` (2.0.8's arithmetic) is taken on 2.0.8 only;
- the processor's ``preprocess`` remembers (2.0.8, ``is_sequence_input``) or not (X) whether a target came as a list;
- targets: X names instance masks apart (``Targets.MASKS``); 2.0.8's ``MASK`` covers ``mask`` and ``masks``;
- replay: 2.0.8's ``ReplayCompose`` and ``save_applied_params`` keep the transform's ``params``; X's ``ReplayCompose``
  keeps ``SampledParams.to_dict()`` and its ``save_applied_params`` keeps constructor arguments (the values a
  ``sample_parameters`` writes to ``sampling.applied_overrides`` over the constructor's: here the record, as the
  ``insertion`` argument), replayed with ``Compose.from_applied_transforms``.
"""

from __future__ import annotations

from importlib import metadata

import albumentations as A
import numpy as np
from albumentations.core.bbox_utils import convert_bboxes_to_albumentations, filter_bboxes
from albumentations.core.type_definitions import Targets

#: True when the ``albumentations`` module is AlbumentationsX (it samples through ``sample_parameters``).
IS_X = hasattr(A.BasicTransform, "sample_parameters")


def line() -> str:
    """The installed line and version, e.g. "AlbumentationsX 2.5.1" or "albumentations 2.0.8"."""
    name = "albumentationsx" if IS_X else "albumentations"
    try:
        version = metadata.version(name)
    except metadata.PackageNotFoundError:
        version = A.__version__
    return f"{'AlbumentationsX' if IS_X else 'albumentations'} {version}"


#: Every 2D target of the line.
TARGETS = tuple(
    getattr(Targets, name) for name in ("IMAGE", "MASK", "MASKS", "BBOXES", "KEYPOINTS") if hasattr(Targets, name)
)


def bbox_format(params) -> str:
    """The ``BboxParams``' box format ("coco", "pascal_voc", "yolo", "albumentations"; X also "cxcywh")."""
    return params.coord_format if IS_X else params.format


def clips_on_input(params) -> bool:
    """Whether the ``BboxParams`` clip boxes to the image when they come in."""
    return bool(params.clip_bboxes_on_input if IS_X else params.clip)


def encodes_like_2_0_8(params) -> bool:
    """Whether the processor of these ``BboxParams`` turns a box into the bits
    :func:`aias_augment.adapters.bbox_encoding.encode_boxes` computes: 2.0.8, COCO / Pascal VOC / YOLO, no clipping
    or filtering on input."""
    from aias_augment.adapters.bbox_encoding import ENCODED_FORMATS

    return not IS_X and params.format in ENCODED_FORMATS and not params.clip and not params.filter_invalid_bboxes


def to_albumentations(boxes: np.ndarray, fmt: str, hw: tuple[int, int]) -> np.ndarray:
    """``boxes`` in ``fmt`` as the line's normalised x_min, y_min, x_max, y_max rows (float32)."""
    if IS_X:
        return convert_bboxes_to_albumentations(boxes, fmt, hw, "hbb")
    return convert_bboxes_to_albumentations(boxes, fmt, hw)


def kept_rows(rows: np.ndarray, hw: tuple[int, int], proc) -> np.ndarray:
    """(K,) bool: which normalised rows (K, 4) the Compose's bbox processor ``proc`` keeps after a transform
    (``min_area``, ``min_visibility``, ``min_width``, ``min_height``, ``max_accept_ratio``; all kept without one)."""
    rows = np.asarray(rows, np.float32).reshape(-1, 4)
    if proc is None or len(rows) == 0:
        return np.ones(len(rows), bool)
    if IS_X:
        return np.asarray(proc.filter_with_keep_mask(rows, hw)[1], bool)
    p = proc.params
    indexed = np.c_[rows, np.arange(len(rows), dtype=np.float32)]
    kept = filter_bboxes(
        indexed,
        {"height": hw[0], "width": hw[1]},
        min_area=p.min_area,
        min_visibility=p.min_visibility,
        min_width=p.min_width,
        min_height=p.min_height,
        max_accept_ratio=p.max_accept_ratio,
    )
    out = np.zeros(len(rows), bool)
    out[kept[:, 4].astype(np.int64)] = True
    return out


def preprocess(proc, data: dict) -> None:
    """``proc.preprocess(data)`` on a scratch ``data``, leaving the processor's memory of the call's own targets
    (2.0.8's ``is_sequence_input``: whether to give lists back) as it was."""
    saved = getattr(proc, "is_sequence_input", None)
    saved = None if saved is None else dict(saved)
    try:
        proc.preprocess(data)
    finally:
        if saved is not None:
            proc.is_sequence_input.clear()
            proc.is_sequence_input.update(saved)


def shape_arg(hw: tuple[int, int]):
    """The image shape as the line's processors take it: (H, W) for X, ``{"height", "width"}`` for 2.0.8."""
    return tuple(hw) if IS_X else {"height": hw[0], "width": hw[1]}
