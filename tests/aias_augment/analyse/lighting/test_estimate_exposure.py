"""Issue 15 lighting tempering: the exposure anchor on the ground's implied albedo, sun tempering, and the saturation
guard. Truths come from the analytic scene (known albedo, sky and sun), a uniform env map, and pixel counts."""

import numpy as np
import pytest

from aias_augment.analyse.lighting.estimate import LightingConfig, estimate_lighting
from aias_augment.analyse.lighting.exposure import (
    ground_exposure_scale,
    ground_white_balance_gains,
    peak_white_radiance,
    temper_sun,
)
from aias_augment.analyse.lighting.sh import project_envmap_to_sh, sh_irradiance
from aias_augment.apply.composite import to_uint8
from aias_augment.apply.shading import shade_object
from aias_augment.core.geometry import Intrinsics
from aias_augment.core.hdr import luminance
from tests.aias_augment.analyse.lighting.synthetic_scene import Box, render, sun_direction
from tests.aias_augment.fixtures import tracon_train_photo

K = Intrinsics.from_fov(320, 240, 60.0)
OFF = LightingConfig(ground_albedo_range=None, sun_full_confidence=0.0, cap_white_to_scene_percentile=None)


def test_ground_exposure_scale_by_hand():
    # implied = pi 0.1 / 1 = 0.3142 -> clamped to 0.30: k = 0.3142 / 0.30
    assert ground_exposure_scale(0.1, 1.0, (0.08, 0.30)) == pytest.approx(np.pi * 0.1 / 0.30)
    assert ground_exposure_scale(0.01, 1.0, (0.08, 0.30)) == pytest.approx(np.pi * 0.01 / 0.08)
    assert ground_exposure_scale(0.05, 1.0, (0.08, 0.30)) == 1.0  # implied 0.157: inside the range
    assert ground_exposure_scale(0.0, 1.0, (0.08, 0.30)) == 1.0  # nothing to anchor on


def test_temper_sun_adds_uniform_irradiance_equal_to_a_constant_env_map():
    rng = np.random.default_rng(0)
    sh = rng.normal(size=(9, 3)) * 0.1
    sh[0] += 3.0  # positive irradiance everywhere (sh_irradiance clamps at 0)
    sun = np.array([3.0, 2.5, 2.0])
    cos_z = 0.6
    sh2, sun2 = temper_sun(sh, sun, cos_z, keep=0.25)
    assert np.allclose(sun2, 0.25 * sun)
    # the added part equals the SH of a uniform map of radiance L = dE / pi (independent projection)
    dE = 0.75 * sun * cos_z
    const = project_envmap_to_sh(np.broadcast_to(dE / np.pi, (32, 64, 3)).astype(np.float32))
    assert np.allclose(sh2 - sh, const, atol=1e-3 * np.abs(const).max())
    normals = rng.normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    assert np.allclose(sh_irradiance(sh2, normals) - sh_irradiance(sh, normals), dE, rtol=1e-3)


@pytest.mark.parametrize("exposure", [0.25, 1.0, 3.0])
def test_implied_ground_albedo_stays_in_range_at_any_exposure(exposure):
    # No boxes, no shadows: a sky and a ground of albedo ~0.33 under sky 1 + sun 6 sin 40 deg, times the exposure.
    # The estimate's white radiance on the ground, E(up) / pi (plus the sun's share), against the truth of the scene:
    # ground radiance = albedo_true x exposure x (sky + sun sin el) / pi; their ratio is the implied albedo.
    s = sun_direction(60.0, 40.0)
    img, R = render([], s, K, exposure=exposure, noise=0.0)
    # a narrower range than the default, the gain unbounded (its bound: the next test)
    anchored = LightingConfig(ground_albedo_range=(0.06, 0.15), ground_anchor_max_gain=1e6)
    est = estimate_lighting(img, None, None, {}, config=anchored)
    e_up = float(luminance(sh_irradiance(est.ambient_sh, est.up_in_cam)))
    if est.dominant_sun:
        e_up += float(luminance(est.sun_irradiance_rgb)) * max(float(est.sun_direction_in_cam @ est.up_in_cam), 0)
    albedo_true = float(luminance(np.array([0.35, 0.33, 0.3])))
    truth = albedo_true * exposure * (1.0 + 6.0 * np.sin(np.deg2rad(40.0))) / np.pi
    ground_linear = np.clip(truth, 0, 1)  # what the 8-bit image can hold
    implied = np.pi * ground_linear / e_up
    lo, hi = anchored.ground_albedo_range
    assert implied >= lo * 0.9  # never brighter than the darkest plausible road allows
    # ... and no darker than the brightest plausible road, unless the saturation guard holds white at sRGB 250 (a
    # white surface in this unclipped frame would otherwise exceed 1.0: with albedo 0.30 the ground at exposure 1
    # implies a white radiance of 0.51 / 0.30 = 1.7)
    peak = peak_white_radiance(
        est.ambient_sh,
        est.sun_irradiance_rgb if est.dominant_sun else None,
        est.sun_direction_in_cam if est.dominant_sun else None,
    )
    assert implied <= hi * 1.1 or peak == pytest.approx(0.95, rel=1e-6)
    # without the tempering the same frame implies an albedo outside the range (the fix is what keeps it inside)
    off = estimate_lighting(img, None, None, {}, config=OFF)
    e_off = float(luminance(sh_irradiance(off.ambient_sh, off.up_in_cam)))
    assert not lo <= np.pi * ground_linear / e_off <= hi


