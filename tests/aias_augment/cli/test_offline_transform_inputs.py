"""Issue 16, the transform's rows: every odd input to ``InsertObjects`` is converted explicitly or left unchanged and
counted by reason (``transform.counts``); bad constructor arguments fail at construction; huge images stay bounded.

Calls that render use the real renderer on the 640x480 test image (fast preset)."""

import json
import logging
import subprocess
import sys
import textwrap

import albumentations as A
import numpy as np
import pytest
import trimesh

from aias_augment import InsertObjects
from aias_augment.adapters.boundary import InputError, SampleSkip, image_for_insertion
from aias_augment.assets.asset import DEFAULT_ASSETS, AssetError, PathAssets
from aias_augment.core.config import data_root
from aias_augment.plan.placement import PlacementConfig
from tests.aias_augment.pipeline.test_image import road_frame

needs_data = pytest.mark.skipif(
    not (data_root() / DEFAULT_ASSETS["traffic_cone"][0]).exists(), reason="shared data not present"
)
K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])


def _compose(seed=3, **kw):
    kw = {"categories": ["traffic_cone"], "max_objects": 1, "min_objects": 1, "p": 1.0, "preset": "fast", **kw}
    tf = InsertObjects(**kw)
    return A.Compose([tf], bbox_params=A.BboxParams(format="coco", label_fields=["category_ids"]), seed=seed), tf


# ---------------------------------------------------------------------------- the image boundary (no rendering)
@pytest.mark.parametrize(
    "dtype,scale",
    [(np.uint16, 257), (np.float32, 1 / 255), (np.float16, 1 / 255), (np.float64, 1 / 255), (np.uint8, 1)],
)
@pytest.mark.parametrize("channels", [None, 1, 3, 4])
def test_image_for_insertion_converts_explicitly_and_restores_untouched_pixels_bit_for_bit(dtype, scale, channels):
    base = road_frame()[:40, :50]
    img8 = (
        base[..., 0]
        if channels is None
        else (base[..., :1] if channels == 1 else base if channels == 3 else np.dstack([base, base[..., :1]]))
    )
    img = (img8.astype(np.float64) * scale).astype(dtype)
    rgb, restore, conversion = image_for_insertion(img)
    assert rgb.shape == (40, 50, 3) and rgb.dtype == np.uint8
    assert (conversion is None) == (dtype == np.uint8)
    ref = np.repeat(img8[..., None], 3, 2) if channels in (None, 1) else img8[..., :3]
    assert np.array_equal(rgb, ref.reshape(40, 50, 3))  # the 8-bit values are the ones the input encodes
    assert np.array_equal(restore(rgb), img) and restore(rgb).dtype == img.dtype  # nothing changed: same bits
    out = rgb.copy()
    out[10:20, 10:20] = 255  # "inserted" pixels
    back = restore(out)
    assert back.shape == img.shape and back.dtype == img.dtype
    untouched = np.ones((40, 50), bool)
    untouched[10:20, 10:20] = False
    assert np.array_equal(back[untouched], img[untouched])
    top = {np.uint16: 65535, np.uint8: 255}.get(dtype, 1.0)
    px = back[15, 15] if back.ndim == 2 else back[15, 15, : min(3, back.shape[2])]
    assert np.all(px == top)
    if channels == 4:
        assert np.array_equal(back[..., 3], img[..., 3])  # alpha kept


@pytest.mark.parametrize(
    "img,kind",
    [
        (np.full((8, 8, 3), np.nan, np.float32), "float image with NaN/Inf"),
        (np.full((8, 8, 3), np.inf, np.float16), "float image with NaN/Inf"),
        (np.full((8, 8, 3), 200.0, np.float32), "float image outside [0, 1]"),  # a [0, 255] float image
        (np.full((8, 8, 3), -0.1, np.float32), "float image outside [0, 1]"),
        (np.zeros((8, 8, 3), np.int32), "unsupported dtype"),
        (np.zeros((8, 8, 2), np.uint8), "unsupported image shape"),
        (np.zeros((8,), np.uint8), "unsupported image shape"),
        (np.zeros((0, 8, 3), np.uint8), "empty image"),
    ],
)
def test_image_for_insertion_refuses_with_a_named_reason(img, kind):
    with pytest.raises(SampleSkip) as e:
        image_for_insertion(img)
    assert e.value.kind == kind


