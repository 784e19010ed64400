from __future__ import annotations

import math

import numpy as np
import pytest

from detection_eval.data import DetectionRecord, DetectionSet
from detection_eval.study.arms import ARM_FLAGS
from detection_eval.study.config import InsertionStudyConfig, StudyConfig, load_study_config
from detection_eval.study.report import mean_ci95, summarize
from detection_eval.study.splits import pool_backgrounds, pool_share, real_box_height_fractions, thin_cone_images


def _set(n_with, n_without):
    recs = [DetectionRecord(f"c{i}.jpg", 10, 10, np.array([[1.0, 1, 5, 5]]), np.array([0])) for i in range(n_with)]
    recs += [DetectionRecord(f"e{i}.jpg", 10, 10, np.zeros((0, 4)), np.zeros(0, np.int64)) for i in range(n_without)]
    return DetectionSet(tuple(recs), ("cone",))


def test_thinning_keeps_fraction_of_cone_images_and_all_empty_ones():
    ds = _set(200, 199)
    thin, empty = thin_cone_images(ds, 0.1, seed=3)
    paths = [r.image_path for r in thin.records]
    assert sum(p.startswith("c") for p in paths) == 20
    assert sum(p.startswith("e") for p in paths) == 199 and len(empty) == 199
    again, _ = thin_cone_images(ds, 0.1, seed=3)
    other, _ = thin_cone_images(ds, 0.1, seed=4)
    assert [r.image_path for r in again.records] == paths  # seeded: reproducible
    assert [r.image_path for r in other.records] != paths  # and different per seed


def test_pool_backgrounds_cycle_through_empty_images_in_a_seeded_order():
    empty = list(range(100, 150))
    bg = pool_backgrounds(empty, 0, 120)
    assert set(bg) == set(empty) and len(bg) == 120
    assert bg[:50] == bg[50:100] and bg[100:] == bg[:20]  # a fixed order of all 50, then again
    assert sorted(bg[:50]) == empty
    assert bg == pool_backgrounds(empty, 0, 120) and bg != pool_backgrounds(empty, 1, 120)


def test_pool_share_is_seeded_nested_and_whole_at_full_size():
    a, b = pool_share(600, 200, seed=0), pool_share(600, 200, seed=1)
    assert len(a) == len(set(a)) == 200 and a != b and set(a) <= set(range(600))
    assert set(pool_share(600, 60, 0)) <= set(a)  # smaller amounts are subsets of larger ones
    assert pool_share(600, 600, 3) == list(range(600))


def test_real_box_height_fractions():
    recs = (
        DetectionRecord("a.jpg", 100, 200, np.array([[0.0, 10, 5, 60], [1, 0, 2, 200]]), np.array([0, 0])),
        DetectionRecord("b.jpg", 10, 10, np.zeros((0, 4)), np.zeros(0, np.int64)),
    )
    assert real_box_height_fractions(DetectionSet(recs, ("cone",))) == pytest.approx((0.25, 1.0))


def test_amounts_must_fit_the_pool():
    with pytest.raises(ValueError):
        StudyConfig(amounts=(700,), insertion=InsertionStudyConfig(pool_size=600))
    StudyConfig(amounts=(60, 600), insertion=InsertionStudyConfig(pool_size=600))


def test_mean_ci95_known_values():
    m, h = mean_ci95([1.0, 2.0, 3.0])
    assert m == pytest.approx(2.0)
    assert h == pytest.approx(4.302653 * 1.0 / math.sqrt(3), rel=1e-5)  # t(0.975, 2) * s / sqrt(n), s = 1
    assert math.isnan(mean_ci95([0.5])[1])


