import colorsys

import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.assets.asset import Asset
from aias_augment.assets.bank.variety import (
    VarietyConfig,
    VarietyParams,
    _jitter_rgb_uint8,
    apply_variety,
    sample_variety,
    scale_range,
)


def _asset(height=0.7):
    box = trimesh.creation.box(extents=[0.3, 0.3, height])
    box.apply_translation([0, 0, height / 2])
    box.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.SimpleMaterial(diffuse=[200, 80, 20, 255])
    )
    return Asset("box", "traffic_cone", (box,), "test")


@given(h=st.floats(0.01, 10), lo=st.floats(0.05, 2), span=st.floats(0.01, 3), j=st.floats(0, 0.5))
@settings(max_examples=200, deadline=None)
def test_scale_range_stays_in_category_and_jitter(h, lo, span, j):
    hi = lo + span
    a, b = scale_range(h, (lo, hi), j)
    assert 1 - j - 1e-12 <= a <= b <= 1 + j + 1e-12
    if lo <= h <= hi:  # inside the range: never pushed out of it
        assert lo - 1e-9 <= a * h and b * h <= hi + 1e-9


def test_same_seed_same_sample_and_heights_in_range():
    cfg = VarietyConfig()
    p1 = sample_variety(0.7, (0.25, 1.1), cfg, np.random.default_rng(3))
    p2 = sample_variety(0.7, (0.25, 1.1), cfg, np.random.default_rng(3))
    assert p1 == p2
    rng = np.random.default_rng(0)
    hs = [0.7 * sample_variety(0.7, (0.65, 0.75), cfg, rng).scale for _ in range(200)]
    assert min(hs) >= 0.65 - 1e-9 and max(hs) <= 0.75 + 1e-9 and np.ptp(hs) > 0.05


def test_apply_scales_about_contact_point_and_recolours():
    a = _asset()
    out = apply_variety(a, VarietyParams(scale=1.1, hue_shift=0.0, saturation_gain=1.0, value_gain=0.5))
    np.testing.assert_allclose(out.extents_m, a.extents_m * 1.1)
    assert out.bounds_m[0, 2] == pytest.approx(0.0)
    np.testing.assert_array_equal(out.meshes[0].visual.material.diffuse[:3], [100, 40, 10])  # value halved
    np.testing.assert_array_equal(a.meshes[0].visual.material.diffuse[:3], [200, 80, 20])  # input untouched
    assert out.meta["variety"]["scale"] == 1.1


def test_hsv_jitter_matches_colorsys():
    rgb = np.random.default_rng(1).integers(0, 256, (300, 3)).astype(np.uint8)
    p = VarietyParams(1.0, 0.013, 1.1, 0.9)
    out = _jitter_rgb_uint8(rgb, p)
    for c, o in zip(rgb, out):
        h, s, v = colorsys.rgb_to_hsv(*(c / 255.0))
        ref = colorsys.hsv_to_rgb((h + p.hue_shift) % 1.0, min(s * 1.1, 1), min(v * 0.9, 1))
        assert np.abs(np.array(ref) * 255 - o).max() <= 1.01


def test_config_validation():
    with pytest.raises(ValueError):
        VarietyConfig(scale_jitter=1.5)
    with pytest.raises(ValueError):
        VarietyConfig(value_gain_range=(1.2, 0.8))
    with pytest.raises(ValueError):
        sample_variety(0.0, (0.1, 1), VarietyConfig(), np.random.default_rng(0))
