"""Draw-free vanishing-point fits with the signature of ``fit_vanishing_point`` (``rng`` accepted, never used).

All share today's scoring and refinement: a hypothesis VP's support is the length of the segments within
``inlier_angle_deg`` of pointing at it (``_consistency_deg``, against all segments), and the winner is refined by
two rounds of length-weighted least squares on its inliers. They differ in where the hypotheses come from
(every pair among the K longest segments, or a great-circle accumulator) and in how many of the best hypotheses
are refined (``multistart``: the M best by support each refined, the best refined support kept -- locally
optimised RANSAC, without the draws).
"""

from __future__ import annotations

import numpy as np

from aias_augment.analyse.single_image import _consistency_deg, _homogeneous_lines, _near

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


def _refine(seg, lines, length, mask, inlier_angle_deg, min_inliers, finite_within) -> Fit:
    """Today's refinement: two rounds of the smallest eigenvector of sum w l l^T over the inliers."""
    for _ in range(2):
        w = length[mask]
        M = (lines[mask] * w[:, None]).T @ lines[mask]
        vp = np.linalg.eigh(M)[1][:, 0]
        mask = _consistency_deg(seg, vp[None])[0] < inlier_angle_deg
        if mask.sum() < min_inliers or (finite_within is not None and not _near(vp[None], *finite_within)[0]):
            return None
    return vp, mask


def fit_from_hypotheses(
    seg: np.ndarray,
    vps: np.ndarray,
    *,
    inlier_angle_deg: float = 1.5,
    min_inliers: int = 6,
    finite_within: tuple[np.ndarray, float] | None = None,
    multistart: int = 1,
) -> Fit:
    """Score homogeneous hypothesis VPs (H, 3) against all segments; refine the ``multistart`` best (distinct
    inlier sets), keep the refined fit with the largest length-weighted support. ``multistart=1`` is today's rule."""
    lines = _homogeneous_lines(seg)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    norm = np.linalg.norm(vps, axis=1)
    ok = norm > 1e-12
    if not ok.any():
        return None
    vps = vps[ok] / norm[ok, None]
    if finite_within is not None:
        vps = vps[_near(vps, *finite_within)]
        if len(vps) == 0:
            return None
    inl = _consistency_deg(seg, vps) < inlier_angle_deg
    score = inl @ length
    order = np.argsort(-score, kind="stable")
    if multistart == 1:  # today's rule: refine the best hypothesis, give up when it has too few inliers
        mask = inl[order[0]]
        if mask.sum() < min_inliers:
            return None
        return _refine(seg, lines, length, mask, inlier_angle_deg, min_inliers, finite_within)
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
        fit = _refine(seg, lines, length, mask, inlier_angle_deg, min_inliers, finite_within)
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
) -> Fit:
    """Hypotheses: every pair among the ``k`` longest segments (``iterations`` and ``rng`` unused)."""
    if len(seg) < max(2, min_inliers):
        return None
    pairs = top_k_pairs(seg, k)
    lines = _homogeneous_lines(seg)
    vps = np.cross(lines[pairs[:, 0]], lines[pairs[:, 1]])
    return fit_from_hypotheses(
        seg,
        vps,
        inlier_angle_deg=inlier_angle_deg,
        min_inliers=min_inliers,
        finite_within=finite_within,
        multistart=multistart,
    )
