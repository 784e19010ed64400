import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.apply import shadows


def test_shadow_ratio_convention():
    v = np.array([[0.0, 0.5, 1.0]])
    out = shadows.shadow_ratio_from_sun_sky(v, 3.0)
    assert np.allclose(out, [[1 / 4, 2.5 / 4, 1.0]])
    assert np.allclose(shadows.shadow_ratio_from_sun_sky(v, 0.0), 1.0)  # no sun: no shadow
    ao = shadows.shadow_ratio_from_sun_sky(np.ones((1, 1)), 3.0, ambient_occlusion=np.zeros((1, 1)))
    assert ao[0, 0] == pytest.approx(0.75)
    with pytest.raises(ValueError):
        shadows.shadow_ratio_from_sun_sky(np.full((1, 1), np.nan), 1.0)


def _edge_width_px(profile):
    """25-75 % rise distance of a monotone edge profile (a Gaussian of sigma s gives 1.349 s)."""
    lo, hi = profile.min(), profile.max()
    x = np.arange(profile.size)
    p = (profile - lo) / (hi - lo)
    return np.interp(0.75, p, x) - np.interp(0.25, p, x)


def test_penumbra_matches_sun_cone_and_grows_with_distance():
    s = np.ones((40, 200))
    s[:, :100] = 0.2
    alpha = np.deg2rad(2.0)
    widths = []
    for d in (1.0, 4.0):
        out = shadows.soften_shadow(s, np.full(s.shape, d), alpha, pixels_per_metre=100.0, max_sigma_px=40.0)
        widths.append(_edge_width_px(out[20]))
        expected_sigma = d * np.tan(alpha) * 100.0
        assert widths[-1] == pytest.approx(1.349 * expected_sigma, rel=0.15)
    assert widths[1] > 3 * widths[0]


def test_soften_keeps_constant_and_unknown_distance_is_filled():
    s = np.full((20, 20), 0.4)
    d = np.full((20, 20), np.nan)
    d[5, 5] = 2.0
    assert np.allclose(shadows.soften_shadow(s, d, 0.01, 50.0), 0.4)
    assert np.allclose(shadows.soften_shadow(s, None, 0.01, 50.0), 0.4)


def test_soften_off_the_ground_needs_no_distance():
    """Pixels without a scale (ppm 0: off the ground patch) take the least blur whatever their occluder distance:
    leaving their unknown distances unfilled gives, bit for bit, what filling them from the nearest known pixel
    gives; an unknown distance where the scale is known is filled."""
    rng = np.random.default_rng(0)
    s = np.where(rng.random((40, 60)) < 0.3, 0.3, 1.0)
    ground = np.zeros((40, 60), bool)
    ground[8:35, 5:50] = True
    d = np.where(ground, rng.uniform(0.05, 3.0, (40, 60)), np.nan)
    ppm = np.where(ground, rng.uniform(20.0, 300.0, (40, 60)), 0.0)
    filled = shadows.fill_nearest(np.where(ground, d, 0.0), ground)
    out = shadows.soften_shadow(s, d, 0.05, ppm, min_sigma_px=0.7)
    np.testing.assert_array_equal(out, shadows.soften_shadow(s, filled, 0.05, ppm, min_sigma_px=0.7))
    d[20, 20] = np.nan  # on the ground: its distance is its nearest known neighbour's
    out = shadows.soften_shadow(s, d, 0.05, ppm, min_sigma_px=0.7)
    np.testing.assert_array_equal(
        out,
        shadows.soften_shadow(
            s, shadows.fill_nearest(np.where(np.isfinite(d), d, 0.0), np.isfinite(d)), 0.05, ppm, min_sigma_px=0.7
        ),
    )


@settings(max_examples=25, deadline=None)
@given(st.floats(0, 1e5), st.floats(0.0, 0.5), st.floats(0, 1e3))
def test_soften_finite_and_in_range(dist, alpha, ppm):
    s = np.ones((16, 16))
    s[4:10, 4:10] = 0.0
    out = shadows.soften_shadow(s, np.full(s.shape, dist), alpha, ppm)
    assert np.all(np.isfinite(out)) and out.min() >= 0 and out.max() <= 1


def test_occluder_distance_by_brute_force_is_the_trees(monkeypatch):
    """A box's corners are searched by brute force: the same distances, bit for bit, as the k-d tree gives (the
    path of larger footprints), and the nearest corner's Euclidean distance over cos(elevation)."""
    rng = np.random.default_rng(0)
    g = rng.normal(0.0, 2.0, (5000, 2))
    box = np.array([[x, y] for x in (-0.21, 0.19) for y in (-0.2, 0.23) for _ in range(2)])  # 8 corners, 4 distinct
    el = np.deg2rad(35.0)
    brute = shadows.occluder_distance_from_footprint(g, box, el)
    monkeypatch.setattr(shadows, "_BRUTE_FORCE_POINTS", 0)
    np.testing.assert_array_equal(brute, shadows.occluder_distance_from_footprint(g, box, el))
    nearest = np.min(np.hypot(g[:, None, 0] - box[None, :, 0], g[:, None, 1] - box[None, :, 1]), axis=1)
    np.testing.assert_allclose(brute, nearest / np.cos(el), rtol=1e-12)


def test_occluder_distance_and_contact():
    g = np.array([[1.0, 0.0], [0.0, 0.0]])
    d = shadows.occluder_distance_from_footprint(g, np.array([[0.0, 0.0]]), np.deg2rad(60.0))
    assert np.allclose(d, [2.0, 0.0])  # rho / cos 60
    a = shadows.contact_occlusion(np.array([0.0, 10.0]), object_height_m=1.0, strength=0.6)
    assert a[0] == pytest.approx(0.4) and a[1] == pytest.approx(1.0, abs=1e-6)
