import numpy as np
import pytest

from aias_augment.lighting import envmap as em, sh
from aias_augment.lighting.estimate import LightingEstimate
from aias_augment.lighting.shading import shade_object


def _uniform_sky(L=0.5):
    return sh.project_envmap_to_sh(np.full((128, 256, 3), L))


def test_white_surface_under_uniform_sky_shows_sky_radiance():
    light = LightingEstimate(None, np.zeros(3), _uniform_sky(0.5), 0.0, False, 1.0, "test")
    n = np.zeros((4, 4, 3))
    n[..., 2] = -1.0
    out = shade_object(np.ones((4, 4, 3)), n, np.ones((4, 4), bool), light)
    assert np.allclose(out, 0.5, rtol=1e-3)


def test_sun_term_cosine_and_visibility():
    sun_dir = np.array([0.0, -1.0, 0.0])  # straight up in a level camera
    light = LightingEstimate(sun_dir, np.array([np.pi, np.pi, np.pi]), np.zeros((9, 3)), 2.0, True, 1.0, "test")
    n = np.zeros((1, 3, 3))
    n[0, 0] = [0, -1, 0]  # facing the sun
    n[0, 1] = [0, -np.sqrt(0.5), -np.sqrt(0.5)]  # 45 deg
    n[0, 2] = [0, 1, 0]  # facing away
    albedo = np.full((1, 3, 3), 0.5)
    out = shade_object(albedo, n, np.ones((1, 3), bool), light)
    assert out[0, :, 0] == pytest.approx([0.5, 0.5 * np.sqrt(0.5), 0.0], abs=1e-6)
    shadowed = shade_object(albedo, n, np.ones((1, 3), bool), light, sun_visibility=np.zeros((1, 3)))
    assert np.allclose(shadowed, 0.0)
    assert np.all(shade_object(albedo, n, np.zeros((1, 3), bool), light) == 0)


def test_degenerate_normals_and_bad_shapes():
    light = LightingEstimate(None, np.zeros(3), _uniform_sky(1e5), 0.0, False, 1.0, "test")
    out = shade_object(np.ones((2, 2, 3)), np.zeros((2, 2, 3)), np.ones((2, 2), bool), light)
    assert np.all(np.isfinite(out)) and out.max() == pytest.approx(1e5, rel=1e-3)
    with pytest.raises(ValueError):
        shade_object(np.ones((2, 2, 3)), np.zeros((2, 3, 3)), np.ones((2, 2), bool), light)


def test_fluorescent_gain_only_on_saturated_orange_and_never_above_white():
    from aias_augment.lighting.hdr import srgb_to_linear
    from aias_augment.lighting.shading import FLUORESCENT_GAIN, fluorescent_gain
    srgb = np.array([[255, 72, 18], [208, 64, 16], [240, 224, 224], [128, 128, 128], [30, 90, 255], [120, 40, 10],
                     [255, 0, 80], [230, 160, 120]], np.uint8)
    # orange (hue 13 deg, s 0.93, v 1), orange (15 deg, 0.92, 0.82), white, grey, blue, dark orange (v 0.47),
    # pink (hue < 0), pale orange (s 0.48)
    g = fluorescent_gain(srgb_to_linear(srgb))
    assert np.allclose(g, [FLUORESCENT_GAIN, FLUORESCENT_GAIN, 1, 1, 1, 1, 1, 1])
    # shading: a white and an orange albedo under the same uniform light; no channel of the orange exceeds white's
    light = LightingEstimate(None, np.zeros(3), _uniform_sky(1.0), 0.0, False, 1.0, "none")
    albedo = srgb_to_linear(srgb[[0, 1, 2]])[:, None].repeat(2, 1)
    albedo[2] = 1.0
    normals = np.tile(np.array([0.0, -1.0, 0.0]), (3, 2, 1))
    out = shade_object(albedo, normals, np.ones((3, 2), bool), light)
    assert out[:2].max() <= out[2].max() + 1e-6
    assert np.allclose(out[1, 0], np.minimum(albedo[1, 0] * FLUORESCENT_GAIN, 1.0) * out[2, 0], rtol=1e-5)
