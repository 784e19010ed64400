"""Feature-space distances between two image sets: Fréchet distance (FID's formula) and KID (unbiased MMD^2 with the
cubic polynomial kernel of Bińkowski et al. 2018), exact small implementations on (N, D) feature arrays.

FID = |mu_a - mu_b|^2 + tr(S_a + S_b - 2 (S_a S_b)^(1/2)). The matrix square root is taken as the symmetric
``S_a^(1/2) S_b S_a^(1/2)`` square root (same trace, real and PSD by construction), so no complex parts arise.
KID = mean over random subsets of the unbiased MMD^2 with k(x, y) = (x.y / d + 1)^3.
"""

from __future__ import annotations

import numpy as np

from aias_augment.core.rng import require_rng

__all__ = ["frechet_distance", "fid_from_features", "polynomial_mmd2_unbiased", "kid_from_features"]


def _psd_sqrt(S: np.ndarray) -> np.ndarray:
    """Square root of a symmetric PSD matrix by eigendecomposition (negative round-off eigenvalues clamped to 0)."""
    w, V = np.linalg.eigh((S + S.T) / 2)
    return (V * np.sqrt(np.clip(w, 0.0, None))) @ V.T


def frechet_distance(mu_a: np.ndarray, cov_a: np.ndarray, mu_b: np.ndarray, cov_b: np.ndarray) -> float:
    """Fréchet (2-Wasserstein) distance squared between N(mu_a, cov_a) and N(mu_b, cov_b)."""
    mu_a, mu_b = np.asarray(mu_a, np.float64), np.asarray(mu_b, np.float64)
    cov_a, cov_b = np.atleast_2d(np.asarray(cov_a, np.float64)), np.atleast_2d(np.asarray(cov_b, np.float64))
    if cov_a.shape != cov_b.shape or cov_a.shape != (mu_a.size, mu_a.size) or mu_a.shape != mu_b.shape:
        raise ValueError(f"frechet_distance: shapes {mu_a.shape} {cov_a.shape} vs {mu_b.shape} {cov_b.shape}")
    ra = _psd_sqrt(cov_a)
    cross = np.trace(_psd_sqrt(ra @ cov_b @ ra))
    d = float(np.sum((mu_a - mu_b) ** 2) + np.trace(cov_a) + np.trace(cov_b) - 2.0 * cross)
    return max(d, 0.0)


def fid_from_features(feats_a: np.ndarray, feats_b: np.ndarray) -> float:
    """Fréchet distance of the Gaussians fitted to two (N, D) feature sets (unbiased covariances)."""
    a, b = np.asarray(feats_a, np.float64), np.asarray(feats_b, np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or len(a) < 2 or len(b) < 2:
        raise ValueError(f"fid_from_features: need (N>=2, D) arrays of equal D, got {a.shape}, {b.shape}")
    return frechet_distance(a.mean(0), np.cov(a, rowvar=False), b.mean(0), np.cov(b, rowvar=False))


def polynomial_mmd2_unbiased(
    x: np.ndarray, y: np.ndarray, degree: int = 3, gamma: float | None = None, coef0: float = 1.0
) -> float:
    """Unbiased MMD^2 between samples x (m, D) and y (n, D) with k(a, b) = (gamma a.b + coef0)^degree
    (gamma = 1 / D by default): mean of k over distinct pairs within x, within y, minus twice the cross mean."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    m, n = len(x), len(y)
    if m < 2 or n < 2:
        raise ValueError("polynomial_mmd2_unbiased needs at least 2 samples per set")
    g = 1.0 / x.shape[1] if gamma is None else gamma
    kxx = (g * x @ x.T + coef0) ** degree
    kyy = (g * y @ y.T + coef0) ** degree
    kxy = (g * x @ y.T + coef0) ** degree
    return float(
        (kxx.sum() - np.trace(kxx)) / (m * (m - 1)) + (kyy.sum() - np.trace(kyy)) / (n * (n - 1)) - 2.0 * kxy.mean()
    )


def kid_from_features(
    feats_a: np.ndarray, feats_b: np.ndarray, n_subsets: int = 100, subset_size: int = 1000, *, rng: np.random.Generator
) -> tuple[float, float]:
    """KID: mean and standard deviation of the unbiased polynomial MMD^2 over ``n_subsets`` random subsets of
    ``min(subset_size, len(a), len(b))`` samples drawn without replacement from each set. When both sets are no
    larger than the subset size every subset is the whole set (one exact value, std 0)."""
    a, b = np.asarray(feats_a, np.float64), np.asarray(feats_b, np.float64)
    rng = require_rng(rng, "kid_from_features")
    k = min(subset_size, len(a), len(b))
    if k == len(a) == len(b):
        return polynomial_mmd2_unbiased(a, b), 0.0
    vals = [
        polynomial_mmd2_unbiased(a[rng.choice(len(a), k, replace=False)], b[rng.choice(len(b), k, replace=False)])
        for _ in range(n_subsets)
    ]
    return float(np.mean(vals)), float(np.std(vals))
