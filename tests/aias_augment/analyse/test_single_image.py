import cv2
import numpy as np
import pytest

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.analyse.single_image import (
    estimate_camera_from_image,
    fit_vanishing_point,
    horizon_row_error_px,
    weighted_pairs,
)
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics, project_points

INTR = Intrinsics(500, 500, 399.5, 299.5, 800, 600)


def _synthetic_street(pitch, roll, rng):
    """Image of 3D line segments: poles (world vertical) and road-parallel lines, seen by a camera with the given
    pitch/roll at 1.5 m. World up in camera = prior_ground_plane(...).normal, independent of the estimator."""
    g = prior_ground_plane(1.5, pitch, roll)
    up = g.normal
    fwd = np.cross(np.array([1.0, 0, 0]), up)  # horizontal direction roughly along +z
    fwd /= np.linalg.norm(fwd) * np.sign(fwd[2])
    side = np.cross(up, fwd)
    img = np.full((600, 800), 90, np.uint8)
    segs = []
    for _ in range(25):  # poles
        base = -1.5 * up + rng.uniform(-8, 8) * side + rng.uniform(6, 30) * fwd
        segs.append((base, base + rng.uniform(2, 5) * up))
    for _ in range(25):  # road-direction lines (curbs, lane marks, facade edges)
        start = -1.5 * up + rng.uniform(-6, 6) * side + rng.uniform(0, 2.5) * up + rng.uniform(4, 10) * fwd
        segs.append((start, start + rng.uniform(5, 20) * fwd))
    for a, b in segs:
        uv, z = project_points(np.array([a, b]), INTR.K)
        if np.all(z > 0.1):
            cv2.line(img, tuple(np.round(uv[0]).astype(int)), tuple(np.round(uv[1]).astype(int)), 230, 3)
    return img, g


@pytest.mark.parametrize("pitch_deg,roll_deg", [(0, 0), (4, 0), (-3, 2), (6, -3)])
def test_horizon_of_synthetic_street(pitch_deg, roll_deg):
    img, truth = _synthetic_street(np.deg2rad(pitch_deg), np.deg2rad(roll_deg), np.random.default_rng(1))
    est = estimate_camera_from_image(img, np.random.default_rng(0), intrinsics=INTR)
    assert est.horizon_source == "vertical+horizontal_vp"
    err = horizon_row_error_px(est.horizon_line, truth.horizon_line(INTR), np.array([0, 399.5, 799]))
    assert err.max() < 4.0
    assert np.degrees(est.pitch_rad) == pytest.approx(pitch_deg, abs=0.5)
    assert np.degrees(est.roll_rad) == pytest.approx(roll_deg, abs=0.5)


def test_focal_from_orthogonal_vanishing_points():
    img, _ = _synthetic_street(np.deg2rad(8), 0.0, np.random.default_rng(2))  # pitch makes the vertical VP finite
    est = estimate_camera_from_image(img, np.random.default_rng(0))
    assert est.focal_source == "vanishing_points"
    assert est.intrinsics.fx == pytest.approx(500, rel=0.1)


def test_blank_image_falls_back_to_prior():
    est = estimate_camera_from_image(np.full((100, 200, 3), 128, np.uint8), np.random.default_rng(0))
    assert est.horizon_source == "prior" and est.focal_source == "prior"
    assert est.horizon_row_at(100) == pytest.approx(49.5)
    assert est.ground.d == pytest.approx(1.65)


def test_vanishing_point_at_infinity():
    # parallel vertical segments: their VP is a point at infinity (w = 0), which must be representable
    segs = np.array([[x, 10.0, x, 90.0] for x in range(10, 200, 20)], float)
    vp, inl = fit_vanishing_point(segs, np.random.default_rng(0), min_inliers=5)
    assert abs(vp[2]) < 1e-9 and abs(vp[0]) < 1e-9 and inl.all()


def test_bad_input():
    with pytest.raises(ValueError):
        estimate_camera_from_image(np.zeros((10, 10), np.float32), np.random.default_rng(0))


