import pickle

import albumentations as A
import numpy as np
import pytest
import torch

from aias_augment import InsertObjects
from tests.aias_augment.pipeline.test_image import road_frame

K = [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]


def _compose(seed=137, **kw):
    return A.Compose(
        [InsertObjects(categories=["traffic_cone"], max_objects=2, p=1.0, preset="fast", **kw)],
        bbox_params=A.BboxParams(format="coco", label_fields=["category_ids"], min_visibility=0.2),
        seed=seed,
    )


def test_zero_boxes_with_label_fields_gets_inserted_boxes_and_labels():
    out = _compose()(image=road_frame(), bboxes=[], category_ids=[], camera_k=np.array(K))
    assert len(out["bboxes"]) >= 1 and len(out["bboxes"]) == len(out["category_ids"])
    assert set(out["category_ids"]) == {"traffic_cone"}
    for x, y, w, h in out["bboxes"]:
        assert 0 <= x and 0 <= y and x + w <= 640 + 1e-3 and y + h <= 480 + 1e-3 and w > 0 and h > 0


def test_numeric_ids_and_existing_boxes_kept():
    tf = _compose(category_ids={"traffic_cone": 7})
    out = tf(image=road_frame(), bboxes=[[5, 5, 30, 30]], category_ids=[3])
    assert out["category_ids"][0] == 3 and all(c == 7 for c in out["category_ids"][1:])
    assert len(out["category_ids"]) >= 2
    with pytest.raises(ValueError, match="category_ids"):
        _compose()(image=road_frame(), bboxes=[[5, 5, 30, 30]], category_ids=[3])


def test_same_seed_same_sample():
    a = _compose(seed=5)(image=road_frame(), bboxes=[], category_ids=[])
    b = _compose(seed=5)(image=road_frame(), bboxes=[], category_ids=[])
    assert np.array_equal(a["image"], b["image"]) and a["bboxes"] == b["bboxes"]


@pytest.mark.parametrize(
    "img",
    [
        road_frame()[..., 0],  # grey (H, W)
        np.dstack([road_frame(), np.full((480, 640), 200, np.uint8)]),  # RGBA: alpha kept
        road_frame().astype(np.float32) / 255.0,  # float in [0, 1]
    ],
)
def test_grey_rgba_float_inputs(img):
    out = _compose()(image=img, bboxes=[], category_ids=[])
    assert out["image"].shape == img.shape and out["image"].dtype == img.dtype
    if img.ndim == 3 and img.shape[2] == 4:
        assert np.array_equal(out["image"][..., 3], img[..., 3])


def test_odd_image_is_skipped_not_fatal():
    tf = _compose()
    tiny = np.zeros((3, 3, 3), np.uint8)
    out = tf(image=tiny, bboxes=[], category_ids=[], camera_k=np.full((3, 3), np.nan))
    assert np.array_equal(out["image"], tiny) and out["bboxes"] == []
    assert tf.transforms[0].skipped == 1


def test_bad_arguments_raise_at_construction():
    with pytest.raises(ValueError):
        InsertObjects(preset="nope")
    with pytest.raises(TypeError):
        InsertObjects(config_overrides={"not_a_field": 1})


class _Data(torch.utils.data.Dataset):
    def __init__(self, tf):
        self.tf = tf

    def __len__(self):
        return 4

    def __getitem__(self, i):
        out = self.tf(image=road_frame(), bboxes=[], category_ids=[])
        return torch.from_numpy(out["image"]), len(out["bboxes"])


def test_pickles_and_runs_in_dataloader_with_two_workers():
    tf = _compose()
    tf(image=road_frame(), bboxes=[], category_ids=[])  # after a call (renderer exists in this process)
    tf2 = pickle.loads(pickle.dumps(tf))
    # spawn: this process already holds an EGL context, which a forked child must not inherit.
    dl = torch.utils.data.DataLoader(_Data(tf2), batch_size=2, num_workers=2, multiprocessing_context="spawn")
    n = 0
    for imgs, counts in dl:
        assert imgs.shape == (2, 480, 640, 3)
        n += int(counts.sum())
    assert n >= 4


