import numpy as np
import pytest

from aias_augment.analyse.lighting import envmap as em
from aias_augment.core.geometry import Intrinsics


def test_pixel_direction_round_trip_and_convention():
    d = em.pixel_directions(16)
    pix = em.direction_to_pixel(d, 16)
    assert np.allclose(pix[..., 0], np.arange(32)[None, :], atol=1e-9)
    assert np.allclose(pix[..., 1], np.arange(16)[:, None], atol=1e-9)
    # Blender convention: centre column looks along +x, a quarter to the left along +y, row 0 is the zenith side.
    assert np.allclose(em.direction_to_pixel(np.array([1.0, 0, 0]), 16), [15.5, 7.5])
    assert np.allclose(em.direction_to_pixel(np.array([0, 1.0, 0]), 16), [7.5, 7.5])
    assert em.direction_to_pixel(np.array([0, 0, 1.0]), 16)[1] == pytest.approx(-0.5)


def test_solid_angles_sum_to_sphere():
    assert em.pixel_solid_angles(37).sum() * 74 == pytest.approx(4 * np.pi, rel=1e-12)


def test_cam_from_env_look_axes():
    R = em.cam_from_env_look(0.0, 0.0)
    assert np.allclose(R @ [1.0, 0, 0], [0, 0, 1])  # forward
    assert np.allclose(R @ [0, 0, 1.0], [0, -1, 0])  # env up is camera -y
    assert np.allclose(R @ [0, 1.0, 0], [-1, 0, 0])  # env +y (left) is camera -x
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_render_perspective_sees_a_marked_direction():
    h = 64
    rad = np.zeros((h, 2 * h, 3), np.float32)
    target = em.azimuth_elevation_to_direction(np.deg2rad(40.0), np.deg2rad(10.0))
    col, row = np.round(em.direction_to_pixel(target, h)).astype(int)
    rad[row, col] = 1000.0
    K = Intrinsics.from_fov(101, 81, 90.0)
    R = em.cam_from_env_look(np.deg2rad(40.0), np.deg2rad(10.0))
    view = em.render_perspective(rad, K, R)
    v, u = np.unravel_index(np.argmax(view[..., 0]), view.shape[:2])
    assert abs(u - K.cx) <= 2 and abs(v - K.cy) <= 2


def test_assemble_envmap_round_trip_where_seen():
    h = 32
    dirs = em.pixel_directions(h)
    rad = (1.0 + dirs[..., :1] * 0.5 + dirs[..., 2:3] * np.array([0.2, 0.3, 0.4])).astype(np.float32)  # smooth
    K = Intrinsics.from_fov(160, 120, 90.0)
    poses = [em.cam_from_env_look(np.deg2rad(a), 0.0) for a in (0, 90, 180, 270)]
    frames = [em.render_perspective(rad, K, R) for R in poses]
    out, seen = em.assemble_envmap(frames, [K] * 4, poses, height=h, fill=lambda d: np.zeros((len(d), 3)))
    assert seen[h // 2].all() and not seen[0].any()
    assert np.allclose(out[seen], rad[seen], rtol=0.05)
    assert np.all(out[~seen] == 0)


def test_environment_map_validation():
    with pytest.raises(ValueError):
        em.EnvironmentMap(np.zeros((4, 4, 3)))
    with pytest.raises(ValueError, match="NaN"):
        em.EnvironmentMap(np.full((4, 8, 3), np.nan))
    with pytest.raises(ValueError, match=">= 0"):
        em.EnvironmentMap(-np.ones((4, 8, 3)))


@pytest.mark.parametrize("fx", [5e3, 1e5, 1e7])
def test_assemble_envmap_long_focal_lengths_average_what_the_frame_sees(fx):
    """A frame whose whole field of view is smaller than a map pixel (fx = 1e5, 1e7: the pre-blur would need
    kernels of 10^4-10^6 taps) contributes the area mean of its pixels to the map pixel it looks through: a
    two-tone frame (left quarter 1, the rest 3) gives 2.5 there (a blur that long over replicated borders gives
    the mean of the two border tones, 2). At fx = 5e3 the values stay between the tones."""
    h = 16
    img = np.ones((120, 160, 3), np.float32)
    img[:, 40:] = 3.0
    K = Intrinsics(fx, fx, 79.5, 59.5, 160, 120)
    d = em.pixel_directions(h)[h // 2 - 3, h + 2]  # look through a map pixel's centre
    az, el = np.arctan2(d[1], d[0]), np.arcsin(d[2])
    assert np.allclose(em.azimuth_elevation_to_direction(az, el), d)
    out, seen = em.assemble_envmap([img], [K], [em.cam_from_env_look(az, el)], height=h)
    assert seen[h // 2 - 3, h + 2] and np.isfinite(out).all()
    vals = out[seen][:, 0]
    if fx >= 1e5:
        assert np.allclose(vals, 2.5, atol=0.05), vals
    else:
        assert 1.0 <= vals.min() and vals.max() <= 3.0


def test_large_map_averaged_down_keeping_its_power(tmp_path):
    from aias_augment.core.hdr import write_exr

    rng = np.random.default_rng(0)
    big = rng.uniform(0.2, 1.0, (64, 128, 3)).astype(np.float32)
    big[12:16, 40:44] = 1e4  # a sun, 4x4 px
    write_exr(tmp_path / "m.exr", big)
    env = em.EnvironmentMap.from_file(tmp_path / "m.exr", max_height=16)
    assert env.shape == (16, 32)

    def power(r):  # radiance integrated over the sphere, per channel
        return (r * em.pixel_solid_angles(r.shape[0])[..., None]).sum(axis=(0, 1))

    assert np.allclose(power(env.radiance), power(big), rtol=0.02)
    assert np.unravel_index(np.argmax(env.radiance[..., 0]), env.shape) == (3, 10)  # the sun's block, 4x smaller
    assert em.EnvironmentMap.from_file(tmp_path / "m.exr").shape == (64, 128)  # under the default bound: as read