def test_summary_pairs_seeds_against_reference():
    def row(arm, seed, ap):
        return {
            "arm": arm,
            "seed": seed,
            "amount": None if arm == "original" else 60,
            "real_images": 219,
            "inserted_images": 0 if arm == "original" else 60,
            "train_seconds": 100.0,
            "train_images_per_second": 5.0,
            "metrics": {"AP": ap, "AP50": 2 * ap, "AP_small": None, "AP_medium": ap, "AP_large": ap},
        }

    rows = [row("original", s, 0.1 + 0.01 * s) for s in range(3)] + [
        row("inserted", s, 0.15 + 0.01 * s) for s in range(3)
    ]
    rows += [row("naive_paste", s, 0.13 + 0.02 * s) for s in range(3)]
    table, summary = summarize(rows)
    assert summary["inserted n=60"]["delta_AP"][0] == pytest.approx(0.05)
    assert summary["inserted n=60"]["delta_AP"][1] == pytest.approx(0.0, abs=1e-9)  # identical paired gains
    # vs naive paste: differences 0.02, 0.01, 0.00 -> mean 0.01, t(0.975, 2) * 0.01 / sqrt(3)
    assert summary["inserted n=60"]["delta_AP_vs_naive"][0] == pytest.approx(0.01)
    assert summary["inserted n=60"]["delta_AP_vs_naive"][1] == pytest.approx(4.302653 * 0.01 / math.sqrt(3), rel=1e-5)
    assert summary["original"]["AP"][0] == pytest.approx(0.11)
    assert "| inserted n=60 | 3 | 219 + 60 |" in table and "n/a" in table  # AP_small undefined everywhere


def test_study_configs_load_and_name_known_arms():
    core = load_study_config("tracon_cones")
    abl = load_study_config("tracon_cones_ablations")
    assert {"original", "inserted", "naive_paste"} <= set(core.arms) and len(core.seeds) >= 3
    assert set(abl.arms) == {"no_placement", "no_shadow", "no_lighting", "no_harmonize"}
    amounts = load_study_config("tracon_cones_amounts")
    for other in (abl, amounts):  # one pool per arm and the same runs: the tables can be read together
        assert (core.max_iters, core.insertion, core.detector, core.seeds) == (
            other.max_iters,
            other.insertion,
            other.detector,
            other.seeds,
        )
    assert len(core.seeds) >= 5 and set(amounts.amounts) | set(core.amounts) == {20, 60, 200}
    with pytest.raises(ValueError):
        StudyConfig(arms=("original", "bogus"))
    assert set(ARM_FLAGS) >= set(core.arms) | set(abl.arms)


def test_closeup_crop_is_a_slice_with_the_target_height_and_exact_boxes():
    from detection_eval.study.pools import closeup_crop

    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (360, 640, 3), dtype=np.uint8)
    boxes = np.array(
        [
            [300.0, 200.0, 330.0, 260.0],  # tallest: 60 px = 1/6 of the height
            [100.0, 250.0, 110.0, 270.0],
        ]
    )  # far left: falls outside most crops
    for seed in range(20):
        crop, out, info = closeup_crop(img, boxes, (0.4,), np.random.default_rng(seed), min_side_px=100)
        ch, cw = crop.shape[:2]
        x0, y0, w0, h0 = info["crop_xywh"]
        assert np.array_equal(crop, img[y0 : y0 + h0, x0 : x0 + w0])  # no resampling: a slice
        assert abs(cw / ch - 640 / 360) < 0.02  # the image's aspect
        assert abs(60 / ch - 0.4) < 0.01  # the tallest box now 0.4 of the frame
        np.testing.assert_allclose(out[0], boxes[0] - [x0, y0, x0, y0])  # whole, moved by the origin
        assert len(out) + info["dropped_boxes"] == 2
    # A target below the current size, or no boxes: unchanged.
    same, out, info = closeup_crop(img, boxes, (0.1,), rng)
    assert same is img and info["zoom"] == 1.0 and np.array_equal(out, boxes)
    # The short side never goes below min_side_px: the zoom is capped.
    crop, _, info = closeup_crop(img, boxes, (0.95,), rng, min_side_px=160)
    assert crop.shape[0] >= 159 and info["zoom"] <= 360 / 160 + 0.01


def test_closeup_arm_is_a_study_flag_not_an_insertion_override():
    from detection_eval.study.arms import STUDY_FLAGS

    assert ARM_FLAGS["inserted_closeup"] == {"closeup_crop": True} and "closeup_crop" in STUDY_FLAGS


