"""AUC, grouped folds and the two-sample classifiers on sets whose separability is known by construction."""

import numpy as np
import pytest

from aias_augment.evaluation.realism.two_sample import (
    auc_mann_whitney,
    cnn_two_sample,
    group_bootstrap_auc_ci,
    grouped_folds,
    logistic_two_sample,
)


def test_auc_equals_pair_count():
    rng = np.random.default_rng(0)
    s = rng.integers(0, 5, 40).astype(float)  # ties on purpose
    y = rng.random(40) < 0.4
    pos, neg = s[y], s[~y]
    expected = np.mean([(p > n) + 0.5 * (p == n) for p in pos for n in neg])
    assert auc_mann_whitney(s, y) == pytest.approx(expected)


def test_grouped_folds_keep_each_group_in_one_fold():
    rng = np.random.default_rng(1)
    groups = rng.integers(0, 30, 300)
    folds = grouped_folds(groups, 5, rng)
    for g in np.unique(groups):
        assert len(np.unique(folds[groups == g])) == 1
    assert sorted(np.unique(folds)) == [0, 1, 2, 3, 4]


def test_logistic_chance_for_same_distribution_and_one_for_separable():
    rng = np.random.default_rng(2)
    n = 400
    groups = np.arange(n) // 2
    y = rng.random(n) < 0.5
    X = rng.normal(size=(n, 8))
    null = logistic_two_sample(X, y, groups, rng)
    assert null.ci95[0] < 0.5 < null.ci95[1] and abs(null.auc - 0.5) < 0.1
    X_sep = X + 3.0 * y[:, None]
    sep = logistic_two_sample(X_sep, y, groups, rng)
    assert sep.auc > 0.99 and sep.ci95[0] > 0.97


def test_bootstrap_interval_brackets_the_auc():
    rng = np.random.default_rng(3)
    y = rng.random(200) < 0.5
    s = rng.normal(size=200) + 0.8 * y
    lo, hi = group_bootstrap_auc_ci(s, y, np.arange(200), rng, n_boot=300)
    assert lo < auc_mann_whitney(s, y) < hi


def test_cnn_separates_a_colour_shift_through_its_augmentations():
    rng = np.random.default_rng(4)
    n = 160

    def noise_img(tint):
        img = rng.integers(60, 200, (64, 64, 3)).astype(np.float32)
        img[..., 0] += tint
        return np.clip(img, 0, 255).astype(np.uint8)

    y = np.arange(n) % 2 == 0
    groups = np.arange(n)
    colour = np.stack([noise_img(40.0 if yy else 0.0) for yy in y])
    res = cnn_two_sample(colour, y, groups, rng, epochs=4)
    assert res.auc > 0.9


def test_stratified_grouped_folds_keep_class_proportions_and_null_auc_unbiased():
    # 100 groups of class 1 and 400 of class 0 (one class per group, as real vs inserted photos are): every fold
    # gets 20 +- 1 and 80 +- 1 of them; and over many null draws the mean out-of-fold AUC stays at 0.5.
    rng = np.random.default_rng(5)
    groups = np.arange(500)
    y = groups < 100
    folds = grouped_folds(groups, 5, rng, y)
    for k in range(5):
        assert abs(int(y[folds == k].sum()) - 20) <= 1 and abs(int((~y)[folds == k].sum()) - 80) <= 1
    aucs = [logistic_two_sample(rng.normal(size=(500, 4)), y, groups, rng).auc for _ in range(20)]
    assert abs(np.mean(aucs) - 0.5) < 0.03
