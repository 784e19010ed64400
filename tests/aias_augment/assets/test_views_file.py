"""A views file's cost is bounded before decoding (issue 54, item 6): large photos are worked on at most at
MAX_VIEW_PIXELS with their K, mask and box scaled; a photo whose header claims too many pixels is refused."""

import json
import resource

import cv2
import numpy as np
import pytest

from aias_augment.assets.views_file import MAX_VIEW_PIXELS, read_views
from tests.aias_augment.cli.test_assets import _png_header_only


def _project(K, p):
    return K[0, 0] * p[0] / p[2] + K[0, 2], K[1, 1] * p[1] / p[2] + K[1, 2]


def test_a_6000x4000_photo_is_downscaled_with_its_camera(tmp_path):
    w, h = 6000, 4000
    img = np.full((h, w, 3), 120, np.uint8)
    mask = np.zeros((h, w), np.uint8)
    mask[1000:3000, 2000:4400] = 255  # x 2000..4399, y 1000..2999
    cv2.imwrite(str(tmp_path / "big.png"), img)
    cv2.imwrite(str(tmp_path / "big_mask.png"), mask)
    K = np.array([[5000.0, 0, 2999.5], [0, 5000.0, 1999.5], [0, 0, 1]])
    view = {"image": "big.png", "mask": "big_mask.png", "K": K.tolist(), "cam_from_object": np.eye(4).tolist()}
    (tmp_path / "views.json").write_text(json.dumps({"views": [view, view]}))
    photos, _ = read_views(tmp_path / "views.json")
    rgb, m, intr, _ = photos[0]
    assert rgb.shape[0] * rgb.shape[1] <= MAX_VIEW_PIXELS and m.shape == rgb.shape[:2]
    assert (intr.width, intr.height) == (rgb.shape[1], rgb.shape[0])
    sx, sy = intr.width / w, intr.height / h
    # a point projects where the original projection lands once the pixel grid is scaled (pixel centres)
    for p in ([0.1, -0.2, 2.0], [-0.3, 0.25, 3.0]):
        u, v = _project(K, p)
        u2, v2 = _project(intr.K, p)
        assert u2 == pytest.approx((u + 0.5) * sx - 0.5, abs=1e-6)
        assert v2 == pytest.approx((v + 0.5) * sy - 0.5, abs=1e-6)
    ys, xs = np.nonzero(m)
    assert xs.min() == pytest.approx(2000 * sx, abs=1) and xs.max() + 1 == pytest.approx(4400 * sx, abs=1)
    assert ys.min() == pytest.approx(1000 * sy, abs=1) and ys.max() + 1 == pytest.approx(3000 * sy, abs=1)


def test_a_photo_whose_header_claims_400_megapixels_is_refused_before_decoding(tmp_path):
    _png_header_only(tmp_path / "huge.png", 20000, 20000)
    cv2.imwrite(str(tmp_path / "m.png"), np.zeros((4, 4), np.uint8))
    view = {"image": "huge.png", "mask": "m.png", "K": np.eye(3).tolist(), "cam_from_object": np.eye(4).tolist()}
    (tmp_path / "views.json").write_text(json.dumps({"views": [view, view]}))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(ValueError, match="view 0: image too large"):
        read_views(tmp_path / "views.json")
    assert (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024 < 100  # MB; a decode is 1200
