import cv2
import numpy as np
import pytest

from aias_augment.analyse.ground import ground_plane_from_depth
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics
from aias_augment.scenes.stereo import disparity_to_depth, stereo_depth, stereo_disparity

KITTI_SEQ = data_root() / "kitti06_seq"


def _textured(rng, h=120, w=320):
    img = rng.integers(0, 256, (h // 4, w // 4), dtype=np.uint8)
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_LINEAR)


@pytest.mark.parametrize("shift", [8, 21])
def test_constant_shift_gives_its_disparity(shift):
    rng = np.random.default_rng(0)
    left = _textured(rng)
    right = np.roll(left, -shift, axis=1)  # a scene point at x in the left image is at x - shift in the right
    disp = stereo_disparity(left, right, num_disparities=64, block_size=5)
    interior = disp[20:-20, 64 + 10 : -20]
    valid = interior > 0
    assert valid.mean() > 0.9
    assert np.median(interior[valid]) == pytest.approx(shift, abs=0.25)


def test_depth_from_disparity_formula_and_invalid():
    disp = np.array([[0.0, 0.2, 10.0, 40.0]], np.float32)
    depth = disparity_to_depth(disp, 700.0, 0.5)
    np.testing.assert_allclose(depth, [[0, 0, 35.0, 8.75]])
    with pytest.raises(ValueError):
        disparity_to_depth(disp, 700.0, 0.0)


def test_rgb_equals_grey_input():
    rng = np.random.default_rng(1)
    left = _textured(rng)
    right = np.roll(left, -10, axis=1)
    intr = Intrinsics(300, 300, 160, 60, 320, 120)
    a = stereo_depth(left, right, intr, 0.5, num_disparities=32)
    b = stereo_depth(np.repeat(left[..., None], 3, 2), np.repeat(right[..., None], 3, 2), intr, 0.5, num_disparities=32)
    np.testing.assert_array_equal(a, b)
    assert a.dtype == np.float32


def test_bad_inputs_raise():
    img = np.zeros((50, 200), np.uint8)
    with pytest.raises(ValueError, match="differ"):
        stereo_disparity(img, np.zeros((50, 190), np.uint8))
    with pytest.raises(ValueError, match="multiple of 16"):
        stereo_disparity(img, img, num_disparities=100)
    with pytest.raises(ValueError, match="odd"):
        stereo_disparity(img, img, block_size=4)
    with pytest.raises(ValueError, match="uint8"):
        stereo_disparity(img.astype(np.float32), img)
    with pytest.raises(ValueError, match="intrinsics"):
        stereo_depth(img, img, Intrinsics(100, 100, 50, 25, 100, 50), 0.5)


@pytest.mark.skipif(not (KITTI_SEQ / "calib.txt").exists(), reason="KITTI 06 sequence not available")
@pytest.mark.parametrize("frame", [10, 40])
def test_kitti_stereo_ground_gives_camera_height(frame):
    """KITTI's cam0 is mounted 1.65 m above the road (Geiger et al., IJRR 2013): the ground fitted to SGBM depth
    must reproduce it (within a few cm of suspension and road camber), which checks the baseline, the disparity
    scale and the plane fit together."""
    P = np.loadtxt(KITTI_SEQ / "calib.txt").reshape(2, 3, 4)
    left = cv2.imread(str(KITTI_SEQ / f"image_l/{frame:06d}.png"), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(str(KITTI_SEQ / f"image_r/{frame:06d}.png"), cv2.IMREAD_GRAYSCALE)
    intr = Intrinsics.from_matrix(P[0][:, :3], left.shape[1], left.shape[0])
    depth = stereo_depth(left, right, intr, -P[1][0, 3] / P[1][0, 0])
    assert (depth > 0).mean() > 0.5
    lower = np.zeros(depth.shape, bool)
    lower[int(intr.cy) + 20 :] = True
    g = ground_plane_from_depth(depth, intr, np.random.default_rng(0), mask=lower, max_depth_m=25)
    assert g.d == pytest.approx(1.65, abs=0.06)
    assert abs(np.degrees(g.pitch_roll_rad()[0])) < 3
