import numpy as np
import pytest

from aias_augment.analyse.ground import ground_plane_from_depth
from aias_augment.core.config import data_root
from aias_augment.scenes.nyu import open_rgbd_sequence, read_tum_poses

NYU = data_root() / "nyu_rgbd"
pytestmark = pytest.mark.skipif(not NYU.exists(), reason="shared NYU data not available")


def test_frames_depth_poses():
    seq = open_rgbd_sequence(NYU)
    assert len(seq) == 5
    f = seq.frame(0)
    assert f.image.shape == (480, 640, 3) and f.depth.dtype == np.float32
    valid = f.depth[f.depth > 0]
    assert 0.3 < np.median(valid) < 6.0  # indoor room, metres (value / 1000)
    assert (f.depth[:8] == 0).all()  # white border masked
    row = np.loadtxt(NYU / "pose.txt")[0]
    np.testing.assert_allclose(np.linalg.inv(f.cam_from_world)[:3, 3], row[:3], atol=1e-9)


def test_indoor_floor_is_found():
    f = open_rgbd_sequence(NYU).frame(0)
    lower = np.zeros(f.depth.shape, bool)
    lower[300:] = True
    g = ground_plane_from_depth(f.depth, f.intrinsics, np.random.default_rng(0), mask=lower, max_tilt_deg=40)
    assert 0.5 < g.d < 2.0  # a hand-held Kinect is between knee and head height above the floor


def test_bad_pose_file(tmp_path):
    p = tmp_path / "pose.txt"
    p.write_text("1 2 3\n")
    with pytest.raises(ValueError, match="7 numbers"):
        read_tum_poses(p)