def test_dev_split_is_fixed_disjoint_and_of_the_asked_size():
    from detection_eval.study.splits import split_dev

    ds = _set(200, 199)
    rest, dev = split_dev(ds, 50, 50, seed=0)
    dev_paths = {r.image_path for r in dev.records}
    rest_paths = {r.image_path for r in rest.records}
    assert not dev_paths & rest_paths and len(dev_paths | rest_paths) == 399
    assert sum(p.startswith("c") for p in dev_paths) == 50 and sum(p.startswith("e") for p in dev_paths) == 50
    assert {r.image_path for r in split_dev(ds, 50, 50, seed=0)[1].records} == dev_paths
    thin, empty = thin_cone_images(rest, 0.01, seed=2)  # thinning never reaches into dev
    assert not {r.image_path for r in thin.records} & dev_paths
    assert sum(1 for r in thin.records if len(r.labels)) == 2  # the probe: 1 % of the 150 left
    with pytest.raises(ValueError):
        split_dev(ds, 201, 0, seed=0)


def _yolo_cones(root, n_cone, n_empty):
    """A tiny YOLO dataset: grey-green noise roads, orange triangle cones on the cone images."""
    import cv2

    from tests.aias_augment.assets.bank.test_lift import _noise_background, draw_cone

    (root / "images" / "train").mkdir(parents=True)
    (root / "labels" / "train").mkdir(parents=True)
    for i in range(n_cone + n_empty):
        img = _noise_background(240, 320, i)
        lines = []
        if i < n_cone:
            b = draw_cone(img, 100 + 20 * i, 200, 120, 32)
            lines.append(f"0 {(b[0] + b[2]) / 640} {(b[1] + b[3]) / 480} {(b[2] - b[0]) / 320} {(b[3] - b[1]) / 240}")
        cv2.imwrite(str(root / "images" / "train" / f"im{i}.png"), img[..., ::-1])
        (root / "labels" / "train" / f"im{i}.txt").write_text("\n".join(lines))


def test_copy_paste_pool_uses_only_the_seeds_own_instances(tmp_path):
    import json

    from detection_eval.data import load_yolo_dir
    from detection_eval.study.pools import generate_arm_set

    _yolo_cones(tmp_path / "data", 4, 6)
    train = load_yolo_dir(tmp_path / "data", "train", ("cone",))
    cfg = StudyConfig(
        dataset=str(tmp_path / "data"),
        keep_fraction=0.5,
        arms=("original", "copy_paste"),
        amounts=(3,),
        insertion=InsertionStudyConfig(pool_size=3, max_objects=2),
        cache_dir=str(tmp_path / "cache"),
    )
    seen = {}
    for seed in (0, 1):
        base, empty = thin_cone_images(train, cfg.keep_fraction, seed)
        out = generate_arm_set(cfg, "copy_paste", train, empty, seed, base)
        done = json.loads((out / "done.json").read_text())
        own = sorted(r.image_path.rsplit("/", 1)[1] for r in base.records if len(r.labels))
        assert sorted(done["sources"]) == own and done["num_images"] == 3 and done["num_boxes"] >= 3
        seen[seed] = own
        pool = load_yolo_dir(out, names=("cone",))
        for r in pool.records:
            assert np.all(r.boxes_xyxy[:, :2] >= 0) and np.all(r.boxes_xyxy[:, 2] <= r.width)
            assert np.all(r.boxes_xyxy[:, 3] <= r.height)
    assert seen[0] != seen[1]


def test_paste_instances_changes_only_the_pasted_boxes():
    from aias_augment.assets.bank.lift import cut_out
    from detection_eval.copy_paste import paste_instances
    from tests.aias_augment.assets.bank.test_lift import _noise_background, draw_cone

    src = _noise_background(240, 320)
    cut, _ = cut_out(src, draw_cone(src, 160, 200, 120, 32))
    bg = np.full((200, 300, 3), 77, np.uint8)
    out, boxes = paste_instances(bg, [cut], np.random.default_rng(0), (0.3, 0.5), n_objects=3)
    assert len(boxes) >= 2
    inside = np.zeros(bg.shape[:2], bool)
    for x0, y0, x1, y1 in boxes.astype(int):
        assert 0 <= x0 < x1 <= 300 and 0 <= y0 < y1 <= 200
        assert 0.25 * 200 <= y1 - y0 <= 0.55 * 200
        inside[max(0, y0 - 2) : y1 + 2, max(0, x0 - 2) : x1 + 2] = True
    assert np.all(out[~inside] == 77)  # soft edges stay within 2 px of the box
    assert np.any(out[inside] != 77)
