import numpy as np
import pytest

from aias_augment.analyse.lighting import ratio
from aias_augment.core.geometry import Intrinsics


def _ground(r_true, with_shadow=True, seed=0):
    rng = np.random.default_rng(seed)
    albedo = 0.2 * np.exp(rng.normal(0, 0.08, (120, 160)))  # asphalt-like texture
    vis = np.ones((120, 160))
    if with_shadow:
        vis[30:60, 20:140] = 0.0  # a cast shadow band
        vis[80:90, 40:100] = 0.0
    sky = np.array([0.8, 0.9, 1.1])  # bluish sky light
    sun = np.array([1.0, 0.95, 0.85])
    E = sky[None, None] + r_true * sun[None, None] * vis[..., None] * (1.0 / sun.mean()) * sky.mean()
    return (albedo[..., None] * E * 0.3).astype(np.float32)


@pytest.mark.parametrize("r_true", [1.5, 4.0, 8.0])
def test_ratio_recovered_on_synthetic_ground(r_true):
    img = _ground(r_true)
    m = ratio.measure_lit_shadow(img, np.ones(img.shape[:2], bool))
    assert m.dominant_sun
    assert m.sun_sky_ratio == pytest.approx(r_true, rel=0.1)


def test_overcast_ground_has_no_dominant_sun():
    img = _ground(0.0, with_shadow=False)
    m = ratio.measure_lit_shadow(img, np.ones(img.shape[:2], bool))
    assert not m.dominant_sun


def test_too_few_pixels_and_black():
    img = _ground(3.0)
    assert ratio.measure_lit_shadow(img, np.zeros(img.shape[:2], bool)) is None
    assert ratio.measure_lit_shadow(np.zeros_like(img), np.ones(img.shape[:2], bool)) is None
    with pytest.raises(ValueError):
        ratio.measure_lit_shadow(img, np.ones((3, 3), bool))


def test_ground_region_is_below_horizon_and_in_front():
    K = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, 1226, 370)
    m = ratio.ground_region_mask(K, np.array([0.0, -1.0, 0.0]), 1.65, (-1.5, 1.5), (5.0, 20.0))
    v, u = np.nonzero(m)
    # Rows: ground 20 m ahead projects to cy + f h / 20, 5 m ahead below the image bottom.
    assert v.min() == pytest.approx(183.1104 + 707.0912 * 1.65 / 20, abs=1.5)
    assert v.max() == 369
    assert abs(u.mean() - 601.9) < 30


def test_shadow_axis_of_pole_shadow_bands():
    # Thin, broken shadow bands at 30 deg from the lateral axis on a ground grid: the axis is recovered.
    xs, ys = np.meshgrid(np.linspace(-2, 2, 200), np.linspace(5, 20, 300))
    ground = np.stack([xs, ys], axis=-1)
    region = np.ones(xs.shape, bool)
    th = np.deg2rad(30.0)
    normal = np.array([-np.sin(th), np.cos(th)])
    dist = ground @ normal
    shadow = (np.abs(dist - 7.0) < 0.05) | (np.abs(dist - 11.0) < 0.05)
    shadow &= np.random.default_rng(0).random(xs.shape) > 0.3  # fragmented
    angle, strength = ratio.shadow_axis_on_ground(shadow, region, ground)
    assert abs(np.rad2deg(angle) - 30.0) < 4.0 and strength > 0.5
    assert ratio.shadow_axis_on_ground(np.zeros_like(shadow), region, ground) == (0.0, 0.0)


def _axis_by_histograms(shadow, region, ground, bin_m, step_deg):
    """The projection-profile axis as its docstring defines it, with np.histogram's bins for both point sets."""
    from scipy import ndimage

    shadow = shadow & region
    if shadow.sum() < 50 or region.sum() < 50:  # the documented minimum
        return 0.0, 0.0
    ps, pr = ground[shadow], ground[region]
    thetas = np.deg2rad(np.arange(0.0, 180.0, step_deg))
    rel = np.empty(len(thetas))
    for k, th in enumerate(thetas):
        normal = np.array([-np.sin(th), np.cos(th)])
        a, b = ps @ normal, pr @ normal
        edges = np.arange(b.min(), b.max() + 2 * bin_m, bin_m)
        hs, hr = np.histogram(a, edges)[0].astype(float), np.histogram(b, edges)[0].astype(float)
        rel[k] = (np.sum(hs**2) / len(a) ** 2) / max(np.sum(hr**2) / len(b) ** 2, 1e-12)
    rel = ndimage.uniform_filter1d(rel, 3, mode="wrap")
    best = int(np.argmax(rel))
    return float(thetas[best]), float(np.clip(1.0 - np.median(rel) / max(rel[best], 1e-12), 0.0, 1.0))


