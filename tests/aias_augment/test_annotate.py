import json

import numpy as np
from pycocotools import mask as mask_utils

from aias_augment.annotate import annotate_object, box_visibility_under_cover, mask_box_xywh
from aias_augment.coco_io import CocoBuilder


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
