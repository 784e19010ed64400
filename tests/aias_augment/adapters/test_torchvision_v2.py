"""The torchvision v2 door: the same seed gives the albumentations door's bytes; boxes in every torchvision format
(converted here by hand), instance masks and labels in step, inside ``v2.Compose`` with ``SanitizeBoundingBoxes``."""

import albumentations as A
import numpy as np
import pytest
import torch
from torchvision import tv_tensors
from torchvision.transforms import v2

from aias_augment import InsertObjects, InsertObjectsV2
from tests.aias_augment.pipeline.test_image import road_frame

H, W = 480, 640
CONE = 9
ARGS = {"categories": ["traffic_cone"], "max_objects": 3, "min_objects": 2, "p": 1.0, "preset": "fast"}
BOXES_XYWH = np.array([[40.0, 250.0, 60.0, 50.0], [0.0, 300.0, 640.0, 180.0]])


def _in_format(xywh: np.ndarray, fmt: str) -> np.ndarray:
    x, y, w, h = xywh.T
    return {
        "XYWH": np.c_[x, y, w, h],
        "XYXY": np.c_[x, y, x + w, y + h],
        "CXCYWH": np.c_[x + w / 2, y + h / 2, w, h],
    }[fmt]


def _xywh(boxes: np.ndarray, fmt: str) -> np.ndarray:
    a, b, c, d = np.asarray(boxes, np.float64).T
    return {"XYWH": np.c_[a, b, c, d], "XYXY": np.c_[a, b, c - a, d - b], "CXCYWH": np.c_[a - c / 2, b - d / 2, c, d]}[
        fmt
    ]


def _masks() -> np.ndarray:
    m = np.zeros((2, H, W), np.uint8)
    for k, (x, y, w, h) in enumerate(BOXES_XYWH.astype(int)):
        m[k, y : y + h, x : x + w] = 1
    return m


def _sample(fmt="XYXY", dtype=torch.float32):
    return {
        "image": tv_tensors.Image(torch.from_numpy(road_frame()).permute(2, 0, 1)),
        "boxes": tv_tensors.BoundingBoxes(
            torch.as_tensor(_in_format(BOXES_XYWH, fmt), dtype=dtype), format=fmt, canvas_size=(H, W)
        ),
        "masks": tv_tensors.Mask(torch.from_numpy(_masks())),
        "labels": torch.tensor([1, 2]),
        "meta": "kept",
    }


@pytest.mark.parametrize("fmt", ["XYXY", "XYWH", "CXCYWH"])
def test_same_seed_same_bytes_as_the_albumentations_door_in_every_box_format(fmt):
    door = InsertObjectsV2(seed=5, category_ids={"traffic_cone": CONE}, min_visibility=0.2, **ARGS)
    out = door(_sample(fmt))
    ref = A.Compose(
        [InsertObjects(category_ids={"traffic_cone": CONE}, **ARGS)],
        bbox_params=A.BboxParams(format="coco", label_fields=["labels"], min_visibility=0.2),
        seed=5,
    )(image=road_frame(), bboxes=BOXES_XYWH, labels=[1, 2], masks=list(_masks()))
    assert isinstance(out["image"], tv_tensors.Image) and out["image"].dtype == torch.uint8
    assert out["image"].permute(1, 2, 0).numpy().tobytes() == ref["image"].tobytes()
    assert isinstance(out["boxes"], tv_tensors.BoundingBoxes) and out["boxes"].format.name == fmt
    assert tuple(out["boxes"].canvas_size) == (H, W)
    assert np.allclose(_xywh(out["boxes"].numpy(), fmt), np.asarray(ref["bboxes"]), atol=1e-3)
    assert out["labels"].tolist() == [int(v) for v in ref["labels"]] and out["labels"].dtype == torch.int64
    assert isinstance(out["masks"], tv_tensors.Mask) and len(out["masks"]) == len(out["boxes"])
    assert np.array_equal(out["masks"].numpy(), np.stack(ref["masks"]))
    assert out["meta"] == "kept"


def test_in_v2_compose_with_sanitize_boxes_masks_and_labels_stay_in_step():
    pipeline = v2.Compose(
        [
            InsertObjectsV2(rng=np.random.default_rng(1), category_ids={"traffic_cone": CONE}, **ARGS),
            v2.RandomHorizontalFlip(p=1.0),
            v2.SanitizeBoundingBoxes(min_size=1),
        ]
    )
    image, target = pipeline(*_pair())
    n = len(target["boxes"])
    assert n > 2 and len(target["labels"]) == len(target["masks"]) == n
    assert (target["labels"] == CONE).sum() >= 2
    for box, mask in zip(target["boxes"].tolist(), target["masks"].numpy()):  # XYXY, flipped together
        ys, xs = np.nonzero(mask)
        assert xs.min() >= box[0] - 1 and xs.max() + 1 <= box[2] + 1 and ys.min() >= box[1] - 1
    new = target["labels"] == CONE
    for box, mask in zip(target["boxes"][new].tolist(), target["masks"][new].numpy()):
        ys, xs = np.nonzero(mask)
        assert np.allclose([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], box, atol=1.0)
    assert image.shape == (3, H, W)


def _pair():
    s = _sample()
    return s["image"], {"boxes": s["boxes"], "masks": s["masks"], "labels": s["labels"]}


def test_float_image_and_semantic_mask():
    img = tv_tensors.Image(torch.from_numpy(road_frame()).permute(2, 0, 1).float() / 255)
    sem = tv_tensors.Mask(torch.zeros(H, W, dtype=torch.uint8))
    door = InsertObjectsV2(seed=2, category_ids={"traffic_cone": CONE}, mask_values={"traffic_cone": 4}, **ARGS)
    out = door({"image": img, "mask": sem})
    assert out["image"].dtype == torch.float32 and out["image"].shape == img.shape
    changed = (out["image"] != img).any(0)
    painted = out["mask"] == 4
    assert painted.any() and changed[painted].all()  # painted pixels are inserted ones
    assert set(torch.unique(out["mask"]).tolist()) == {0, 4}


def test_bad_arguments_raise_at_construction():
    with pytest.raises(ValueError, match="seed"):
        InsertObjectsV2(category_ids={"traffic_cone": 1}, **ARGS)
    with pytest.raises(ValueError, match="category_ids"):
        InsertObjectsV2(seed=1, category_ids={"traffic_cone": "cone"}, **ARGS)
