import cv2
import numpy as np
import pytest

from aias_augment.apply.harmonize import camera_pipeline as cp
from aias_augment.apply.harmonize.camera_pipeline import (
    CameraMatchParams,
    apply_atmosphere,
    camera_match,
    chroma_subsampled,
    estimate_gains,
    estimate_jpeg_quality,
    match_blur,
    noise_level_function,
    sharpness_index,
)
from aias_augment.apply.harmonize.color import linear_to_srgb, srgb_to_linear
from aias_augment.apply.harmonize.regions import ring
from aias_augment.core.config import data_root

FULL = CameraMatchParams(
    exposure_strength=1.0, wb_strength=1.0, match_sharpness=False, match_noise=False, match_jpeg=False
)


def stationary_texture(h=160, w=200, seed=0, period=10):
    """A tiled random colour patch: a region and a ring aligned to the tiles hold exactly the same pixel values."""
    rng = np.random.default_rng(seed)
    tile = (0.1 + 0.5 * rng.random((period, period, 3)) * np.array([1.0, 0.9, 0.7])).astype(np.float32)
    return np.tile(tile, (h // period, w // period, 1))  # at most 0.6: no clipping after a 2x linear gain


def square_mask(h, w, x0, y0, s):
    m = np.zeros((h, w), bool)
    m[y0 : y0 + s, x0 : x0 + s] = True
    return m


@pytest.mark.parametrize("gains", [(2.0, 2.0, 2.0), (0.6, 0.6, 0.6), (1.3, 1.0, 0.7), (0.8, 1.1, 1.4)])
def test_recovers_known_exposure_and_wb_gain(gains):
    srgb = stationary_texture()
    mask = square_mask(160, 200, 70, 50, 60)
    lin = srgb_to_linear(srgb)
    lin[mask] *= np.asarray(gains, np.float32)
    est = estimate_gains(lin, mask, ring(mask, 20), FULL)
    np.testing.assert_allclose(est * np.asarray(gains), 1.0, rtol=0.05)


def test_gain_estimate_is_equivariant_on_a_real_image(street_rgb):
    """On real content the estimate moves by exactly the applied gain (up to quantisation)."""
    srgb = street_rgb.astype(np.float32) / 255
    mask = square_mask(*srgb.shape[:2], 120, 140, 50)
    surround = ring(mask, 20)
    lin = srgb_to_linear(srgb)
    base = estimate_gains(lin, mask, surround, FULL)
    gains = np.array([1.25, 1.0, 0.8], np.float32)
    lin2 = lin.copy()
    lin2[mask] *= gains
    np.testing.assert_allclose(estimate_gains(lin2, mask, surround, FULL) * gains / base, 1.0, rtol=0.03)


def test_camera_match_restores_a_brightened_region():
    srgb = stationary_texture()
    target = np.rint(srgb * 255).astype(np.uint8)
    mask = square_mask(160, 200, 70, 50, 60)
    lin = srgb_to_linear(srgb)
    lin[mask] *= np.array([1.6, 1.2, 0.9], np.float32)
    comp = np.rint(linear_to_srgb(lin) * 255).astype(np.uint8)
    out = camera_match(comp, mask, np.random.default_rng(0), FULL)
    err = lambda a: np.mean((a[mask].astype(float) - target[mask]) ** 2)  # noqa: E731
    assert err(out) < 0.05 * err(comp)
    np.testing.assert_array_equal(out[~mask], comp[~mask])


def test_noise_level_function_recovers_signal_dependent_noise():
    rng = np.random.default_rng(1)
    ramp = np.tile(np.linspace(0.1, 0.9, 256, dtype=np.float32), (192, 1))
    a, b = 4e-4, 1e-5
    noisy = ramp + np.sqrt(a * ramp + b) * rng.standard_normal(ramp.shape).astype(np.float32)
    nlf = noise_level_function(noisy, np.ones_like(ramp, bool))
    assert nlf is not None
    for level in (0.2, 0.5, 0.8):
        assert np.sqrt(nlf[0] * level + nlf[1]) == pytest.approx(np.sqrt(a * level + b), rel=0.2)


def test_noise_is_added_to_a_clean_object():
    rng = np.random.default_rng(2)
    img = np.clip(0.5 + 0.03 * rng.standard_normal((120, 160, 3)), 0, 1).astype(np.float32)
    mask = square_mask(120, 160, 50, 30, 50)
    img[mask] = 0.5
    comp = np.rint(img * 255).astype(np.uint8)
    params = CameraMatchParams(match_sharpness=False, match_jpeg=False)
    out = camera_match(comp, mask, np.random.default_rng(0), params).astype(np.float32) / 255
    assert out[mask].std() == pytest.approx(img[~mask].std(), rel=0.25)


def test_blur_is_matched_to_a_defocused_background(street_rgb):
    srgb = street_rgb.astype(np.float32) / 255
    blurred = cv2.GaussianBlur(srgb, (0, 0), 2.0)
    mask = square_mask(*srgb.shape[:2], 130, 60, 70)
    comp = blurred.copy()
    comp[mask] = srgb[mask]  # a sharp object pasted into a blurred photo
    surround = ring(mask, 25)
    out = match_blur(comp, mask, surround, CameraMatchParams(motion_coherence_threshold=1.1))
    inner = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    target = sharpness_index(blurred @ np.array([0.2126, 0.7152, 0.0722], np.float32), inner)
    before = sharpness_index(comp @ np.array([0.2126, 0.7152, 0.0722], np.float32), inner)
    after = sharpness_index(out @ np.array([0.2126, 0.7152, 0.0722], np.float32), inner)
    assert abs(after - target) < 0.3 * abs(before - target)
    np.testing.assert_array_equal(out[~mask], comp[~mask])


def _blur_on_the_whole_crop(img, fg, surround, params):
    """match_blur's choice made by blurring the whole crop with every trial kernel (no window)."""
    luma = np.array([0.2126, 0.7152, 0.0722], np.float32)
    inner = cv2.erode(fg.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    target, own = sharpness_index(img @ luma, surround), sharpness_index(img @ luma, inner)
    kernels = list(np.linspace(0.3, params.max_blur_sigma_px, 12))
    best, best_err = img, abs(own - target)
    for k in kernels:
        blurred = cv2.GaussianBlur(img, (0, 0), k)
        err = abs(sharpness_index(blurred @ luma, inner) - target)
        if err < best_err:
            best, best_err = blurred, err
    out = img.copy()
    out[fg] = best[fg]
    return out


@pytest.mark.parametrize("where", ["middle", "corner", "edge"])
def test_blur_trials_on_the_foreground_window_match_the_whole_crop(street_rgb, where):
    """The trial blurs run on the foreground's box grown by the kernels' reach: the same result (to float32 rounding)
    as blurring the whole crop, with the object in the middle, in a corner and against an edge of the crop."""
    srgb = street_rgb.astype(np.float32) / 255
    blurred = cv2.GaussianBlur(srgb, (0, 0), 1.6)
    h, w = srgb.shape[:2]
    x0, y0 = {"middle": (w // 2 - 15, h // 2 - 15), "corner": (2, 2), "edge": (w - 32, h // 2)}[where]
    mask = square_mask(h, w, x0, y0, 30)
    comp = blurred.copy()
    comp[mask] = srgb[mask]
    params = CameraMatchParams(motion_coherence_threshold=1.1)
    surround = ring(mask, 12)
    got, want = match_blur(comp, mask, surround, params), _blur_on_the_whole_crop(comp, mask, surround, params)
    assert not np.array_equal(got, comp)  # a blur was chosen
    np.testing.assert_allclose(got, want, atol=3e-7, rtol=0)


def _every_block_dct(channel: np.ndarray) -> np.ndarray:
    """The orthonormal DCT-II of every 8x8 block on the grid at (0, 0): (rows, cols, 8, 8)."""
    from scipy.fft import dctn

    h, w = (channel.shape[0] // 8) * 8, (channel.shape[1] // 8) * 8
    return dctn(channel[:h, :w].reshape(h // 8, 8, w // 8, 8).transpose(0, 2, 1, 3), axes=(2, 3), norm="ortho")


@pytest.mark.parametrize("crop", [(0, 0), (3, 5)])
@pytest.mark.parametrize("size", [(240, 320), (1080, 1920)])
def test_jpeg_quality_reads_the_same_blocks_as_transforming_them_all(street_rgb, size, crop):
    """The estimate transforms only the ~2000 blocks it reads: their coefficients are those of the whole image's block
    DCT thinned to every k-th block (bit for bit), on a JPEG-compressed frame, its grid shifted by a crop, large and
    small."""
    big = cv2.resize(street_rgb, size[::-1], interpolation=cv2.INTER_LINEAR)
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(big, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 80])
    img = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)[crop[0] :, crop[1] :]
    y = img.astype(np.float64) @ np.array([0.299, 0.587, 0.114]) - 128.0
    every = _every_block_dct(y).reshape(-1, 8, 8)
    every = every[:: max(1, len(every) // 2000)]
    steps = [cp._lattice_step(every[:, u, v]) for u, v in cp._PROBE_FREQS]
    found = [(f, s) for f, s in zip(cp._PROBE_FREQS, steps) if s is not None]
    want = None
    if len(found) >= 3:
        err = [sum(abs(cp.ijg_table(q)[u, v] - s) / s for (u, v), s in found) for q in range(1, 101)]
        want = int(np.argmin(err[::-1]) * -1 + 100)
    assert estimate_jpeg_quality(img) == want
    if crop == (0, 0):
        assert want is not None and abs(want - 80) <= 5


@pytest.mark.parametrize("quality", [50, 75, 90])
def test_jpeg_quality_and_subsampling_are_estimated(street_rgb, quality):
    bgr = cv2.cvtColor(street_rgb, cv2.COLOR_RGB2BGR)
    samplings = ((cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420, True), (cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444, False))
    for sampling, expect in samplings:
        params = [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling]
        ok, buf = cv2.imencode(".jpg", bgr, params)
        dec = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        q = estimate_jpeg_quality(dec)
        assert q is not None and abs(q - quality) <= 5, (quality, q)
        assert chroma_subsampled(dec) is expect


@pytest.mark.parametrize("quality", [60, 90])
def test_subsampling_is_decided_from_a_bounded_sample_of_blocks(quality):
    """A lossless KITTI frame tiled to 2.4 MP (36 800 blocks, 7x the sample's bound) and encoded at 4:2:0 and 4:4:4:
    the decision from every 8th block is the encoder's sampling factor."""
    path = data_root() / "kitti06_color_snippet" / "kitti06-12-color.png"
    if not path.exists():
        pytest.skip(f"real data missing: {path}")
    bgr = cv2.imread(str(path))
    bgr = np.ascontiguousarray(np.tile(bgr, (3, 2, 1))[:1216, :1936])
    assert (1216 // 8) * (1936 // 8) > 4 * cp.CHROMA_MAX_BLOCKS
    samplings = ((cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420, True), (cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444, False))
    for sampling, expect in samplings:
        params = [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling]
        ok, buf = cv2.imencode(".jpg", bgr, params)
        dec = cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
        assert chroma_subsampled(dec) is expect


def test_png_without_jpeg_history_has_no_quality(street_rgb):
    # KITTI frames are lossless PNG from the camera; a half-pixel shift removes any block grid anyway.
    shifted = cv2.resize(street_rgb, None, fx=0.77, fy=0.77, interpolation=cv2.INTER_AREA)
    assert estimate_jpeg_quality(shifted) is None


def test_atmosphere_limits():
    img = np.random.default_rng(0).random((4, 4, 3)).astype(np.float32)
    air = np.array([0.8, 0.85, 0.9], np.float32)
    np.testing.assert_allclose(apply_atmosphere(img, 0.0, air, 0.01), img)
    np.testing.assert_allclose(apply_atmosphere(img, 1e4, air, 0.01), np.broadcast_to(air, img.shape), atol=1e-6)
    with pytest.raises(ValueError):
        apply_atmosphere(img, np.full((4, 4), np.nan), air, 0.01)


@pytest.mark.parametrize("shape", [(7, 7, 3), (8, 7, 3), (7, 400, 3), (9, 17, 3)])
def test_subsampling_on_images_with_no_or_few_whole_blocks(shape):
    """Under one whole 8x8 block there is no evidence (False); a few blocks are read without error."""
    img = np.random.default_rng(0).integers(0, 256, shape, dtype=np.uint8)
    got = chroma_subsampled(img)
    assert isinstance(got, bool)
    if shape[0] < 8 or shape[1] < 8:
        assert got is False
