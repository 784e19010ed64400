"""``InsertObjects`` under AlbumentationsX: the contract of the albumentations door (boxes in every format, instance
and semantic masks, keypoints, replay from JSON, same seed -> same bytes) on the AGPL line, which is never a
dependency. These run where AlbumentationsX is the installed ``albumentations`` (``tools/ax_venv.sh`` builds
``.venv-ax`` beside ``.venv`` and runs them); elsewhere they are skipped. Every check is computed here from the
outputs: boxes of mask pixels by ``np.nonzero``, box formats converted by hand."""

import json

import numpy as np
import pytest

from aias_augment.adapters import albu_compat

pytestmark = pytest.mark.skipif(
    not albu_compat.IS_X,
    reason=f"AlbumentationsX is not installed ({albu_compat.line()} is): tools/ax_venv.sh runs these in .venv-ax",
)

import albumentations as A  # noqa: E402

from aias_augment import InsertObjects  # noqa: E402
from tests.aias_augment.pipeline.test_image import road_frame  # noqa: E402

K = [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]
H, W = 480, 640
CONE = 9
#: Two objects of the scene: one small on the left, one large over the road where cones stand.
BOXES = [[40.0, 250.0, 60.0, 50.0], [0.0, 300.0, 640.0, 180.0]]


def _insert(**kw):
    args = {"categories": ["traffic_cone"], "max_objects": 3, "min_objects": 2, "p": 1.0, "preset": "fast"}
    return InsertObjects(**{**args, "category_ids": {"traffic_cone": CONE}, **kw})


def _compose(fmt="coco", seed=3, bbox_kw=None, keypoints=None, **kw):
    return A.Compose(
        [_insert(**kw)],
        bbox_params=A.BboxParams(coord_format=fmt, label_fields=["labels"], **(bbox_kw or {"min_visibility": 0.2})),
        keypoint_params=keypoints,
        seed=seed,
    )


def _scene_masks() -> np.ndarray:
    """One mask per box; the road object's reaches up to the horizon band where the cones stand (the transform
    places by boxes and hides by masks, so the cones in front of it must cut it)."""
    masks = np.zeros((len(BOXES), H, W), np.uint8)
    for m, (x, y, w, h) in zip(masks, BOXES):
        m[int(y) : int(y + h), int(x) : int(x + w)] = 1
    masks[1, 240:] = 1
    return masks


def _mask_box(m: np.ndarray):
    ys, xs = np.nonzero(m)
    return None if len(xs) == 0 else [xs.min(), ys.min(), xs.max() + 1 - xs.min(), ys.max() + 1 - ys.min()]


def _to(fmt: str, xywh) -> list:
    """COCO xywh pixel boxes in ``fmt``, by hand."""
    out = []
    for x, y, w, h in xywh:
        out.append(
            {
                "coco": [x, y, w, h],
                "pascal_voc": [x, y, x + w, y + h],
                "albumentations": [x / W, y / H, (x + w) / W, (y + h) / H],
                "yolo": [(x + w / 2) / W, (y + h / 2) / H, w / W, h / H],
                "cxcywh": [x + w / 2, y + h / 2, w, h],
            }[fmt]
        )
    return out


def _from(fmt: str, boxes) -> np.ndarray:
    """Boxes in ``fmt`` as COCO xywh pixels, by hand."""
    b = np.asarray(boxes, np.float64).reshape(-1, 4)
    if fmt == "coco":
        return b
    if fmt == "pascal_voc":
        return np.c_[b[:, :2], b[:, 2:] - b[:, :2]]
    if fmt == "albumentations":
        s = b * [W, H, W, H]
        return np.c_[s[:, :2], s[:, 2:] - s[:, :2]]
    if fmt == "yolo":
        s = b * [W, H, W, H]
        return np.c_[s[:, :2] - s[:, 2:] / 2, s[:, 2:]]
    return np.c_[b[:, :2] - b[:, 2:] / 2, b[:, 2:]]  # cxcywh


@pytest.fixture(scope="module")
def base():
    """One call with boxes, labels and instance masks (COCO boxes)."""
    masks = _scene_masks()
    out = _compose()(image=road_frame(), bboxes=BOXES, labels=[1, 2], masks=masks, camera_k=K)
    return masks, out


