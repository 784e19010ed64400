"""Insertion variants (adapters/variants.py, ``InsertObjects(variants_per_image=K)``): a variant is the full
pipeline's output for its own generator (the pasted window reproduces it byte for byte), a cached variant and a
computed one give the same bytes (memory, disk, a fresh transform, warm), an image shows at most K insertions, and
the key follows what the insertion reads."""

import json
import os
import pickle

import albumentations as A
import numpy as np
import pytest

from aias_augment import InsertObjects
from aias_augment.adapters.variants import (
    Variant,
    VariantCache,
    plain_image_key,
    variant_key,
    variant_key_prefix,
    variant_rng,
)
from aias_augment.pipeline.bounded import insert_bounded
from aias_augment.pipeline.image import load_preset
from tests.aias_augment.pipeline.test_image import road_frame

K = [[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]]
BOXES = [[20.0, 300.0, 40.0, 60.0]]  # an existing box (COCO xywh) the insertion must avoid / may cover


def _compose(seed=5, k=3, **kw):
    return A.Compose(
        [InsertObjects(categories=["traffic_cone"], max_objects=2, p=1.0, preset="fast", variants_per_image=k, **kw)],
        bbox_params=A.BboxParams(format="coco", label_fields=["labels"], min_visibility=0.2),
        seed=seed,
    )


def _call(tf, img, boxes=BOXES):
    return tf(image=img, bboxes=boxes, labels=["real"] * len(boxes), camera_k=K)


def test_variant_window_reproduces_the_full_insertion_byte_for_byte():
    """Variant j pasted on the image equals the pipeline's own output for variant j's generator (the window holds
    every changed pixel), with the same boxes."""
    img = road_frame()
    cfg = load_preset("fast", categories=("traffic_cone",), max_objects=2)
    boxes = np.asarray(BOXES)
    key = variant_key(img, camera_k=K, existing_xywh=boxes, prefix=variant_key_prefix(cfg))
    full = insert_bounded(img, boxes, [0], variant_rng(0, 1, key), cfg, intrinsics=K)
    v = Variant.from_result(img, full)
    y0, y1, x0, x1 = v.window
    assert (y1 - y0) * (x1 - x0) < img.shape[0] * img.shape[1] / 2  # a window, not the frame
    got = v.result(img, boxes, ["real"], min_visibility=0.0)
    assert np.array_equal(got.image, full.image)
    assert np.array_equal(got.inserted_bboxes, full.inserted_bboxes) and got.inserted_labels == full.inserted_labels
    assert np.array_equal(got.keep_existing, full.keep_existing)
    outside = np.ones(img.shape[:2], bool)
    outside[y0:y1, x0:x1] = False
    assert np.array_equal(full.image[outside], img[outside])  # nothing changed outside the window
    assert not np.shares_memory(got.image, img)


def test_at_most_k_insertions_per_image_and_cached_equals_computed(tmp_path):
    """Over 12 calls an image shows at most K = 2 different outputs (both of them); every output equals that of a
    transform that computed nothing before (same seed), one reading the variants from disk, and one warmed."""
    img = road_frame()
    a = _compose(k=2, scene_cache=str(tmp_path))
    outs = [_call(a, img) for _ in range(12)]
    distinct = {o["image"].tobytes() for o in outs}
    assert len(distinct) == 2
    va = a.transforms[0]._variants
    assert va.misses == 2 and va.hits == 10
    fresh = _compose(k=2)  # no cache folder, nothing computed
    reader = _compose(k=2, scene_cache=str(tmp_path))  # a DataLoader worker: reads the folder
    warmed = _compose(k=2)
    assert warmed.transforms[0].warm([img], camera_ks=[K], variants=True, bboxes=[BOXES])["variants_computed"] == 2
    for t in (fresh, reader, warmed):
        for o in outs:
            got = _call(t, img)
            assert np.array_equal(got["image"], o["image"])
            assert np.allclose(np.asarray(got["bboxes"]), np.asarray(o["bboxes"])) and got["labels"] == o["labels"]
    assert reader.transforms[0]._variants.disk_hits == 2 and reader.transforms[0]._variants.misses == 0
    assert warmed.transforms[0]._variants.misses == 2  # warm's own misses; the calls only hit


