"""KID intervals by bootstrap over photos, paired across sets that share their photos.

A photo holds several crops, and crops of one photo look alike. Resampling whole photos with replacement and
recomputing the unbiased MMD^2 on the resampled multiset would count pairs formed by two copies of one photo: a
photo drawn twice doubles the weight of its within-photo pairs (expected weight E[c^2] ~ 2 against ~1 for a pair of
two photos), which inflates both within-set terms and biases the replicates upward (by ~+0.02 on two halves of
TraCon's real cones, whose point estimate is 0.015). So every copy of a photo is a cluster of its own, and pairs
between two copies of the same photo are left out, as the unbiased estimator leaves out a sample paired with itself:

    photo g drawn c_g times, with n_g crops; K summed over the crops of photos g and h = Q_gh; trace of g's block = T_g
    within = [sum_{g != h} c_g c_h Q_gh + sum_g c_g (Q_gg - T_g)] / [sum_{g != h} c_g c_h n_g n_h + sum_g c_g n_g (n_g - 1)]
    cross  = sum_{g, h} c_g d_h Qxy_gh / (sum_g c_g n_g  sum_h d_h n_h)
    MMD^2  = within(x) + within(y) - 2 cross

Every expected pair weight is then 1, as in the original sample; with every c_g = 1 it is exactly
:func:`~.distances.polynomial_mmd2_unbiased`. Sets whose crops come from the same photos (the inserted arms, the
control and the floor of one protocol) are resampled with the same draws in each replicate, so their differences
have paired intervals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["polynomial_kernel", "PhotoBlocks", "photo_blocks", "photo_mmd2", "kid_photo_bootstrap"]


def polynomial_kernel(
    x: np.ndarray, y: np.ndarray, degree: int = 3, gamma: float | None = None, coef0: float = 1.0
) -> np.ndarray:
    """(m, D), (n, D) -> (m, n): (gamma x.y + coef0)^degree, gamma = 1 / D by default (KID's kernel)."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    g = 1.0 / x.shape[1] if gamma is None else gamma
    return (g * x @ y.T + coef0) ** degree


def _indicator(groups, photos: list) -> np.ndarray:
    """(N, G) one-hot: row i has a 1 in the column of its photo."""
    col = {p: k for k, p in enumerate(photos)}
    m = np.zeros((len(groups), len(photos)))
    m[np.arange(len(groups)), [col[g] for g in groups]] = 1.0
    return m


@dataclass(frozen=True)
class PhotoBlocks:
    """A set's kernel summed over photo blocks: ``q`` (G, G), per-photo traces ``t`` (G,), crops per photo ``n``."""

    photos: list
    q: np.ndarray
    t: np.ndarray
    n: np.ndarray


def photo_blocks(feats: np.ndarray, groups, photos: list) -> PhotoBlocks:
    """Block sums of the set's kernel over ``photos`` (every group of ``groups`` must be in it; others get 0)."""
    m = _indicator(groups, photos)
    k = polynomial_kernel(feats, feats)
    return PhotoBlocks(photos, m.T @ k @ m, m.T @ np.diag(k), m.sum(0))


def _within(b: PhotoBlocks, c: np.ndarray) -> float:
    cn = c * b.n
    num = c @ b.q @ c - (c * c) @ np.diag(b.q) + c @ (np.diag(b.q) - b.t)
    den = cn.sum() ** 2 - (cn * cn).sum() + c @ (b.n * (b.n - 1))
    return float(num / den) if den > 0 else float("nan")


def photo_mmd2(bx: PhotoBlocks, by: PhotoBlocks, qxy: np.ndarray, cx: np.ndarray, cy: np.ndarray) -> float:
    """MMD^2 with photo g of x drawn ``cx[g]`` times and photo h of y ``cy[h]`` times (module docstring); ``qxy``
    (Gx, Gy): the cross kernel summed over photo blocks. NaN when a set has fewer than two crops in all."""
    sx, sy = cx @ bx.n, cy @ by.n
    if sx == 0 or sy == 0:
        return float("nan")
    return _within(bx, cx) + _within(by, cy) - 2.0 * float(cx @ qxy @ cy) / (sx * sy)


def kid_photo_bootstrap(
    sets: dict, ref_feats: np.ndarray, ref_groups, rng: np.random.Generator, n_boot: int = 1000
) -> dict:
    """Bootstrap replicates of each set's KID (polynomial MMD^2) against the reference.

    sets: name -> (features (N, D), photo of each row). The photos of all sets are drawn together (one draw of
    multiplicities per replicate, shared by every set, so replicates of two sets are paired); the reference's
    photos are drawn separately. Returns name -> (n_boot,) array; replicate 0 is not special."""
    ref_photos = sorted(set(ref_groups))
    set_photos = sorted({g for _, groups in sets.values() for g in groups})
    by = photo_blocks(ref_feats, list(ref_groups), ref_photos)
    my = _indicator(list(ref_groups), ref_photos)
    pre = {}
    for name, (f, groups) in sets.items():
        mx = _indicator(list(groups), set_photos)
        pre[name] = (photo_blocks(f, list(groups), set_photos), mx.T @ polynomial_kernel(f, ref_feats) @ my)
    out = {name: np.empty(n_boot) for name in sets}
    for b in range(n_boot):
        cx = np.bincount(rng.integers(0, len(set_photos), len(set_photos)), minlength=len(set_photos)).astype(float)
        cy = np.bincount(rng.integers(0, len(ref_photos), len(ref_photos)), minlength=len(ref_photos)).astype(float)
        for name, (bx, qxy) in pre.items():
            out[name][b] = photo_mmd2(bx, by, qxy, cx, cy)
    return out
