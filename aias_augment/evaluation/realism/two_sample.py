"""Two-sample tests: can a classifier tell real from inserted? Out-of-fold scores from K folds grouped by photo (no
photo contributes to both the training and the test part of a fold), AUC of the pooled out-of-fold scores, and a 95 %
interval by bootstrap over photos (resampling whole photos keeps the dependence between boxes of one photo).

AUC 0.5: indistinguishable; 1.0: perfectly separable. The interval is about the test sets, not about retraining.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "auc_mann_whitney",
    "group_bootstrap_auc_ci",
    "grouped_folds",
    "logistic_two_sample",
    "cnn_two_sample",
    "TwoSampleResult",
]


@dataclass(frozen=True)
class TwoSampleResult:
    auc: float
    ci95: tuple[float, float]
    fold_aucs: tuple[float, ...]
    n_pos: int
    n_neg: int
    n_groups: int

    def to_dict(self) -> dict:
        return {
            "auc": self.auc,
            "ci95": list(self.ci95),
            "fold_aucs": list(self.fold_aucs),
            "n_pos": self.n_pos,
            "n_neg": self.n_neg,
            "n_groups": self.n_groups,
        }


def auc_mann_whitney(scores: np.ndarray, labels: np.ndarray) -> float:
    """ROC AUC = P(score of a positive > score of a negative) + 0.5 P(tie), from average ranks (Mann-Whitney U)."""
    from scipy.stats import rankdata

    s, y = np.asarray(scores, np.float64), np.asarray(labels).astype(bool)
    n1, n0 = int(y.sum()), int((~y).sum())
    if n1 == 0 or n0 == 0:
        return float("nan")
    r = rankdata(s)
    return float((r[y].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def grouped_folds(groups, n_splits: int, rng: np.random.Generator, labels=None) -> np.ndarray:
    """Fold index (N,) per sample: the distinct groups shuffled with ``rng`` and dealt round-robin to the folds; with
    ``labels``, the groups of each class (a group's majority label) are dealt separately, so every fold keeps about
    the overall class proportions. (Without that, a fold with more of one class than the rest is scored by a model
    trained on fewer of it: under the null the pooled out-of-fold AUC then falls below 0.5, 0.40 on two real sets.)"""
    g = np.asarray(groups)
    uniq, inv = np.unique(g, return_inverse=True)
    if len(uniq) < n_splits:
        raise ValueError(f"{len(uniq)} groups < {n_splits} folds")
    if labels is None:
        cls = np.zeros(len(uniq), np.int64)
    else:
        y = np.asarray(labels).astype(np.float64)
        cls = (np.bincount(inv, weights=y, minlength=len(uniq)) / np.bincount(inv, minlength=len(uniq)) >= 0.5).astype(
            np.int64
        )
    fold = np.zeros(len(uniq), np.int64)
    start = 0
    for c in np.unique(cls):
        members = np.flatnonzero(cls == c)
        members = members[rng.permutation(len(members))]
        fold[members] = (start + np.arange(len(members))) % n_splits
        start += len(members)
    return fold[inv]


def group_bootstrap_auc_ci(scores, labels, groups, rng: np.random.Generator, n_boot: int = 1000) -> tuple[float, float]:
    """Percentile 95 % interval of the AUC when whole groups (photos) are resampled with replacement."""
    s, y, g = np.asarray(scores, np.float64), np.asarray(labels).astype(bool), np.asarray(groups)
    uniq, inv = np.unique(g, return_inverse=True)
    members = [np.flatnonzero(inv == k) for k in range(len(uniq))]
    vals = []
    for _ in range(n_boot):
        idx = np.concatenate([members[k] for k in rng.integers(0, len(uniq), len(uniq))])
        a = auc_mann_whitney(s[idx], y[idx])
        if np.isfinite(a):
            vals.append(a)
    return float(np.percentile(vals, 2.5)), float(np.percentile(vals, 97.5))


def _result(scores, y, g, folds, rng) -> TwoSampleResult:
    fold_aucs = tuple(auc_mann_whitney(scores[folds == k], y[folds == k]) for k in np.unique(folds))
    return TwoSampleResult(
        auc_mann_whitney(scores, y),
        group_bootstrap_auc_ci(scores, y, g, rng),
        fold_aucs,
        int(y.sum()),
        int((~y).sum()),
        len(np.unique(g)),
    )


def logistic_two_sample(
    features: np.ndarray, labels, groups, rng: np.random.Generator, n_splits: int = 5, C: float = 0.1
) -> TwoSampleResult:
    """Standardised features -> L2 logistic regression (class-balanced), out-of-fold decision scores."""
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    X, y, g = np.asarray(features, np.float64), np.asarray(labels).astype(bool), np.asarray(groups)
    folds = grouped_folds(g, n_splits, rng, y)
    scores = np.zeros(len(y))
    for k in range(n_splits):
        tr, te = folds != k, folds == k
        clf = make_pipeline(StandardScaler(), LogisticRegression(C=C, max_iter=2000, class_weight="balanced"))
        clf.fit(X[tr], y[tr])
        scores[te] = clf.decision_function(X[te])
    return _result(scores, y, g, folds, rng)


# ------------------------------------------------------------------ small CNN from scratch


def _augment(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Flip, shift up to 4 px, random downscale (x0.4-1) and back, random JPEG quality 40-95: so neither resolution
    nor compression alone separates the sets. No colour change: colour is what realism is about."""
    s = img.shape[0]
    if rng.random() < 0.5:
        img = img[:, ::-1]
    dx, dy = rng.integers(-4, 5, 2)
    img = cv2.warpAffine(
        np.ascontiguousarray(img), np.float32([[1, 0, dx], [0, 1, dy]]), (s, s), borderMode=cv2.BORDER_REFLECT
    )
    f = rng.uniform(0.4, 1.0)
    if f < 0.97:
        small = cv2.resize(img, (max(8, round(s * f)),) * 2, interpolation=cv2.INTER_AREA)
        img = cv2.resize(small, (s, s), interpolation=cv2.INTER_LINEAR)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(40, 96))])
    return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)