def test_key_follows_what_the_insertion_reads():
    img = road_frame()
    p = variant_key_prefix(load_preset("fast"))
    k0 = variant_key(img, camera_k=K, existing_xywh=np.asarray(BOXES), prefix=p)
    assert variant_key(img.copy(), camera_k=np.asarray(K), existing_xywh=np.asarray(BOXES), prefix=p) == k0
    img2 = img.copy()
    img2[0, 0, 0] ^= 1
    others = [
        variant_key(img2, camera_k=K, existing_xywh=np.asarray(BOXES), prefix=p),
        variant_key(img, camera_k=None, existing_xywh=np.asarray(BOXES), prefix=p),
        variant_key(img, camera_k=K, existing_xywh=np.asarray(BOXES) + 1, prefix=p),
        variant_key(
            img, camera_k=K, existing_xywh=np.asarray(BOXES), prefix=variant_key_prefix(load_preset("balanced"))
        ),
        variant_key(
            img, camera_k=K, existing_xywh=np.asarray(BOXES), prefix=variant_key_prefix(load_preset("fast"), seed=1)
        ),
    ]
    assert len(set(others + [k0])) == 6
    from aias_augment.core.scene_inputs import SceneInputs

    m = np.zeros(img.shape[:2], bool)
    m[300:, :] = True
    m2 = m.copy()
    m2[479, 639] = False  # one pixel of a large mask (a repr would elide it)
    ks = {variant_key(img, camera_k=K, scene=SceneInputs(placeable_mask=x), prefix=p) for x in (m, m2)}
    assert len(ks) == 2 and k0 not in ks


def test_boxes_through_the_compose_round_trip_find_warms_variant():
    """warm() gets raw COCO boxes; the call sees them after albumentations' normalise/denormalise: both must key
    (and insert) the same, or warming would be wasted."""
    img = road_frame()
    boxes = [[20.123456789, 300.3333333, 40.7777777, 60.1]]
    t = _compose(k=1)
    t.transforms[0].warm([img], camera_ks=[K], variants=True, bboxes=[boxes])
    _call(t, img, boxes)
    assert t.transforms[0]._variants.hits == 1 and t.transforms[0]._variants.misses == 1


@pytest.mark.parametrize("fmt", ["coco", "pascal_voc", "yolo"])
def test_warm_with_many_boxes_keys_as_every_call(fmt):
    """40 boxes with arbitrary float coordinates, passed to warm() and to the calls in the Compose's own format:
    the calls see them after albumentations' float32 conversion, which moves a coordinate by ~1e-5 px (enough to
    cross a 1e-3 px rounding step somewhere among 160 coordinates); warm must key them as the calls do, so every
    call finds the warmed variant."""
    rng = np.random.default_rng(11)
    img = road_frame()
    h, w = img.shape[:2]
    xy, wh = rng.uniform([0, 0], [w - 12, h - 12], (40, 2)), rng.uniform(2, 10, (40, 2))
    boxes = {
        "coco": np.c_[xy, wh],
        "pascal_voc": np.c_[xy, xy + wh],
        "yolo": np.c_[(xy + wh / 2) / [w, h], wh / [w, h]],
    }[fmt]
    tf = A.Compose(
        [InsertObjects(categories=["traffic_cone"], max_objects=1, p=1.0, preset="fast", variants_per_image=1)],
        bbox_params=A.BboxParams(format=fmt, label_fields=["labels"]),
        seed=5,
    )
    t = tf.transforms[0]
    assert t.warm([img], camera_ks=[K], variants=True, bboxes=[boxes])["variants_computed"] == 1
    for b in (boxes, boxes.tolist()):  # an array or lists (the Compose makes lists float32 first)
        out = tf(image=img, bboxes=b, labels=["real"] * len(boxes), camera_k=K)
        assert len(out["bboxes"]) >= 1
    assert t._variants.hits == 2 and t._variants.misses == 1  # warm's miss; both calls hit


def test_warm_counts_boxes_the_compose_refuses_and_goes_on(caplog):
    """An image whose boxes the Compose's processor refuses (x_max < x_min) gets no variants, is counted and logged;
    the next image is warmed."""
    img = road_frame()
    t = _compose(k=1)
    with caplog.at_level("WARNING"):
        out = t.transforms[0].warm([img, img], camera_ks=[K, K], variants=True, bboxes=[[[50, 50, -5, 5]], BOXES])
    assert out["boxes_refused"] == 1 and out["variants_computed"] == 1
    assert "boxes are refused" in caplog.text
    with pytest.raises(ValueError):  # the call refuses them too
        _call(t, img, [[50, 50, -5, 5]])


