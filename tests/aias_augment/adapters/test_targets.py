"""Every albumentations target through ``InsertObjects``: instance masks in step with the boxes, the semantic mask
painted, keypoints under inserted objects handled as albumentations' invisible ones, every bbox format. Each check
is computed here from the outputs (bounding boxes of mask pixels by ``np.nonzero``, box formats by hand)."""

import albumentations as A
import numpy as np
import pytest

from aias_augment import InsertObjects
from aias_augment.adapters.targets import instance_masks_after, paint_semantic
from tests.aias_augment.pipeline.test_image import road_frame

K = [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]
H, W = 480, 640
CONE = 9  # the inserted objects' label
#: Two standing objects of the scene: one small on the left, and a barrier across the road whose lower part the
#: cones standing nearer than it cover (labelled objects occlude by depth order, so the barrier must stand farther).
BOXES = [[40.0, 250.0, 60.0, 50.0], [0.0, 280.0, 640.0, 60.0]]


def _scene_masks() -> list[np.ndarray]:
    masks = [np.zeros((H, W), np.uint8) for _ in BOXES]
    for m, (x, y, w, h) in zip(masks, BOXES):
        m[int(y) : int(y + h), int(x) : int(x + w)] = 1
    return masks


def _compose(fmt="coco", seed=3, keypoints=None, bbox_kw=None, **kw):
    return A.Compose(
        [
            InsertObjects(
                categories=["traffic_cone"],
                max_objects=3,
                min_objects=2,
                p=1.0,
                preset="fast",
                category_ids={"traffic_cone": CONE},
                **kw,
            )
        ],
        bbox_params=A.BboxParams(format=fmt, label_fields=["labels"], **(bbox_kw or {"min_visibility": 0.2})),
        keypoint_params=keypoints,
        seed=seed,
    )


def _mask_box(m: np.ndarray):
    ys, xs = np.nonzero(m)
    return None if len(xs) == 0 else [xs.min(), ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()]


def test_instance_masks_stay_in_step_with_the_boxes():
    """n boxes and n masks in, m and m out: the new masks follow in the order of the new boxes (each box is its
    mask's bounding box within 1 px), and the scene's masks lose exactly no pixel that is not now an inserted one's."""
    masks = _scene_masks()
    # each cone on its own: this seed's independent draws stand cones in front of the barrier
    compose = _compose(config_overrides={"arrangement": "independent"})
    out = compose(image=road_frame(), bboxes=BOXES, labels=[1, 2], masks=masks, camera_k=K)
    boxes, labels, got = out["bboxes"], out["labels"], out["masks"]
    assert len(boxes) == len(got) == len(labels) and isinstance(got, list)
    new = [i for i, lab in enumerate(labels) if lab == CONE]
    assert len(new) >= 2 and labels[: len(labels) - len(new)] == [1, 2][: len(labels) - len(new)]
    union = np.zeros((H, W), bool)
    for i in new:
        assert got[i].dtype == np.uint8 and got[i].shape == (H, W)
        assert np.allclose(_mask_box(got[i]), boxes[i], atol=1.0), (boxes[i], _mask_box(got[i]))
        assert not (union & (got[i] > 0)).any()  # one object per pixel
        union |= got[i] > 0
    for i, lab in enumerate(labels):
        if lab == CONE:
            continue
        before = masks[int(lab) - 1] > 0
        after = got[i] > 0
        assert not (after & ~before).any() and not (after & union).any()
        assert np.array_equal(after | (before & union), before)
    big = labels.index(2)  # the barrier is partly hidden by the cones standing in front of it
    assert (masks[1] > 0).sum() > (got[big] > 0).sum()


def test_no_masks_in_gives_the_new_objects_masks():
    out = _compose()(image=road_frame(), bboxes=[], labels=[], masks=[], camera_k=K)
    assert len(out["masks"]) == len(out["bboxes"]) >= 2
    for m, b in zip(out["masks"], out["bboxes"]):
        assert np.allclose(_mask_box(m), b, atol=1.0)


def test_a_new_box_the_compose_drops_takes_its_mask_with_it():
    """``BboxParams(min_area=...)``: the inserted boxes under it are dropped from boxes and masks alike (as
    albumentations' Mosaic filters what it adds)."""
    free = _compose(bbox_kw={})(image=road_frame(), bboxes=[], labels=[], masks=[], camera_k=K)
    areas = sorted(w * h for _, _, w, h in free["bboxes"])
    assert len(areas) >= 2
    threshold = (areas[0] + areas[1]) / 2
    out = _compose(bbox_kw={"min_area": threshold})(image=road_frame(), bboxes=[], labels=[], masks=[], camera_k=K)
    assert len(out["bboxes"]) == len(out["masks"]) == len(areas) - 1
    assert all(w * h >= threshold for _, _, w, h in out["bboxes"])
    for m, b in zip(out["masks"], out["bboxes"]):
        assert np.allclose(_mask_box(m), b, atol=1.0)


def test_instance_masks_after_drops_the_masks_of_dropped_boxes():
    masks = np.zeros((3, 4, 5, 2), np.uint8)
    masks[:, 1:3, 1:4] = 7
    hidden = np.zeros((4, 5), bool)
    hidden[2, 3] = True
    new = np.zeros((1, 4, 5), bool)
    new[0, 2, 3] = True
    out = instance_masks_after(masks, np.array([True, False, True]), new, hidden)
    assert out.shape == (3, 4, 5, 2) and out.dtype == np.uint8
    assert (out[:2, 2, 3] == 0).all() and (out[:2, 1, 1] == 7).all()
    assert (out[2, 2, 3] == 1).all() and out[2].sum() == 2
    assert len(instance_masks_after(masks, np.array([True]), new, hidden)) == 4  # not one mask per box: all kept


