"""A realism filter: the two-sample classifier of :mod:`.two_sample` used as a judge while generating.

Fitted on crops of real objects (label 0) against crops of inserted ones (label 1), with the crops and features
the realism report uses (:mod:`.crops`, :class:`~.features.Lite0Features`, standardised L2 logistic regression,
class-balanced), it scores each inserted object of a new image: the decision value, higher for what looks inserted.
:func:`best_of` draws an insertion up to ``attempts`` times and keeps the first whose objects score at or below the
threshold on average, else the draw with the lowest mean score (the mean, not the worst object: a worst-object
rule would favour draws with fewer objects). The threshold is the median out-of-fold score of the real crops:
an accepted insertion looks no more inserted than half of the real objects do to a classifier that never saw them.

A filter trained on the same features as the realism report's classifier lowers that report's AUC partly by
construction; what it buys a detector is measured by training one (the study arm ``inserted_filtered``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from aias_augment.evaluation.realism.crops import CropConfig, object_crops

__all__ = ["RealismFilter", "best_of"]


@dataclass(frozen=True, eq=False)
class RealismFilter:
    """``score(image, boxes_xyxy, rng)`` -> (K,) decision values (nan for boxes too small to crop)."""

    features: Callable[[list[np.ndarray]], np.ndarray]
    model: object  # a fitted sklearn pipeline with decision_function
    threshold: float
    crop_cfg: CropConfig
    fit_report: dict

    @classmethod
    def fit(
        cls,
        real_crops: list[np.ndarray],
        real_groups: list,
        inserted_crops: list[np.ndarray],
        inserted_groups: list,
        features: Callable[[list[np.ndarray]], np.ndarray],
        rng: np.random.Generator,
        *,
        C: float = 0.1,
        n_splits: int = 5,
        crop_cfg: CropConfig = CropConfig(),
    ) -> "RealismFilter":
        """Fit on the crops (groups: the photo each crop comes from, kept within one fold). The threshold is the
        median of the real crops' out-of-fold scores; ``fit_report`` holds the out-of-fold AUC and the counts."""
        from sklearn.linear_model import LogisticRegression
        from sklearn.pipeline import make_pipeline
        from sklearn.preprocessing import StandardScaler

        from aias_augment.evaluation.realism.two_sample import auc_mann_whitney, grouped_folds

        if len(real_crops) < n_splits or len(inserted_crops) < n_splits:
            raise ValueError(
                f"realism filter: {len(real_crops)} real and {len(inserted_crops)} inserted crops; "
                f"need at least {n_splits} of each"
            )
        X = features(list(real_crops) + list(inserted_crops))
        y = np.r_[np.zeros(len(real_crops), bool), np.ones(len(inserted_crops), bool)]
        g = np.array([f"r:{x}" for x in real_groups] + [f"i:{x}" for x in inserted_groups])

        def model():
            return make_pipeline(StandardScaler(), LogisticRegression(C=C, max_iter=2000, class_weight="balanced"))

        folds = grouped_folds(g, n_splits, rng, y)
        oof = np.zeros(len(y))
        for k in range(n_splits):
            tr, te = folds != k, folds == k
            oof[te] = model().fit(X[tr], y[tr]).decision_function(X[te])
        threshold = float(np.median(oof[~y]))
        report = {
            "real_crops": int((~y).sum()),
            "inserted_crops": int(y.sum()),
            "out_of_fold_auc": float(auc_mann_whitney(oof, y)),
            "threshold": threshold,
            "inserted_accepted_share": float(np.mean(oof[y] <= threshold)),
        }
        return cls(features, model().fit(X, y), threshold, crop_cfg, report)

    def score(self, image: np.ndarray, boxes_xyxy: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        boxes = np.asarray(boxes_xyxy, np.float64).reshape(-1, 4)
        out = np.full(len(boxes), np.nan)
        crops, kept = object_crops(image, boxes, rng, self.crop_cfg)
        if crops:
            out[kept] = self.model.decision_function(self.features(crops))
        return out


def best_of(
    draw: Callable[[np.random.Generator], tuple],
    boxes_of: Callable[[tuple], tuple[np.ndarray, np.ndarray]],
    judge: RealismFilter,
    rng: np.random.Generator,
    attempts: int,
) -> tuple[tuple, dict]:
    """Up to ``attempts`` draws of an insertion, the first with ``rng`` itself (so it is the unfiltered draw) and
    each later one with a generator seeded from ``rng``: ``draw(generator) -> result``, ``boxes_of(result) ->
    (image, boxes_xyxy)``. The first draw whose objects' mean score is at or below the judge's threshold is kept,
    else the draw with the lowest mean score. A draw without a scorable object scores +inf (kept only if every
    draw is so). Returns (result, info: attempt kept, scores of each draw, accepted)."""
    if attempts < 1:
        raise ValueError(f"attempts must be >= 1, got {attempts}")
    best, best_score, scores = None, np.inf, []
    gen = rng
    for a in range(attempts):
        if a:
            gen = np.random.default_rng(int(rng.integers(0, 2**63 - 1)))
        result = draw(gen)
        image, boxes = boxes_of(result)
        s = judge.score(image, boxes, np.random.default_rng(int(rng.integers(0, 2**63 - 1))))
        mean = float(np.nanmean(s)) if np.isfinite(s).any() else np.inf
        scores.append(mean)
        if best is None or mean < best_score:
            best, best_score, kept = result, mean, a
        if mean <= judge.threshold:
            break
    return best, {"attempt": kept, "scores": scores, "accepted": bool(best_score <= judge.threshold)}
