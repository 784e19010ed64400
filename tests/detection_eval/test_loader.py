from __future__ import annotations

import numpy as np

from detection_eval.config import AugmentConfig
from detection_eval.data import load_yolo_dir, write_yolo_sample
from detection_eval.loader import TrainBatches, cache_dataset, cache_image, pad_to_square


def test_cache_maps_boxes_onto_content_with_reduced_jpeg_decode(tmp_path):
    image = np.full((600, 1000, 3), 30, np.uint8)
    image[200:400, 500:700] = 250                               # bright square, xyxy (500, 200, 700, 400)
    rec = write_yolo_sample(tmp_path, "big", image, np.array([[500.0, 200.0, 700.0, 400.0]]), np.array([0]))
    c = cache_image(rec, 128)                                    # decoded at 1/4 (250 x 150 >= 128) then resized
    assert c.image.shape == (77, 128, 3)                         # 600 * 0.128 = 76.8 -> 77
    x0, y0, x1, y1 = c.boxes_xyxy[0]
    assert np.allclose(c.boxes_xyxy[0], [64.0, 25.6, 89.6, 51.2])
    inner = c.image[int(y0) + 2:int(y1) - 1, int(x0) + 2:int(x1) - 1]
    assert inner.min() > 200
    square = pad_to_square(c.image, c.letterbox)
    lb_box = c.letterbox.boxes_to_letterbox(rec.boxes_xyxy)[0]
    assert square[int(lb_box[1]) + 2:int(lb_box[3]) - 1, int(lb_box[0]) + 2:int(lb_box[2]) - 1].min() > 200


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
    assert all(np.array_equal(x, c.image) for x, c in zip(before, cache))   # cache never mutated
    # every image appears once per epoch
    assert sorted(a.index_at(i) for i in range(len(cache))) == list(range(len(cache)))
