import numpy as np
import pytest

from aias_augment.analyse.lighting import sun
from aias_augment.analyse.lighting import sun_side as ss
from aias_augment.core.geometry import Intrinsics
from tests.aias_augment.analyse.lighting.synthetic_scene import Box, render, sun_direction

K = Intrinsics.from_fov(640, 240, 80)
UP_WORLD = np.array([0.0, -1.0, 0.0])


def _grid_in_cam(R: np.ndarray) -> np.ndarray:
    grid_up, _ = sun.sun_direction_grid()
    return (grid_up @ sun.frame_from_up(UP_WORLD)) @ R.T


def _az_err(a_deg: float, b_deg: float) -> float:
    return abs((a_deg - b_deg + 180.0) % 360.0 - 180.0)


def _project(p: np.ndarray, intr: Intrinsics) -> np.ndarray:
    return np.array([intr.fx * p[0] / p[2] + intr.cx, intr.fy * p[1] / p[2] + intr.cy])


def test_classify_segments_recovers_vertical_lines_and_facade_normals():
    up = np.array([0.0, -1.0, 0.0])
    # A vertical pole 8 m ahead, 2 m left; a horizontal line on a facade facing (-1, 0, -1)/sqrt2, 3 m above ground.
    pole = np.array([_project(np.array([-2.0, 1.6, 8.0]), K), _project(np.array([-2.0, -2.0, 8.0]), K)])
    facade_normal = np.array([-1.0, 0.0, -1.0]) / np.sqrt(2.0)
    along = np.cross(up, facade_normal)  # horizontal, in the facade
    p0 = np.array([4.0, -1.5, 12.0])
    line = np.array([_project(p0, K), _project(p0 + 3.0 * along, K)])
    segs = ss.classify_segments(np.stack([pole, line]), K, up)
    assert segs.is_vertical.tolist() == [True, False]
    assert segs.facade_weight[0] == 0 and segs.facade_weight[1] > 0
    assert np.degrees(np.arccos(np.clip(segs.facade_normal_in_cam[1] @ facade_normal, -1, 1))) < 0.5


def test_classify_segments_line_on_the_horizon_has_no_facade_normal():
    # Any horizontal 3D line at eye height projects onto the horizon row: its facade orientation is undetermined.
    seg = np.array([[[100.0, K.cy], [400.0, K.cy]]])
    segs = ss.classify_segments(seg, K, np.array([0.0, -1.0, 0.0]))
    assert segs.facade_weight[0] == 0 and not segs.is_vertical[0]


@pytest.mark.parametrize("sun_az_deg", [-150.0, -60.0, 20.0, 120.0])
def test_vertical_surface_loglik_finds_the_sun_side_of_lambertian_walls(sun_az_deg):
    """Walls in 8 orientations, 3 lines each, with random albedos (x exp(0.3 N(0, 1)) per line), Lambertian:
    E = sky (1/2) + sun max(0, n.s)."""
    rng = np.random.default_rng(1)
    up = np.array([0.0, -1.0, 0.0])
    s = sun_direction(sun_az_deg, 40.0)
    normal_az = np.deg2rad(np.repeat(np.arange(0.0, 360.0, 45.0), 3) + rng.uniform(-3, 3, 24))
    normals = np.stack([np.cos(normal_az), np.zeros_like(normal_az), np.sin(normal_az)], axis=1)
    albedo = 0.4 * np.exp(0.3 * rng.standard_normal(len(normals)))
    E = 0.5 + 5.0 * np.maximum(normals @ s, 0.0)
    walls = ss.facade_clusters(ss.FacadeSamples(normals, np.log(albedo * E / np.pi), np.ones(len(normals))), up)
    assert len(walls.weights) == 8 and np.all(walls.weights == 3)
    grid = _grid_in_cam(np.eye(3))
    ll, r2 = ss.vertical_surface_loglik(walls, grid, up)
    az = np.rad2deg(ss.grid_ground_azimuths(grid, up))
    assert _az_err(az[int(np.argmax(ll))], sun_az_deg) < 30.0
    assert r2 > 0.5 and np.all(np.isfinite(ll)) and ll.max() == 0.0
    # Gaussian albedo model: the mirrored sun costs (sum of squares difference) / (2 sigma^2), many nats here.
    near_mirror = np.array([_az_err(a, sun_az_deg + 180.0) < 10.0 for a in az])
    assert ll[near_mirror].max() < -5.0