# -------------------------------------------------------------------------------------------- construction
def test_unknown_category_and_missing_mesh_fail_at_construction(tmp_path):
    with pytest.raises(InputError, match=r"unknown categories \['unicorn'\]"):
        InsertObjects(categories=["traffic_cone", "unicorn"])
    with pytest.raises(AssetError, match="do not exist"):
        InsertObjects(categories=["person"], assets={"person": [str(tmp_path / "nope.obj")]})
    with pytest.raises(ValueError, match="min_objects"):
        InsertObjects(min_objects=3, max_objects=1)


def _pedestrian_in_cm(tmp_path, suffix):
    mesh = trimesh.creation.box(extents=(45.0, 187.0, 30.0))  # a pedestrian-sized box in centimetres (y up)
    path = tmp_path / f"pedestrian{suffix}"
    mesh.export(path)
    return str(path)


@pytest.mark.parametrize("suffix", [".obj", ".glb"])
def test_mesh_in_centimetres_is_rescaled_with_a_warning(tmp_path, caplog, suffix):
    path = _pedestrian_in_cm(tmp_path, suffix)
    InsertObjects(categories=["person"], assets={"person": [path]})  # a user's own category: accepted
    with caplog.at_level(logging.WARNING):
        asset = PathAssets({"person": [path]}).sample("person", np.random.default_rng(0))
    assert abs(asset.height_m - 1.87) < 0.02
    assert "centimetres" in caplog.text and "1.87 m" in caplog.text


@needs_data
def test_users_pedestrian_in_centimetres_is_inserted_at_its_real_size(tmp_path):
    """The issue's row: loaded as 187 m tall, every placement rejected, nothing counted. Now rescaled and placed."""
    compose, tf = _compose(seed=2, categories=["person"], assets={"person": [_pedestrian_in_cm(tmp_path, ".glb")]})
    out = compose(image=road_frame(), bboxes=[], category_ids=[], camera_k=K)
    assert tf.counts.to_dict()["inserted"] == 1 and out["category_ids"] == ["person"]
    placement = tf.last_record.placements[0]
    assert 1.0 < placement.height_m < 2.5


# ------------------------------------------------------------------------------------- calls (real renderer)
@needs_data
def test_odd_samples_never_stop_a_loop_and_are_counted_by_reason():
    compose, tf = _compose()
    img = road_frame()
    odd = [
        dict(image=np.full(img.shape, np.nan, np.float32)),
        dict(image=img.astype(np.float32)),  # [0, 255] float
        dict(image=img, depth=np.full(img.shape[:2], 10.0, np.float32)),  # depth without camera_k
        dict(image=img, depth=np.ones((4, 4), np.float32), camera_k=K),  # depth of another size
        dict(image=img, camera_k=np.eye(2)),
        dict(image=np.zeros((3, 3, 3), np.uint8), camera_k=np.full((3, 3), np.nan)),  # fails inside the pipeline
    ]
    for sample in odd:
        box = [[5, 5, 20, 20]] if sample["image"].shape[0] > 25 else [[0, 0, 2, 2]]
        out = compose(**sample, bboxes=box, category_ids=["sign"])
        assert np.allclose(out["bboxes"], box) and out["category_ids"] == ["sign"]
        assert np.array_equal(out["image"], sample["image"], equal_nan=True)  # left unchanged
    c = tf.counts.to_dict()
    assert c["calls"] == len(odd) and tf.skipped == len(odd) and c["inserted"] == 0
    assert c["skipped"]["float image with NaN/Inf"] == 1 and c["skipped"]["float image outside [0, 1]"] == 1
    assert c["skipped"]["depth without camera_k"] == 1 and c["skipped"]["depth shape mismatch"] == 1
    assert c["skipped"]["camera_k not 3x3"] == 1
    assert sum(c["skipped"].values()) == len(odd)
    json.dumps(c)  # plain JSON: a training script can log it per epoch