def test_shadow_axis_counts_the_bins_np_histogram_counts():
    """Ground coordinates on grids whose points fall exactly on bin edges (and the last edge), random masks: the axis
    and its strength equal those of np.histogram's profiles, bit for bit."""
    rng = np.random.default_rng(0)
    for t in range(60):
        h, w = rng.integers(20, 90, 2)
        xs, ys = np.meshgrid(
            np.arange(w) * rng.choice([0.1, 0.05, 0.005, 1 / 30]), np.arange(h) * rng.choice([0.1, 0.2])
        )
        ground = np.stack([xs, ys], axis=-1) + rng.choice([0.0, 0.05, -3.0])
        if t % 3 == 0:
            ground = ground + rng.normal(0, 0.3, ground.shape)
        region, shadow = rng.random((h, w)) < rng.uniform(0.3, 1), rng.random((h, w)) < rng.uniform(0.05, 0.6)
        kw = dict(bin_m=float(rng.choice([0.1, 0.05, 0.3])), step_deg=float(rng.choice([2.0, 5.0, 45.0, 90.0])))
        assert ratio.shadow_axis_on_ground(shadow, region, ground, **kw) == _axis_by_histograms(
            shadow, region, ground, **kw
        ), (t, kw)


def test_sun_over_sky_colour_from_a_lit_and_shadowed_pair_and_a_non_physical_pair_made_grey():
    from aias_augment.analyse.lighting.ambient import sun_over_sky_rgb
    from aias_augment.analyse.lighting.config import LightingConfig
    from aias_augment.core.hdr import luminance

    # a warm sun and a blue sky on one coloured surface: lit = a (E_sky + E_sun cos z), shadow = a E_sky
    albedo = np.array([0.55, 0.25, 0.08])
    e_sky, e_sun_cosz = np.array([0.30, 0.36, 0.48]), np.array([2.4, 2.1, 1.7])
    r = sun_over_sky_rgb(albedo * (e_sky + e_sun_cosz), albedo * e_sky, 2.5)
    np.testing.assert_allclose(r, e_sun_cosz / e_sky, rtol=1e-9)  # the albedo cancels
    # a shadow over a patch of another colour: no green left in the sun, which daylight cannot be
    bad_lit, bad_shadow = np.array([0.30, 0.12, 0.10]), np.array([0.17, 0.116, 0.085])
    raw = bad_lit / bad_shadow - 1
    got = sun_over_sky_rgb(bad_lit, bad_shadow, 2.5)
    assert got[0] == got[1] == got[2]
    assert float(luminance(got)) == pytest.approx(float(luminance(raw)))
    # darker in shadow in no channel: no sun at all
    np.testing.assert_array_equal(sun_over_sky_rgb(np.full(3, 0.2), np.full(3, 0.3), 2.5), np.zeros(3))
    with pytest.raises(ValueError, match="max_sun_sky_chroma"):
        LightingConfig(max_sun_sky_chroma=0.9)


def _lit_shadow_on_the_whole_image(img, region, erode_px=0):
    """measure_lit_shadow's statistics computed over every pixel of the image in float64, then read in the region:
    (usable, lit, shadow, lit/shadow medians, separation); None where it finds too few pixels."""
    from scipy import ndimage

    img = np.asarray(img, np.float64)
    Y = (img.astype(np.float32) @ np.array([0.2126, 0.7152, 0.0722], np.float32)).astype(np.float64)
    usable = region & np.isfinite(Y) & (Y > 1e-4) & (img.max(axis=2) < 0.97)
    if usable.sum() < 200:
        return None
    chroma = img / np.maximum(img.sum(axis=2, keepdims=True), 1e-6)
    dev = chroma - np.median(chroma[usable], axis=0)
    dev[..., 2] = np.where(dev[..., 2] > 0, dev[..., 2] * 0.5, dev[..., 2])
    usable &= np.abs(dev).max(axis=2) < 0.08
    if usable.sum() < 200:
        return None
    logY = np.log(np.maximum(Y, 1e-6)).ravel()
    idx = np.flatnonzero(usable.ravel())
    fit_idx = idx[np.linspace(0, idx.size - 1, 8000).round().astype(int)] if idx.size > 8000 else idx
    gm = ratio.TwoGaussians.fit(logY[fit_idx])
    mu, var = gm.means, gm.variances
    dark = int(np.argmin(mu))
    odds = np.zeros(Y.size)
    odds[idx] = gm.log_odds(logY[idx]) * (1.0 if dark == 0 else -1.0)
    odds = odds.reshape(Y.shape)
    shadow, lit = usable & (odds >= np.log(0.95 / 0.05)), usable & (odds <= -np.log(0.95 / 0.05))
    if erode_px:
        shadow = ndimage.binary_erosion(shadow, iterations=erode_px)
        lit = ndimage.binary_erosion(lit, iterations=erode_px)
    separation = float(abs(mu.max() - mu.min()) / np.sqrt(0.5 * (var[0] + var[1])))
    return usable, lit, shadow, np.median(img[lit], 0), np.median(img[shadow], 0), np.median(Y[lit]), separation


