"""Thin structures off the ground (analyse/thin_structures.py) and the sites the placement refuses behind them
(plan/placement.thin_structure_in_front): a painted pole and rail beside a painted road, a lane marking on it."""

import numpy as np

from aias_augment.analyse.thin_structures import thin_structure_segments
from aias_augment.plan.placement import thin_structure_in_front


def _scene():
    """A 480x640 picture: sky, a grey road from row 200 down between columns 120 and 520 with a white lane line
    down its middle, verge beside it; a dark pole at columns 540-546 standing on the verge from row 120 to row 420,
    and a dark rail along rows 300-305 over the verge left of the road (columns 10-115)."""
    rng = np.random.default_rng(0)
    img = np.empty((480, 640, 3), np.uint8)
    img[:] = (150, 180, 215)
    img[200:] = (70, 120, 50)  # verge
    img[200:, 120:520] = (105, 105, 108)  # road
    img[200:, 317:323] = (235, 235, 235)  # lane line, road on both sides
    img[120:420, 540:546] = (30, 30, 32)  # pole
    img[300:305, 10:115] = (30, 30, 32)  # rail
    img = np.clip(img.astype(int) + rng.integers(-3, 4, img.shape), 0, 255).astype(np.uint8)
    road = np.zeros((480, 640), bool)
    road[205:, 124:516] = True
    road[205:, 315:325] = False  # the region leaves the paint out, as the appearance region does
    return img, road


def _near(segs, x, y0, y1, vertical=True):
    """Some segment runs along x (vertical) or along row x (horizontal) between y0 and y1."""
    for x1, ya, x2, yb in segs:
        if vertical and abs(x1 - x) <= 4 and abs(x2 - x) <= 4 and min(ya, yb) <= y0 + 10 and max(ya, yb) >= y1 - 10:
            return True
        if not vertical and abs(ya - x) <= 4 and abs(yb - x) <= 4 and min(x1, x2) <= y0 + 10 and max(x1, x2) >= y1 - 10:
            return True
    return False


def test_pole_and_rail_found_the_lane_line_not():
    img, road = _scene()
    segs = thin_structure_segments(img, road)
    assert _near(segs, 540, 120, 420) or _near(segs, 546, 120, 420)  # an edge of the pole
    assert _near(segs, 300, 10, 115, vertical=False) or _near(segs, 305, 10, 115, vertical=False)  # the rail
    assert not any(min(a, c) > 310 and max(a, c) < 330 and max(b, d) > 250 for a, b, c, d in segs)  # the paint


def test_sites_behind_a_pole_or_a_rail_are_refused_others_not():
    pole = np.array([[540.0, 120.0, 540.0, 420.0]], np.float32)  # foot at row 420
    rail = np.array([[10.0, 300.0, 115.0, 302.0]], np.float32)
    # a cone whose base (row 380) is farther than the pole's foot, its box crossed by the pole: refused
    assert thin_structure_in_front(np.array([520.0, 300.0, 560.0, 380.0]), pole) is not None
    # the same box with its base nearer than the pole's foot (row 440): the pole stands behind it
    assert thin_structure_in_front(np.array([520.0, 360.0, 560.0, 440.0]), pole) is None
    # a box beside the pole: nothing crosses it
    assert thin_structure_in_front(np.array([440.0, 300.0, 480.0, 380.0]), pole) is None
    # a rail across the box's upper part: refused; below the box's bottom tenth, or beside it: not
    assert thin_structure_in_front(np.array([40.0, 260.0, 80.0, 340.0]), rail) is not None
    assert thin_structure_in_front(np.array([40.0, 230.0, 80.0, 302.0]), rail) is None
    assert thin_structure_in_front(np.array([200.0, 260.0, 240.0, 340.0]), rail) is None


def test_the_analysis_keeps_them_and_its_cache_file_round_trips(tmp_path):
    """``thin_structures=True``: the analysis' region carries the segments (its note counts them) and a saved
    analysis loads with the same segments; off, none are looked for."""
    from aias_augment.analyse.analysis import SceneAnalysis, analyse_scene
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.config import InsertionConfig

    img, _ = _scene()
    on = analyse_scene(Frame(img, None), InsertionConfig(thin_structures=True))
    assert len(on.region.thin_segments) >= 1
    assert f"{len(on.region.thin_segments)} thin structures" in on.modules["region"]
    on.save(tmp_path / "a.npz")
    back = SceneAnalysis.load(tmp_path / "a.npz")
    np.testing.assert_array_equal(back.region.thin_segments, on.region.thin_segments)
    off = analyse_scene(Frame(img, None), InsertionConfig(thin_structures=False))
    assert len(off.region.thin_segments) == 0 and off.key != on.key