def test_scene_analysed_once_per_image_and_cache_never_changes_pixels(tmp_path):
    """The second call on the same image hits the transform's scene cache (in memory, then on disk for a new
    transform) and the pixels equal those of a transform that never saw the image."""
    img = road_frame()
    cold = _compose(seed=11, scene_cache=str(tmp_path))
    a = cold(image=img, bboxes=[], category_ids=[], camera_k=K)
    b = cold(image=img, bboxes=[], category_ids=[], camera_k=K)
    ins = cold.transforms[0]
    assert (ins._scene_cache.misses, ins._scene_cache.hits) == (1, 1)
    warm = _compose(seed=11, scene_cache=str(tmp_path))
    c = warm(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert warm.transforms[0]._scene_cache.disk_hits == 1 and warm.transforms[0]._scene_cache.misses == 0
    fresh = _compose(seed=11)(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert len(a["bboxes"]) > 0
    assert np.array_equal(a["image"], c["image"]) and np.array_equal(a["image"], fresh["image"])
    assert np.allclose(np.asarray(a["bboxes"]), np.asarray(fresh["bboxes"]))
    assert not np.array_equal(a["image"], b["image"])  # the second call is another sample, not a replay


def test_warm_analyses_beforehand_and_changes_no_output(tmp_path):
    """``warm`` puts each image's analysis in the scene cache (on disk: a new transform, as a DataLoader worker,
    reads it), draws nothing from the transform's generator, and the calls after it return the bytes of a transform
    that was never warmed."""
    img = road_frame()
    warmed = _compose(seed=11, scene_cache=str(tmp_path))
    ins = warmed.transforms[0]
    assert ins.warm([img, img], camera_ks=[K, K]) == {
        "images": 2,
        "analysed": 1,
        "already_cached": 1,
        "skipped": 0,
        "views_rendered": 0,
        "views_cached": 0,
        "variants_computed": 0,
        "variants_cached": 0,
        "boxes_refused": 0,
    }
    assert ins.counts.to_dict() == InsertObjects().counts.to_dict()  # no call counted
    a = warmed(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert ins._scene_cache.misses == 1 and ins._scene_cache.hits >= 2  # the call found warm's analysis
    worker = _compose(seed=11, scene_cache=str(tmp_path))
    worker(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert worker.transforms[0]._scene_cache.disk_hits == 1 and worker.transforms[0]._scene_cache.misses == 0
    fresh = _compose(seed=11)(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert np.array_equal(a["image"], fresh["image"])
    assert np.allclose(np.asarray(a["bboxes"]), np.asarray(fresh["bboxes"]))
    assert ins.warm([np.full((4, 4, 3), np.nan, np.float32)])["skipped"] == 1


def test_warm_with_view_plans_renders_views_the_calls_then_read(tmp_path):
    """``warm(..., view_plans=n)`` renders views into ``scene_cache/views``; a worker-like transform on the same
    folder reads views from there, and its output equals a transform's that has neither cache. (Views are kept for
    mesh assets: a procedural cone is a new mesh per object.)"""
    img = road_frame()
    mesh = {"config_overrides": {"asset_source": "default"}}
    warmed = _compose(seed=11, scene_cache=str(tmp_path), **mesh)
    got = warmed.transforms[0].warm([img], camera_ks=[K], view_plans=4)
    assert got["views_rendered"] >= 1 and got["analysed"] == 1
    assert warmed.transforms[0]._scene_cache.misses == 1  # the views' plans used the cached analysis
    assert any((tmp_path / "views").rglob("*.npz"))
    worker = _compose(seed=11, scene_cache=str(tmp_path), **mesh)
    a = worker(image=img, bboxes=[], category_ids=[], camera_k=K)
    fresh = _compose(seed=11, **mesh)(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert np.array_equal(a["image"], fresh["image"])
    assert np.allclose(np.asarray(a["bboxes"]), np.asarray(fresh["bboxes"]))


def test_warm_renders_no_view_for_ray_cast_cones(tmp_path):
    """The fast preset ray-casts its procedural cones at their pose in every call: ``warm(..., view_plans=n)``
    analyses the image and renders no view for them (no GL call: the renderer's entry point raises)."""
    import aias_augment.apply.render as render

    tf = _compose(seed=11, scene_cache=str(tmp_path))
    assert tf.transforms[0].config.render_method == "raycast"

    def no_gl(*a, **k):
        raise AssertionError("GL call while warming ray-cast cones")

    old, render._renderer = render._renderer, no_gl
    try:
        got = tf.transforms[0].warm([road_frame()], camera_ks=[K], view_plans=4)
    finally:
        render._renderer = old
    assert got["analysed"] == 1 and got["views_rendered"] == 0 and got["views_cached"] == 0


def test_scene_target_reaches_the_planner_and_a_bad_one_is_a_counted_skip():
    from aias_augment import SceneInputs

    mask = np.zeros((480, 640), bool)
    mask[260:, 420:] = True  # objects may stand only in the lower right
    tf = _compose(seed=3)
    out = tf(
        image=road_frame(), bboxes=[], category_ids=[], camera_k=np.array(K), scene=SceneInputs(placeable_mask=mask)
    )
    rec = tf.transforms[0].last_record
    assert out["bboxes"] and rec.placements
    assert all(p.contact_pixel[0] >= 419.5 and p.contact_pixel[1] >= 259.5 for p in rec.placements)
    bad = tf(image=road_frame(), bboxes=[], category_ids=[], scene=SceneInputs(placeable_mask=mask[:10]))
    assert np.array_equal(bad["image"], road_frame()) and bad["bboxes"] == []
    assert tf.transforms[0].skipped == 1


class _Boxes:
    """What ``_encode_new_boxes`` reads from a result: the new boxes (COCO xywh pixels) and their category names."""

    def __init__(self, xywh, labels):
        self.inserted_bboxes = np.asarray(xywh, np.float64).reshape(-1, 4)
        self.inserted_labels = list(labels)


def _attached(fmt, label_fields, ids=None, **bbox_kw):
    """An InsertObjects inside a Compose (so it has the Compose's bbox processor), and that processor."""
    t = InsertObjects(categories=["traffic_cone"], preset="fast", category_ids=ids)
    A.Compose([t], bbox_params=A.BboxParams(format=fmt, label_fields=label_fields, **bbox_kw))
    return t, t.get_processor("bboxes")


@pytest.mark.parametrize("fmt", ["coco", "pascal_voc", "yolo"])
@pytest.mark.parametrize(
    "ids,fields",
    [
        (None, ["labels"]),
        ({"traffic_cone": 7}, ["labels"]),
        ({"traffic_cone": 2.5}, ["labels", "extra"]),
        ({"traffic_cone": "c"}, ["l"]),
    ],
)
def test_new_boxes_encoded_as_the_compose_processor_encodes_them(fmt, ids, fields):
    """The new boxes' rows (our float32 round trip plus the label manager's codes) equal, byte for byte and dtype,
    what the Compose's processor makes of them with ``preprocess`` (run on a twin transform), call after call, and
    both leave their label managers in the same state. Boxes of random sizes and places, on edges and corners, in
    images of random sizes."""
    from aias_augment.adapters.transform import encode_boxes

    rng = np.random.default_rng(0)
    ours, proc = _attached(fmt, fields, ids)
    ref, ref_proc = _attached(fmt, fields, ids)
    for _ in range(60):
        h, w = (int(v) for v in rng.integers(8, 2000, 2))
        n = int(rng.integers(1, 4))
        x0, y0 = rng.uniform(0, w - 1, n), rng.uniform(0, h - 1, n)
        bw, bh = rng.uniform(1e-3, 1, n) * (w - x0), rng.uniform(1e-3, 1, n) * (h - y0)
        xywh = np.c_[x0, y0, bw, bh]
        if rng.random() < 0.3:  # integer pixel boxes touching the image's edges
            xywh = np.array([[0, 0, w, h], [w - 3, h - 5, 3, 5]], np.float64)[:n]
        res = _Boxes(xywh, ["traffic_cone"] * len(xywh))
        got = ours._encode_new_boxes(res, np.zeros((0, 4 + len(fields))), (h, w, 3))
        assert encode_boxes(res.inserted_bboxes, h, w, fmt) is not False  # the fast path was taken
        values = [ref._label_for(c, ref_proc, fields[0]) for c in res.inserted_labels]
        want = ref._preprocess_new_boxes(res, ref_proc, values, fields, h, w)
        assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes()
    for f in fields:
        a, b = proc.label_manager.metadata["bboxes"][f], ref_proc.label_manager.metadata["bboxes"][f]
        assert (a.is_numerical, a.input_type) == (b.is_numerical, b.input_type)
        assert (a.encoder is None) == (b.encoder is None)
        if a.encoder is not None:
            assert a.encoder.classes_ == b.encoder.classes_ and a.encoder.is_numerical == b.encoder.is_numerical


def test_new_box_labels_known_or_not_to_the_manager_get_its_codes():
    """Label strings the manager already codes (from the caller's boxes) keep their codes; a new one gets the next
    code, as ``process_field`` gives it, and the Compose decodes both."""
    tf = A.Compose(
        [InsertObjects(categories=["traffic_cone"], max_objects=2, p=1.0, preset="fast", variants_per_image=1)],
        bbox_params=A.BboxParams(format="coco", label_fields=["labels"]),
        seed=3,
    )
    out = tf(image=road_frame(), bboxes=[[5, 5, 30, 30]], labels=["car"], camera_k=K)
    assert out["labels"][0] == "car" and set(out["labels"][1:]) == {"traffic_cone"}
    enc = tf.processors["bboxes"].label_manager.metadata["bboxes"]["labels"].encoder
    assert enc.classes_ == {"car": 0, "traffic_cone": 1}
    again = tf(image=road_frame(), bboxes=[[5, 5, 30, 30]], labels=["truck"], camera_k=K)
    assert again["labels"][0] == "truck" and set(again["labels"][1:]) == {"traffic_cone"}
    assert enc.classes_ == {"car": 0, "traffic_cone": 1, "truck": 2}


def test_a_box_the_processor_must_check_goes_through_preprocess():
    """A box outside [0, 1] once normalised is not encoded by the fast path: the processor's own check decides
    (here: its error), as before."""
    from aias_augment.adapters.transform import encode_boxes

    t, _ = _attached("coco", ["labels"])
    res = _Boxes([[300.0, 10.0, 30.0, 20.0]], ["traffic_cone"])  # x_max 330 > width 320
    assert encode_boxes(res.inserted_bboxes, 240, 320, "coco") is False
    with pytest.raises(ValueError, match="x_max"):
        t._encode_new_boxes(res, np.zeros((0, 5)), (240, 320, 3))


@pytest.mark.parametrize("variants", [None, 2])
def test_existing_boxes_with_the_inserted_label_set_the_sizes_others_do_not(variants):
    """A caller's box carrying the label the inserted boxes get (numeric through ``category_ids``, or the category
    name) is the scene's own object of that kind and sets the sizes (the record says so); a box of another label
    does not. The variant cache keys the difference."""
    box = [300.0, 330.0, 30.0, 60.0]

    def record(labels, ids, field_values):
        tf = A.Compose(
            [
                InsertObjects(
                    categories=["traffic_cone"],
                    max_objects=1,
                    p=1.0,
                    preset="fast",
                    category_ids=ids,
                    variants_per_image=variants,
                )
            ],
            bbox_params=A.BboxParams(format="coco", label_fields=["labels"]),
            seed=3,
        )
        tf(image=road_frame(), bboxes=[box] * len(labels), labels=field_values(labels))
        rec = tf.transforms[0].last_record
        return getattr(rec, "record", rec).to_dict()

    numeric = {"traffic_cone": 3}
    assert "1 existing boxes of the inserted kind" in record([3], numeric, list)["modules"]["sizes"]
    assert "sizes" not in record([5], numeric, list)["modules"]
    assert "sizes" in record(["traffic_cone"], None, list)["modules"]
    assert "sizes" not in record(["car"], None, list)["modules"]
