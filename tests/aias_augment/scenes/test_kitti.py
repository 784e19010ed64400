import numpy as np
import pytest

from aias_augment.core.config import data_root
from aias_augment.core.geometry import invert_rigid
from aias_augment.scenes.kitti import open_kitti_sequence, read_kitti_calib, read_kitti_poses

SEQ = data_root() / "kitti06_seq"
SNIPPET = data_root() / "kitti06_color_snippet"
pytestmark = pytest.mark.skipif(not SEQ.exists(), reason="shared KITTI data not available")


def test_compact_layout_calib_poses_frames():
    seq = open_kitti_sequence(SEQ)
    assert len(seq) == 51 and seq.frame_ids[0] == 0
    assert seq.intrinsics.fx == pytest.approx(707.0912) and seq.intrinsics.width == 1226
    assert seq.baseline_m == pytest.approx(379.8145 / 707.0912)
    f = seq.frame(3)
    assert f.image.shape == (370, 1226, 3) and f.meta["frame_id"] == 3
    # poses.txt line 4 is world_from_cam of frame 3; the frame stores its inverse
    row = np.loadtxt(SEQ / "poses.txt")[3].reshape(3, 4)
    np.testing.assert_allclose(invert_rigid(f.cam_from_world)[:3], row, atol=1e-9)
    # 51 frames, ~60 m almost straight ahead (+z of cam0): SOURCE.txt
    assert seq.world_from_cams[-1][2, 3] == pytest.approx(59.9, abs=1.0)


def test_official_layout_with_prefixed_calib(tmp_path):
    """The official layout (P0:..P3: lines, image_0/image_1, poses/<seq>.txt) read from a rebuilt copy."""
    seq_dir = tmp_path / "sequences" / "06"
    (seq_dir / "image_0").mkdir(parents=True)
    (seq_dir / "image_1").mkdir()
    (tmp_path / "poses").mkdir()
    P = np.loadtxt(SEQ / "calib.txt").reshape(2, 3, 4)
    lines = [f"P{i}: " + " ".join(map(str, P[min(i, 1)].ravel())) for i in range(4)]
    (seq_dir / "calib.txt").write_text("\n".join(lines) + "\nTr: " + " ".join(["0"] * 12) + "\n")
    for i in range(2):
        for src, dst in (("image_l", "image_0"), ("image_r", "image_1")):
            (seq_dir / dst / f"{i:06d}.png").write_bytes((SEQ / src / f"{i:06d}.png").read_bytes())
    (tmp_path / "poses" / "06.txt").write_text("\n".join((SEQ / "poses.txt").read_text().splitlines()[:2]) + "\n")
    seq = open_kitti_sequence(seq_dir)
    assert len(seq) == 2 and seq.baseline_m == pytest.approx(0.537, abs=1e-3)
    assert seq.world_from_cams.shape == (2, 4, 4)


def test_snippet_layout_yaml_and_sparse_frames():
    seq = open_kitti_sequence(SNIPPET)
    assert seq.frame_ids == (12, 13, 14, 17)
    assert seq.right_paths[0] is not None and seq.right_paths[1] is None
    all_poses = read_kitti_poses(SNIPPET / "06.txt")
    np.testing.assert_allclose(seq.world_from_cams[3], all_poses[17])
    with pytest.raises(ValueError, match="no right image"):
        seq.stereo_depth(1)


def test_bad_calib_and_poses(tmp_path):
    bad = tmp_path / "calib.txt"
    bad.write_text("P0: 1 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(ValueError, match="P1"):
        read_kitti_calib(bad, 10, 10)
    poses = tmp_path / "poses.txt"
    poses.write_text("1 0 0 0 0 1 0 0 0 0 1\n")
    with pytest.raises(ValueError, match="12 numbers"):
        read_kitti_poses(poses)
    with pytest.raises(FileNotFoundError):
        open_kitti_sequence(tmp_path / "missing")