def test_instance_masks_stay_in_step_with_the_boxes(base):
    """n boxes and n masks in, m and m out: each new box is its mask's bounding box (within 1 px), the new masks do
    not overlap, and a scene mask loses exactly the pixels an inserted object now shows."""
    masks, out = base
    boxes, labels, got = np.asarray(out["bboxes"]), list(out["labels"]), np.asarray(out["masks"])
    assert len(boxes) == len(got) == len(labels)
    new = [i for i, lab in enumerate(labels) if lab == CONE]
    assert len(new) >= 2 and labels[: len(labels) - len(new)] == [1, 2]
    union = np.zeros((H, W), bool)
    for i in new:
        assert got[i].shape == (H, W)
        assert np.allclose(_mask_box(got[i]), boxes[i], atol=1.0), (boxes[i], _mask_box(got[i]))
        assert not (union & (got[i] > 0)).any()
        union |= got[i] > 0
    for i, lab in enumerate(labels[: len(labels) - len(new)]):
        before, after = masks[int(lab) - 1] > 0, got[i] > 0
        assert np.array_equal(after, before & ~union)
    assert (masks[1] > 0).sum() > (got[1] > 0).sum()  # the road object is partly hidden by the cones on it
    assert (got[1] > 0).sum() == (masks[1] > 0).sum() - ((masks[1] > 0) & union).sum()


@pytest.mark.parametrize("fmt", ["pascal_voc", "yolo", "albumentations", "cxcywh"])
def test_every_bbox_format_gives_the_same_boxes(base, fmt):
    """The scene's boxes given in ``fmt`` (converted by hand) give the COCO run's image and, converted back by hand,
    its boxes and labels."""
    _, want = base
    assert len(want["bboxes"]) >= len(BOXES) + 2  # objects were inserted
    out = _compose(fmt=fmt)(image=road_frame(), bboxes=_to(fmt, BOXES), labels=[1, 2], masks=_scene_masks(), camera_k=K)
    assert out["image"].tobytes() == want["image"].tobytes()
    assert list(out["labels"]) == list(want["labels"])
    assert np.allclose(_from(fmt, out["bboxes"]), np.asarray(want["bboxes"]), atol=1e-3)


def test_no_boxes_in_gives_boxes_and_masks_of_the_new_objects():
    out = _compose()(image=road_frame(), bboxes=[], labels=[], masks=np.zeros((0, H, W), np.uint8), camera_k=K)
    assert len(out["bboxes"]) == len(out["masks"]) == len(out["labels"]) >= 2
    assert set(out["labels"]) == {CONE}
    for m, b in zip(out["masks"], out["bboxes"]):
        assert np.allclose(_mask_box(m), b, atol=1.0)


def test_a_new_box_the_compose_drops_takes_its_mask_with_it():
    free = _compose(bbox_kw={})(image=road_frame(), bboxes=[], labels=[], masks=np.zeros((0, H, W)), camera_k=K)
    areas = sorted(w * h for _, _, w, h in free["bboxes"])
    assert len(areas) >= 2
    threshold = (areas[0] + areas[1]) / 2
    out = _compose(bbox_kw={"min_area": threshold})(
        image=road_frame(), bboxes=[], labels=[], masks=np.zeros((0, H, W)), camera_k=K
    )
    assert len(out["bboxes"]) == len(out["masks"]) == len(areas) - 1
    for m, b in zip(out["masks"], out["bboxes"]):
        assert b[2] * b[3] >= threshold and np.allclose(_mask_box(m), b, atol=1.0)


def test_semantic_mask_painted_where_the_new_objects_show_and_untouched_elsewhere():
    sem = np.zeros((H, W), np.uint8)
    sem[300:, :] = 1
    tf = _compose(mask_values={"traffic_cone": 3})
    out = tf(image=road_frame(), bboxes=[], labels=[], masks=np.zeros((0, H, W), np.uint8), mask=sem, camera_k=K)
    shown = np.any(np.asarray(out["masks"]) > 0, axis=0)
    assert shown.any() and out["mask"].shape == (H, W)
    assert np.array_equal(out["mask"][shown], np.full(shown.sum(), 3, np.uint8))
    assert np.array_equal(out["mask"][~shown], sem[~shown])


