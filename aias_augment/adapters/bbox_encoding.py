"""Boxes between the pipeline (COCO xywh pixels) and an albumentations Compose (normalised x_min, y_min, x_max,
y_max rows with encoded label columns), with albumentations' own arithmetic: the same operations in the same dtypes as
its ``convert_bboxes_to_albumentations`` / ``convert_bboxes_from_albumentations``, so the same bits."""

from __future__ import annotations

import numpy as np
from albumentations.core.bbox_utils import denormalize_bboxes

#: Bbox formats whose round trip through the Compose's processor :func:`encode_boxes` reproduces.
ENCODED_FORMATS = ("coco", "pascal_voc", "yolo")


def xywh_from_internal(boxes_internal, h: int, w: int) -> np.ndarray:
    """COCO xywh pixels (float64) of albumentations' normalised x_min, y_min, x_max, y_max boxes (extra columns
    ignored): what a call reads from the Compose, and what warm() makes of its boxes."""
    xyxy = denormalize_bboxes(np.asarray(boxes_internal)[:, :4], (h, w))
    return np.c_[xyxy[:, :2], xyxy[:, 2:] - xyxy[:, :2]]


def internal_from_xywh(xywh, h: int, w: int) -> np.ndarray:
    """(K, 4) float32 albumentations boxes (normalised x_min, y_min, x_max, y_max) of COCO xywh pixel boxes."""
    xywh = np.asarray(xywh, np.float64).reshape(-1, 4)
    xyxy = np.c_[xywh[:, :2], xywh[:, :2] + xywh[:, 2:]]
    return (xyxy / np.array([w, h, w, h], np.float64)).astype(np.float32)


def pad_columns(rows: np.ndarray, bboxes: np.ndarray) -> np.ndarray:
    """``rows`` with zero columns added up to ``bboxes``' (extra columns, e.g. bbox ids)."""
    if len(bboxes) and rows.shape[1] < bboxes.shape[1]:
        rows = np.c_[rows, np.zeros((len(rows), bboxes.shape[1] - rows.shape[1]), rows.dtype)]
    return rows


def encode_boxes(xywh: np.ndarray, h: int, w: int, fmt: str):
    """(K, 4) float32: COCO xywh pixel boxes as albumentations' processor (``clip`` and ``filter_invalid_bboxes``
    off) encodes them when they arrive in ``fmt`` ("coco", "pascal_voc" or "yolo") from our normalised float32
    boxes: ``convert_bboxes_from_albumentations`` then ``convert_bboxes_to_albumentations``, the same operations
    in the same dtypes (float32 storage, float64 where albumentations scales), so the same bits. False when a box
    is not strictly inside [0, 1] with x_max > x_min and y_max > y_min: the processor's ``check_bboxes`` must
    then decide (its tolerance, its error)."""
    scale = np.array([w, h, w, h], np.float64)
    norm = internal_from_xywh(xywh, h, w)  # what the boxes are in albumentations' format
    user = np.empty_like(norm)  # convert_bboxes_from_albumentations(norm, fmt)
    if fmt == "yolo":
        user[:, :2] = (norm[:, :2] + norm[:, 2:]) / 2
        user[:, 2:] = norm[:, 2:] - norm[:, :2]
    else:
        den = norm * scale  # denormalize_bboxes: float64
        if fmt == "coco":
            user[:, :2] = den[:, :2]
            user[:, 2:] = den[:, 2:] - den[:, :2]
        else:
            user[:] = den
    geo = np.empty_like(user)  # convert_bboxes_to_albumentations(user, fmt)
    if fmt == "yolo":
        half = user[:, 2:] / 2
        geo[:, :2] = user[:, :2] - half
        geo[:, 2:] = user[:, :2] + half
    else:
        if fmt == "coco":
            geo[:, :2] = user[:, :2]
            geo[:, 2:] = user[:, :2] + user[:, 2:]
        else:
            geo[:] = user
        geo[:] = geo.astype(np.float64) / scale  # normalize_bboxes: float64, stored as float32
    if not (((geo >= 0) & (geo <= 1)).all() and (geo[:, 2:] > geo[:, :2]).all()):
        return False
    geo.flags.writeable = False
    return geo


def encoded_labels(manager, label_fields, values: list) -> list[np.ndarray]:
    """``manager.process_field("bboxes", field, values)`` for each label field, as the processor's ``preprocess``
    calls it: (K, 1) arrays. Where that call would change nothing in the manager (a field it has seen, holding
    numbers; or strings its encoder knows all of) the same array is made here without it; else it is called."""
    meta = manager.metadata.get("bboxes")
    out = []
    for f in label_fields:
        m = None if meta is None else meta.get(f)
        if m is not None and m.is_numerical:  # _encode_data of a list: float32
            out.append(np.array(values, dtype=np.float32).reshape(-1, 1))
            continue
        e = None if m is None else m.encoder
        if e is not None and not e.is_numerical and all(type(v) is str and v in e.classes_ for v in values):
            out.append(np.array([e.classes_[v] for v in values]).reshape(-1, 1))  # LabelEncoder.transform
            continue
        out.append(manager.process_field("bboxes", f, list(values)))
    return out