@pytest.mark.parametrize("exposure", [0.25, 3.0])
def test_the_anchor_changes_the_light_by_at_most_its_gain_bound(exposure):
    """The same frames as above: the anchored light over the unanchored one (the ground's irradiance, which the
    saturation guard leaves alone in these frames or lowers) stays within the bound of 3 either way, while the
    unbounded anchor moves it further."""
    s = sun_direction(60.0, 40.0)
    img, _ = render([], s, K, exposure=exposure, noise=0.0)

    def e_ground(cfg):
        est = estimate_lighting(img, None, None, {}, config=cfg)
        e = float(luminance(sh_irradiance(est.ambient_sh, est.up_in_cam)))
        if est.dominant_sun:
            e += float(luminance(est.sun_irradiance_rgb)) * max(float(est.sun_direction_in_cam @ est.up_in_cam), 0)
        return e

    no_guard = {"cap_white_to_scene_percentile": None}
    base = e_ground(LightingConfig(ground_albedo_range=None, **no_guard))
    bounded = e_ground(LightingConfig(ground_albedo_range=(0.06, 0.15), ground_anchor_max_gain=3.0, **no_guard))
    free = e_ground(LightingConfig(ground_albedo_range=(0.06, 0.15), ground_anchor_max_gain=1e6, **no_guard))
    assert 1 / 3 - 1e-6 <= bounded / base <= 3 + 1e-6
    assert abs(np.log(free / base)) > abs(np.log(bounded / base)) - 1e-9


def _white_sphere_uint8(est, n=4000):
    """A white (albedo 0.96) Lambertian sphere's pixels under the estimate, encoded as the pipeline does."""
    rng = np.random.default_rng(1)
    normals = rng.normal(size=(n, 1, 3))
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    albedo = np.full((n, 1, 3), 0.96, np.float32)
    return to_uint8(shade_object(albedo, normals, np.ones((n, 1), bool), est))


def test_no_white_pixel_saturates_in_an_unclipped_sunny_scene():
    boxes = [Box((-3.0, 0.0, 9.0), (1.0, 1.2, 1.0), (0.5, 0.5, 0.5)), Box((2.0, 0.0, 12.0), (1.5, 2.0, 1.0))]
    s = sun_direction(30.0, 25.0)
    img, R = render(boxes, s, K, exposure=0.7, noise=0.0)
    assert img.max() < 250  # the scene itself does not clip
    est = estimate_lighting(img, None, None, {})
    white = _white_sphere_uint8(est)
    assert white.max() < 255
    assert (
        peak_white_radiance(
            est.ambient_sh,
            est.sun_irradiance_rgb if est.dominant_sun else None,
            est.sun_direction_in_cam if est.dominant_sun else None,
        )
        <= 0.95 + 1e-9
    )


@pytest.mark.parametrize(
    "name",
    [
        "imh_115_00000000.jpg",
        "imh_134_00000000.jpg",
        "imh_179_00000000.jpg",
        "img_806_00000000.jpg",
        "img_845_00000000.jpg",
        "imh_314_00000000.jpg",
    ],
)
def test_saturation_check_on_real_road_photos(name):
    # Real empty roads (low-confidence suns with sun/sky ratios up to 10.9 among them): a white Lambertian surface in
    # any orientation saturates only where the photo itself clips (its 99.5th percentile of the brightest channel).
    img = tracon_train_photo(name, 640)
    est = estimate_lighting(img, None, None, {})
    scene_clips = np.percentile(img.max(-1), 99.5) >= 252
    if not scene_clips:
        assert _white_sphere_uint8(est).max() < 255


def test_ground_white_balance_gains_by_hand():
    g, e = np.array([0.2, 0.2, 0.2]), np.array([1.0, 1.0, 2.0])
    full = ground_white_balance_gains(g, e, strength=1.0) * e
    assert np.allclose(full / full[0], [1, 1, 1])  # the ground's (neutral) colour
    assert float(luminance(full)) == pytest.approx(float(luminance(e)))  # luminance kept
    half = ground_white_balance_gains(g, e, strength=0.5) * e
    assert half[2] / half[0] == pytest.approx(np.sqrt(2.0))  # half way in log
    assert np.allclose(ground_white_balance_gains(g, np.array([1.0, 0.0, 1.0])), 1.0)  # nothing to balance on


