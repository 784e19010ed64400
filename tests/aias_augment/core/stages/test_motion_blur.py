"""Motion blur of an object's layer. Truths derived without the stage's code: a line of length L has the variance
of the uniform distribution on [-L/2, L/2] (L^2 / 12) along it and none across; a normalised convolution keeps the
layer's coverage mass; an object of one colour and one depth keeps them on its streak."""

import numpy as np
import pytest

from aias_augment.core.stages import ObjectLayer
from aias_augment.core.stages.motion_blur import STAGE, line_kernel
from aias_augment.pipeline.config import InsertionConfig


def _moments(k: np.ndarray, angle_deg: float):
    ys, xs = np.mgrid[: k.shape[0], : k.shape[1]]
    c = k.shape[0] // 2
    a = np.radians(angle_deg)
    along = (xs - c) * np.cos(a) + (ys - c) * np.sin(a)
    across = -(xs - c) * np.sin(a) + (ys - c) * np.cos(a)
    return (k * along).sum(), (k * across).sum(), (k * along**2).sum(), (k * across**2).sum()


@pytest.mark.parametrize("length", [1.0, 2.5, 7.0, 20.0])
@pytest.mark.parametrize("angle", [0.0, 30.0, 90.0, 135.0])
def test_line_kernel_is_a_centred_uniform_segment(length, angle):
    k = line_kernel(length, angle)
    assert k.shape[0] == k.shape[1] and k.shape[0] % 2 == 1
    assert abs(k.sum() - 1) < 1e-5 and (k >= 0).all()
    m_along, m_across, v_along, v_across = _moments(k, angle)
    assert abs(m_along) < 1e-4 and abs(m_across) < 1e-4
    # Bilinear splatting adds at most 1/4 px^2 of variance in each direction (a sample between two pixels).
    assert length**2 / 12 - 0.01 <= v_along <= length**2 / 12 + 0.25
    assert v_across <= 0.25


def _square_layer(colour=(0.6, 0.3, 0.1), depth=7.0, size=21, object_px=9):
    alpha = np.zeros((size, size), np.float32)
    lo = (size - object_px) // 2
    alpha[lo : lo + object_px, lo : lo + object_px] = 1.0
    rgb = alpha[..., None] * np.asarray(colour, np.float32)
    return ObjectLayer((100, 50, 100 + size, 50 + size), alpha, alpha * depth, rgb)


def test_blur_keeps_coverage_mass_colour_and_depth_and_streaks_along_its_direction():
    layer = _square_layer()
    out = STAGE.apply(layer, {"length_px": 8.0, "angle_deg": 0.0}, None)
    assert abs(out.alpha.sum() - layer.alpha.sum()) < 1e-3 * layer.alpha.sum()
    covered = out.alpha > 1e-3
    assert np.allclose(out.rgb[covered], [0.6, 0.3, 0.1], atol=1e-4)
    assert np.allclose(out.depth[covered], 7.0, atol=1e-4)
    rows, cols = np.nonzero(covered)
    assert rows.max() - rows.min() + 1 == 9  # across the motion: unchanged
    assert cols.max() - cols.min() + 1 >= 9 + 8 - 1  # along it: longer by the streak
    # The window grew around the old one (nothing of the streak is cut off).
    x0, y0, x1, y1 = out.roi
    assert x0 < 100 and y0 < 50 and x1 > 121 and y1 > 71 and out.alpha.shape == (y1 - y0, x1 - x0)


def test_in_a_clip_the_streak_follows_the_objects_own_motion():
    layer = _square_layer()
    out = STAGE.apply(layer, {"length_px": 8.0, "angle_deg": 0.0}, np.array([0.0, 3.0]))  # moving down
    rows, cols = np.nonzero(out.alpha > 1e-3)
    assert cols.max() - cols.min() + 1 == 9 and rows.max() - rows.min() + 1 >= 16


def test_under_half_a_pixel_is_no_blur():
    layer = _square_layer()
    assert STAGE.apply(layer, {"length_px": 0.3, "angle_deg": 40.0}, None) is layer


def test_draws_within_the_configured_range_and_is_off_by_default():
    assert not STAGE.enabled(InsertionConfig())
    cfg = InsertionConfig(motion_blur_px=(2.0, 5.0))
    assert STAGE.enabled(cfg)
    draws = [STAGE.draw(cfg, np.random.default_rng(s)) for s in range(50)]
    assert all(2.0 <= d["length_px"] <= 5.0 and 0 <= d["angle_deg"] < 180 for d in draws)


@pytest.mark.parametrize("bad", [(-1.0, 2.0), (3.0, 1.0)])
def test_a_bad_range_is_refused_at_construction(bad):
    with pytest.raises(ValueError, match="motion_blur_px"):
        InsertionConfig(motion_blur_px=bad)