def test_min_visibility_decided_per_call_from_the_stored_visibility():
    img = road_frame()
    cfg = load_preset("fast", categories=("traffic_cone",), max_objects=2)
    full = insert_bounded(img, np.asarray(BOXES), [0], np.random.default_rng(3), cfg, intrinsics=K)
    v = Variant.from_result(img, full)
    vis = float(v.existing_visibility[0])
    assert v.result(img, np.asarray(BOXES), ["real"], min_visibility=vis).keep_existing[0]
    assert not v.result(img, np.asarray(BOXES), ["real"], min_visibility=vis + 1e-6).keep_existing[0]
    with pytest.raises(ValueError, match="existing boxes"):
        v.result(img, np.zeros((0, 4)), [])


def test_bad_arguments_pickling_and_cache_bounds(tmp_path):
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="variants_per_image"):
            InsertObjects(variants_per_image=bad)
    with pytest.raises(ValueError, match="variants_per_image"):
        InsertObjects().warm([road_frame()], variants=True)
    t = _compose(k=2)
    _call(t, road_frame())
    t2 = pickle.loads(pickle.dumps(t))  # spawn workers get an empty LRU and no hash object
    assert len(t2.transforms[0]._variants) == 0 and t2.transforms[0]._variant_prefix is None
    assert np.array_equal(_call(t2, road_frame())["image"], _call(_compose(k=2), road_frame())["image"])
    c = VariantCache(max_bytes=5000)
    small = Variant((0, 1, 0, 1), np.zeros((1, 1, 3), np.uint8), np.zeros((0, 4)), (), np.zeros(0), None)
    for j in range(5):
        c.put("ab" * 16, j, small)
    assert len(c) == 5000 // small.nbytes and c.nbytes <= 5000
    (tmp_path / "ab").mkdir()
    (tmp_path / "ab" / f"{'ab' * 16}_0.variant").write_bytes(b"not a variant")
    assert VariantCache(directory=tmp_path).get("ab" * 16, 0) is None  # damaged file: recomputed, not fatal


_PROCESS_SCRIPT = r"""
import hashlib, sys
import albumentations as A
import numpy as np
from aias_augment import InsertObjects
from tests.aias_augment.pipeline.test_image import road_frame
img = road_frame()
t = InsertObjects(categories=["traffic_cone"], max_objects=2, p=1.0, preset="fast", variants_per_image=3)
if sys.argv[1] == "warm":   # another history: every variant made beforehand, in another order than drawn
    t.warm([img], variants=True)
tf = A.Compose([t], bbox_params=A.BboxParams(format="coco", label_fields=["l"]), seed=9)
print(*[hashlib.sha256(tf(image=img, bboxes=np.zeros((0, 4)), l=[])["image"]).hexdigest()[:16] for _ in range(6)])
"""


