"""Draw-free vanishing-point fits with the signature of ``fit_vanishing_point`` (``rng`` accepted, never used).

All share today's scoring and refinement: a hypothesis VP's support is the length of the segments within
``inlier_angle_deg`` of pointing at it (``consistency_deg``, against all segments), and the winner is refined by
two rounds of length-weighted least squares on its inliers. They differ in where the hypotheses come from
(every pair among the K longest segments, or a great-circle accumulator) and in how many of the best hypotheses
are refined (``multistart``: the M best by support each refined, the best refined support kept -- locally
optimised RANSAC, without the draws).
"""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.single_image import (
    consistency_deg,
    homogeneous_lines,
    refine_vanishing_point,
    unit_hypotheses,
)

Fit = tuple[np.ndarray, np.ndarray] | None


def longest_first(seg: np.ndarray) -> np.ndarray:
    """Segment indices by decreasing length, ties by index (a stable order: the same segments, the same pairs)."""
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    return np.argsort(-length, kind="stable")


def top_k_pairs(seg: np.ndarray, k: int) -> np.ndarray:
    """(P, 2) every pair i < j among the ``k`` longest segments (all segments when there are fewer)."""
    idx = longest_first(seg)[:k]
    i, j = np.triu_indices(len(idx), 1)
    return np.column_stack([idx[i], idx[j]])


def support_inliers(seg: np.ndarray, vps: np.ndarray, inlier_angle_deg: float) -> np.ndarray:
    """``consistency_deg(seg, vps) < inlier_angle_deg`` as two matrix products and a comparison, (K, N) bool.

    With the segment's unit line l (its midpoint m on it) and t = v_xy - w m, sin(angle) = |l . v| / |t|, and
    |t|^2 = |v_xy|^2 - 2 w v_xy . m + w^2 |m|^2: both are products of a per-VP and a per-segment factor, so no
    (K, N) arccos, square root or division (the same test up to rounding at the threshold; thousands of
    hypotheses for the cost of hundreds).
    """
    lines = homogeneous_lines(seg)
    mid = (seg[:, :2] + seg[:, 2:]) / 2
    num = vps @ lines.T
    vx, vy, w = vps[:, 0], vps[:, 1], vps[:, 2]
    a = np.column_stack([vx * vx + vy * vy, -2 * w * vx, -2 * w * vy, w * w])
    b = np.column_stack([np.ones(len(seg)), mid, (mid * mid).sum(1)])
    t2 = a @ b.T
    s2 = np.sin(np.radians(inlier_angle_deg)) ** 2
    np.multiply(num, num, out=num)  # in place: these (K, N) passes are the cost
    t2 *= s2
    inl = np.less(num, t2)
    inl &= t2 > s2 * 1e-18  # the VP on the midpoint: no direction, 90 deg in consistency_deg
    return inl


def pair_hypotheses(seg: np.ndarray, k: int) -> np.ndarray:
    """(P, 3) the VPs (line intersections) of every pair among the ``k`` longest segments, not normalised."""
    pairs = top_k_pairs(seg, k)
    lines = homogeneous_lines(seg)
    return np.cross(lines[pairs[:, 0]], lines[pairs[:, 1]])


def fit_from_hypotheses(
    seg: np.ndarray,
    vps: np.ndarray,
    *,
    inlier_angle_deg: float = 1.5,
    min_inliers: int = 6,
    finite_within: tuple[np.ndarray, float] | None = None,
    multistart: int = 1,
    fast: bool = True,
) -> Fit:
    """Score homogeneous hypothesis VPs (H, 3) against all segments; refine the ``multistart`` best (distinct
    inlier sets), keep the refined fit with the largest length-weighted support. ``multistart=1`` is today's rule."""
    lines = homogeneous_lines(seg)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    vps = unit_hypotheses(vps, finite_within)
    if len(vps) == 0:
        return None
    inl = support_inliers(seg, vps, inlier_angle_deg) if fast else consistency_deg(seg, vps) < inlier_angle_deg
    score = inl @ length
    order = np.argsort(-score, kind="stable")
    if multistart == 1:  # today's rule: refine the best hypothesis, give up when it has too few inliers
        mask = inl[order[0]]
        if mask.sum() < min_inliers:
            return None
        return refine_vanishing_point(seg, lines, length, mask, inlier_angle_deg, min_inliers, finite_within)
    best: Fit = None
    best_support = -1.0
    seen: set[bytes] = set()
    for h in order:
        if len(seen) == multistart:
            break
        mask = inl[h]
        key = np.packbits(mask).tobytes()
        if key in seen:
            continue
        seen.add(key)
        if mask.sum() < min_inliers:
            continue
        fit = refine_vanishing_point(seg, lines, length, mask, inlier_angle_deg, min_inliers, finite_within)
        if fit is not None and (support := float(fit[1] @ length)) > best_support:
            best, best_support = fit, support
    return best


def fit_vp_top_k(
    seg: np.ndarray,
    rng: np.random.Generator | None = None,
    *,
    iterations: int = 400,
    inlier_angle_deg: float = 1.5,
    min_inliers: int = 6,
    finite_within: tuple[np.ndarray, float] | None = None,
    k: int = 40,
    multistart: int = 1,
    fast: bool = True,
) -> Fit:
    """Hypotheses: every pair among the ``k`` longest segments (``iterations`` and ``rng`` unused)."""
    if len(seg) < max(2, min_inliers):
        return None
    return fit_from_hypotheses(
        seg,
        pair_hypotheses(seg, k),
        inlier_angle_deg=inlier_angle_deg,
        min_inliers=min_inliers,
        finite_within=finite_within,
        multistart=multistart,
        fast=fast,
    )


def fit_vp_screened(
    seg: np.ndarray,
    rng: np.random.Generator | None = None,
    *,
    iterations: int = 400,
    inlier_angle_deg: float = 1.5,
    min_inliers: int = 6,
    finite_within: tuple[np.ndarray, float] | None = None,
    k: int = 10**6,
    screen_segments: int = 64,
) -> Fit:
    """Every pair among the ``k`` longest segments (all, by default), screened by their support among the
    ``screen_segments`` longest; the ``iterations`` best then go through the full scoring and refinement.

    Why: the exhaustive pair set is the most accurate draw-free set on KITTI 06, but scoring ~10^4 hypotheses
    against every segment costs several times the drawn 400; the long segments carry most of the support."""
    if len(seg) < max(2, min_inliers):
        return None
    vps = unit_hypotheses(pair_hypotheses(seg, k), finite_within)
    if len(vps) > iterations:
        screen = longest_first(seg)[:screen_segments]
        length = np.hypot(seg[screen, 2] - seg[screen, 0], seg[screen, 3] - seg[screen, 1])
        score = support_inliers(seg[screen], vps, inlier_angle_deg) @ length
        vps = vps[np.sort(np.argsort(-score, kind="stable")[:iterations])]
    return fit_from_hypotheses(
        seg, vps, inlier_angle_deg=inlier_angle_deg, min_inliers=min_inliers, finite_within=finite_within
    )