@pytest.mark.parametrize("erode_px", [0, 1])
@pytest.mark.parametrize("big", [False, True])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_region_pixels_only_give_the_whole_image_statistics(erode_px, big, dtype):
    """The measurement reads only the region's pixels: its masks, medians and mixture are those of the same
    statistics computed over the whole image (bit for bit), with lane paint (a chroma outlier), clipped and black
    pixels in the region, more usable pixels than the mixture's sample (``big``: 8000 evenly spaced), and float64 colours
    (whose channel sums depend on the order of the additions)."""
    img = _ground(4.0, seed=1).astype(dtype)
    if dtype == np.float64:
        img *= np.random.default_rng(2).uniform(0.999, 1.001, img.shape)
    if big:
        img = np.tile(img, (2, 2, 1))
    img[100:104, 10:150] = [0.6, 0.55, 0.1]  # yellow paint
    img[5:9, 5:60] = 1.0  # clipped
    img[110:114, 100:140] = 0.0  # black
    region = np.zeros(img.shape[:2], bool)
    region[3:, 4:-7] = True
    m = ratio.measure_lit_shadow(img, region, erode_px=erode_px)
    usable, lit, shadow, lit_rgb, shadow_rgb, lit_y, separation = _lit_shadow_on_the_whole_image(img, region, erode_px)
    assert m.dominant_sun and m.n_pixels == usable.sum()
    np.testing.assert_array_equal(m.lit_mask, lit)
    np.testing.assert_array_equal(m.shadow_mask, shadow)
    np.testing.assert_array_equal(m.lit_rgb, lit_rgb)
    np.testing.assert_array_equal(m.shadow_rgb, shadow_rgb)
    assert m.lit_luminance == lit_y and m.separation == separation


@pytest.mark.parametrize("shadow_share", [0.03, 0.2, 0.5, 0.8])
@pytest.mark.parametrize("seed", [0, 1])
def test_two_gaussians_match_sklearn_mixture(shadow_share, seed):
    """The draw-free 1-D mixture finds what sklearn's GaussianMixture (k-means start, 20 restarts) finds on bimodal
    log-luminance: means, standard deviations and weights, and posteriors on a grid."""
    from sklearn.mixture import GaussianMixture

    rng = np.random.default_rng(seed)
    n = 8000
    k = int(shadow_share * n)
    x = np.concatenate([rng.normal(-2.3, 0.25, k), rng.normal(-0.9, 0.18, n - k)])
    mine = ratio.TwoGaussians.fit(x, tol=1e-6)
    ref = GaussianMixture(2, n_init=20, tol=1e-6, random_state=seed).fit(x[:, None])
    order, ref_order = np.argsort(mine.means), np.argsort(ref.means_.ravel())
    np.testing.assert_allclose(mine.means[order], ref.means_.ravel()[ref_order], atol=2e-3)
    np.testing.assert_allclose(np.sqrt(mine.variances[order]), np.sqrt(ref.covariances_.ravel()[ref_order]), atol=2e-3)
    np.testing.assert_allclose(mine.weights[order], ref.weights_[ref_order], atol=2e-3)
    grid = np.linspace(-3.5, 0.0, 50)
    np.testing.assert_allclose(
        mine.posterior(grid)[:, order], ref.predict_proba(grid[:, None])[:, ref_order], atol=5e-3
    )


def test_two_gaussians_refuse_a_constant_sample():
    with pytest.raises(ValueError, match="two or more distinct values"):
        ratio.TwoGaussians.fit(np.full(100, 0.5))


def test_lit_shadow_measurement_does_not_move_with_the_order_of_draws():
    """No generator: the same image gives the same measurement, and a region larger than the mixture's sample (8000)
    still splits a clean two-level ground exactly at its shadow edge."""
    img = np.tile(_ground(4.0, seed=3), (2, 2, 1))
    region = np.ones(img.shape[:2], bool)
    a, b = ratio.measure_lit_shadow(img, region), ratio.measure_lit_shadow(img.copy(), region.copy())
    assert a.n_pixels > 8000
    np.testing.assert_array_equal(a.shadow_mask, b.shadow_mask)
    assert a.sun_sky_ratio == b.sun_sky_ratio and a.dominant_sun
