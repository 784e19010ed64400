from __future__ import annotations

import math

import numpy as np
import pytest

from detection_eval.data import DetectionRecord, DetectionSet
from detection_eval.study import (ARM_FLAGS, StudyConfig, insertion_backgrounds, load_study_config, mean_ci95,
                                  summarize, thin_cone_images)


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


def test_insertion_backgrounds_are_a_seeded_subset_of_empty_images():
    empty = list(range(100, 150))
    bg = insertion_backgrounds(empty, 0, 10)
    assert len(bg) == 10 and len(set(bg)) == 10 and set(bg) <= set(empty)
    assert bg == insertion_backgrounds(empty, 0, 10)
    assert sorted(insertion_backgrounds(empty, 0, None)) == empty


def test_mean_ci95_known_values():
    m, h = mean_ci95([1.0, 2.0, 3.0])
    assert m == pytest.approx(2.0)
    assert h == pytest.approx(4.302653 * 1.0 / math.sqrt(3), rel=1e-5)   # t(0.975, 2) * s / sqrt(n), s = 1
    assert math.isnan(mean_ci95([0.5])[1])


def test_summary_pairs_seeds_against_reference():
    def row(arm, seed, ap):
        return {"arm": arm, "seed": seed, "real_images": 219, "inserted_images": 0 if arm == "original" else 60,
                "train_seconds": 100.0, "train_images_per_second": 5.0,
                "metrics": {"AP": ap, "AP50": 2 * ap, "AP_small": None, "AP_medium": ap, "AP_large": ap}}
    rows = [row("original", s, 0.1 + 0.01 * s) for s in range(3)] + [row("inserted", s, 0.15 + 0.01 * s)
                                                                      for s in range(3)]
    table, summary = summarize(rows)
    assert summary["inserted"]["delta_AP"][0] == pytest.approx(0.05)
    assert summary["inserted"]["delta_AP"][1] == pytest.approx(0.0, abs=1e-9)   # identical paired gains
    assert summary["original"]["AP"][0] == pytest.approx(0.11)
    assert "| inserted | 3 | 219 + 60 |" in table and "n/a" in table           # AP_small undefined everywhere


def test_study_configs_load_and_name_known_arms():
    core = load_study_config("tracon_cones")
    abl = load_study_config("tracon_cones_ablations")
    assert {"original", "inserted", "naive_paste"} <= set(core.arms) and len(core.seeds) >= 3
    assert set(abl.arms) == {"no_placement", "no_shadow", "no_lighting", "no_harmonize"}
    assert (core.max_iters, core.insertion, core.detector) == (abl.max_iters, abl.insertion, abl.detector)
    with pytest.raises(ValueError):
        StudyConfig(arms=("original", "bogus"))
    assert set(ARM_FLAGS) >= set(core.arms) | set(abl.arms)