@pytest.mark.parametrize("remove", [True, False])
def test_keypoints_under_new_objects_are_invisible_ones(remove):
    """A keypoint on a pixel an inserted object shows (found from the same seed's masks) is removed with
    ``remove_invisible`` and kept without; one far from them is kept either way."""
    first = _compose()(image=road_frame(), bboxes=[], labels=[], masks=np.zeros((0, H, W), np.uint8), camera_k=K)
    shown = np.any(np.asarray(first["masks"]) > 0, axis=0)
    ys, xs = np.nonzero(shown)
    under, free = [float(xs[0]) + 0.5, float(ys[0]) + 0.5], [5.5, 5.5]
    assert not shown[5, 5]
    out = _compose(keypoints=A.KeypointParams(coord_format="xy", remove_invisible=remove))(
        image=road_frame(), bboxes=[], labels=[], keypoints=[under, free], camera_k=K
    )
    assert out["image"].tobytes() == first["image"].tobytes()
    want = [under, free] if not remove else [free]
    assert np.allclose(np.asarray(out["keypoints"]), want)


def test_same_seed_same_bytes_other_seed_other_insertion():
    a = _compose(seed=5)(image=road_frame(), bboxes=[], labels=[], camera_k=K)
    b = _compose(seed=5)(image=road_frame(), bboxes=[], labels=[], camera_k=K)
    c = _compose(seed=6)(image=road_frame(), bboxes=[], labels=[], camera_k=K)
    assert a["image"].tobytes() == b["image"].tobytes() and np.array_equal(a["bboxes"], b["bboxes"])
    assert a["image"].tobytes() != c["image"].tobytes()


@pytest.mark.parametrize("variants", [None, 2])
def test_replay_compose_record_is_json_and_replays_to_the_same_bytes(variants):
    sample = {"image": road_frame(), "bboxes": BOXES, "labels": ["car", "road"], "camera_k": K}
    c = A.ReplayCompose(
        [_insert(variants_per_image=variants, category_ids=None), A.HorizontalFlip(p=0.5)],
        bbox_params=A.BboxParams(coord_format="coco", label_fields=["labels"], min_visibility=0.2),
        seed=7,
    )
    out = c(**sample)
    assert len(out["bboxes"]) > 2
    saved = json.loads(json.dumps(out["replay"]))
    params = saved["transforms"][0]["params"]["params"]
    assert set(params) <= {"insertion", "shape", "bbox_type"} and params["insertion"]["placements"]
    again = A.ReplayCompose.replay(saved, **sample)
    assert again["image"].tobytes() == out["image"].tobytes()
    assert np.array_equal(np.asarray(again["bboxes"]), np.asarray(out["bboxes"]))
    assert list(again["labels"]) == list(out["labels"])


def test_save_applied_params_log_holds_the_record_and_from_applied_transforms_replays_it():
    """The log of ``save_applied_params`` (constructor arguments under AlbumentationsX), through JSON, builds with
    ``Compose.from_applied_transforms`` a pipeline that, under another seed, gives the logged call's bytes, boxes
    and labels: it replays the logged insertion instead of drawing one."""
    sample = {"image": road_frame(), "bboxes": BOXES, "labels": [1, 2], "camera_k": K}
    bbox = {"coord_format": "coco", "label_fields": ["labels"], "min_visibility": 0.2}
    c = A.Compose([_insert()], bbox_params=A.BboxParams(**bbox), save_applied_params=True, seed=4)
    out = c(**sample)
    assert len(out["bboxes"]) >= len(BOXES) + 2
    log = json.loads(json.dumps(out["applied_transforms"]))
    ((name, config),) = log
    assert name.endswith("InsertObjects") and config["insertion"]["placements"]
    other = _compose(seed=5)(**sample)
    assert other["image"].tobytes() != out["image"].tobytes()  # seed 5 draws another insertion
    again = A.Compose.from_applied_transforms(log, bbox_params=A.BboxParams(**bbox), seed=5)(**sample)
    assert again["image"].tobytes() == out["image"].tobytes()
    assert np.array_equal(np.asarray(again["bboxes"]), np.asarray(out["bboxes"]))
    assert list(again["labels"]) == list(out["labels"])
