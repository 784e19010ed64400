"""KITTI-3D labels: the devkit's box built from a label line is the object's own box; alpha and calib as the
devkit reads them."""

import math

import numpy as np
import pytest

from aias_augment.core.geometry import make_rigid, rotation_about_axis
from aias_augment.core.kitti3d import (
    box_from_pose,
    calib_text,
    devkit_corners,
    label_line,
    occlusion_level,
    truncation,
)

# object z up = camera -y; object x (the heading) along camera x at yaw 0 (plan.placement.object_pose_on_ground)
LEVEL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _pose(yaw, t, tilt_deg=0.0):
    R = rotation_about_axis([1.0, 0.0, 0.0], math.radians(tilt_deg)) @ LEVEL @ rotation_about_axis([0, 0, 1], yaw)
    return make_rigid(R, t)


def _object_corners_in_cam(T, lo, hi):
    corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return (T @ corners.T).T[:, :3]


def _same_point_sets(a, b, tol):
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    return np.all(d.min(axis=1) < tol) and np.all(d.min(axis=0) < tol)


@pytest.mark.parametrize("yaw", [-3.0, -1.2, 0.0, 0.4, 1.5707963, 2.9])
def test_devkit_box_of_the_label_is_the_objects_box(yaw):
    """An off-centre asset box (bounds not centred on the object's origin) at a level pose: the 8 corners the devkit
    builds from (h, w, l, x, y, z, ry) are the 8 corners of the object's bounds moved by its pose."""
    lo, hi = np.array([-0.2, -0.1, 0.0]), np.array([0.5, 0.3, 0.9])
    T = _pose(yaw, [1.3, 1.6, 7.0])
    box = box_from_pose(T, (lo, hi))
    assert (box.l, box.w, box.h) == pytest.approx((0.7, 0.4, 0.9))
    assert box.tilt_deg == pytest.approx(0.0, abs=1e-9)
    assert _same_point_sets(devkit_corners(box), _object_corners_in_cam(T, lo, hi), 1e-9)


def test_alpha_is_rotation_y_minus_the_ray_angle():
    """alpha = ry - atan2(x, z) (wrapped): straight ahead alpha = ry; an object to the right seen side-on."""
    ahead = box_from_pose(_pose(0.7, [0.0, 1.6, 10.0]), ((-0.2, -0.2, 0), (0.2, 0.2, 1)))
    assert ahead.alpha == pytest.approx(ahead.rotation_y)
    right = box_from_pose(_pose(0.0, [5.0, 1.6, 5.0]), ((-0.2, -0.2, 0), (0.2, 0.2, 1)))
    assert right.rotation_y == pytest.approx(0.0, abs=1e-12)
    assert right.alpha == pytest.approx(-math.pi / 4)
    behind_wrap = box_from_pose(_pose(3.0, [-5.0, 1.6, 1.0]), ((-0.2, -0.2, 0), (0.2, 0.2, 1)))
    assert -math.pi <= behind_wrap.alpha < math.pi
    expected = (behind_wrap.rotation_y - math.atan2(-5.0, 1.0) + math.pi) % (2 * math.pi) - math.pi
    assert behind_wrap.alpha == pytest.approx(expected)


def test_tilted_ground_is_reported():
    box = box_from_pose(_pose(0.3, [0, 1.6, 8], tilt_deg=4.0), ((-0.2, -0.2, 0), (0.2, 0.2, 1)))
    assert box.tilt_deg == pytest.approx(4.0, abs=1e-6)


def test_label_line_fields_in_devkit_order():
    box = box_from_pose(_pose(0.5, [1.0, 1.6, 9.0]), ((-0.25, -0.25, 0.0), (0.25, 0.25, 0.75)))
    f = label_line("cone", box, (10, 20, 30, 60), 0.25, 1).split()
    assert f[0] == "cone" and len(f) == 15
    assert [float(v) for v in f[1:]] == pytest.approx(
        [0.25, 1, box.alpha, 10, 20, 30, 60, 0.75, 0.5, 0.5, 1.0, 1.6, 9.0, box.rotation_y], abs=0.006
    )
    with pytest.raises(ValueError):
        label_line("traffic cone", box, (0, 0, 1, 1), 0.0, 0)


def test_truncation_and_occlusion():
    assert truncation((10, 10, 20, 20), 100, 100) == 0.0
    assert truncation((-10, 0, 10, 10), 100, 100) == pytest.approx(0.5)
    assert truncation((200, 0, 210, 10), 100, 100) == 1.0
    assert [occlusion_level(v) for v in (1.0, 0.9, 0.6, 0.1)] == [0, 0, 1, 2]


def test_calib_p2_is_k_with_zero_translation():
    K = np.array([[500.0, 0, 320.5], [0, 510.0, 240.25], [0, 0, 1]])
    rows = dict(line.split(": ", 1) for line in calib_text(K).splitlines())
    assert set(rows) == {"P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo"}
    P2 = np.array(rows["P2"].split(), float).reshape(3, 4)
    assert np.allclose(P2, np.c_[K, np.zeros(3)], rtol=1e-12)
