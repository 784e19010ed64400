import numpy as np
import pytest

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.core.geometry import Intrinsics, make_rigid, rotation_about_axis
from aias_augment.plan.collision import (
    OrientedBox,
    boxes_intersect,
    check_candidate,
    depth_occlusion,
    points_inside_box,
    scene_points_collision,
)
from aias_augment.plan.placement import object_pose_on_ground

INTR = Intrinsics(500, 500, 320, 240, 640, 480)
GROUND = prior_ground_plane(1.5)


def _box_at(x, z, size=(0.5, 0.5, 1.0), yaw=0.0):
    return OrientedBox.standing_on_ground(object_pose_on_ground(np.array([x, 1.5, z]), GROUND, yaw), size)


def test_standing_box_rests_on_ground():
    box = _box_at(1.0, 8.0)
    heights = GROUND.signed_distance(box.corners())
    np.testing.assert_allclose(sorted(heights), [0] * 4 + [1.0] * 4, atol=1e-12)


def test_points_inside_rotated_box():
    box = OrientedBox(make_rigid(rotation_about_axis([0, 1, 0], np.pi / 4), [0, 0, 5]), (2.0, 1.0, 1.0))
    # along the rotated x axis (diagonal in x-z) 0.9 m is inside, along the camera x axis 0.9 m is outside
    diag = np.array([np.cos(np.pi / 4), 0, -np.sin(np.pi / 4)])
    pts = np.array([[0, 0, 5.0], [0, 0, 5.0] + 0.9 * diag, [0.9, 0, 5.0], [0, 0.6, 5.0]])
    np.testing.assert_array_equal(points_inside_box(pts, box), [True, True, False, False])
    assert points_inside_box(pts[3:], box, margin_m=0.2).all()


def test_box_intersection_separating_axis():
    a = _box_at(0.0, 8.0)
    assert boxes_intersect(a, _box_at(0.4, 8.0))
    assert not boxes_intersect(a, _box_at(0.6, 8.0))
    assert boxes_intersect(a, _box_at(0.6, 8.0), margin_m=0.06)
    # rotated 45 deg: its corner reaches 0.354 m from its centre
    assert boxes_intersect(a, _box_at(0.55, 8.0, yaw=np.pi / 4))
    assert not boxes_intersect(a, _box_at(0.65, 8.0, yaw=np.pi / 4))


def test_scene_points_cluster_collides_but_ground_points_do_not():
    box = _box_at(0.0, 8.0)
    rng = np.random.default_rng(0)
    ground_pts = np.column_stack([rng.uniform(-0.2, 0.2, 50), np.full(50, 1.5 - 0.02), rng.uniform(7.8, 8.2, 50)])
    assert scene_points_collision(box, ground_pts, GROUND) is None
    pole = np.column_stack([np.zeros(5), np.linspace(1.0, 0.7, 5), np.full(5, 8.0)])  # 0.5..0.8 m above ground
    hit = scene_points_collision(box, np.vstack([ground_pts, pole]), GROUND)
    assert (hit.kind, hit.detail) == ("intersects scene points above the ground", "5 points")
    assert scene_points_collision(box, pole[:2], GROUND) is None  # 2 points < min_points_inside: noise


def test_depth_occlusion_and_reasons():
    box = _box_at(0.0, 10.0)
    far_scene = np.full((480, 640), 30.0, np.float32)
    assert depth_occlusion(box, far_scene, INTR) == (None, 0.0)
    wall = np.full((480, 640), 5.0, np.float32)  # something 5 m away hides the object
    reason, frac = depth_occlusion(box, wall, INTR)
    assert frac == 1.0 and reason.kind == "hidden behind nearer scene surfaces"
    assert depth_occlusion(box, np.zeros((480, 640), np.float32), INTR) == (None, 0.0)  # unknown != occluder
    behind = _box_at(0.0, -3.0)
    assert depth_occlusion(behind, far_scene, INTR)[0].kind == "object crosses the camera plane"
    hit = check_candidate(box, GROUND, INTR, existing=[OrientedBox(box.cam_from_box, (4, 2, 1.5), "car")])
    assert str(hit) == "intersects an existing object: car"
    assert check_candidate(box, GROUND, INTR, depth=far_scene) is None


def test_invalid_box():
    with pytest.raises(ValueError):
        OrientedBox(np.eye(4), (1.0, 0.0, 1.0))


def test_sample_placement_rejects_candidates_inside_point_clusters():
    """placement.sample_placement with points_in_cam: a wall of points across the whole ground in front rejects
    every candidate with the collision reason, and without the points the same seed places the object."""
    import trimesh

    from aias_augment.assets.asset import Asset
    from aias_augment.plan.placement import PlacementConfig, sample_placement

    asset = Asset(
        "box",
        "barrel",
        (trimesh.creation.box((0.6, 0.6, 1.0), trimesh.transformations.translation_matrix([0, 0, 0.5])),),
        "test",
    )
    xs, ys, zs = np.meshgrid(np.linspace(-30, 30, 121), np.linspace(0.6, 1.4, 5), np.linspace(2, 40, 77))
    forest = np.column_stack([xs.ravel(), ys.ravel(), zs.ravel()])  # points 0.1..0.9 m above the ground
    # No local ground refit: these points are a 'forest' above the ground, not ground (the refit would reject
    # every candidate as uneven ground before the collision check this test is about).
    cfg = PlacementConfig(max_tries=20, local_refit=False)
    placed, _ = sample_placement(asset, GROUND, INTR, np.random.default_rng(0), cfg=cfg, height_range_m=(1.0, 1.0))
    assert placed is not None
    none, report = sample_placement(
        asset, GROUND, INTR, np.random.default_rng(0), cfg=cfg, points_in_cam=forest, height_range_m=(1.0, 1.0)
    )
    assert none is None and report.rejected["intersects scene points above the ground"] > 0
