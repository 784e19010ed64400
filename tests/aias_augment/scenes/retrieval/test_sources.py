import cv2
import numpy as np
import pytest

from aias_augment.scenes.retrieval.sources import iter_frames, read_image


def test_video_and_folder(tmp_path):
    video = tmp_path / "v.avi"
    wr = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5, (32, 24))
    for i in range(7):
        wr.write(np.full((24, 32, 3), i * 30, np.uint8))
    wr.release()
    got = list(iter_frames(video, every=3))
    assert [r.frame for r, _ in got] == ["v.avi#00000", "v.avi#00003", "v.avi#00006"]
    assert got[0][1].shape == (24, 32, 3)
    assert len(list(iter_frames(video, max_frames=2))) == 2
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"{i}.png"), np.zeros((4, 4), np.uint8))
    assert [r.frame for r, _ in iter_frames(tmp_path, every=2)] == ["0.png", "2.png"]


def test_bad_sources(tmp_path):
    with pytest.raises(ValueError, match="no images"):
        list(iter_frames(tmp_path))
    (tmp_path / "x.txt").write_text("x")
    with pytest.raises(ValueError, match="not a folder"):
        list(iter_frames(tmp_path / "x.txt"))
    cv2.imwrite(str(tmp_path / "d.png"), np.zeros((4, 4), np.uint16))
    with pytest.raises(ValueError, match="8-bit"):
        read_image(tmp_path / "d.png")
    with pytest.raises(ValueError, match="every"):
        list(iter_frames(tmp_path, every=0))
