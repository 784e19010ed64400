import numpy as np
import pytest

from aias_augment.analyse.ground import fit_ground_plane
from aias_augment.core.config import data_root
from aias_augment.core.geometry import invert_rigid, project_points
from aias_augment.scenes.dgp import open_dgp_scene

DGP = data_root() / "dgp_scene"
pytestmark = pytest.mark.skipif(not DGP.exists(), reason="shared DGP data not available")


@pytest.fixture(scope="module")
def scene():
    return open_dgp_scene(DGP)


def test_calibration_agrees_with_datum_poses(scene):
    """Two independent routes to cam_from_lidar: the rig calibration and the per-datum world poses."""
    for cam in scene.camera_names:
        via_world = invert_rigid(scene.world_from_sensor(0, cam)) @ scene.world_from_sensor(0, "LIDAR")
        np.testing.assert_allclose(scene.cam_from_lidar(0, cam), via_world, atol=1e-5)


def test_frame_lidar_depth_and_ground(scene):
    f = scene.frame(0, "CAMERA_01")
    assert f.image.shape == (1216, 1936, 3)
    pts = f.meta["lidar_points_in_cam"]
    uv, z = project_points(pts, f.intrinsics.K)
    vis = (z > 0) & np.all((uv >= 0) & (uv < [1936, 1216]), axis=1)
    assert (f.depth > 0).sum() > 0.7 * vis.sum()  # the z-buffer keeps most visible points (a few share pixels)
    # the camera-frame ground near the car is 1.3..1.7 m below the camera (roof rig, camera 1.35 m above the
    # LiDAR origin and the road ~0.2 m below it: calibration + point heights, see SOURCE/extrinsics)
    near = pts[(pts[:, 2] > 0) & (pts[:, 2] < 12)]
    g = fit_ground_plane(near, np.random.default_rng(0), up_hint=f.meta["up_in_cam"])
    assert 1.3 < g.d < 1.7
    assert np.degrees(np.arccos(g.normal @ f.meta["up_in_cam"])) < 5


def test_boxes_contain_their_lidar_points(scene):
    f = scene.frame(0, "CAMERA_01")
    from aias_augment.plan.collision import points_inside_box

    counts = [points_inside_box(f.meta["lidar_points_in_cam"], b, 0.1).sum() for b in f.meta["boxes_in_cam"]]
    assert len(counts) > 5 and np.median(counts) > 5  # annotated cars hold LiDAR returns: frames are consistent


def test_unknown_camera(scene):
    with pytest.raises(KeyError):
        scene.frame(0, "CAMERA_99")
