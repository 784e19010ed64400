from __future__ import annotations

import math

import numpy as np
import pytest

from detection_eval.data import DetectionRecord, DetectionSet
from detection_eval.study import (ARM_FLAGS, InsertionStudyConfig, StudyConfig, load_study_config, mean_ci95,
                                  pool_backgrounds, pool_share, real_box_height_fractions, summarize,
                                  thin_cone_images)


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
    assert [r.image_path for r in again.records] == paths                 # seeded: reproducible
    assert [r.image_path for r in other.records] != paths                 # and different per seed


def test_pool_backgrounds_cycle_through_empty_images_in_a_seeded_order():
    empty = list(range(100, 150))
    bg = pool_backgrounds(empty, 0, 120)
    assert set(bg) == set(empty) and len(bg) == 120
    assert bg[:50] == bg[50:100] and bg[100:] == bg[:20]          # a fixed order of all 50, then again
    assert sorted(bg[:50]) == empty
    assert bg == pool_backgrounds(empty, 0, 120) and bg != pool_backgrounds(empty, 1, 120)


def test_pool_share_is_seeded_nested_and_whole_at_full_size():
    a, b = pool_share(600, 200, seed=0), pool_share(600, 200, seed=1)
    assert len(a) == len(set(a)) == 200 and a != b and set(a) <= set(range(600))
    assert set(pool_share(600, 60, 0)) <= set(a)                   # smaller amounts are subsets of larger ones
    assert pool_share(600, 600, 3) == list(range(600))


def test_real_box_height_fractions():
    recs = (DetectionRecord("a.jpg", 100, 200, np.array([[0.0, 10, 5, 60], [1, 0, 2, 200]]), np.array([0, 0])),
            DetectionRecord("b.jpg", 10, 10, np.zeros((0, 4)), np.zeros(0, np.int64)))
    assert real_box_height_fractions(DetectionSet(recs, ("cone",))) == pytest.approx((0.25, 1.0))


def test_amounts_must_fit_the_pool():
    with pytest.raises(ValueError):
        StudyConfig(amounts=(700,), insertion=InsertionStudyConfig(pool_size=600))
    StudyConfig(amounts=(60, 600), insertion=InsertionStudyConfig(pool_size=600))


def test_mean_ci95_known_values():
    m, h = mean_ci95([1.0, 2.0, 3.0])
    assert m == pytest.approx(2.0)
    assert h == pytest.approx(4.302653 * 1.0 / math.sqrt(3), rel=1e-5)   # t(0.975, 2) * s / sqrt(n), s = 1
    assert math.isnan(mean_ci95([0.5])[1])


def test_summary_pairs_seeds_against_reference():
    def row(arm, seed, ap):
        return {"arm": arm, "seed": seed, "amount": None if arm == "original" else 60,
                "real_images": 219, "inserted_images": 0 if arm == "original" else 60,
                "train_seconds": 100.0, "train_images_per_second": 5.0,
                "metrics": {"AP": ap, "AP50": 2 * ap, "AP_small": None, "AP_medium": ap, "AP_large": ap}}
    rows = [row("original", s, 0.1 + 0.01 * s) for s in range(3)] + [row("inserted", s, 0.15 + 0.01 * s)
                                                                      for s in range(3)]
    rows += [row("naive_paste", s, 0.13 + 0.02 * s) for s in range(3)]
    table, summary = summarize(rows)
    assert summary["inserted n=60"]["delta_AP"][0] == pytest.approx(0.05)
    assert summary["inserted n=60"]["delta_AP"][1] == pytest.approx(0.0, abs=1e-9)   # identical paired gains
    # vs naive paste: differences 0.02, 0.01, 0.00 -> mean 0.01, t(0.975, 2) * 0.01 / sqrt(3)
    assert summary["inserted n=60"]["delta_AP_vs_naive"][0] == pytest.approx(0.01)
    assert summary["inserted n=60"]["delta_AP_vs_naive"][1] == pytest.approx(4.302653 * 0.01 / math.sqrt(3), rel=1e-5)
    assert summary["original"]["AP"][0] == pytest.approx(0.11)
    assert "| inserted n=60 | 3 | 219 + 60 |" in table and "n/a" in table     # AP_small undefined everywhere


def test_study_configs_load_and_name_known_arms():
    core = load_study_config("tracon_cones")
    abl = load_study_config("tracon_cones_ablations")
    assert {"original", "inserted", "naive_paste"} <= set(core.arms) and len(core.seeds) >= 3
    assert set(abl.arms) == {"no_placement", "no_shadow", "no_lighting", "no_harmonize"}
    amounts = load_study_config("tracon_cones_amounts")
    for other in (abl, amounts):   # one pool per arm and the same runs: the tables can be read together
        assert (core.max_iters, core.insertion, core.detector, core.seeds) == \
            (other.max_iters, other.insertion, other.detector, other.seeds)
    assert len(core.seeds) >= 5 and set(amounts.amounts) | set(core.amounts) == {20, 60, 200}
    with pytest.raises(ValueError):
        StudyConfig(arms=("original", "bogus"))
    assert set(ARM_FLAGS) >= set(core.arms) | set(abl.arms)


def test_closeup_crop_is_a_slice_with_the_target_height_and_exact_boxes():
    from detection_eval.study import closeup_crop
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, (360, 640, 3), dtype=np.uint8)
    boxes = np.array([[300.0, 200.0, 330.0, 260.0],     # tallest: 60 px = 1/6 of the height
                      [100.0, 250.0, 110.0, 270.0]])    # far left: falls outside most crops
    for seed in range(20):
        crop, out, info = closeup_crop(img, boxes, (0.4,), np.random.default_rng(seed), min_side_px=100)
        ch, cw = crop.shape[:2]
        x0, y0, w0, h0 = info["crop_xywh"]
        assert np.array_equal(crop, img[y0:y0 + h0, x0:x0 + w0])           # no resampling: a slice
        assert abs(cw / ch - 640 / 360) < 0.02                              # the image's aspect
        assert abs(60 / ch - 0.4) < 0.01                                    # the tallest box now 0.4 of the frame
        np.testing.assert_allclose(out[0], boxes[0] - [x0, y0, x0, y0])     # whole, moved by the origin
        assert len(out) + info["dropped_boxes"] == 2
    # A target below the current size, or no boxes: unchanged.
    same, out, info = closeup_crop(img, boxes, (0.1,), rng)
    assert same is img and info["zoom"] == 1.0 and np.array_equal(out, boxes)
    # The short side never goes below min_side_px: the zoom is capped.
    crop, _, info = closeup_crop(img, boxes, (0.95,), rng, min_side_px=160)
    assert crop.shape[0] >= 159 and info["zoom"] <= 360 / 160 + 0.01


def test_closeup_arm_is_a_study_flag_not_an_insertion_override():
    from detection_eval.study import STUDY_FLAGS
    assert ARM_FLAGS["inserted_closeup"] == {"closeup_crop": True} and "closeup_crop" in STUDY_FLAGS