@pytest.mark.slow
def test_same_variants_across_processes_hash_seeds_and_histories():
    """Two fresh interpreters (PYTHONHASHSEED 1 and 2), one computing variants as drawn and one warmed first: the
    same six outputs, byte for byte."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    outs = []
    for hash_seed, history in (("1", "cold"), ("2", "warm")):
        r = subprocess.run(
            [sys.executable, "-c", _PROCESS_SCRIPT, history],
            env={**os.environ, "PYTHONHASHSEED": hash_seed},
            capture_output=True,
            text=True,
            timeout=600,
            cwd=Path(__file__).resolve().parents[3],
        )
        assert r.returncode == 0, r.stderr[-2000:]
        outs.append(r.stdout.split())
    assert len(outs[0]) == 6 and outs[0] == outs[1]
    assert 1 < len(set(outs[0])) <= 3  # more than one variant drawn, never more than K


_WORKER_SCRIPT = r"""
import hashlib, pickle, sys
import numpy as np
tf = pickle.load(open(sys.argv[1], "rb"))          # as a spawned DataLoader worker receives the transform
img = np.load(sys.argv[2])
outs = [hashlib.sha256(tf(image=img, bboxes=np.zeros((0, 4)), l=[])["image"]).hexdigest()[:16] for _ in range(6)]
print(*outs, "pyrender" in sys.modules, "trimesh" in sys.modules, tf.transforms[0]._variants.disk_hits)
"""


def test_a_worker_pasting_warmed_variants_never_imports_the_renderer(tmp_path):
    """A fresh interpreter given the pickled Compose (as a spawned DataLoader worker) and warmed variants on disk:
    its outputs are the parent's, byte for byte, and it never imports pyrender or trimesh (~0.4 s that a
    non-persistent worker would pay every epoch)."""
    import hashlib
    import os
    import subprocess
    import sys
    from pathlib import Path

    img = road_frame()
    tf = A.Compose(
        [
            InsertObjects(
                categories=["traffic_cone"],
                max_objects=2,
                p=1.0,
                preset="fast",
                variants_per_image=2,
                scene_cache=str(tmp_path / "cache"),
            )
        ],
        bbox_params=A.BboxParams(format="coco", label_fields=["l"]),
        seed=9,
    )
    assert tf.transforms[0].warm([img], variants=True)["variants_computed"] == 2
    (tmp_path / "tf.pkl").write_bytes(pickle.dumps(tf))
    np.save(tmp_path / "img.npy", img)
    want = [hashlib.sha256(tf(image=img, bboxes=np.zeros((0, 4)), l=[])["image"]).hexdigest()[:16] for _ in range(6)]
    r = subprocess.run(
        [sys.executable, "-c", _WORKER_SCRIPT, str(tmp_path / "tf.pkl"), str(tmp_path / "img.npy")],
        env={**os.environ, "NO_ALBUMENTATIONS_UPDATE": "1"},
        capture_output=True,
        text=True,
        timeout=300,
        cwd=Path(__file__).resolve().parents[3],
    )
    assert r.returncode == 0, r.stderr[-2000:]
    *outs, has_pyrender, has_trimesh, disk_hits = r.stdout.split()
    assert outs == want and len(set(outs)) == 2
    assert (has_pyrender, has_trimesh) == ("False", "False")
    assert disk_hits == "2"


def test_plain_image_key_is_the_variant_key_of_the_documented_stream():
    import xxhash

    img = road_frame()
    p = variant_key_prefix(load_preset("fast"), seed=3)
    from aias_augment.adapters.variants import VARIANT_FORMAT

    version = __import__("aias_augment").__version__
    stream = xxhash.xxh3_128(f"aias-variant v{VARIANT_FORMAT} package {version} seed 3".encode())
    for name, v in (("cfg", repr(load_preset("fast"))), ("assets", repr([]))):
        stream.update(name.encode())
        from aias_augment.analyse.analysis import hash_value

        hash_value(stream, v)
    stream.update(b"image:uint8(480, 640, 3)" + img.tobytes() + b"K:Nonedepth:Noneboxes:None")
    assert plain_image_key(img, p) == variant_key(img, prefix=p) == stream.hexdigest()
    assert variant_key(img, existing_xywh=np.zeros((0, 4)), prefix=p) == stream.hexdigest()


def test_the_training_loop_path_returns_what_the_general_path_returns(tmp_path):
    """A uint8 RGB image without boxes or targets takes the short path (key, lookup, paste, prebuilt boxes); the
    same pixels as a non-contiguous view take the general one: call by call the same image bytes, boxes, labels,
    counts and records, computed and read back from the folder alike."""
    img = road_frame()
    view = np.zeros((480, 640, 4), np.uint8)
    view[..., :3] = img
    view = view[..., :3]
    assert not view.flags.c_contiguous

    def compose(**kw):
        return A.Compose(
            [
                InsertObjects(
                    categories=["traffic_cone"], max_objects=3, p=0.7, preset="fast", variants_per_image=3, **kw
                )
            ],
            bbox_params=A.BboxParams(format="coco", label_fields=["labels"]),
            seed=21,
        )

    short, general, reader = compose(scene_cache=str(tmp_path)), compose(), compose(scene_cache=str(tmp_path))
    for _ in range(10):
        a = short(image=img, bboxes=[], labels=[])
        b = general(image=view, bboxes=[], labels=[])
        c = reader(image=img, bboxes=[], labels=[])
        for o in (b, c):
            assert np.array_equal(a["image"], o["image"]) and a["labels"] == o["labels"]
            assert np.asarray(a["bboxes"]).tobytes() == np.asarray(o["bboxes"]).tobytes()
        ra, rb = short.transforms[0].last_record, general.transforms[0].last_record
        assert (ra is None) == (rb is None) and (ra is None or ra.to_dict() == rb.to_dict())
    assert short.transforms[0].counts.to_dict() == general.transforms[0].counts.to_dict()
    assert reader.transforms[0]._variants.disk_hits >= 1 and reader.transforms[0]._variants.misses == 0


def test_variant_file_round_trip_keeps_everything_and_reads_the_record_when_asked(tmp_path):
    img = road_frame()
    cfg = load_preset("fast", categories=("traffic_cone",), max_objects=2)
    full = insert_bounded(img, np.asarray(BOXES), [0], np.random.default_rng(3), cfg, intrinsics=K)
    v = Variant.from_result(img, full)
    v.encoded[(480, 640, "coco")] = np.ones((len(v.inserted_labels), 4), np.float32)
    v.encoded[(480, 640, "yolo")] = False
    c = VariantCache(directory=tmp_path)
    c.put("cd" * 16, 2, v)
    back = VariantCache(directory=tmp_path).get("cd" * 16, 2)
    assert back is not None and back._record is None  # the record stays bytes until read
    assert back.window == v.window and back.inserted_labels == v.inserted_labels
    for name in ("pixels", "inserted_bboxes", "existing_visibility"):
        a, b = getattr(v, name), getattr(back, name)
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b) and not b.flags.writeable
    assert back.encoded[(480, 640, "yolo")] is False
    assert back.encoded[(480, 640, "coco")] == np.ones((len(v.inserted_labels), 4), np.float32).tobytes()
    assert back.record.to_dict() == full.record.to_dict()
    assert json.dumps(back.record.to_dict()) == json.dumps(full.record.to_dict())  # floats to the last bit
    assert np.array_equal(back.result(img, np.asarray(BOXES), ["real"]).image, full.image)
    assert VariantCache(directory=tmp_path).get("cd" * 16, 1) is None  # another index: not there
    again = pickle.loads(pickle.dumps(v))  # between processes: the same plain bytes
    assert np.array_equal(again.pixels, v.pixels) and again.record.to_dict() == full.record.to_dict()


class _Planted:
    """A pickle that creates ``marker`` when unpickled (what a planted cache file could run)."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (os.system, (f"touch '{self.marker}'",))


