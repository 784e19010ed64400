"""``InsertionConfig.naive_share``: a share of images made as naive pastes, decided per image, recorded, replayed.

The truth is the two plain configs: an image of a ``naive_share`` run is, byte for byte, what the pipeline config
(``naive_share=0``) or the naive-paste config (``naive_paste=True``) makes from the same generator after one uniform,
and which of the two it is follows that uniform against the share (computed here from a copy of the generator).
"""

import json
from dataclasses import replace

import cv2
import numpy as np
import pytest

from aias_augment.core.config import ConfigValueError
from aias_augment.core.frame import Frame
from aias_augment.pipeline.bounded import ANALYSIS_MAX_PIXELS, insert_bounded
from aias_augment.pipeline.image import InsertionConfig, insert_into_image
from aias_augment.pipeline.replay import replay
from tests.aias_augment.fixtures import box_asset
from tests.aias_augment.pipeline.test_image import K, OneAsset, road_frame

SHARE = InsertionConfig(categories=("box",), harmonize=False, ssaa=1, naive_share=0.5)
PIPELINE = replace(SHARE, naive_share=0.0)
NAIVE = replace(SHARE, naive_share=0.0, naive_paste=True)
BANK = OneAsset(box_asset())


def _after_one_uniform(seed: int) -> tuple[np.random.Generator, float]:
    rng = np.random.default_rng(seed)
    return rng, float(rng.random())


def _insert(cfg, rng, image=None):
    return insert_into_image(road_frame() if image is None else image, rng=rng, cfg=cfg, intrinsics=K, bank=BANK)


def test_each_image_is_the_pipeline_or_the_naive_paste_as_its_uniform_says():
    modes = []
    for seed in range(8):
        res = _insert(SHARE, np.random.default_rng(seed))
        rng, u = _after_one_uniform(seed)
        expected = "naive_paste" if u < SHARE.naive_share else "pipeline"
        plain = _insert(NAIVE if expected == "naive_paste" else PIPELINE, rng)
        assert res.record.mode == expected
        assert np.array_equal(res.image, plain.image) and np.array_equal(res.bboxes, plain.bboxes)
        if expected == "naive_paste":  # the stages a naive paste skips are skipped, and the record says why
            assert res.record.modules["placement"].skipped and res.record.modules["shadow"].skipped
        else:
            assert "placement" not in res.record.modules and not getattr(res.record.modules["shadow"], "skipped", False)
        modes.append(expected)
    assert set(modes) == {"pipeline", "naive_paste"}  # both kinds were compared


@pytest.mark.parametrize("seed", [0, 3])
def test_a_share_run_replays_from_its_record_with_the_runs_config(seed):
    res = _insert(SHARE, np.random.default_rng(seed))
    record = json.loads(json.dumps(res.record.to_dict()))
    assert record["mode"] in ("pipeline", "naive_paste")
    again = replay(record, Frame(road_frame(), K), SHARE, assets=lambda p: box_asset())
    assert np.array_equal(again.image, res.image)


def test_share_zero_and_one_need_no_coin_or_always_paste():
    rng = np.random.default_rng(5)
    state = rng.bit_generator.state
    assert PIPELINE.for_image(rng) is PIPELINE and rng.bit_generator.state == state  # no draw without a share
    always = replace(SHARE, naive_share=1.0)
    assert all(always.for_image(np.random.default_rng(s)).mode == "naive_paste" for s in range(20))


def test_the_share_is_the_fraction_of_naive_images():
    cfg = replace(SHARE, naive_share=0.3)
    n = 2000
    k = sum(cfg.for_image(np.random.default_rng([11, i])).mode == "naive_paste" for i in range(n))
    assert abs(k / n - 0.3) < 4 * np.sqrt(0.3 * 0.7 / n)  # binomial, 4 sigma


def test_bad_shares_raise_at_construction():
    with pytest.raises(ValueError, match="naive_share"):
        InsertionConfig(naive_share=1.5)
    with pytest.raises(ConfigValueError, match="naive_share"):
        InsertionConfig(naive_paste=True, naive_share=0.5)
    with pytest.raises(ValueError, match="mode"):
        SHARE.for_mode("paste")


def test_the_bounded_door_draws_once_and_records_the_mode():
    """On an image above the bound (analysis on a smaller copy) the coin is drawn once, as the small door draws it."""
    big = cv2.resize(road_frame(), (1920, 1440), interpolation=cv2.INTER_LINEAR)
    assert big.shape[0] * big.shape[1] > ANALYSIS_MAX_PIXELS
    cfg = replace(SHARE, naive_share=1.0)
    res = insert_bounded(big, None, None, np.random.default_rng(2), cfg, bank=BANK)
    rng, _ = _after_one_uniform(2)
    plain = insert_bounded(big, None, None, rng, NAIVE, bank=BANK)
    assert res.record.mode == "naive_paste" and res.record.working_resolution is not None
    assert np.array_equal(res.image, plain.image)


def test_the_transform_takes_the_share_from_its_overrides():
    from aias_augment.adapters.transform import InsertObjects

    t = InsertObjects(
        categories=("traffic_cone",),
        preset="fast",
        config_overrides={"naive_share": 1.0, "asset_source": "procedural", "ssaa": 1},
        p=1.0,
    )
    t.set_random_seed(0)
    out = t(image=road_frame())
    assert t.last_record.mode == "naive_paste" and not np.array_equal(out["image"], road_frame())
