"""Issue 15, "white stays white": in a photo without colour the light has no colour the camera recorded, so a neutral
(white) Lambertian surface must come out neutral in every orientation, R = G = B. The truth is that physical
statement (a grey image cannot tell one light colour from another), not an output of the code under test."""

from dataclasses import replace

import numpy as np
import pytest

from aias_augment.analyse.lighting.estimate import LightingConfig, estimate_lighting
from aias_augment.apply.composite import to_uint8
from aias_augment.apply.shading import irradiance_at_normals, shade_object
from aias_augment.core.geometry import Intrinsics
from tests.aias_augment.analyse.lighting.synthetic_scene import Box, render, sun_direction
from tests.aias_augment.fixtures import tracon_train_photo

K = Intrinsics.from_fov(320, 240, 60.0)


def _grey(img: np.ndarray) -> np.ndarray:
    y = np.round(img.astype(np.float64) @ [0.299, 0.587, 0.114]).clip(0, 255).astype(np.uint8)
    return np.repeat(y[..., None], 3, axis=2)


def _white_sphere(est, n=2000):
    """Unit normals over the whole sphere, the (H, W, 3) shading of a white (albedo 0.9) surface there, uint8."""
    rng = np.random.default_rng(3)
    normals = rng.normal(size=(n, 1, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    shaded = shade_object(np.full((n, 1, 3), 0.9, np.float32), normals, np.ones((n, 1), bool), est)
    return normals, to_uint8(shaded)[:, 0].astype(int)


def _check_neutral(est):
    normals, px = _white_sphere(est)
    E = irradiance_at_normals(normals[:, 0], est)
    lit = E.max(1) > 1e-4
    assert lit.mean() > 0.5
    log_br = np.log(E[lit, 2] / E[lit, 0])
    assert np.abs(log_br).max() < 0.01  # irradiance: B / R within 1 %
    assert np.abs(px[:, 2] - px[:, 0]).max() <= 1  # pixels: R = G = B to the 8-bit level
    assert np.abs(px[:, 1] - px[:, 0]).max() <= 1


@pytest.mark.parametrize("sunny", [True, False])
def test_white_stays_white_in_a_grey_synthetic_road(sunny):
    boxes = [Box((-3.0, 0.0, 9.0), (1.0, 1.2, 1.0)), Box((2.0, 0.0, 12.0), (1.5, 2.0, 1.0))]
    img, _ = render(boxes, sun_direction(60.0, 40.0), K, exposure=0.8, noise=0.0, sun_irradiance=6.0 if sunny else 0.0)
    grey = _grey(img)
    _check_neutral(estimate_lighting(grey, None, None, {}))
    # the model sky's own colour (the previous fill) gave the grey photo's light a colour: the check is not vacuous
    old = estimate_lighting(
        grey,
        None,
        None,
        {},
        config=replace(LightingConfig(), sky_fill_colour="preetham", ambient_colour="scene"),
    )
    normals, _ = _white_sphere(old)
    E = irradiance_at_normals(normals[:, 0], old)
    lit = E.max(1) > 1e-4
    assert np.abs(np.log(E[lit, 2] / E[lit, 0])).max() > 0.05


@pytest.mark.parametrize("name", ["imh_179_00000000.jpg", "img_814_00000000.jpg"])
def test_white_stays_white_in_a_grey_road_photo(name):
    img = tracon_train_photo(name, 480)
    _check_neutral(estimate_lighting(_grey(img), None, None, {}))


@pytest.mark.parametrize("name", ["imh_179_00000000.jpg", "img_814_00000000.jpg"])
def test_a_red_object_filling_the_view_does_not_colour_the_light(name):
    """A grey road photo with a saturated red rectangle over a quarter of the frame (a truck or sign): the scene's
    light is still colourless (every other pixel is grey), so with ``ambient_colour="neutral"`` a white surface stays
    white in every orientation; with "scene" the ambient takes the red and tints it (not vacuous)."""
    img = _grey(tracon_train_photo(name, 480))
    h, w = img.shape[:2]
    img[h // 8 : h // 2, w // 4 : 3 * w // 4] = (200, 30, 25)
    cfg = replace(LightingConfig(), ambient_colour="neutral")
    _check_neutral(estimate_lighting(img, None, None, {}, config=cfg))
    scene = estimate_lighting(img, None, None, {}, config=replace(cfg, ambient_colour="scene"))
    normals, _ = _white_sphere(scene)
    E = irradiance_at_normals(normals[:, 0], scene)
    lit = E.max(1) > 1e-4
    assert np.abs(np.log(E[lit, 0] / E[lit, 1])).max() > 0.05


def test_neutral_ambient_keeps_the_brightness_in_every_direction_and_has_one_colour():
    """The SH of a map lit red from one side and blue-white from the other: after neutral_ambient the irradiance
    luminance is the same in every direction (luminance is linear in the coefficients) and its chromaticity is
    everywhere that of the upward irradiance."""
    from aias_augment.analyse.lighting.ambient import neutral_ambient
    from aias_augment.analyse.lighting.sh import fibonacci_sphere, project_envmap_to_sh, sh_irradiance
    from aias_augment.core.hdr import luminance

    env = np.zeros((32, 64, 3), np.float32)
    env[:, :32] = (2.0, 0.2, 0.1)
    env[:, 32:] = (0.8, 0.9, 1.2)
    sh = project_envmap_to_sh(env)
    up = np.array([0.0, 0.0, 1.0])
    n = fibonacci_sphere(200)
    new = neutral_ambient(sh, up)
    e_old, e_new = sh_irradiance(sh, n), sh_irradiance(new, n)
    assert np.allclose(luminance(e_new), luminance(e_old), rtol=1e-5)  # luminance() is float32
    pos = e_new.min(1) > 1e-6
    chroma_up = sh_irradiance(sh, up[None])[0] / luminance(sh_irradiance(sh, up[None]))[0]
    assert np.allclose(e_new[pos] / luminance(e_new[pos])[:, None], chroma_up, rtol=1e-5)
    assert np.ptp(e_old[pos, 0] / e_old[pos, 1]) > 1.0  # the input did vary in colour


def test_a_sunlit_white_takes_the_colour_of_the_photos_grey_surfaces():
    """The photo's grey surfaces (a sunlit road, white-balanced by the camera) show sky plus sun, E_sky,c (1 + r_c),
    with r_c = E_sun,c cos z / E_sky,c per channel (lit over shadowed ground, minus 1). The neutral ambient took that
    colour; once the sun is added as its own light, a white facing up in the sun must receive the grey surfaces'
    colour again, E_sky,c (1 + r_c), not that colour times the sun's (here warm: r_R > r_B)."""
    from aias_augment.analyse.lighting.ambient import neutral_ambient, sky_part_of_neutral
    from aias_augment.analyse.lighting.sh import sh_irradiance

    up = np.array([0.0, -1.0, 0.0])
    rng = np.random.default_rng(1)
    grey_surfaces = np.array([0.9, 1.0, 1.1])  # the colour the camera's balance left on its grey surfaces
    radiance_sh = rng.uniform(-0.1, 0.1, size=(9, 3))
    radiance_sh[0] = 1.0  # a light brighter than its variation: positive in every direction
    sh = neutral_ambient(radiance_sh, up, grey_surfaces)
    r = np.array([5.0, 4.0, 2.5])  # the sun warmer than the sky
    sky = sky_part_of_neutral(sh, up, r)
    e_sky = sh_irradiance(sky, up)
    total_up = e_sky * (1.0 + r)  # sky plus the sun at r_c E_sky,c
    assert np.allclose(total_up / total_up[1], grey_surfaces / grey_surfaces[1], rtol=1e-5)
    # Brightness of every coefficient kept; without the correction the sunlit white would be yellow.
    assert np.allclose(sky @ [0.2126, 0.7152, 0.0722], sh @ [0.2126, 0.7152, 0.0722])
    before = sh_irradiance(sh, up) * (1.0 + r)
    assert before[2] / before[0] < 0.75 * grey_surfaces[2] / grey_surfaces[0]
