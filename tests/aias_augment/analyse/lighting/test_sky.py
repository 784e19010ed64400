import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.analyse.lighting import envmap as em
from aias_augment.analyse.lighting import sky


def test_zenith_luminance_matches_formula_at_zenith():
    sun = em.azimuth_elevation_to_direction(0.0, np.deg2rad(40.0))
    Yz, _, _ = sky.preetham_zenith(3.0, np.deg2rad(50.0))
    rgb = sky.preetham_sky_radiance(np.array([0.0, 0.0, 1.0]), sun, turbidity=3.0)
    Y = float(rgb @ np.array([0.2126, 0.7152, 0.0722]))
    assert Y == pytest.approx(Yz, rel=0.02)


def test_brightest_near_sun_and_blue_overhead():
    sun = em.azimuth_elevation_to_direction(np.deg2rad(30.0), np.deg2rad(30.0))
    d = em.pixel_directions(32)
    rgb = sky.preetham_sky_radiance(d, sun)
    Y = rgb @ np.array([0.2126, 0.7152, 0.0722])
    Y[d[..., 2] < 0] = 0
    r, c = np.unravel_index(np.argmax(Y), Y.shape)
    assert np.degrees(np.arccos(np.clip(d[r, c] @ sun, -1, 1))) < 10
    zen = sky.preetham_sky_radiance(np.array([0.0, 0.0, 1.0]), sun)
    assert zen[2] > zen[0]


@settings(max_examples=40, deadline=None)
@given(st.floats(-10.0, 90.0), st.floats(-180, 180), st.floats(1.5, 15.0))
def test_sky_finite_including_horizon_sun(el_deg, az_deg, turbidity):
    sun = em.azimuth_elevation_to_direction(np.deg2rad(az_deg), np.deg2rad(el_deg))
    rgb = sky.preetham_sky_radiance(em.pixel_directions(8), sun, turbidity=turbidity)
    assert np.all(np.isfinite(rgb)) and rgb.min() >= 0


def test_bad_turbidity():
    with pytest.raises(ValueError):
        sky.perez_coefficients(0.5)


def test_exposure_fit_cost_equals_the_direct_fit():
    """The split fit (theta term per pixel, gamma term per candidate, exposure absorbed) gives the residual variance
    of fitting log(F / F0) + c directly with preetham_luminance_ratio, for every candidate and the best turbidity."""
    rng = np.random.default_rng(3)
    P, N = 300, 50
    d = rng.normal(size=(P, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    suns = rng.normal(size=(N, 3))
    suns /= np.linalg.norm(suns, axis=1, keepdims=True)
    up = np.array([0.0, 0.0, 1.0])
    cos_theta, cos_gamma = d @ up, np.clip(suns @ d.T, -1, 1)
    ly = rng.normal(0.0, 0.5, P)
    turbidities = (2.5, 4.0, 7.0)
    direct = np.full(N, np.inf)
    sun_zen = np.arccos(np.clip(suns @ up, -1, 1))[:, None]
    for T in turbidities:
        res = ly[None] - np.log(sky.preetham_luminance_ratio(cos_theta[None], np.arccos(cos_gamma), sun_zen, T))
        res -= res.mean(axis=1, keepdims=True)
        direct = np.minimum(direct, np.mean(res * res, axis=1))
    fast = sky.preetham_exposure_fit_cost(ly, cos_theta, cos_gamma, turbidities)
    np.testing.assert_allclose(fast, direct, rtol=1e-5, atol=1e-8)
    assert int(np.argmin(fast)) == int(np.argmin(direct))
    with pytest.raises(ValueError):
        sky.preetham_exposure_fit_cost(ly[:-1], cos_theta, cos_gamma)


def _exposure_fit_cost_whole_grid(ly, cos_theta, cos_gamma, turbidities):
    """preetham_exposure_fit_cost's arithmetic on the whole (N, P) grid at once: each element-wise step over the
    grid, the row reductions with float64 accumulation, one BLAS product."""
    ct = np.maximum(cos_theta, sky.MIN_COS_VIEW)
    cg = np.clip(cos_gamma, -1.0, 1.0)
    p = len(ly)
    gamma = np.arccos(cg.astype(np.float32))
    cg2 = np.square(cg, dtype=np.float32)
    best = np.full(cg.shape[0], np.inf)
    for T in turbidities:
        A, B, C, D, E = sky.perez_coefficients(T)["Y"]
        h = ly - np.log(np.maximum(1.0 + A * np.exp(B / ct), 1e-12))
        h -= h.mean()
        g = np.exp(gamma * np.float32(D)) * np.float32(C) + np.float32(1.0)
        g += np.float32(E) * cg2
        g = np.log(np.maximum(g, np.float32(1e-12)))
        gm = g.mean(axis=1, dtype=np.float64)
        gg = np.einsum("ij,ij->i", g, g, dtype=np.float64)
        cost = (h @ h) / p + gg / p - gm * gm - 2.0 * (g.astype(np.float64) @ h) / p
        best = np.minimum(best, np.maximum(cost, 0.0))
    return best


@pytest.mark.parametrize("n, p", [(2070, 800), (2070, 333), (97, 41), (3, 1), (5, 9000)])
def test_exposure_fit_cost_in_blocks_is_the_whole_grid_bit_for_bit(n, p):
    """The fit runs over blocks of candidates (so its chain of element-wise passes stays in the cache): the costs
    are those of the whole-grid evaluation exactly, for grids that are not a whole number of blocks and for rows
    longer than numpy's cast buffer (9000 > 8192)."""
    rng = np.random.default_rng(p)
    d = rng.normal(size=(p, 3))
    d[:, 2] = np.abs(d[:, 2])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    suns = rng.normal(size=(n, 3))
    suns /= np.linalg.norm(suns, axis=1, keepdims=True)
    ly = rng.normal(-2.0, 0.5, p)
    cos_gamma = suns @ d.T * 1.0000001  # a few just outside [-1, 1]: the fit clips them
    args = (ly, d[:, 2], cos_gamma, (2.5, 4.0, 7.0))
    np.testing.assert_array_equal(sky.preetham_exposure_fit_cost(*args), _exposure_fit_cost_whole_grid(*args))
