"""``InsertObjectsV2``: the ``torchvision.transforms.v2`` door over the albumentations transform.

A sample in torchvision's detection convention (``tv_tensors.Image`` (C, H, W) uint8 or float in [0, 1],
``BoundingBoxes`` in XYXY, XYWH or CXCYWH, ``Mask`` (N, H, W) per object or (H, W) semantic, ``labels`` an integer
tensor beside the boxes) goes through the same :class:`~aias_augment.adapters.transform.InsertObjects` in an
albumentations Compose seeded with ``seed``: the same seed gives the same bytes as
``A.Compose([InsertObjects(...)], bbox_params=A.BboxParams("coco", label_fields=["labels"], min_visibility=...),
seed=seed)``. Boxes are converted with :func:`torchvision.ops.box_convert`; instance masks stay in step with the
boxes (so ``v2.SanitizeBoundingBoxes`` after it removes a box with its mask and label). Everything else in the
sample passes through untouched.
"""

from __future__ import annotations

from typing import Any

import albumentations as A
import numpy as np
import torch
from torch.utils._pytree import tree_flatten, tree_unflatten
from torchvision import tv_tensors
from torchvision.ops import box_convert
from torchvision.transforms import v2

from aias_augment.adapters.transform import InsertObjects

#: torchvision box formats this door reads and writes, by their ``box_convert`` names.
_FORMATS = {"XYXY": "xyxy", "XYWH": "xywh", "CXCYWH": "cxcywh"}


class InsertObjectsV2(v2.Transform):
    """Insert 3D objects into a torchvision v2 sample (see the module docstring).

    Args:
        seed: the seed of the insertions (a numpy ``Generator`` as ``rng`` instead: one draw of it is the seed).
        min_visibility: the scene's boxes less visible than this under the inserted objects are dropped (with their
            mask and label).
        category_ids: the integer label of each inserted category (required: labels are integer tensors).
        **kwargs: the arguments of :class:`~aias_augment.adapters.transform.InsertObjects` (categories, preset,
            max_objects, mask_values for a semantic ``Mask``, p, ...).
    """

    def __init__(
        self,
        *,
        category_ids: dict[str, int],
        seed: int | None = None,
        rng: np.random.Generator | None = None,
        min_visibility: float = 0.0,
        **kwargs: Any,
    ):
        super().__init__()
        if (seed is None) == (rng is None):
            raise ValueError("InsertObjectsV2 needs exactly one of seed (an int) or rng (a numpy Generator)")
        if rng is not None:
            if not isinstance(rng, np.random.Generator):
                raise TypeError(f"rng must be a numpy Generator, got {type(rng).__name__}")
            seed = int(rng.integers(2**32))
        if not category_ids or not all(isinstance(v, (int, np.integer)) for v in category_ids.values()):
            raise ValueError(f"InsertObjectsV2 needs category_ids={{category: integer label}}, got {category_ids!r}")
        self.seed, self.min_visibility = int(seed), float(min_visibility)
        self.insert = InsertObjects(category_ids=dict(category_ids), **kwargs)
        self._compose = A.Compose(
            [self.insert],
            bbox_params=A.BboxParams("coco", label_fields=["labels"], min_visibility=self.min_visibility),
            seed=self.seed,
        )

    def forward(self, *inputs: Any) -> Any:
        sample = inputs if len(inputs) > 1 else inputs[0]
        flat, spec = tree_flatten(sample)
        found = _find(flat, sample)
        if found["image"] is None:
            raise TypeError("InsertObjectsV2: the sample has no tv_tensors.Image (or plain (C, H, W) tensor)")
        image = flat[found["image"]]
        hw = tuple(image.shape[-2:])
        call: dict[str, Any] = {"image": image.permute(1, 2, 0).cpu().numpy(), "labels": []}
        boxes = None if found["boxes"] is None else flat[found["boxes"]]
        if boxes is not None:
            fmt = _FORMATS.get(boxes.format.name)
            if fmt is None:
                raise ValueError(f"InsertObjectsV2: box format {boxes.format.name} (supported: {sorted(_FORMATS)})")
            if tuple(boxes.canvas_size) != hw:
                raise ValueError(f"InsertObjectsV2: boxes on a {boxes.canvas_size} canvas for a {hw} image")
            call["bboxes"] = box_convert(boxes.as_subclass(torch.Tensor).double(), fmt, "xywh").cpu().numpy()
            labels = found["labels"]
            n = len(boxes)
            call["labels"] = [0] * n if labels is None else flat[labels].cpu().tolist()
        else:
            call["bboxes"] = np.zeros((0, 4))
        for i in found["masks"]:
            m = flat[i].cpu().numpy()
            if m.ndim == 3:
                call["masks"] = list(m)
            else:
                call["mask"] = m
        out = self._compose(**call)
        flat = list(flat)
        flat[found["image"]] = _like(torch.from_numpy(np.ascontiguousarray(out["image"])).permute(2, 0, 1), image)
        if boxes is not None:
            xywh = torch.as_tensor(np.asarray(out["bboxes"], np.float64).reshape(-1, 4))
            flat[found["boxes"]] = tv_tensors.wrap(
                box_convert(xywh, "xywh", _FORMATS[boxes.format.name]).to(boxes.dtype).contiguous(), like=boxes
            )
            if found["labels"] is not None:
                old = flat[found["labels"]]
                flat[found["labels"]] = torch.as_tensor(out["labels"], dtype=old.dtype).reshape(-1)
        for i in found["masks"]:
            m = flat[i]
            if m.ndim == 3:
                new = np.stack(out["masks"]) if len(out["masks"]) else np.zeros((0, *hw), bool)
            else:
                new = out["mask"]
            flat[i] = tv_tensors.wrap(torch.from_numpy(np.ascontiguousarray(new)).to(m.dtype), like=m)
        return tree_unflatten(flat, spec)