@pytest.mark.skipif(not (data_root() / "kitti06_seq").exists(), reason="KITTI data not available")
def test_kitti_frame_horizon_near_truth():
    from aias_augment.scenes.kitti import open_kitti_sequence

    seq = open_kitti_sequence(data_root() / "kitti06_seq")
    est = estimate_camera_from_image(seq.frame(0).image, np.random.default_rng(0), intrinsics=seq.intrinsics)
    # KITTI cam0 is mounted level to within ~1 deg: the true horizon is within ~12 px of cy (fy tan 1 deg)
    assert abs(est.horizon_row_at(seq.intrinsics.cx) - seq.intrinsics.cy) < 25


@pytest.mark.parametrize("seed", range(6))
def test_weighted_pairs_are_numpys_pairs_and_leave_the_same_state(seed):
    """The RANSAC pairs equal n calls of Generator.choice(2, replace=False, p), including pairs where one heavy
    segment is drawn twice (numpy's redraw), and the generator continues where those calls leave it."""
    r = np.random.default_rng(seed)
    w = r.uniform(0.0, 1.0, int(r.integers(2, 30))) ** 4
    w[0] *= 200.0 if seed % 2 else 1.0  # a dominant segment: duplicates and redraws happen
    prob = w / w.sum()
    a_rng, b_rng = np.random.default_rng(seed + 10), np.random.default_rng(seed + 10)
    expect = np.stack([a_rng.choice(len(prob), 2, replace=False, p=prob) for _ in range(300)])
    np.testing.assert_array_equal(weighted_pairs(b_rng, prob, 300), expect)
    assert a_rng.random() == b_rng.random()


def test_consistency_angles_are_the_reductions_over_xy_bit_for_bit():
    """The segment-to-VP angles, computed on (K, N) planes of x and y: the same numbers as norms and dot products
    reduced over a last axis of 2, for finite VPs, VPs at infinity (w = 0) and a VP on a segment's midpoint."""
    from aias_augment.analyse.single_image import consistency_deg

    rng = np.random.default_rng(7)
    seg = rng.uniform(0, 640, (120, 4))
    vps = rng.normal(size=(300, 3))
    vps[::5, 2] = 0.0
    vps[0] = [*(seg[0, :2] + seg[0, 2:]) / 2, 1.0]
    vps /= np.linalg.norm(vps, axis=1, keepdims=True)
    mid = (seg[:, :2] + seg[:, 2:]) / 2
    direction = (seg[:, 2:] - seg[:, :2]) / np.linalg.norm(seg[:, 2:] - seg[:, :2], axis=1, keepdims=True)
    to_vp = vps[:, None, :2] - vps[:, None, 2:3] * mid[None]
    norm = np.linalg.norm(to_vp, axis=2)
    cos = np.abs(np.sum(to_vp / np.maximum(norm, 1e-12)[..., None] * direction[None], axis=2))
    want = np.where(norm > 1e-9, np.degrees(np.arccos(np.clip(cos, 0.0, 1.0))), 90.0)
    np.testing.assert_array_equal(consistency_deg(seg, vps), want)


def test_lsd_segments_are_opencvs_and_shared_between_readers_of_one_image():
    """The camera estimate and the sun's side read one grey copy: the second read is the first's array (by content,
    not identity), the segments are OpenCV's LSD's with its default (standard) refinement, and nobody can change
    them; the sun's side's (S, 2, 2) end points are the same segments."""
    from aias_augment.analyse.lighting.sun_side import detect_line_segments as sun_side_segments
    from aias_augment.analyse.single_image import detect_line_segments, lsd_segments

    rng = np.random.default_rng(4)
    rgb = _synthetic_street(np.radians(8.0), np.radians(2.0), rng)[0]
    rgb = np.ascontiguousarray(rgb if rgb.ndim == 3 else np.repeat(rgb[..., None], 3, -1))
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    first = lsd_segments(grey)
    direct = cv2.createLineSegmentDetector().detect(grey)[0].reshape(-1, 4).astype(np.float64)
    np.testing.assert_array_equal(first, direct)
    assert lsd_segments(grey.copy()) is first
    assert not first.flags.writeable
    other = grey.copy()
    other[:10] = 255 - other[:10]
    assert lsd_segments(other) is not first
    long_ones = detect_line_segments(grey, 20.0)
    np.testing.assert_array_equal(sun_side_segments(rgb, 20.0).reshape(-1, 4), long_ones)
    assert len(long_ones) and long_ones.flags.writeable