def test_white_balance_brings_the_light_colour_to_the_truth():
    # The analytic scene is lit by a white sun and a white sky (its sky pixels are blue, its light is not); grey
    # ground. Truth: the irradiance is neutral, B / R = 1.
    s = sun_direction(60.0, 40.0)
    img, R = render(
        [Box((-3.0, 0.0, 9.0), (1.0, 1.2, 1.0))], s, K, exposure=0.8, noise=0.0, ground_albedo=(0.3, 0.3, 0.3)
    )

    def blue_over_red(cfg):
        est = estimate_lighting(img, None, None, {}, config=cfg)
        e = sh_irradiance(est.ambient_sh, est.up_in_cam)
        if est.dominant_sun:
            e = e + est.sun_irradiance_rgb * max(float(est.sun_direction_in_cam @ est.up_in_cam), 0.26)
        return e[2] / e[0]

    # the ground balance alone, on the ambient with the photo's colours (ambient_colour "scene")
    on = blue_over_red(LightingConfig(ambient_colour="scene", ground_white_balance=0.75))
    off = blue_over_red(LightingConfig(ambient_colour="scene", ground_white_balance=0.0))
    # the default neutral ambient takes the grey ground's colour: the truth within 5 %
    assert abs(np.log(blue_over_red(LightingConfig()))) < 0.05
    assert abs(np.log(on)) < abs(np.log(off))
    # strength 0.75: three quarters of the way (in log) from the unbalanced estimate to the ground's colour (grey)
    assert off > 1.5  # the unbalanced estimate is far too blue
    assert on == pytest.approx(off**0.25, rel=0.05)


def test_tempered_sun_rest_is_the_suns_own_soft_lobe():
    # Issue 15, section 2: the untrusted share of the sun must stay on the sun's side (shading consistent with the
    # shadow it casts). Independent truth: a small bright disc at the sun's direction in an equirectangular map,
    # projected to SH by quadrature, then irradiance at normals: the band-limited sun. Its shape must equal the
    # tempered rest's, the ground's irradiance must be what the sun's share had (E_rest cos z), and a surface facing
    # away from the sun must get almost none of it (the uniform rest gave it E_rest cos z, as much as the ground).
    from aias_augment.analyse.lighting.envmap import pixel_directions, pixel_solid_angles

    up = np.array([0.0, -1.0, 0.0])
    s = np.array([0.3, -0.55, 0.78])
    s /= np.linalg.norm(s)
    cos_z = float(s @ up)
    sh = np.zeros((9, 3))
    sh[0] = 0.5
    sun = np.array([6.0, 5.0, 4.0])
    keep = 0.25
    sh2, sun2 = temper_sun(sh, sun, cos_z, keep, s, up)
    assert np.allclose(sun2, keep * sun)
    rest = (1 - keep) * sun
    assert np.allclose(sh_irradiance(sh2, up[None])[0] - sh_irradiance(sh, up[None])[0], rest * cos_z, rtol=1e-9)
    # the disc (2 deg radius) in a 256 x 512 map whose world frame is the camera frame
    dirs = pixel_directions(256).reshape(-1, 3)
    omega = np.broadcast_to(pixel_solid_angles(256), (256, 512)).reshape(-1)
    disc = dirs @ s > np.cos(np.deg2rad(2.0))
    rad = np.zeros((len(dirs), 3))
    rad[disc] = 1.0 / omega[disc].sum()  # unit irradiance at normal incidence
    disc_sh = project_envmap_to_sh(rad.reshape(256, 512, 3))
    rng = np.random.default_rng(1)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    lobe = (sh_irradiance(sh2, n) - sh_irradiance(sh, n))[:, 0] / rest[0]
    # sh_irradiance clamps at 0, so compare the unclamped band-limited disc where it is positive
    ref = sh_irradiance(disc_sh, n)[:, 0] * cos_z / sh_irradiance(disc_sh, up[None])[0, 0]
    pos = ref > 0.01
    assert pos.sum() > 100 and np.allclose(lobe[pos], ref[pos], atol=2e-3 * ref.max())
    away = sh_irradiance(sh2, -s[None])[0] - sh_irradiance(sh, -s[None])[0]
    assert np.all(away <= 0.1 * rest * cos_z / 0.3)  # f(-1) / f(l.up) = 0.06 / (>= 0.3 here)
    assert np.all(sh_irradiance(sh2, s[None])[0] - sh_irradiance(sh, s[None])[0] > 1.0 * rest * cos_z)
