"""apply/occluders: per-object ground scale and the labelled boxes' visibility under nearer inserted objects."""

from types import SimpleNamespace

import numpy as np
import pytest

from aias_augment.analyse.ground import prior_ground_plane
from aias_augment.apply.occluders import contact_depth, ground_scale, visibility_under_nearer
from aias_augment.core.geometry import Intrinsics
from aias_augment.plan.placement import scaled_ground

K = Intrinsics(500.0, 500.0, 319.5, 239.5, 640, 480)


@pytest.mark.parametrize("k", [0.6, 1.0, 1.7])
def test_a_placement_on_a_scaled_ground_gives_its_scale_and_the_labelled_depth_on_it(k):
    ground = prior_ground_plane(1.6)
    box = (300.0, 300.0, 40.0, 100.0)  # bottom edge middle at (320, 400)
    on_scaled = scaled_ground(ground, k).intersect_pixels(np.array([320.0, 400.0]), K)
    placement = SimpleNamespace(contact_point_in_cam=tuple(on_scaled))
    assert ground_scale(ground, placement) == pytest.approx(k)
    assert contact_depth(box, ground, K) * ground_scale(ground, placement) == pytest.approx(on_scaled[2])


def test_only_nearer_objects_cover_a_labelled_box():
    cover = np.zeros((10, 10), np.float32)
    cover[:, :5] = 1.0  # covers the left half of the box
    boxes = np.array([[0, 0, 10, 10]], float)
    assert visibility_under_nearer(boxes, [5.0], [cover], [4.0])[0] == pytest.approx(0.5)  # nearer: covers
    assert visibility_under_nearer(boxes, [5.0], [cover], [6.0])[0] == 1.0  # farther: hidden behind the box
    assert visibility_under_nearer(boxes, [None], [cover], [60.0])[0] == pytest.approx(0.5)  # no contact: far