@needs_data
@pytest.mark.parametrize("dtype", [np.uint16, np.float32])
def test_16bit_and_float_images_get_objects_and_keep_their_dtype(dtype):
    compose, tf = _compose(seed=5)
    img = road_frame().astype(np.uint16) * 257 if dtype == np.uint16 else road_frame().astype(np.float32) / 255
    out = compose(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert out["image"].dtype == dtype and out["image"].shape == img.shape
    changed = np.any(out["image"] != img, axis=2)
    assert changed.any() and len(out["bboxes"]) == 1
    x, y, w, h = out["bboxes"][0]  # every changed pixel is near the object (or its shadow); the rest untouched
    assert changed[int(y) : int(y + h), int(x) : int(x + w)].any()
    assert tf.counts.converted and tf.counts.inserted == 1 and tf.counts.objects == 1


@needs_data
def test_a_call_that_inserts_nothing_is_counted_with_its_reason():
    impossible = PlacementConfig(max_tries=3, min_box_height_px=10_000.0)  # no object can be that large
    compose, tf = _compose(config_overrides={"placement_cfg": impossible})
    img = road_frame()
    out = compose(image=img, bboxes=[], category_ids=[], camera_k=K)
    assert np.array_equal(out["image"], img) and out["bboxes"] == []
    c = tf.counts.to_dict()
    assert c["calls"] == 1 and c["inserted"] == 0 and tf.skipped == 0
    ((reason, n),) = c["nothing_inserted"].items()
    assert n == 1 and "placements rejected" in reason and "too small in the image" in reason


# ----------------------------------------------------------------------------------------- bounded size
_HUGE = textwrap.dedent("""
    import json, resource, sys, time
    import numpy as np, albumentations as A
    from aias_augment import InsertObjects
    rng = np.random.default_rng(0)
    img = np.full((4000, 6000, 3), 110, np.uint8)
    img[:2000] = (150, 180, 220)
    img = np.clip(img + rng.integers(-8, 8, img.shape, dtype=np.int16), 0, 255).astype(np.uint8)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tf = InsertObjects(categories=["traffic_cone"], min_objects=1, max_objects=1, preset="fast", p=1.0)
    c = A.Compose([tf], bbox_params=A.BboxParams(format="coco", label_fields=["l"]), seed=1)
    t = time.perf_counter()
    out = c(image=img, bboxes=[], l=[])
    s = time.perf_counter() - t
    rec = tf.last_record
    print(json.dumps({"seconds": s, "base_kb": base, "peak_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                      "shape": list(out["image"].shape), "boxes": [list(map(float, b)) for b in out["bboxes"]],
                      "working": rec.modules.get("working_resolution") if rec else None,
                      "counts": tf.counts.to_dict()}))
""")


@needs_data
def test_a_6000x4000_frame_stays_bounded():
    """Peak RSS of one call in a fresh process (the real numbers: benchmarks/bench_offline_transform_huge.py)."""
    r = subprocess.run([sys.executable, "-c", _HUGE], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    m = json.loads(r.stdout.strip().splitlines()[-1])
    assert m["shape"] == [4000, 6000, 3] and m["working"].startswith("analysis and plan at 1732x1154")
    assert m["counts"]["calls"] == 1 and not m["counts"]["skipped"]
    for x, y, w, h in m["boxes"]:
        assert 0 <= x and 0 <= y and w > 0 and h > 0 and x + w <= 6000 and y + h <= 4000
    # Generous: the frame itself is 72 MB; before, one call took 5.7 GB and 204 s.
    assert (m["peak_kb"] - m["base_kb"]) / 1e6 < 2.5 and m["seconds"] < 120
