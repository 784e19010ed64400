"""Photo-bootstrap KID: the block-sum statistic against the unbiased estimator (all photos drawn once) and against a
brute-force average over explicitly duplicated photos; replicates under the null and under a paired shift."""

import numpy as np

from aias_augment.evaluation.realism.bootstrap import kid_photo_bootstrap, photo_blocks, photo_mmd2, polynomial_kernel
from aias_augment.evaluation.realism.distances import polynomial_mmd2_unbiased


def _setup(x, gx, y, gy):
    px, py = sorted(set(gx)), sorted(set(gy))
    bx, by = photo_blocks(x, gx, px), photo_blocks(y, gy, py)
    mx = np.array([[g == p for p in px] for g in gx], float)
    my = np.array([[g == p for p in py] for g in gy], float)
    return px, py, bx, by, mx.T @ polynomial_kernel(x, y) @ my


def test_every_photo_once_equals_the_unbiased_estimator():
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(9, 5)), rng.normal(0.3, 1.0, size=(7, 5))
    gx, gy = list("aabbbcdde"), list("PPQRRRS")
    px, py, bx, by, qxy = _setup(x, gx, y, gy)
    got = photo_mmd2(bx, by, qxy, np.ones(len(px)), np.ones(len(py)))
    assert np.isclose(got, polynomial_mmd2_unbiased(x, y), rtol=1e-12)


def test_drawn_photos_equal_brute_force_over_copies():
    rng = np.random.default_rng(1)
    x, y = rng.normal(size=(7, 4)), rng.normal(size=(5, 4))
    gx, gy = list("aabbbcd"), list("PQQRR")
    px, py, bx, by, qxy = _setup(x, gx, y, gy)
    cx, cy = np.array([2, 0, 1, 3]), np.array([1, 2, 0])  # a twice, b never, c once, d thrice; ...
    # expand: each crop of photo g appears once per copy of g; a pair counts unless both crops are from the same
    # photo in different copies, or the same crop in the same copy
    ex = [(i, gx[i], k) for i in range(7) for k in range(cx[px.index(gx[i])])]
    ey = [(j, gy[j], k) for j in range(5) for k in range(cy[py.index(gy[j])])]

    def k(a, b):
        return (a @ b / 4 + 1.0) ** 3

    def within(z, e):
        vals = [
            k(z[i], z[j]) for (i, g, c) in e for (j, h, d) in e if not (g == h and c != d) and not (i == j and c == d)
        ]
        return np.mean(vals)

    cross = np.mean([k(x[i], y[j]) for (i, _, _) in ex for (j, _, _) in ey])
    expected = within(x, ex) + within(y, ey) - 2 * cross
    assert np.isclose(photo_mmd2(bx, by, qxy, cx.astype(float), cy.astype(float)), expected, rtol=1e-12)


def test_bootstrap_centred_under_clustered_null_and_resolves_a_paired_shift():
    rng = np.random.default_rng(2)
    n_photos, per = 40, 4

    def clustered(offset=0.0):  # crops of one photo share a photo effect: the case that biased a naive bootstrap
        photo = rng.normal(size=(n_photos, 8))
        return np.repeat(photo, per, 0) + 0.5 * rng.normal(size=(n_photos * per, 8)) + offset

    groups = [f"p{i}" for i in range(n_photos) for _ in range(per)]
    ref_groups = [f"r{i}" for i in range(n_photos) for _ in range(per)]
    ref, same = clustered(), clustered()
    shifted = same + 0.6
    reps = kid_photo_bootstrap(
        {"same": (same, groups), "shifted": (shifted, groups)}, ref, ref_groups, np.random.default_rng(3), n_boot=300
    )
    point = polynomial_mmd2_unbiased(same, ref)
    lo, hi = np.nanpercentile(reps["same"], [2.5, 97.5])
    assert lo < point < hi and lo < 0 < hi
    assert abs(np.nanmean(reps["same"]) - point) < 0.25 * (hi - lo)
    assert np.nanpercentile(reps["shifted"] - reps["same"], 2.5) > 0