def test_facade_clusters_groups_walls_across_the_azimuth_wrap_and_drops_strays():
    up = np.array([0.0, -1.0, 0.0])
    # Ground azimuths atan2(forward, right) with right = +x, forward = +z: 178, -179, 179 deg is one wall (facing left),
    # 90 deg twice is a stray pair (fewer than 3 lines), -90 deg x 3 is a wall facing the camera.
    az = np.deg2rad([178.0, -179.0, 179.0, 90.0, 90.0, -90.0, -91.0, -89.0])
    normals = np.stack([np.cos(az), np.zeros_like(az), np.sin(az)], axis=1)
    logs = np.array([0.0, 0.0, 0.0, -2.0, -2.0, -3.0, -3.0, -3.0])
    walls = ss.facade_clusters(ss.FacadeSamples(normals, logs, np.ones(8)), up)
    assert sorted(walls.weights.tolist()) == [3.0, 3.0]
    left = int(np.argmax(walls.log_luminance))
    assert walls.normals_in_cam[left][0] == pytest.approx(-1.0, abs=1e-3)


def test_vertical_surface_loglik_is_silent_when_all_walls_face_one_way():
    up = np.array([0.0, -1.0, 0.0])
    normals = np.tile([0.0, 0.0, -1.0], (6, 1))
    samples = ss.FacadeSamples(normals, np.log(np.linspace(0.1, 0.5, 6)), np.ones(6))
    ll, r2 = ss.vertical_surface_loglik(samples, _grid_in_cam(np.eye(3)), up)
    # One orientation: max(0, n.s) is the same for every sample under any sun, nothing to compare.
    assert np.all(ll == 0.0) and r2 == 0.0
    ll, r2 = ss.vertical_surface_loglik(
        ss.FacadeSamples(np.zeros((0, 3)), np.zeros(0), np.zeros(0)), _grid_in_cam(np.eye(3)), up
    )
    assert np.all(ll == 0.0) and r2 == 0.0


def _poles() -> list[Box]:
    return [
        Box((x, -1.35, z), (x + 0.15, 1.65, z + 0.15), (0.3, 0.3, 0.3))
        for x, z in [(-3.0, 6.0), (2.0, 8.0), (-1.0, 12.0), (5.0, 14.0), (-4.0, 16.0)]
    ]


