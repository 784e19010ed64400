from __future__ import annotations

import json

import numpy as np
import pytest

from detection_eval.data import (
    coco_gt_dict,
    format_yolo_labels,
    load_coco_json,
    load_dataset,
    load_yolo_dir,
    parse_yolo_label_file,
    write_classes,
    write_yolo_sample,
)


def test_yolo_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    written = []
    for i, (h, w) in enumerate([(120, 200), (333, 77), (64, 64)]):
        image = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
        n = i  # 0, 1, 2 boxes: includes an image without objects
        x0 = rng.uniform(0, w / 2, n)
        y0 = rng.uniform(0, h / 2, n)
        boxes = np.c_[x0, y0, x0 + rng.uniform(2, w / 2, n), y0 + rng.uniform(2, h / 2, n)]
        written.append(write_yolo_sample(tmp_path, f"s{i}", image, boxes, np.arange(n) % 2))
    write_classes(tmp_path, ("cone", "barrel"))
    ds = load_yolo_dir(tmp_path)
    assert ds.category_names == ("cone", "barrel")
    assert [r.image_path for r in ds.records] == sorted(r.image_path for r in written)
    by_path = {r.image_path: r for r in ds.records}
    for r in written:
        back = by_path[r.image_path]
        assert (back.width, back.height) == (r.width, r.height)
        # 6 decimals of a normalised coordinate: error <= 1e-6 * side (+ float rounding)
        assert np.allclose(back.boxes_xyxy, r.boxes_xyxy, atol=1e-6 * max(r.width, r.height) + 1e-9)
        assert back.labels.tolist() == r.labels.tolist()


def test_yolo_split_layout_and_missing_label_is_counted(tmp_path):
    img = np.zeros((10, 10, 3), np.uint8)
    write_yolo_sample(tmp_path / "x", "a", img, np.array([[1.0, 1.0, 5.0, 5.0]]), np.array([0]))
    write_yolo_sample(tmp_path / "x", "b", img, np.zeros((0, 4)), np.array([], np.int64))
    (tmp_path / "ds" / "images" / "val").mkdir(parents=True)
    (tmp_path / "ds" / "labels" / "val").mkdir(parents=True)
    for stem in ("a", "b"):
        (tmp_path / "x" / "images" / f"{stem}.jpg").rename(tmp_path / "ds" / "images" / "val" / f"{stem}.jpg")
    (tmp_path / "x" / "labels" / "a.txt").rename(tmp_path / "ds" / "labels" / "val" / "a.txt")
    ds = load_yolo_dir(tmp_path / "ds", split="val", names=("cone",))
    assert len(ds) == 1 and ds.skipped == {"no label file": 1}
    same = load_dataset(tmp_path / "ds" / "images" / "val", names=("cone",))  # image folder given directly
    assert len(same) == 1
    with pytest.raises(ValueError, match="split"):
        load_yolo_dir(tmp_path / "ds")


def test_bad_yolo_line_names_file_and_line(tmp_path):
    p = tmp_path / "l.txt"
    p.write_text("0 0.5 0.5 0.2 0.2\n0 0.5 oops 0.1 0.1\n")
    with pytest.raises(ValueError, match=r"l.txt:2"):
        parse_yolo_label_file(p, 100, 100)
    p.write_text("0 0.5 0.5 0 0.2\n")
    with pytest.raises(ValueError):
        parse_yolo_label_file(p, 100, 100)


def test_format_yolo_labels_known_values():
    assert (
        format_yolo_labels(np.array([[10.0, 20.0, 30.0, 60.0]]), [0], 100, 200)
        == "0 0.200000 0.200000 0.200000 0.200000\n"
    )


def test_coco_json_round_trip(tmp_path, tiny_yolo_dir):
    ds = load_yolo_dir(tiny_yolo_dir)
    gt = coco_gt_dict(ds)
    for im, r in zip(gt["images"], ds.records):
        im["file_name"] = r.image_path  # absolute paths stay valid from anywhere
    path = tmp_path / "gt.json"
    path.write_text(json.dumps(gt))
    back = load_dataset(path)
    assert back.category_names == ("cone",) and back.category_ids == (1,)
    for a, b in zip(ds.records, back.records):
        assert np.allclose(a.boxes_xyxy, b.boxes_xyxy) and a.labels.tolist() == b.labels.tolist()


def test_coco_json_skips_crowd_and_keeps_category_ids(tmp_path):
    data = {
        "images": [{"id": 7, "file_name": "a.jpg", "width": 50, "height": 40}],
        "categories": [{"id": 3, "name": "cone"}, {"id": 9, "name": "barrel"}],
        "annotations": [
            {"id": 1, "image_id": 7, "category_id": 9, "bbox": [1, 2, 10, 20], "iscrowd": 0},
            {"id": 2, "image_id": 7, "category_id": 3, "bbox": [0, 0, 5, 5], "iscrowd": 1},
        ],
    }
    (tmp_path / "c.json").write_text(json.dumps(data))
    ds = load_coco_json(tmp_path / "c.json")
    assert ds.category_ids == (3, 9) and ds.skipped == {"crowd": 1}
    assert ds.records[0].labels.tolist() == [1]
    assert ds.records[0].boxes_xyxy.tolist() == [[1, 2, 11, 22]]