def _small_cnn():
    from torch import nn

    def block(i, o):
        return nn.Sequential(
            nn.Conv2d(i, o, 3, padding=1, bias=False), nn.BatchNorm2d(o), nn.ReLU(inplace=True), nn.MaxPool2d(2)
        )

    return nn.Sequential(
        block(3, 16),
        block(16, 32),
        block(32, 64),
        block(64, 64),
        nn.AdaptiveAvgPool2d(1),
        nn.Flatten(),
        nn.Dropout(0.2),
        nn.Linear(64, 1),
    )


def _to_tensor(batch: list[np.ndarray]):
    import torch

    return torch.from_numpy(np.stack(batch).astype(np.float32).transpose(0, 3, 1, 2) / 127.5 - 1.0)


def cnn_two_sample(
    crops: np.ndarray,
    labels,
    groups,
    rng: np.random.Generator,
    n_splits: int = 5,
    epochs: int = 12,
    batch_size: int = 64,
    lr: float = 2e-3,
) -> TwoSampleResult:
    """A 4-block CNN trained from scratch per fold on (N, S, S, 3) uint8 crops with :func:`_augment`, balanced
    batches (each class sampled equally), Adam; out-of-fold logits on the un-augmented test crops."""
    import torch

    X, y, g = np.asarray(crops), np.asarray(labels).astype(bool), np.asarray(groups)
    folds = grouped_folds(g, n_splits, rng, y)
    scores = np.zeros(len(y))
    # weight init and dropout drawn from a torch seed taken from rng; the process' torch state is left as it was
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(int(rng.integers(2**31)))
        for k in range(n_splits):
            tr = np.flatnonzero(folds != k)
            pos, neg = tr[y[tr]], tr[~y[tr]]
            net = _small_cnn()
            opt = torch.optim.Adam(net.parameters(), lr=lr, weight_decay=1e-4)
            steps = max(1, epochs * len(tr) // batch_size)
            sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=lr, total_steps=steps)
            net.train()
            for _ in range(steps):
                idx = np.r_[rng.choice(pos, batch_size // 2), rng.choice(neg, batch_size // 2)]
                xb = _to_tensor([_augment(X[i], rng) for i in idx])
                yb = torch.from_numpy(y[idx].astype(np.float32))
                loss = torch.nn.functional.binary_cross_entropy_with_logits(net(xb).squeeze(1), yb)
                opt.zero_grad()
                loss.backward()
                opt.step()
                sched.step()
            net.eval()
            te = np.flatnonzero(folds == k)
            with torch.inference_mode():
                for i in range(0, len(te), 256):
                    scores[te[i : i + 256]] = net(_to_tensor([X[j] for j in te[i : i + 256]])).squeeze(1).numpy()
    return _result(scores, y, g, folds, rng)
