import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aias_augment.analyse.ground import (
    GroundFitError,
    GroundPlane,
    fit_ground_plane,
    ground_plane_from_depth,
    prior_ground_plane,
    project_world_point_track,
)
from aias_augment.core.geometry import Intrinsics, invert_rigid, make_rigid, rotation_about_axis

KITTI = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, 1226, 370)


def _ground_points(plane: GroundPlane, rng, n=2000, extent=10.0):
    """Points on ``plane`` in front of the camera (independent construction: basis of the plane)."""
    n_ = plane.normal
    e1 = np.cross(n_, [0, 0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n_, e1)
    origin = -plane.d * n_  # foot of the camera on the plane
    a = rng.uniform(-extent, extent, n)
    b = rng.uniform(-extent, extent, n)
    return origin + a[:, None] * e1 + b[:, None] * e2


def test_fit_recovers_plane_with_outliers():
    rng = np.random.default_rng(0)
    truth = prior_ground_plane(1.65, pitch_rad=np.deg2rad(3), roll_rad=np.deg2rad(-2))
    ground = _ground_points(truth, rng) + rng.normal(0, 0.01, (2000, 3))
    # 40% clutter: points 0.3..3 m above the ground (cars, walls).
    clutter = _ground_points(truth, rng, 1300) + rng.uniform(0.3, 3.0, (1300, 1)) * truth.normal
    fit = fit_ground_plane(np.concatenate([ground, clutter]), rng)
    assert np.degrees(np.arccos(np.clip(fit.normal @ truth.normal, -1, 1))) < 0.5
    assert abs(fit.d - 1.65) < 0.02
    assert 0.5 < fit.inlier_ratio < 0.7
    assert fit.rms_m < 0.03


def test_exactly_three_points_give_their_plane():
    pts = np.array([[0, 1.5, 5.0], [1, 1.5, 6.0], [-1, 1.5, 8.0]])
    fit = fit_ground_plane(pts, np.random.default_rng(0))
    np.testing.assert_allclose(fit.normal, [0, -1, 0], atol=1e-9)
    assert fit.d == pytest.approx(1.5)


@pytest.mark.parametrize("pts", [np.zeros((0, 3)), np.array([[0, 1.5, 5.0], [1, 1.5, 6.0]])])
def test_too_few_points_raise(pts):
    with pytest.raises(GroundFitError, match="at least 3"):
        fit_ground_plane(pts, np.random.default_rng(0))


def test_collinear_points_raise():
    t = np.linspace(0, 10, 50)[:, None]
    pts = np.array([0, 1.6, 3.0]) + t * np.array([0.1, 0.0, 1.0])
    with pytest.raises(GroundFitError, match="collinear"):
        fit_ground_plane(pts, np.random.default_rng(0))
    with pytest.raises(ValueError):  # GroundFitError is a ValueError for callers that catch broadly
        fit_ground_plane(np.repeat([[0, 1.6, 3.0]], 10, axis=0), np.random.default_rng(0))


def test_wall_is_not_ground():
    rng = np.random.default_rng(1)
    wall = np.stack([rng.uniform(-5, 5, 500), rng.uniform(-2, 1.5, 500), np.full(500, 8.0)], axis=1)
    with pytest.raises(GroundFitError, match="no plane within"):
        fit_ground_plane(wall, rng)


def test_plane_above_camera_is_not_ground():
    rng = np.random.default_rng(2)
    ceiling = np.stack([rng.uniform(-5, 5, 500), np.full(500, -2.5), rng.uniform(1, 10, 500)], axis=1)
    with pytest.raises(GroundFitError):
        fit_ground_plane(ceiling, rng)


def test_local_fit_selects_nearby_plane():
    rng = np.random.default_rng(3)
    near = _ground_points(prior_ground_plane(1.6), rng, 1000, 4.0)
    far = _ground_points(prior_ground_plane(1.0), rng, 3000, 4.0) + np.array([0, 0, 20.0])  # a raised terrace
    pts = np.concatenate([near, far])
    assert fit_ground_plane(pts, rng).d == pytest.approx(1.0, abs=0.02)  # the majority
    local = fit_ground_plane(pts, rng, local_center=(0, 1.6, 2.0), local_radius_m=5.0)
    assert local.d == pytest.approx(1.6, abs=0.02)


def test_same_seed_same_plane():
    rng_pts = np.random.default_rng(4)
    pts = _ground_points(prior_ground_plane(1.65), rng_pts) + rng_pts.normal(0, 0.05, (2000, 3))
    a = fit_ground_plane(pts, np.random.default_rng(7))
    b = fit_ground_plane(pts, np.random.default_rng(7))
    assert a == b


def test_rays_horizon_and_behind_camera():
    g = prior_ground_plane(1.65)
    hits = g.intersect_rays(np.array([[0, 0.1, 1.0], [0, 0, 1.0], [0, -0.1, 1.0], [0, 0.1, -1.0], [0, 0, 0.0]]))
    np.testing.assert_allclose(hits[0], [0, 1.65, 16.5])  # y = 1.65 at z = 16.5
    assert np.all(np.isnan(hits[1:]))  # horizon, above horizon, behind the camera, zero ray


def test_horizon_row_from_pitch():
    for pitch_deg in (-5, 0, 2, 10):
        g = prior_ground_plane(1.5, pitch_rad=np.deg2rad(pitch_deg))
        v = g.horizon_row_at(KITTI.cx, KITTI)
        assert v == pytest.approx(KITTI.cy - KITTI.fy * np.tan(np.deg2rad(pitch_deg)), abs=1e-6)
        # pixel just below the horizon sees the ground, just above does not
        assert np.isfinite(g.intersect_pixels(np.array([KITTI.cx, v + 1]), KITTI)).all()
        assert np.isnan(g.intersect_pixels(np.array([KITTI.cx, v - 1]), KITTI)).all()


def test_pitch_roll_round_trip():
    g = prior_ground_plane(1.2, pitch_rad=0.1, roll_rad=-0.05)
    assert g.pitch_roll_rad() == pytest.approx((0.1, -0.05))


def test_transformed_keeps_points_on_plane():
    rng = np.random.default_rng(5)
    g1 = prior_ground_plane(1.65, 0.02, 0.01)
    pts1 = _ground_points(g1, rng, 20)
    cam2_from_cam1 = make_rigid(rotation_about_axis([0.2, 1, 0.1], 0.3), [0.5, -0.2, -3.0])
    g2 = g1.transformed(cam2_from_cam1)
    pts2 = pts1 @ cam2_from_cam1[:3, :3].T + cam2_from_cam1[:3, 3]
    np.testing.assert_allclose(g2.signed_distance(pts2), 0, atol=1e-9)
    back = g2.transformed(invert_rigid(cam2_from_cam1))
    np.testing.assert_allclose(back.normal, g1.normal, atol=1e-12)
    assert back.d == pytest.approx(g1.d)


def test_signed_distance_and_projection():
    g = prior_ground_plane(2.0)
    p = np.array([[1.0, 0.5, 4.0], [0, 3.0, 1.0]])
    np.testing.assert_allclose(g.signed_distance(p), [1.5, -1.0])
    np.testing.assert_allclose(g.project_to_plane(p), [[1.0, 2.0, 4.0], [0, 2.0, 1.0]])


def test_invalid_plane_and_inputs():
    with pytest.raises(ValueError):
        GroundPlane(np.zeros(3), 1.0, "x")
    with pytest.raises(ValueError):
        GroundPlane(np.array([0, -1, np.nan]), 1.0, "x")
    with pytest.raises(ValueError):
        prior_ground_plane(-1.0)
    with pytest.raises(ValueError):
        fit_ground_plane(np.zeros((10, 2)), np.random.default_rng(0))


def test_ground_plane_from_rendered_depth():
    truth = prior_ground_plane(1.65, pitch_rad=np.deg2rad(1.5))
    v, u = np.mgrid[0 : KITTI.height, 0 : KITTI.width]
    pts = truth.intersect_pixels(np.stack([u, v], -1).astype(float), KITTI)
    depth = np.where(np.isfinite(pts[..., 2]), pts[..., 2], 0).astype(np.float32)
    fit = ground_plane_from_depth(depth, KITTI, np.random.default_rng(0), max_depth_m=40)
    assert fit.d == pytest.approx(1.65, abs=1e-3)
    assert fit.pitch_roll_rad()[0] == pytest.approx(np.deg2rad(1.5), abs=1e-4)


def test_world_point_track_visibility_and_behind():
    # Camera moving forward along +z of the world (world = cam0), 1 m per frame.
    poses = [invert_rigid(make_rigid(np.eye(3), [0, 0, float(i)])) for i in range(25)]
    target = np.array([0.0, 1.65, 20.0])  # ground under the camera position of frame 20
    uv, visible = project_world_point_track(target, KITTI, poses)
    # v = cy + fy * 1.65 / (20 - i) stays inside the 370-row image while 20 - i > 6.24 m, i.e. frames 0..13
    assert visible[:14].all() and not visible[14:].any()
    assert np.isfinite(uv[14:20]).all()  # in front but below the image bottom: a pixel, not visible
    assert np.isnan(uv[20:]).all()  # at and behind the camera: no pixel
    assert uv[0] == pytest.approx([KITTI.cx, KITTI.cy + KITTI.fy * 1.65 / 20.0])
    assert np.all(np.diff(uv[:20, 1]) > 0)  # the track moves down the image as the camera approaches


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0.3, 3.0),
    st.floats(-0.3, 0.3),
    st.floats(-0.3, 0.3),
    st.floats(-1, 1),
    st.floats(-1, 1),
    st.floats(0.01, 1),
)
def test_ray_hits_lie_on_plane(h, pitch, roll, rx, ry, rz):
    g = prior_ground_plane(h, pitch, roll)
    hit = g.intersect_rays(np.array([rx, ry, rz]))
    if np.all(np.isfinite(hit)):
        assert abs(g.signed_distance(hit)) < 1e-6 * max(1.0, np.linalg.norm(hit))
        assert hit[2] > 0
        assert np.dot(hit, [rx, ry, rz]) > 0  # ahead along the ray
    else:
        assert np.isnan(hit).all()