def _like(t: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
    t = t.contiguous().to(image.device)
    return tv_tensors.wrap(t, like=image) if isinstance(image, tv_tensors.TVTensor) else t


def _find(flat: list, sample: Any) -> dict[str, Any]:
    """Indices in ``flat`` of the image (a ``tv_tensors.Image``, else the first plain tensor, as torchvision's own
    heuristic), the ``BoundingBoxes``, every ``Mask`` and the labels (the value of the key "labels", any case, of
    the sample's dict or, for an ``(image, target)`` pair, of the target: torchvision's ``SanitizeBoundingBoxes``
    default)."""
    kinds = {"image": None, "boxes": None, "masks": [], "labels": None}
    plain = None
    for i, x in enumerate(flat):
        if isinstance(x, tv_tensors.Image) and kinds["image"] is None:
            kinds["image"] = i
        elif isinstance(x, tv_tensors.BoundingBoxes):
            if kinds["boxes"] is not None:
                raise ValueError("InsertObjectsV2: more than one BoundingBoxes in the sample")
            kinds["boxes"] = i
        elif isinstance(x, tv_tensors.Mask):
            kinds["masks"].append(i)
        elif type(x) is torch.Tensor and plain is None:
            plain = i
    target = sample[1] if isinstance(sample, (tuple, list)) and len(sample) == 2 else sample
    labels = None
    if isinstance(target, dict):
        key = next((k for k in target if isinstance(k, str) and k.lower() == "labels"), None)
        labels = None if key is None else target[key]
    if labels is not None:
        kinds["labels"] = next(i for i, x in enumerate(flat) if x is labels)
        if plain == kinds["labels"]:
            plain = next((i for i, x in enumerate(flat) if type(x) is torch.Tensor and i != kinds["labels"]), None)
    if kinds["image"] is None:
        kinds["image"] = plain
    return kinds
