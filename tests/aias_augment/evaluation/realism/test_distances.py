"""FID/KID against truths derived without the implementation: analytic Fréchet distance of Gaussians, brute-force MMD."""

import numpy as np
import pytest

from aias_augment.evaluation.realism.distances import (
    fid_from_features,
    frechet_distance,
    kid_from_features,
    polynomial_mmd2_unbiased,
)


def test_frechet_of_diagonal_gaussians_is_analytic():
    # W2^2 of N(mu_a, diag(s_a^2)) and N(mu_b, diag(s_b^2)) = |mu_a - mu_b|^2 + sum (s_a - s_b)^2
    rng = np.random.default_rng(0)
    mu_a, mu_b = rng.normal(size=5), rng.normal(size=5)
    s_a, s_b = rng.uniform(0.5, 2, 5), rng.uniform(0.5, 2, 5)
    expected = np.sum((mu_a - mu_b) ** 2) + np.sum((s_a - s_b) ** 2)
    assert frechet_distance(mu_a, np.diag(s_a**2), mu_b, np.diag(s_b**2)) == pytest.approx(expected, rel=1e-9)


def test_frechet_is_rotation_invariant_with_full_covariances():
    # Rotating both Gaussians by the same orthogonal matrix leaves W2 unchanged: full (non-diagonal) covariances.
    rng = np.random.default_rng(1)
    Q, _ = np.linalg.qr(rng.normal(size=(4, 4)))
    mu_a, mu_b, s_a, s_b = rng.normal(size=4), rng.normal(size=4), rng.uniform(0.5, 2, 4), rng.uniform(0.5, 2, 4)
    expected = np.sum((mu_a - mu_b) ** 2) + np.sum((s_a - s_b) ** 2)
    got = frechet_distance(Q @ mu_a, Q @ np.diag(s_a**2) @ Q.T, Q @ mu_b, Q @ np.diag(s_b**2) @ Q.T)
    assert got == pytest.approx(expected, rel=1e-8)


def test_fid_identical_sets_zero_and_shifted_gaussian_sample():
    rng = np.random.default_rng(2)
    a = rng.normal(size=(20000, 3))
    assert fid_from_features(a, a) == pytest.approx(0.0, abs=1e-9)
    shift = np.array([1.0, -0.5, 0.0])
    b = rng.normal(size=(20000, 3)) * 2.0 + shift  # W2^2 = |shift|^2 + 3 (2 - 1)^2 = 1.25 + 3
    assert fid_from_features(a, b) == pytest.approx(4.25, rel=0.03)


def _mmd2_bruteforce(x, y):
    k = lambda a, b: (a @ b / x.shape[1] + 1.0) ** 3
    m, n = len(x), len(y)
    sxx = sum(k(x[i], x[j]) for i in range(m) for j in range(m) if i != j) / (m * (m - 1))
    syy = sum(k(y[i], y[j]) for i in range(n) for j in range(n) if i != j) / (n * (n - 1))
    sxy = sum(k(x[i], y[j]) for i in range(m) for j in range(n)) / (m * n)
    return sxx + syy - 2 * sxy


def test_mmd_matches_bruteforce_pairs():
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=(7, 4)), rng.normal(size=(9, 4)) + 0.3
    assert polynomial_mmd2_unbiased(x, y) == pytest.approx(_mmd2_bruteforce(x, y), rel=1e-10)


def test_kid_near_zero_for_same_distribution_and_positive_for_shift():
    rng = np.random.default_rng(4)
    a, b = rng.normal(size=(600, 16)), rng.normal(size=(600, 16))
    same, _ = kid_from_features(a, b, n_subsets=20, subset_size=300, rng=rng)
    shifted, std = kid_from_features(a, b + 0.5, n_subsets=20, subset_size=300, rng=rng)
    assert abs(same) < 0.01
    assert shifted > 10 * std and shifted > 0.05
    # whole sets when they are no larger than the subset size: one exact value
    assert kid_from_features(a[:50], b[:50], subset_size=100, rng=np.random.default_rng(0)) == (
        polynomial_mmd2_unbiased(a[:50], b[:50]),
        0.0,
    )
