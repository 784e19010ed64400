"""Inserted cones drawn like the photo's own: the looks of its labelled cones, for the procedural family to draw from.

A photo's labelled objects show what its cones look like (body colour, base, sleeves); the family's variety (five
colours, three bases, zero to three sleeves) helps a detector in general, but beside a photo's own cones an inserted
cone of another colour or base reads as pasted. With ``cone_look="labels"`` (the default) an image with labelled cones
draws its inserted cones like one of them (:func:`aias_augment.assets.bank.procedural.procedural_asset_like`); an
image without any keeps the family's variety, as does ``cone_look="variety"``.
"""

from __future__ import annotations

import logging

import numpy as np

from aias_augment.analyse.instances import fit_cone_looks
from aias_augment.assets.cone_look import ConeLook
from aias_augment.plan.insertion import label_category

__all__ = ["labelled_cone_looks"]

log = logging.getLogger(__name__)


def labelled_cone_looks(image_rgb: np.ndarray, boxes_xyxy, labels) -> tuple[ConeLook, ...]:
    """The looks of the boxes among ``boxes_xyxy`` (N, 4) whose label names a traffic cone (the category itself or a
    name the taxonomy classifies as one: "cone", "Traffic cone", ...); () without labels or cones. Boxes that cannot be
    measured (cut by the frame, small, unsaturated) are counted in a debug message."""
    if labels is None or not len(boxes_xyxy):
        return ()
    from aias_augment.assets.bank.taxonomy import load_taxonomy  # the bank package imports trimesh: only when needed

    taxonomy = load_taxonomy()
    kinds = {
        lab: label_category(lab, ("traffic_cone",), taxonomy) == "traffic_cone"
        for lab in {str(x) for x in labels if x is not None}
    }
    cones = [
        b for b, lab in zip(np.asarray(boxes_xyxy, float).reshape(-1, 4), labels) if lab is not None and kinds[str(lab)]
    ]
    if not cones:
        return ()
    looks = tuple(fit_cone_looks(image_rgb, np.array(cones)))
    log.debug("cone looks: %d of %d labelled cones measured", len(looks), len(cones))
    return looks
