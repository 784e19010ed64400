"""The ground's pitch from labelled objects, checked on analytic projections of a camera whose pitch is known.

Upright 0.7 m objects stand on flat ground 1.3 m below a camera pitched down by a known angle; a box's bottom row is
its base's nearest edge and its top the object's top above the base's centre (0.28 of its height farther away). Starting from
the level-camera prior, :func:`ground_from_references` must find the true camera's horizon and pitch."""

import numpy as np
import pytest

from aias_augment.analyse.ground import GroundPlane, prior_ground_plane
from aias_augment.core.geometry import Intrinsics
from aias_augment.plan.references import RowHeights, ground_from_references, row_heights

K = Intrinsics(700.0, 700.0, 319.5, 239.5, 640, 480)
HEIGHT_M = 0.7


def _boxes(ground: GroundPlane, pixels, footprint: float = 0.28) -> np.ndarray:
    """Boxes of upright objects whose base's nearest edge is at ``pixels`` and whose axis stands ``footprint`` of
    their height farther along the ground (a cone's base half width), the top above the axis."""
    out = []
    for u, v in pixels:
        front = ground.intersect_pixels(np.array([[u, v]], float), K)[0]
        away = front - (front @ ground.normal) * ground.normal
        base = front + footprint * HEIGHT_M * away / np.linalg.norm(away)
        top = base + HEIGHT_M * ground.normal  # the normal points up
        pt = K.K @ top
        out.append([u - 20, pt[1] / pt[2], u + 20, v])
    return np.array(out)


@pytest.mark.parametrize("pitch_deg", [-3.0, 10.0, 24.0])
def test_the_horizon_and_pitch_come_back_from_equal_objects(pitch_deg):
    truth = prior_ground_plane(1.3, np.radians(pitch_deg))
    boxes = _boxes(truth, [(150, 300), (330, 360), (500, 420), (250, 460)])
    start = prior_ground_plane(1.65)  # the level-camera prior
    got, why = ground_from_references(start, K, boxes)
    assert got is not None, why
    u = float(((boxes[:, 0] + boxes[:, 2]) / 2).mean())
    true_row = float(truth.horizon_row_at(u, K))
    assert abs(float(got.horizon_row_at(u, K)) - true_row) <= 0.01 * K.height, (got.horizon_row_at(u, K), true_row)
    assert abs(np.degrees(got.pitch_roll_rad()[0]) - pitch_deg) <= 0.25
    assert got.d == pytest.approx(start.d) and got.assumed_scale  # the scale is fitted afterwards, from the same boxes


def test_a_turn_beyond_the_limit_keeps_the_estimate():
    truth = prior_ground_plane(1.3, np.radians(40.0))
    boxes = _boxes(truth, [(150, 300), (330, 360), (500, 420)])
    got, why = ground_from_references(prior_ground_plane(1.65), K, boxes, max_change_deg=25.0)
    assert got is None and "beyond 25 deg" in why
    got, why = ground_from_references(prior_ground_plane(1.65), K, boxes, max_change_deg=45.0)
    assert got is not None and abs(np.degrees(got.pitch_roll_rad()[0]) - 40.0) <= 0.25, why


def test_what_gives_no_pitch():
    truth = prior_ground_plane(1.3, np.radians(10.0))
    start = prior_ground_plane(1.65)
    one = _boxes(truth, [(300, 400)])
    close_rows = _boxes(truth, [(150, 400), (450, 410)])  # 10 px apart: < 10 % of 480
    assert ground_from_references(start, K, one)[0] is None
    assert ground_from_references(start, K, close_rows)[0] is None
    scattered = _boxes(truth, [(150, 300), (330, 360), (500, 420)])
    scattered[1, 1] = scattered[1, 3] - 5  # one box far too short: not one kind on one ground
    got, why = ground_from_references(start, K, scattered)
    assert got is None and "RMS" in why
    measured = GroundPlane(truth.normal, 1.3, "depth", assumed_scale=False)
    got, why = ground_from_references(measured, K, _boxes(truth, [(150, 300), (330, 360), (500, 420)]))
    assert got is None and "measured" in why


# --- box heights on each row (RowHeights) --------------------------------------------------------------------------


def _truth_height_at(truth: GroundPlane, u: float, v: float) -> float:
    b = _boxes(truth, [(u, v)])[0]
    return float(b[3] - b[1])


@pytest.mark.parametrize("pitch_deg", [2.0, 12.0, 35.0])
def test_row_heights_from_spread_boxes_give_the_height_on_other_rows(pitch_deg):
    """The line through four labelled boxes gives the analytic box height of the same object on rows between and
    beyond them (a wrong ground estimate does not enter: the boxes spread)."""
    truth = prior_ground_plane(1.3, np.radians(pitch_deg))
    rows = [300, 340, 380, 420] if pitch_deg < 30 else [120, 200, 280, 360]
    boxes = _boxes(truth, [(150 + 90 * i, v) for i, v in enumerate(rows)])
    line, why = row_heights(prior_ground_plane(1.65), K, boxes)  # the level prior: far from the truth
    assert line is not None and line.source == "fit", why
    for v in (rows[0] + 20, rows[-1] - 20, min(rows[-1] + 50, 470)):
        want = _truth_height_at(truth, 320.0, v)
        assert abs(float(line.at(v)) / want - 1.0) < 0.03, (v, float(line.at(v)), want)


def test_row_heights_through_the_horizon_when_the_rows_do_not_spread():
    truth = prior_ground_plane(1.3, np.radians(10.0))
    boxes = _boxes(truth, [(150, 400), (450, 410)])  # 10 px apart: no line from them alone
    line, why = row_heights(truth, K, boxes)
    assert line is not None and line.source == "horizon", why
    assert abs(line.zero_row - float(truth.horizon_row_at(300.0, K))) < 0.5
    for v in (300, 460):
        assert abs(float(line.at(v)) / _truth_height_at(truth, 300.0, v) - 1.0) < 0.05


def test_what_gives_no_row_heights():
    truth = prior_ground_plane(1.3, np.radians(10.0))
    cut = _boxes(truth, [(150, 400), (450, 470)])
    cut[:, 1] = 0.0  # both cut by the frame's top: no height seen
    assert row_heights(truth, K, cut)[0] is None
    above = np.array([[100.0, 50.0, 140.0, 90.0]])  # a lone box above the horizon
    assert row_heights(truth, K, above)[0] is None
    with pytest.raises(ValueError):
        RowHeights(-1.0, 100.0, "fit")
