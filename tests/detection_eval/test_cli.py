"""End-to-end plumbing of the commands on a real (tiny) dataset: saved weights evaluate on a YOLO folder and on a
COCO json, and predict writes one drawn image per input."""

from __future__ import annotations

import json

import pytest

from detection_eval.cli import align_categories, main
from detection_eval.data import DetectionSet, coco_gt_dict, load_yolo_dir
from detection_eval.predict import predict_folder


def test_eval_on_yolo_dir_and_coco_json(weights, tiny_yolo_dir, tmp_path):
    out = tmp_path / "m.json"
    main(["--weights", str(weights), "--data", str(tiny_yolo_dir), "--out", str(out)])
    m = json.loads(out.read_text())
    assert m["num_images"] == 4 and m["num_gt"] == 6 and 0.0 <= m["AP"] <= 1.0
    ds = load_yolo_dir(tiny_yolo_dir)
    gt = coco_gt_dict(ds)
    for im, r in zip(gt["images"], ds.records):
        im["file_name"] = r.image_path
    (tmp_path / "gt.json").write_text(json.dumps(gt))
    out2 = tmp_path / "m2.json"
    main(["eval", "--weights", str(weights), "--data", str(tmp_path / "gt.json"), "--out", str(out2)])
    assert json.loads(out2.read_text())["AP"] == pytest.approx(m["AP"])  # same data, same model: same score


def test_predict_writes_drawn_images(weights, tiny_yolo_dir, tmp_path):
    res = predict_folder(weights, tiny_yolo_dir / "images", tmp_path / "pred", score=0.0)
    assert sorted(p.name for p in (tmp_path / "pred").glob("*.jpg")) == [f"img_{i}.jpg" for i in range(4)]
    assert len(res) == len(json.loads((tmp_path / "pred" / "detections.json").read_text()))


def test_align_categories_by_name_and_single_class(tiny_yolo_dir):
    ds = load_yolo_dir(tiny_yolo_dir)
    assert align_categories(ds, ["traffic_cone"]).category_names == ("traffic_cone",)
    two = DetectionSet(ds.records, ("cone", "barrel"))
    with pytest.raises(ValueError):
        align_categories(two, ["cone", "person"])
