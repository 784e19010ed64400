from __future__ import annotations

import numpy as np

from detection_eval.config import AugmentConfig
from detection_eval.data import load_yolo_dir, write_yolo_sample
from detection_eval.loader import TrainBatches, cache_dataset, cache_image, pad_to_square


def test_cache_maps_boxes_onto_content_with_reduced_jpeg_decode(tmp_path):
    image = np.full((600, 1000, 3), 30, np.uint8)
    image[200:400, 500:700] = 250  # bright square, xyxy (500, 200, 700, 400)
    rec = write_yolo_sample(tmp_path, "big", image, np.array([[500.0, 200.0, 700.0, 400.0]]), np.array([0]))
    c = cache_image(rec, 128)  # decoded at 1/4 (250 x 150 >= 128) then resized
    assert c.image.shape == (77, 128, 3)  # 600 * 0.128 = 76.8 -> 77
    x0, y0, x1, y1 = c.boxes_xyxy[0]
    assert np.allclose(c.boxes_xyxy[0], [64.0, 25.6, 89.6, 51.2])
    inner = c.image[int(y0) + 2 : int(y1) - 1, int(x0) + 2 : int(x1) - 1]
    assert inner.min() > 200
    square = pad_to_square(c.image, c.letterbox)
    lb_box = c.letterbox.boxes_to_letterbox(rec.boxes_xyxy)[0]
    assert square[int(lb_box[1]) + 2 : int(lb_box[3]) - 1, int(lb_box[0]) + 2 : int(lb_box[2]) - 1].min() > 200


def test_batches_are_deterministic_and_boxes_stay_inside(tiny_yolo_dir):
    cache = cache_dataset(load_yolo_dir(tiny_yolo_dir), 64)
    before = [c.image.copy() for c in cache]
    cfg = AugmentConfig(mosaic_prob=0.5)
    a = TrainBatches(cache, 64, 3, cfg, seed=5)
    b = TrainBatches(cache, 64, 3, cfg, seed=5)
    for it in range(4):
        (ia, ta), (ib, tb) = a.batch(it), b.batch(it)
        assert np.array_equal(ia.numpy(), ib.numpy()) and np.array_equal(ta.boxes_xyxy, tb.boxes_xyxy)
        for k in range(3):
            n = int(ta.num_gt[k])
            boxes = ta.boxes_xyxy[k, :n]
            assert (boxes >= 0).all() and (boxes <= 64).all()
            assert (ta.boxes_xyxy[k, n:] == 0).all()
    assert all(np.array_equal(x, c.image) for x, c in zip(before, cache))  # cache never mutated
    # every image appears once per epoch
    assert sorted(a.index_at(i) for i in range(len(cache))) == list(range(len(cache)))


def _fake_cache(n_obj, n_empty):
    from detection_eval.boxes import letterbox_params
    from detection_eval.loader import CachedImage

    lb = letterbox_params(8, 8, 32)
    img = np.zeros((8, 8, 3), np.uint8)
    obj = [CachedImage(img, np.array([[1.0, 1, 4, 4]]), np.array([0]), lb) for _ in range(n_obj)]
    return obj + [CachedImage(img, np.zeros((0, 4)), np.zeros(0, np.int64), lb) for _ in range(n_empty)]


def test_epoch_items_repeat_object_images_to_the_asked_share():
    from detection_eval.loader import epoch_items

    cache = _fake_cache(20, 199)  # TraCon thinned to 10 %: 20 cone images, 199 empty roads
    items = epoch_items(cache, 0.5)
    counts = np.bincount(items, minlength=len(cache))
    assert (counts[:20] == 10).all() and (counts[20:] == 1).all()  # round(0.5 * 199 / (0.5 * 20)) = 10
    share = counts[:20].sum() / counts.sum()
    assert abs(share - 0.5) < 0.01
    assert (epoch_items(cache, 0.0) == np.arange(len(cache))).all()  # off: every image once
    balanced = _fake_cache(150, 50)  # already 75 % with objects: nothing repeated
    assert (epoch_items(balanced, 0.5) == np.arange(200)).all()
    batches = TrainBatches(cache, 32, 8, AugmentConfig(), seed=1, object_image_fraction=0.5)
    seen = [batches.index_at(k) for k in range(len(items))]  # one epoch visits exactly the repeated items
    assert np.array_equal(np.bincount(seen, minlength=len(cache)), counts)


def test_synthetic_images_take_only_empty_slots_and_keep_the_real_sequence():
    real = _fake_cache(20, 199)
    synthetic = _fake_cache(200, 0)
    mask = np.r_[np.zeros(len(real), bool), np.ones(len(synthetic), bool)]
    plain = TrainBatches(real, 32, 8, AugmentConfig(), seed=3, object_image_fraction=0.5)
    mixed = TrainBatches(
        real + synthetic,
        32,
        8,
        AugmentConfig(),
        seed=3,
        object_image_fraction=0.5,
        synthetic_mask=mask,
        synthetic_fraction=0.25,
    )
    n = 3 * len(plain.epoch_items)
    a = np.array([plain.index_at(k) for k in range(n)])
    b = np.array([mixed.index_at(k) for k in range(n)])
    real_obj = a < 20
    assert np.array_equal(a[real_obj], b[real_obj])  # every real cone image at the same position
    changed = a != b
    assert (a[changed] >= 20).all() and (b[changed] >= len(real)).all()  # only empty slots, only by synthetic ones
    assert abs(changed.mean() - 0.25) < 0.03  # the asked share of all samples
    assert len(set(b[changed])) > 150  # spread over the pool
    with_empty = np.array([len(mixed.cache[i].labels) == 0 for i in b])
    assert with_empty.mean() > 0.15  # real empty roads still seen (no cone everywhere)
