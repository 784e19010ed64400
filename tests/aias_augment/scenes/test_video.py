import numpy as np
import pytest

from aias_augment.core.config import data_root
from aias_augment.scenes.video import estimate_video_motion, read_video, trajectory_errors

KITTI = data_root() / "kitti06_seq"


@pytest.mark.skipif(not KITTI.exists(), reason="KITTI data not available")
def test_kitti_motion_matches_ground_truth():
    from aias_augment.scenes.kitti import open_kitti_sequence

    seq = open_kitti_sequence(KITTI)
    idx = [0, 1, 2, 3]
    m = estimate_video_motion([seq.frame(i).image for i in idx], np.random.default_rng(0), intrinsics=seq.intrinsics)
    assert m.status == ("moving",) * 3
    err = trajectory_errors(m.cams_from_world, np.stack([seq.cam_from_world(i) for i in idx]))
    assert err["rotation_err_deg_median"] < 0.5 and err["translation_dir_err_deg_median"] < 3.0
    same = estimate_video_motion([seq.frame(i).image for i in idx], np.random.default_rng(0), intrinsics=seq.intrinsics)
    np.testing.assert_array_equal(m.cams_from_world, same.cams_from_world)  # seeded RANSAC: reproducible


@pytest.mark.skipif(not (data_root() / "video/vtest.avi").exists(), reason="video not available")
def test_static_camera_video():
    frames = read_video(str(data_root() / "video/vtest.avi"), max_frames=3, stride=10)
    m = estimate_video_motion(frames, np.random.default_rng(0))
    assert m.status == ("static", "static")
    np.testing.assert_array_equal(m.cams_from_world, np.tile(np.eye(4), (3, 1, 1)))


def test_too_few_frames():
    with pytest.raises(ValueError):
        estimate_video_motion([np.zeros((10, 10, 3), np.uint8)], np.random.default_rng(0))
