"""The ground's pitch from the photo's own labelled objects (single-view metrology as in Hoiem, Efros and Hebert,
"Putting objects in perspective", CVPR 2006).

Objects of one kind standing on a planar ground have box heights fixed by where they stand: their bottom rows and
heights together say how far the camera looks down. A single photo's camera estimate (vanishing lines, or the
level-camera prior when it finds none) is often far from that on close-ups looking down at cones, and an inserted
object then takes the wrong size wherever it stands away from the labelled ones. :func:`ground_from_references`
turns the estimated ground about the camera's x axis to the pitch whose exact projection best gives the labelled
boxes' heights from their bottom rows (roll and camera height kept; the scene's scale is then fitted to the same
boxes). The fit searches the turn and the object-to-camera-height ratio on a grid: the projection of a standing
object depends on nothing else.

The same metrology sizes each inserted object without any camera model: objects of one height standing on a plane
seen by a camera without roll have box heights linear in their bottom rows, zero on the horizon
(:class:`RowHeights`). The labelled boxes give that line directly when their rows spread; the ground's horizon
anchors it when they do not. An inserted object of the labelled kind is scaled to the line's height on its own
bottom row, so it has its neighbours' size wherever the ground estimate is wrong (a wrong focal length or a pitch
the boxes ask to turn past :func:`ground_from_references`'s limit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aias_augment.analyse.ground import GroundPlane
from aias_augment.core.geometry import Intrinsics

__all__ = ["RowHeights", "ground_from_references", "row_heights", "whole_box_mask"]

MIN_SPREAD_FRAC = 0.1  # the bottom rows must spread over this fraction of the image height
MIN_TURN_DEG = 1.0  # a smaller turn is within what the boxes' footprints and pixels leave unknown: the estimate stands
MAX_RMS_LOG = 0.15  # with three or more boxes, the fit's RMS log height error (about 15 %) must stay below this
#: A standing object's base reaches this fraction of its height towards the camera from its axis (a road cone's
#: base half width is 0.24-0.33 of its height; a barrel's about 0.3).
FOOTPRINT = 0.28
_TURN_STEP_DEG = 0.25
_RATIOS = np.geomspace(0.02, 2.0, 1200)  # object height / camera height (0.4 % steps)


def _pitched(normal: np.ndarray, angle: float) -> np.ndarray:
    ca, sa = np.cos(angle), np.sin(angle)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, ca, -sa], [0.0, sa, ca]])
    return rx @ normal


def _log_errors(normal: np.ndarray, rays: np.ndarray, v_bottom: np.ndarray, log_h: np.ndarray, K: np.ndarray):
    """(len(_RATIOS), N) log(predicted / observed) box heights of objects standing with the front of their base at
    ``rays`` (N, 3) on the plane ``normal``, camera 1 above it, for every height ratio; NaN where the ray misses the
    ground or a top is behind. A box's bottom row is its base's nearest edge and its top the object's top above the
    base's centre, :data:`FOOTPRINT` of its height farther along the ground."""
    nr = rays @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        front = np.where((nr < 0)[:, None], -rays / nr[:, None], np.nan)  # n.p + 1 = 0
        away = front - (front @ normal)[:, None] * normal  # the ground direction from the camera's foot
        away /= np.linalg.norm(away, axis=1, keepdims=True)
        base = front[None] + (FOOTPRINT * _RATIOS)[:, None, None] * away[None]
        top = base + _RATIOS[:, None, None] * normal  # (R, N, 3)
        z = top[..., 2]
        v_top = (top @ K[1]) / z
        h = v_bottom[None] - v_top
        return np.where((z > 0) & (h > 0), np.log(h) - log_h[None], np.nan)


