"""studies._shared.pictures: a picture is written as a JPEG of at most MAX_SIDE px on a side, read back by PIL."""

import numpy as np
import pytest
from PIL import Image

from studies._shared.pictures import MAX_SIDE, fit_max_side, save_figure_jpeg, write_jpeg


def test_a_large_picture_is_shrunk_to_the_bound_with_its_aspect_and_colour(tmp_path):
    bgr = np.zeros((900, 3600, 3), np.uint8)
    bgr[..., 2] = 200  # red in BGR
    write_jpeg(tmp_path / "wide.jpg", bgr)
    with Image.open(tmp_path / "wide.jpg") as im:
        assert im.format == "JPEG" and im.size == (MAX_SIDE, MAX_SIDE // 4)  # 3600 x 900: aspect 4
        rgb = np.asarray(im.convert("RGB"), float)
    assert np.abs(rgb.mean((0, 1)) - [200, 0, 0]).max() < 3


def test_a_small_picture_keeps_its_size_and_a_png_name_is_refused(tmp_path):
    small = np.full((30, 40), 128, np.uint8)
    assert fit_max_side(small) is small
    write_jpeg(tmp_path / "small.jpg", small)
    with Image.open(tmp_path / "small.jpg") as im:
        assert im.size == (40, 30)
    with pytest.raises(ValueError, match="name the picture .jpg"):
        write_jpeg(tmp_path / "sheet.png", small)
    assert not (tmp_path / "sheet.png").exists()


def test_a_figure_is_written_as_a_bounded_jpeg(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(20, 4))
    ax.plot([0, 1], [0, 1])
    save_figure_jpeg(fig, tmp_path / "plot.jpg", dpi=110)  # 2200 x 440 before the bound
    plt.close(fig)
    with Image.open(tmp_path / "plot.jpg") as im:
        assert im.format == "JPEG" and im.size == (MAX_SIDE, MAX_SIDE // 5)  # 2200 x 440: aspect 5