def _plain_call(tf, img):
    return tf(image=img, bboxes=np.zeros((0, 4)), labels=[])


def test_a_planted_pickle_in_the_variant_folder_runs_nothing_and_the_variant_is_computed(tmp_path):
    """A pickle that would run a command, planted where a lookup reads (and at the older ``.pkl`` name): the call
    unpickles nothing, counts the file, computes the variant (the bytes of a transform without a folder) and
    writes it over the planted file."""
    img = road_frame()
    tf = _compose(k=1, scene_cache=str(tmp_path))
    t = tf.transforms[0]
    key = plain_image_key(img, t._key_prefix())
    folder = tmp_path / "variants" / key[:2]
    folder.mkdir(parents=True)
    markers = [tmp_path / "ran_variant", tmp_path / "ran_pkl"]
    (folder / f"{key}_0.variant").write_bytes(pickle.dumps(_Planted(markers[0])))
    (folder / f"{key}_0.pkl").write_bytes(pickle.dumps(_Planted(markers[1])))
    got = _plain_call(tf, img)
    assert not any(m.exists() for m in markers)
    assert t._variants.unreadable == 1 and t._variants.misses == 1 and t._variants.disk_hits == 0
    want = _plain_call(_compose(k=1), img)
    assert np.array_equal(got["image"], want["image"]) and got["labels"] == want["labels"]
    assert np.asarray(got["bboxes"]).tobytes() == np.asarray(want["bboxes"]).tobytes()
    assert VariantCache(directory=tmp_path / "variants").get(key, 0) is not None  # overwritten with the variant


@pytest.mark.parametrize("damage", ["truncated", "pixel flipped", "header garbled", "empty"])
def test_a_damaged_variant_file_is_counted_and_computed_again(tmp_path, damage, caplog):
    """A variant file cut short, with one pixel byte flipped, with a header that is not JSON, or empty: never
    pasted; the reader logs and counts it and computes the variant (the same bytes as a transform without a
    folder)."""
    img = road_frame()
    _plain_call(_compose(k=1, scene_cache=str(tmp_path)), img)
    [path] = (tmp_path / "variants").glob("*/*.variant")
    data = bytearray(path.read_bytes())
    if damage == "truncated":
        data = data[:-100]
    elif damage == "pixel flipped":
        n = int.from_bytes(data[13:17], "little")  # after the magic: the header's length, then the pixels
        data[17 + n] ^= 1
    elif damage == "header garbled":
        data[20:24] = b"\xff\xfe{["
    else:
        data = b""
    path.write_bytes(bytes(data))
    reader = _compose(k=1, scene_cache=str(tmp_path))
    with caplog.at_level("WARNING"):
        got = _plain_call(reader, img)
    vc = reader.transforms[0]._variants
    assert vc.unreadable == 1 and vc.misses == 1 and vc.disk_hits == 0
    assert "not used" in caplog.text
    assert np.array_equal(got["image"], _plain_call(_compose(k=1), img)["image"])