def ground_from_references(
    ground: GroundPlane, intrinsics: Intrinsics, boxes_xyxy: np.ndarray, max_change_deg: float = 25.0
) -> tuple[GroundPlane | None, str]:
    """``ground`` turned about the camera's x axis (at most ``max_change_deg``) to the pitch at which objects of one
    height standing at the bottom centres of ``boxes_xyxy`` (whole boxes of one kind) are as tall as the boxes;
    (None, why) for a measured ground (not ``assumed_scale``: kept), fewer than two boxes, bottom rows spread less than
    10 % of the image height, (three or more boxes) an RMS height error above 15 %, a turn under 1 deg or one that
    would pass the limit. The reason names the turn."""
    if not ground.assumed_scale:
        return None, f"measured ground ({ground.source}): kept"
    b = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    if len(b) < 2:
        return None, f"{len(b)} whole reference box(es): two or more give the pitch"
    vb, h = b[:, 3], b[:, 3] - b[:, 1]
    if np.ptp(vb) < MIN_SPREAD_FRAC * intrinsics.height:
        return None, f"the references' bottom rows spread {np.ptp(vb):.0f} px (< {MIN_SPREAD_FRAC:.0%} of the height)"
    K = intrinsics.K
    uv1 = np.c_[(b[:, 0] + b[:, 2]) / 2, vb, np.ones(len(b))]
    rays = uv1 @ np.linalg.inv(K).T
    log_h = np.log(np.maximum(h, 1.0))
    lim = np.radians(max_change_deg)

    def search(turns) -> tuple[float, float]:
        best = (np.inf, 0.0)
        for t in turns:
            err = _log_errors(_pitched(ground.normal, t), rays, vb, log_h, K)
            ok = np.isfinite(err).all(axis=1)
            if ok.any():
                rms = float(np.sqrt((err[ok] ** 2).mean(axis=1)).min())
                if rms < best[0] - 1e-12:
                    best = (rms, float(t))
        return best

    step = np.radians(_TURN_STEP_DEG)
    rms, angle = search(np.arange(-lim, lim + 1e-12, step))
    if np.isfinite(rms):  # a finer search around the grid's best
        rms, angle = search(np.clip(angle + np.linspace(-step, step, 21), -lim, lim))
    if not np.isfinite(rms):
        return None, f"no pitch within {max_change_deg:.0f} deg puts the references on the ground"
    if len(b) >= 3 and rms > MAX_RMS_LOG:
        return None, f"one height on one ground fits the {len(b)} references only to {rms:.0%} (RMS)"
    if abs(np.degrees(angle)) < MIN_TURN_DEG:
        return None, f"the references agree with the estimated ground (a turn of {np.degrees(angle):+.2f} deg): kept"
    if abs(abs(np.degrees(angle)) - max_change_deg) < _TURN_STEP_DEG / 2:
        # the boxes ask for more than the limit: a ground turned part of the way fits them no better than the
        # estimate (objects are still the wrong size away from them) and leaves less room for the right size
        return None, f"the references ask for a turn beyond {max_change_deg:.0f} deg: the estimated ground is kept"
    out = GroundPlane(
        _pitched(ground.normal, angle),
        ground.d,
        f"{ground.source}:references",
        ground.inlier_ratio,
        ground.rms_m,
        ground.num_inliers,
        ground.assumed_scale,
    )
    return out, (
        f"the ground turned {np.degrees(angle):+.2f} deg about the camera's x axis to fit {len(b)} reference boxes "
        f"(RMS height error {rms:.1%})"
    )


def whole_box_mask(b: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(N,) bool: boxes (N, 4) xyxy not cut by the frame's top or bottom edge (height and base seen), >= 4 px tall."""
    return (b[:, 1] > 1.0) & (b[:, 3] < intrinsics.height - 2.0) & (b[:, 3] - b[:, 1] >= 4.0)


@dataclass(frozen=True)
class RowHeights:
    """The box height in pixels of an object of one labelled kind whose box's bottom edge is on image row ``v``:
    ``slope * (v - zero_row)`` (``zero_row``: the horizon's row, where such an object shrinks to a point).
    ``source`` says where the line came from."""

    slope: float
    zero_row: float
    source: str

    def __post_init__(self):
        if not (np.isfinite(self.slope) and self.slope > 0 and np.isfinite(self.zero_row)):
            raise ValueError(f"RowHeights needs a finite slope > 0 and a finite zero row, got {self}")

    def at(self, v):
        """Box height(s) in pixels at bottom row(s) ``v`` (<= 0 on and above the horizon)."""
        return self.slope * (np.asarray(v, float) - self.zero_row)

    def scaled(self, factor: float) -> "RowHeights":
        """The line of objects ``factor`` times as tall."""
        return RowHeights(self.slope * float(factor), self.zero_row, self.source)


def row_heights(ground: GroundPlane, intrinsics: Intrinsics, boxes_xyxy: np.ndarray) -> tuple[RowHeights | None, str]:
    """The box heights that objects of the kind of ``boxes_xyxy`` (N, 4: labelled boxes of one kind) have on each
    bottom row, from their whole boxes (:func:`whole_box_mask`): the least-squares line of height against bottom row
    when two or more spread over :data:`MIN_SPREAD_FRAC` of the image height and it rises towards the camera (each
    box's fitted height positive); else the line through ``ground``'s horizon (at the boxes' mean column) fitted to
    the boxes below it (the median of their height over their depth below it). ``(None, why)`` when neither
    exists."""
    b = np.asarray(boxes_xyxy, float).reshape(-1, 4)
    b = b[whole_box_mask(b, intrinsics)]
    if not len(b):
        return None, "no whole labelled box"
    vb, h = b[:, 3], b[:, 3] - b[:, 1]
    if len(b) >= 2 and np.ptp(vb) >= MIN_SPREAD_FRAC * intrinsics.height:
        c, c0 = np.polyfit(vb, h, 1)
        if c > 0 and np.all(c * vb + c0 > 0):
            rms = float(np.sqrt(np.mean((np.log(h) - np.log(c * vb + c0)) ** 2)))
            return RowHeights(float(c), float(-c0 / c), "fit"), (
                f"box heights on each row from the line through the {len(b)} labelled boxes (zero on row "
                f"{-c0 / c:.0f}, RMS {rms:.0%})"
            )
    try:
        zero = float(ground.horizon_row_at(float(np.mean((b[:, 0] + b[:, 2]) / 2)), intrinsics))
    except ValueError:
        zero = float("nan")
    below = vb - zero
    ok = below > 1.0
    if not (np.isfinite(zero) and ok.any()):
        return None, "the labelled boxes' rows do not spread and none stands below the ground's horizon"
    slope = float(np.median(h[ok] / below[ok]))
    return RowHeights(slope, zero, "horizon"), (
        f"box heights on each row from the ground's horizon (row {zero:.0f}) and {int(ok.sum())} labelled box(es)"
    )
