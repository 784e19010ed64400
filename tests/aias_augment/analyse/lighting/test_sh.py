import numpy as np
import pytest

from aias_augment.analyse.lighting import envmap as em
from aias_augment.analyse.lighting import sh


def test_constant_radiance_gives_pi_l():
    rad = np.full((32, 64, 3), 2.0)
    c = sh.project_envmap_to_sh(rad)
    n = sh.fibonacci_sphere(50)
    assert np.allclose(sh.sh_irradiance(c, n), 2.0 * np.pi, rtol=1e-3)


def test_linear_radiance_is_exact():
    # L(w) = 1 + w.z has irradiance pi + 2 pi / 3 n_z (bands 0 and 1 only: SH is exact).
    dirs = em.pixel_directions(64)
    rad = np.repeat(1.0 + dirs[..., 2:3], 3, axis=2)
    c = sh.project_envmap_to_sh(rad)
    n = sh.fibonacci_sphere(40)
    assert np.allclose(sh.sh_irradiance(c, n)[:, 0], np.pi + 2 * np.pi / 3 * n[:, 2], rtol=2e-3)


def test_rotation_matches_reprojection():
    rng = np.random.default_rng(3)
    rad = rng.random((16, 32, 3))
    R = em.cam_from_env_look(0.7, -0.3, 0.2)
    assert np.allclose(sh.rotate_sh(sh.project_envmap_to_sh(rad), R), sh.project_envmap_to_sh(rad, R), atol=1e-9)


@pytest.mark.parametrize("name", ["courtyard", "forest", "sunset"])
def test_sh_irradiance_within_15pct_of_brute_force(blender_world, name):
    from aias_augment.core import hdr

    rad = hdr.read_hdr_image(blender_world(name)).reshape(128, 4, 256, 4, 3).mean((1, 3))
    n = sh.fibonacci_sphere(100)
    ref = sh.brute_force_irradiance(rad, n)
    est = sh.sh_irradiance(sh.project_envmap_to_sh(rad), n)
    rel_rms = np.sqrt(np.mean((est - ref) ** 2)) / np.sqrt(np.mean(ref**2))
    assert rel_rms < 0.15


def test_point_light_at_radiance_1e5_stays_finite():
    rad = np.zeros((32, 64, 3))
    rad[3, 10] = 1e5
    c = sh.project_envmap_to_sh(rad)
    E = sh.sh_irradiance(c, sh.fibonacci_sphere(30))
    assert np.all(np.isfinite(E)) and E.min() >= 0