@pytest.mark.parametrize("sun_az_deg", [-150.0, -30.0, 30.0, 150.0, 100.0])
def test_shadow_end_puts_the_sun_on_the_side_of_the_occluders(sun_az_deg):
    """Poles on a plane ray-cast under a known sun (independent renderer): the shadow-end cue alone must find the sun's
    azimuth (not only its axis); the mirrored sun (az + 180) is what a side-blind cue would confuse it with."""
    img, R = render(_poles(), sun_direction(sun_az_deg, 35.0), K, pitch_deg=3.0)
    up = R @ UP_WORLD
    grid = _grid_in_cam(R)
    segs = ss.classify_segments(ss.detect_line_segments(img, 16.0), K, up)
    bases, dirs = ss.occluder_bases(segs, K, up)
    assert len(bases) >= 5  # each pole gives one base (they do not hide behind one another in the image)
    scores, alphas = ss.shadow_end_scores(ss.ground_darkness(img), bases, dirs, K, up)
    ll, conf = ss.shadow_end_loglik(scores, alphas, grid, up)
    az = np.rad2deg(ss.grid_ground_azimuths(grid, up))
    true_az = float(np.rad2deg(ss.grid_ground_azimuths((R @ sun_direction(sun_az_deg, 35.0))[None], up))[0])
    assert _az_err(az[int(np.argmax(ll))], true_az) < 20.0
    assert conf > 0.02  # thin shadows fill only part of each ray: well below 1, but not zero
    near_true = np.array([_az_err(a, true_az) < 10.0 for a in az])
    near_mirror = np.array([_az_err(a, true_az + 180.0) < 10.0 for a in az])
    assert ll[near_true].max() - ll[near_mirror].max() > 0.5  # nats in favour of the right end of the axis
    # Antisymmetric: the mean score at a and a + 180 deg are opposite.
    v = np.isfinite(scores)
    mean = np.where(v, scores, 0).sum(0) / np.maximum(v.sum(0), 1)
    assert np.allclose(mean, -np.roll(mean, len(alphas) // 2), atol=1e-9)


@pytest.mark.parametrize("sun_az_deg", [-150.0, 30.0])
def test_sun_side_cue_facades_of_a_rendered_street(sun_az_deg):
    """Two striped buildings facing each other across a street: the one facing the sun is lit."""
    boxes = [
        Box((-14.0, -6.0, 8.0), (-6.0, 1.65, 30.0), (0.6, 0.55, 0.5), 1.0),
        Box((6.0, -6.0, 8.0), (14.0, 1.65, 30.0), (0.6, 0.55, 0.5), 1.0),
        Box((-1.0, 0.2, 25.0), (1.0, 1.65, 30.0), (0.6, 0.6, 0.6), 0.5),
    ]
    img, R = render(boxes, sun_direction(sun_az_deg, 35.0), K, pitch_deg=3.0)
    up = R @ UP_WORLD
    grid = _grid_in_cam(R)
    cue = ss.sun_side_cue(img, K, up, grid)
    az = np.rad2deg(ss.grid_ground_azimuths(grid, up))
    true_az = float(np.rad2deg(ss.grid_ground_azimuths((R @ sun_direction(sun_az_deg, 35.0))[None], up))[0])
    assert cue.n_facade_samples >= 2 and cue.facade_orientation_spread > 0.2  # walls in two or more directions
    # Three walls: the azimuth is only bracketed (any sun lighting the same walls fits as well), the side is not.
    assert _az_err(az[int(np.argmax(cue.facade_loglik))], true_az) < 90.0
    near_true = np.array([_az_err(a, true_az) < 10.0 for a in az])
    near_mirror = np.array([_az_err(a, true_az + 180.0) < 10.0 for a in az])
    assert cue.facade_loglik[near_true].max() - cue.facade_loglik[near_mirror].max() > 2.0


@pytest.mark.parametrize("value", [0, 255])
def test_sun_side_cue_flat_images_are_silent_and_finite(value):
    img = np.full((120, 200, 3), value, np.uint8)
    intr = Intrinsics.from_fov(200, 120, 60)
    cue = ss.sun_side_cue(img, intr, np.array([0.0, -1.0, 0.0]), _grid_in_cam(np.eye(3)))
    assert np.all(cue.log_likelihood == 0.0) and cue.confidence == 0.0
    assert cue.n_bases == 0 and cue.n_facade_samples == 0


def test_sun_side_cue_bad_inputs():
    with pytest.raises(ValueError):
        ss.sun_side_cue(
            np.zeros((10, 10), np.uint8),
            Intrinsics.from_fov(10, 10, 60),
            np.array([0, -1.0, 0]),
            _grid_in_cam(np.eye(3)),
        )
    with pytest.raises(ValueError):
        ss.sun_side_cue(
            np.zeros((10, 12, 3), np.uint8),
            Intrinsics.from_fov(10, 10, 60),
            np.array([0, -1.0, 0]),
            _grid_in_cam(np.eye(3)),
        )


def _street_with_poles() -> list[Box]:
    # Low walls set back from the road (4 m tall, 7 m off the axis), so that the road box is sunlit with pole shadows.
    boxes = [
        Box((-15.0, -2.35, 8.0), (-7.0, 1.65, 30.0), (0.6, 0.55, 0.5), 1.0),
        Box((7.0, -2.35, 8.0), (15.0, 1.65, 30.0), (0.6, 0.55, 0.5), 1.0),
    ]
    boxes += [
        Box((x, -1.35, z), (x + 0.15, 1.65, z + 0.15), (0.3, 0.3, 0.3))
        for x, z in [(-3.0, 6.0), (2.5, 7.0), (-2.0, 11.0), (3.0, 13.0)]
    ]
    return boxes


@pytest.mark.parametrize("sun_az_deg", [-140.0, 40.0])
def test_estimate_sun_direction_picks_the_side_on_a_rendered_street(sun_az_deg):
    """End to end through the production estimator (sky, ground lit/shadow and shadow axis, walls, shadow ends) on a
    ray-cast street whose sky carries no sun information (a plain gradient): the side must come from the scene."""
    from aias_augment.analyse.lighting.estimate import estimate_sun_direction

    s_world = sun_direction(sun_az_deg, 35.0)
    img, R = render(_street_with_poles(), s_world, K, pitch_deg=3.0)
    est = estimate_sun_direction(img, K, R, {"up_in_world": UP_WORLD})
    h_est = est.direction_in_world - (est.direction_in_world @ UP_WORLD) * UP_WORLD
    h_true = s_world - (s_world @ UP_WORLD) * UP_WORLD
    assert float(h_est @ h_true) > 0.0  # same half-plane: the side is right
    assert np.all(np.isfinite(est.direction_in_world)) and 0.0 <= est.confidence <= 1.0


def test_half_turn_index_mirrors_the_azimuth():
    from aias_augment.analyse.lighting.sun_direction import _half_turn_index

    grid, azel = sun.sun_direction_grid()
    idx = _half_turn_index(azel)
    assert np.allclose(grid[idx, :2], -grid[:, :2], atol=1e-9) and np.allclose(grid[idx, 2], grid[:, 2])
    assert np.array_equal(idx[idx], np.arange(len(idx)))
