"""Decoys: objects of other categories inserted through the same stages and never annotated."""

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest
from pycocotools import mask as mask_utils

from aias_augment.assets.asset import DEFAULT_ASSETS
from aias_augment.core.config import ConfigValueError, data_root
from aias_augment.core.frame import Frame
from aias_augment.pipeline.image import insert_into_image, load_preset
from aias_augment.pipeline.replay import replay

DATA = data_root()
needs_data = pytest.mark.skipif(
    not all((DATA / DEFAULT_ASSETS[c][0]).exists() for c in ("traffic_cone", "barrel")), reason="shared data missing"
)


def _kitti():
    img = cv2.imread(str(DATA / "kitti06_color_snippet" / "kitti06-12-color.png"))
    if img is None:
        pytest.skip("KITTI frame missing")
    return np.ascontiguousarray(img[:, :, ::-1])


def _cfg(**kw):
    return load_preset("fast", min_objects=2, max_objects=2, decoy_categories=("barrel",), decoys=(2, 2), **kw)


def test_decoys_need_their_own_categories():
    with pytest.raises(ConfigValueError, match="decoy_categories"):
        load_preset("fast", decoys=(1, 2))
    with pytest.raises(ConfigValueError, match="also annotated"):
        load_preset("fast", categories=("traffic_cone",), decoy_categories=("traffic_cone",), decoys=(1, 1))
    with pytest.raises(ConfigValueError, match="decoys"):
        load_preset("fast", decoy_categories=("barrel",), decoys=(2, 1))


@needs_data
def test_decoys_are_drawn_and_rendered_but_never_annotated():
    img = _kitti()
    cfg = _cfg()
    plain = replace(cfg, decoy_categories=(), decoys=(0, 0))
    seen = 0
    for seed in range(4):
        res = insert_into_image(img, None, None, np.random.default_rng(seed), cfg)
        ref = insert_into_image(img, None, None, np.random.default_rng(seed), plain)
        decoys = [(p, a) for p, a in zip(res.record.placements, res.record.annotations) if p.decoy]
        labelled = [(p, a) for p, a in zip(res.record.placements, res.record.annotations) if not p.decoy]
        # the labelled objects draw before the decoys: where they stand does not depend on the decoys
        assert [p.contact_point_in_cam for p, _ in labelled] == [p.contact_point_in_cam for p in ref.record.placements]
        assert all(p.category == "barrel" and a.decoy for p, a in decoys)
        assert set(res.labels) <= {"traffic_cone"}
        assert len(res.bboxes) == sum(a.visible_box_xywh is not None for _, a in labelled)
        for p, a in decoys:
            if a.visible_box_xywh is None:
                continue
            seen += 1
            # rendered: the image changed under the decoy's own visible mask ...
            m = mask_utils.decode({"size": a.rle["size"], "counts": a.rle["counts"].encode()}).astype(bool)
            assert np.abs(res.image[m].astype(int) - img[m].astype(int)).mean() > 5
            # ... and no output box is the decoy's
            assert not any(np.allclose(b, a.visible_box_xywh) for b in res.bboxes)
    assert seen >= 1, "no decoy was placed on four seeds"


@needs_data
def test_a_record_with_decoys_replays_byte_for_byte():
    img = _kitti()
    cfg = _cfg()
    for seed in range(4):
        res = insert_into_image(img, None, None, np.random.default_rng(seed), cfg)
        record = json.loads(json.dumps(res.record.to_dict()))
        if any(p["decoy"] for p in record["placements"]):
            break
    else:
        pytest.fail("no decoy was placed on four seeds")
    again = replay(record, Frame(img, None), cfg)
    assert np.array_equal(again.image, res.image)
    assert [a.decoy for a in again.annotations] == [p["decoy"] for p in record["placements"]]


@needs_data
def test_offline_coco_masks_belong_to_their_boxes_with_decoys(tmp_path):
    from aias_augment.cli.offline import Item, run

    p = tmp_path / "in" / "kitti.png"
    p.parent.mkdir()
    cv2.imwrite(str(p), _kitti()[..., ::-1])
    items = [Item(str(p))] * 3
    cfg = replace(_cfg(), harmonize=False)
    run(items, cfg, seed=1, out_dir=str(tmp_path / "out"), workers=1)
    coco = json.loads((tmp_path / "out" / "annotations.json").read_text())
    records = [json.loads(r.read_text()) for r in sorted((tmp_path / "out" / "records").glob("*.json"))]
    assert any(a.get("decoy") for r in records for a in r["annotations"]), "no decoy was placed"
    names = {c["id"]: c["name"] for c in coco["categories"]}
    assert {names[a["category_id"]] for a in coco["annotations"]} == {"traffic_cone"}
    for a in coco["annotations"]:
        # each box is its own mask's box (a decoy's mask attached to a cone's box would not be)
        assert np.allclose(mask_utils.toBbox(a["segmentation"]), a["bbox"], atol=1.0)
