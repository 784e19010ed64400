"""The direct-sun evidence: each feature measures the physical trace it names, the model is data, presets agree."""

import json

import numpy as np
import pytest

from aias_augment.analyse.lighting.sun_evidence import (
    DEFAULT_MODEL,
    FEATURES,
    SunEvidenceModel,
    direct_sun_probability,
    sun_evidence_features,
)
from aias_augment.core.hdr import linear_to_srgb


def _photo(sky_rgb, lit_rgb, shadow_rgb, h=240, w=320) -> np.ndarray:
    """A sky over a ground that is half lit, half in shadow; colours linear, written as sRGB uint8."""
    lin = np.zeros((h, w, 3), np.float32)
    lin[: h // 2] = sky_rgb
    lin[h // 2 :, : w // 2] = lit_rgb
    lin[h // 2 :, w // 2 :] = shadow_rgb
    return (np.clip(linear_to_srgb(lin), 0, 1) * 255 + 0.5).astype(np.uint8)


# Under direct sun: a blue sky; the lit ground gets the warm sun plus the sky, the shadow the blue sky alone.
SUNNY = _photo((0.25, 0.40, 0.75), (0.45, 0.40, 0.33), (0.05, 0.06, 0.09))
# Overcast: a grey sky, lit and shadowed ground under the same grey light (the "shadow" is a darker material).
OVERCAST = _photo((0.60, 0.60, 0.62), (0.20, 0.20, 0.20), (0.06, 0.06, 0.06))


def test_features_measure_sky_colour_and_shadow_tint():
    sunny, overcast = sun_evidence_features(SUNNY), sun_evidence_features(OVERCAST)
    # log(B/R) of the sky, from the linear colours above
    assert sunny["sky_blue"] == pytest.approx(np.log(0.75 / 0.25), abs=0.05)
    assert overcast["sky_blue"] == pytest.approx(np.log(0.62 / 0.60), abs=0.05)
    # shadow minus lit log(B/R): log(0.09/0.05) - log(0.33/0.45) under sun, 0 under one grey light
    assert sunny["shadow_blue"] == pytest.approx(np.log(0.09 / 0.05) - np.log(0.33 / 0.45), abs=0.08)
    assert overcast["shadow_blue"] == pytest.approx(0.0, abs=0.03)
    assert sunny["clipped"] == 0.0


def test_clipped_share_counts_saturated_pixels():
    img = OVERCAST.copy()
    img[:60, :80] = 255  # a quarter of the top half: 60 * 80 of 240 * 320 pixels
    assert sun_evidence_features(img)["clipped"] == pytest.approx(60 * 80 / (240 * 320), abs=0.01)


def test_features_do_not_depend_on_resolution():
    big = np.kron(SUNNY, np.ones((4, 4, 1), np.uint8))  # the same photo at 4x the pixels
    a, b = sun_evidence_features(SUNNY), sun_evidence_features(big)
    for k in FEATURES:
        assert a[k] == pytest.approx(b[k], abs=0.02)


def test_shipped_model_separates_sun_from_overcast():
    assert direct_sun_probability(SUNNY) > 0.5 > direct_sun_probability(OVERCAST)


def test_model_round_trips_as_json_and_rejects_bad_coefficients(tmp_path):
    m = SunEvidenceModel.load(DEFAULT_MODEL)
    p = tmp_path / "m.json"
    p.write_text(json.dumps(m.to_dict()))
    assert SunEvidenceModel.load(p) == m
    bad = m.to_dict() | {"scale": [0.0] * len(m.features)}
    p.write_text(json.dumps(bad))
    with pytest.raises(ValueError, match="scale"):
        SunEvidenceModel.load(p)
    with pytest.raises(ValueError, match="unknown features"):
        SunEvidenceModel(("sun_disc",), (0.0,), (1.0,), (1.0,), 0.0, 0.5, {})
    with pytest.raises(ValueError, match="threshold"):
        SunEvidenceModel(m.features, m.mean, m.scale, m.coef, m.intercept, 1.0, {})


def test_bad_image_is_refused():
    with pytest.raises(ValueError, match="uint8"):
        sun_evidence_features(np.zeros((32, 32, 3), np.float32))


def test_fast_and_balanced_decide_the_same():
    from aias_augment.analyse.analysis import analyse_scene
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.config import load_preset

    for img in (SUNNY, OVERCAST):
        decisions = {
            preset: analyse_scene(Frame(img, None), load_preset(preset)).lighting.dominant_sun
            for preset in ("fast", "balanced")
        }
        assert decisions["fast"] == decisions["balanced"]
    assert analyse_scene(Frame(OVERCAST, None), load_preset("fast")).lighting.dominant_sun is False
