import json

import numpy as np
from pycocotools import mask as mask_utils

from aias_augment.apply.annotate import annotate_object, box_visibility_under_cover, mask_box_xywh
from aias_augment.core.coco_io import CocoBuilder


def test_mask_box_pixel_edges():
    m = np.zeros((10, 10), bool)
    m[2:5, 3:9] = True
    assert mask_box_xywh(m) == (3.0, 2.0, 6.0, 3.0)
    assert mask_box_xywh(np.zeros((4, 4), bool)) is None


def test_rle_round_trip_and_visibility():
    amodal = np.zeros((20, 30), np.float32)
    amodal[5:15, 10:20] = 1
    vis = amodal.copy()
    vis[5:10] = 0
    ann = annotate_object("cone", amodal, vis)
    assert ann.visibility == 0.5 and ann.visible_box_xywh == (10.0, 10.0, 10.0, 5.0)
    rle = dict(ann.rle, counts=ann.rle["counts"].encode())
    assert np.array_equal(mask_utils.decode(rle).astype(bool), vis > 0.5)


def test_box_visibility_under_cover():
    cover = np.zeros((10, 10), np.float32)
    cover[:, :5] = 1
    v = box_visibility_under_cover(np.array([[0, 0, 10, 10], [5, 0, 10, 10], [0, 0, 0, 0]]), cover)
    assert np.allclose(v, [0.5, 1.0, 1.0])


def test_coco_file_is_valid_for_pycocotools(tmp_path):
    b = CocoBuilder()
    i = b.add_image("a.png", 30, 20)
    b.add_box(i, "cone", [1, 2, 3, 4], inserted=True)
    coco = b.write(tmp_path / "x.json")
    assert coco.getCatIds() == [1] and coco.loadAnns(coco.getAnnIds())[0]["bbox"] == [1, 2, 3, 4]
    assert json.loads((tmp_path / "x.json").read_text())["annotations"][0]["inserted"] is True


def test_rle_in_window_is_the_full_frame_rle():
    """encode_rle_in_window against pycocotools' encoding of the whole frame, for windows at the frame's corners and
    edges, masks that start or end with a covered pixel, empty and full windows."""
    from aias_augment.apply.annotate import encode_rle, encode_rle_in_window

    rng = np.random.default_rng(0)
    H, W = 37, 53
    cases = [(0, 0, 10, 12), (W - 9, H - 7, 9, 7), (5, 0, 20, H), (0, 3, W, 20), (0, 0, W, H), (17, 11, 1, 1)]
    for x0, y0, w, h in cases:
        for kind in ("random", "empty", "full", "corner"):
            m = {
                "random": rng.random((h, w)) > 0.5,
                "empty": np.zeros((h, w), bool),
                "full": np.ones((h, w), bool),
                "corner": np.pad(np.ones((1, 1), bool), ((0, h - 1), (0, w - 1))),
            }[kind]
            frame = np.zeros((H, W), bool)
            frame[y0 : y0 + h, x0 : x0 + w] = m
            assert encode_rle_in_window(m, x0, y0, (H, W)) == encode_rle(frame), (x0, y0, w, h, kind)


def test_annotate_in_window_is_annotate_object_of_the_frame():
    from aias_augment.apply.annotate import annotate_in_window

    rng = np.random.default_rng(1)
    a = (rng.random((20, 30)) > 0.3).astype(np.float32)
    v = a * (rng.random((20, 30)) > 0.4)
    win = (40, 25, 70, 45)
    A = np.zeros((60, 80), np.float32)
    V = np.zeros((60, 80), np.float32)
    A[25:45, 40:70], V[25:45, 40:70] = a, v
    assert annotate_in_window("cone", win, a, v, (60, 80)) == annotate_object("cone", A, V)


def test_box_visibility_under_a_window_cover_is_that_of_the_frame():
    """A cover given as a window at an origin: the same visibilities as the cover pasted into the whole frame
    (boxes inside, across and outside the window, and past the frame's edges)."""
    rng = np.random.default_rng(3)
    win = rng.random((30, 40)).astype(np.float32)
    frame = np.zeros((100, 120), np.float32)
    frame[50:80, 60:100] = win
    boxes = np.array(
        [
            [55, 45, 70, 60],
            [0, 0, 120, 100],
            [10, 10, 30, 30],
            [90, 75, 130, 110],
            [-5, -5, 62, 52],
            [61.5, 52.2, 61.7, 52.9],
        ]
    )
    np.testing.assert_allclose(
        box_visibility_under_cover(boxes, win, (60, 50), (100, 120)),
        box_visibility_under_cover(boxes, frame),
        atol=1e-12,
    )


def test_a_box_following_a_convention_has_its_margins_around_the_mask():
    from aias_augment.apply.annotate import follow_convention

    mask_box = (40.0, 30.0, 50.0, 100.0)
    margins = (0.1, 0.05, 0.08, 0.02)
    X, Y, W, H = follow_convention(mask_box, margins, (480, 640))
    got = [(40 - X) / W, (30 - Y) / H, (X + W - 90) / W, (Y + H - 130) / H]
    assert np.allclose(got, margins, atol=1e-12)
    assert follow_convention(mask_box, (0, 0, 0, 0), (480, 640)) is mask_box  # tight: the box itself
    assert follow_convention(None, margins, (480, 640)) is None
    X, Y, W, H = follow_convention((1.0, 2.0, 20.0, 40.0), margins, (480, 640))  # at the frame's corner: clipped
    assert X == 0.0 and Y == 0.0 and X + W > 21 and Y + H > 42
