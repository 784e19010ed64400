"""Edge blending of an object's layer. Truths derived without the stage's code: a normalised Gaussian keeps the
layer's coverage mass; a blurred straight edge crosses 1/2 where the edge was (the erf profile is symmetric);
thresholding an anti-aliased edge at 1/2 leaves 0/1 coverage; an object of one colour and depth keeps them."""

import numpy as np
import pytest
from scipy.special import erf

from aias_augment.core.stages import ObjectLayer
from aias_augment.core.stages.edge_blend import STAGE
from aias_augment.pipeline.config import InsertionConfig

COLOUR, DEPTH = np.array([0.6, 0.3, 0.1], np.float32), 7.0


def _square(size=41, object_px=15, soft_edge=False):
    alpha = np.zeros((size, size), np.float32)
    lo = (size - object_px) // 2
    alpha[lo : lo + object_px, lo : lo + object_px] = 1.0
    if soft_edge:  # an anti-aliased left edge: half-covered column
        alpha[lo : lo + object_px, lo - 1] = 0.4
    rgb = np.where(alpha[..., None] > 0, COLOUR, 0).astype(np.float32)
    return ObjectLayer((100, 50, 100 + size, 50 + size), alpha, np.where(alpha > 0, DEPTH, 0).astype(np.float32), rgb)


@pytest.mark.parametrize("sigma", [0.5, 1.0, 2.0])
def test_feather_keeps_coverage_mass_colour_and_the_edge_position(sigma):
    layer = _square()
    out = STAGE.apply(layer, {"mode": "feather", "sigma_px": sigma}, None)
    assert abs(out.alpha.sum() - layer.alpha.sum()) < 1e-3 * layer.alpha.sum()
    covered = out.alpha > 1e-4
    assert np.allclose(out.rgb[covered], COLOUR, atol=1e-5) and np.allclose(out.depth[covered], DEPTH, atol=1e-4)
    # the middle row across the left edge: the erf step centred half a pixel before the first covered column
    pad = (out.alpha.shape[0] - layer.alpha.shape[0]) // 2
    row = out.alpha[pad + 20, :]
    first = pad + (41 - 15) // 2
    x = np.arange(len(row)) - (first - 0.5)
    want = 0.5 * (1 + erf(x / (sigma * np.sqrt(2))))
    near = np.abs(x) <= 2 * sigma
    assert np.abs(row[near] - want[near]).max() < 0.06  # a sampled Gaussian against the continuous profile
    assert out.roi[0] < layer.roi[0] and out.roi[2] > layer.roi[2]  # grown: the fringe has room


def test_hard_edge_is_binary_at_one_half_and_changes_nothing_else():
    layer = _square(soft_edge=True)
    out = STAGE.apply(layer, {"mode": "hard", "sigma_px": 1.0}, None)
    assert set(np.unique(out.alpha)) == {0.0, 1.0}
    assert np.array_equal(out.alpha, (layer.alpha >= 0.5).astype(np.float32))
    assert out.rgb is layer.rgb and out.depth is layer.depth and out.roi == layer.roi
    assert STAGE.apply(layer, {"mode": "rendered", "sigma_px": 1.0}, None) is layer


def test_modes_drawn_uniformly_within_range_off_by_default_and_bad_modes_refused():
    assert not STAGE.enabled(InsertionConfig())
    cfg = InsertionConfig(edge_blend=("rendered", "hard", "feather"), edge_feather_px=(0.5, 2.0))
    draws = [STAGE.draw(cfg, np.random.default_rng(s)) for s in range(600)]
    counts = {m: sum(d["mode"] == m for d in draws) for m in cfg.edge_blend}
    assert all(150 <= c <= 250 for c in counts.values()), counts  # 200 +- 3.5 sigma of a binomial
    assert all(0.5 <= d["sigma_px"] <= 2.0 for d in draws)
    with pytest.raises(ValueError, match="edge_blend"):
        InsertionConfig(edge_blend=("poisson",))
    with pytest.raises(ValueError, match="edge_feather_px"):
        InsertionConfig(edge_feather_px=(2.0, 1.0))
    with pytest.raises(ValueError, match="unknown mode"):
        STAGE.apply(_square(), {"mode": "poisson", "sigma_px": 1.0}, None)


def test_the_pipeline_records_and_replays_the_drawn_edges():
    """Through the image door: the plan records each object's mode; a replay of the record gives the same bytes;
    the boxes stay where the rendered edges put them (within a pixel)."""
    import json
    from dataclasses import replace

    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.image import insert_into_image
    from aias_augment.pipeline.replay import replay
    from tests.aias_augment.pipeline.test_image import road_frame

    base = InsertionConfig(categories=("traffic_cone",), min_objects=2, max_objects=2, harmonize=False, ssaa=1)
    cfg = replace(base, edge_blend=("hard", "feather"))
    plain = insert_into_image(road_frame(), None, None, np.random.default_rng(4), base)
    res = insert_into_image(road_frame(), None, None, np.random.default_rng(4), cfg)
    modes = [p["edge_blend"]["mode"] for p in res.record.layer_params]
    assert len(modes) == len(res.record.placements) and set(modes) <= {"hard", "feather"}
    assert not np.array_equal(plain.image, res.image)
    assert np.abs(np.asarray(plain.inserted_bboxes) - np.asarray(res.inserted_bboxes)).max() <= 1.0
    again = replay(json.loads(json.dumps(res.record.to_dict())), Frame(road_frame(), None), cfg)
    assert np.array_equal(again.image, res.image)