def test_semantic_mask_painted_with_the_category_value_and_untouched_elsewhere():
    sem = np.zeros((H, W), np.uint8)
    sem[300:, :] = 1  # road
    tf = _compose(mask_values={"traffic_cone": 3})
    out = tf(image=road_frame(), bboxes=[], labels=[], mask=sem, camera_k=K)
    boxes = np.asarray(out["bboxes"])
    assert len(boxes) >= 2 and out["mask"].dtype == np.uint8
    in_boxes = np.zeros((H, W), bool)
    for x, y, w, h in boxes:
        in_boxes[int(y) : int(np.ceil(y + h)), int(x) : int(np.ceil(x + w))] = True
        assert (out["mask"][int(y) : int(np.ceil(y + h)), int(x) : int(np.ceil(x + w))] == 3).any()
    painted = out["mask"] == 3
    assert np.array_equal(out["mask"][~in_boxes], sem[~in_boxes])
    lo, hi = boxes[:, :2].min(0), (boxes[:, :2] + boxes[:, 2:]).max(0)
    assert np.allclose(_mask_box(painted), [*lo, *(hi - lo)], atol=1.0)
    with pytest.raises(ValueError, match="mask_values"):
        _compose()(image=road_frame(), bboxes=[], labels=[], mask=sem, camera_k=K)
    with pytest.raises(ValueError, match="mask_values"):
        InsertObjects(categories=["traffic_cone"], mask_values={"cone": 3})


def test_paint_semantic_refuses_a_value_the_dtype_cannot_hold():
    from pycocotools import mask as mask_utils

    class Ann:
        visible_box_xywh, decoy, category = (0, 0, 1, 1), False, "traffic_cone"
        rle = mask_utils.encode(np.asfortranarray(np.array([[1, 0], [0, 0]], np.uint8)))

    assert paint_semantic(np.zeros((2, 2), np.uint8), [Ann()], {"traffic_cone": 5}).tolist() == [[5, 0], [0, 0]]
    with pytest.raises(ValueError, match="dtype"):
        paint_semantic(np.zeros((2, 2), np.uint8), [Ann()], {"traffic_cone": 300})


@pytest.mark.parametrize("remove_invisible", [True, False])
def test_keypoints_under_inserted_objects_are_invisible_ones(remove_invisible):
    """A grid of keypoints with labels: with ``remove_invisible`` (albumentations' default) exactly those whose
    pixel an inserted object now shows are removed, labels in step; without it, all stay where they were."""
    xs, ys = np.meshgrid(np.arange(2.5, W, 4.0), np.arange(200.5, H, 4.0))
    kps = np.c_[xs.ravel(), ys.ravel()]
    names = [f"k{i}" for i in range(len(kps))]
    params = A.KeypointParams(format="xy", label_fields=["names"], remove_invisible=remove_invisible)
    out = _compose(keypoints=params)(
        image=road_frame(), bboxes=[], labels=[], masks=[], keypoints=kps, names=names, camera_k=K
    )
    union = np.any(np.stack(out["masks"]) > 0, axis=0)
    hidden = union[kps[:, 1].astype(int), kps[:, 0].astype(int)]
    assert hidden.sum() >= 3
    expect = ~hidden if remove_invisible else np.ones(len(kps), bool)
    assert np.allclose(np.asarray(out["keypoints"]), kps[expect])
    assert out["names"] == [n for n, e in zip(names, expect) if e]


def _to_fmt(xywh, fmt):
    x, y, w, h = xywh
    return {
        "coco": [x, y, w, h],
        "pascal_voc": [x, y, x + w, y + h],
        "yolo": [(x + w / 2) / W, (y + h / 2) / H, w / W, h / H],
        "albumentations": [x / W, y / H, (x + w) / W, (y + h) / H],
    }[fmt]


def _from_fmt(b, fmt):
    b = list(b)[:4]
    if fmt == "coco":
        return b
    if fmt == "pascal_voc":
        return [b[0], b[1], b[2] - b[0], b[3] - b[1]]
    if fmt == "yolo":
        return [(b[0] - b[2] / 2) * W, (b[1] - b[3] / 2) * H, b[2] * W, b[3] * H]
    return [b[0] * W, b[1] * H, (b[2] - b[0]) * W, (b[3] - b[1]) * H]


def test_every_bbox_format_gives_the_same_boxes():
    """The same sample in each ``BboxParams`` format (converted here by hand) gives the same boxes and labels,
    read back by hand to COCO pixels."""
    results = {}
    for fmt in ("coco", "pascal_voc", "yolo", "albumentations"):
        out = _compose(fmt=fmt)(image=road_frame(), bboxes=[_to_fmt(b, fmt) for b in BOXES], labels=[1, 2], camera_k=K)
        results[fmt] = (out["labels"], np.array([_from_fmt(b, fmt) for b in out["bboxes"]]), out["image"])
    labels, boxes, image = results["coco"]
    assert labels.count(CONE) >= 2
    for fmt, (lab, bx, img) in results.items():
        assert lab == labels and np.allclose(bx, boxes, atol=1e-3) and np.array_equal(img, image), fmt
