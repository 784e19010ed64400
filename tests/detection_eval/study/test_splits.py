from __future__ import annotations

import numpy as np
import pytest

from detection_eval.data import DetectionRecord, DetectionSet
from detection_eval.study.splits import pool_backgrounds, pool_share, real_box_height_fractions, thin_cone_images
from tests.detection_eval.study.sets import cone_set


def test_thinning_keeps_fraction_of_cone_images_and_all_empty_ones():
    ds = cone_set(200, 199)
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


def test_dev_split_is_fixed_disjoint_and_of_the_asked_size():
    from detection_eval.study.splits import split_dev

    ds = cone_set(200, 199)
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
