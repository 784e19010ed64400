"""Is a photo lit by direct sunlight? A calibrated probability from what the photo shows.

A dominant sun leaves three traces a single photo keeps whatever its framing:

- ``sky_blue``: a clear sky. The median log(B/R) of the brighter half of the top third (overcast sky, haze, a
  studio wall or a facade are grey or warm; a clear sky is blue).
- ``shadow_blue``: shadows lit by the blue sky alone. In the bottom half, mean log(B/R) of the darkest fifth minus
  that of the brightest fifth (unclipped): sunlit surfaces get the warm sun, shadows only the sky, so under direct
  sun shadows are bluer than lit surfaces; under an overcast sky both get the same light.
- ``clipped``: the share of pixels at the sensor's top (a sunlit white or a sun-facing surface saturates; diffuse
  light rarely does).

Measured on one fixed-size copy (longest side :data:`FEATURE_SIDE` px, area-averaged), so every preset and every
working resolution measures the same evidence and decides the same. The probability is a logistic model of the
standardised features; its coefficients, the decision threshold and their provenance are data
(``checkpoints/sun_evidence.json``), fitted by ``studies/lighting/sun_evidence/run.py`` on the train half of the labelled
lighting benchmark (``studies/lighting/sun_benchmark/labels/labels.csv``) and scored on its test half
(``studies/lighting/sun_evidence/result``).
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.config import CHECKPOINT_DIR
from aias_augment.core.hdr import max_channel
from aias_augment.core.srgb import srgb_to_linear

FEATURE_SIDE = 320
FEATURES = ("sky_blue", "shadow_blue", "clipped")
DEFAULT_MODEL = CHECKPOINT_DIR / "sun_evidence.json"
_EPS = 1e-3
_CLIP_LEVEL = 0.98  # of full scale: a channel at or above it is clipped


def sun_evidence_features(image_rgb_uint8: np.ndarray) -> dict[str, float]:
    """The evidence of :data:`FEATURES` for one (H, W, 3) uint8 RGB photo (see the module docstring)."""
    img = np.asarray(image_rgb_uint8)
    if img.ndim != 3 or img.shape[2] != 3 or img.dtype != np.uint8 or min(img.shape[:2]) < 8:
        raise ValueError(
            f"sun_evidence_features: need an (H, W, 3) uint8 RGB image of >= 8 px, got {img.shape} {img.dtype}"
        )
    s = FEATURE_SIDE / max(img.shape[:2])
    if s < 1:
        img = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
    x = img.astype(np.float32) / 255.0
    lin = srgb_to_linear(img)
    lum = lin @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    log_br = np.log((lin[..., 2] + _EPS) / (lin[..., 0] + _EPS))
    h = img.shape[0]
    top_l, top_br = lum[: max(h // 3, 1)], log_br[: max(h // 3, 1)]
    sky_blue = float(np.median(top_br[top_l >= np.quantile(top_l, 0.5)]))
    x_max = max_channel(x)
    bot_l, bot_br, bot_x_max = lum[h // 2 :], log_br[h // 2 :], x_max[h // 2 :]
    dark = bot_l <= np.quantile(bot_l, 0.2)
    lit = (bot_l >= np.quantile(bot_l, 0.8)) & (bot_x_max < _CLIP_LEVEL)
    shadow_blue = float(bot_br[dark].mean() - bot_br[lit].mean()) if dark.any() and lit.any() else 0.0
    clipped = float(np.mean(x_max >= _CLIP_LEVEL))
    return {"sky_blue": sky_blue, "shadow_blue": shadow_blue, "clipped": clipped}


@dataclass(frozen=True)
class SunEvidenceModel:
    """Logistic model p(direct sun) = sigmoid(intercept + coef . (f - mean) / scale) and its threshold."""

    features: tuple[str, ...]
    mean: tuple[float, ...]
    scale: tuple[float, ...]
    coef: tuple[float, ...]
    intercept: float
    threshold: float
    provenance: dict

    def __post_init__(self):
        n = len(self.features)
        if not (len(self.mean) == len(self.scale) == len(self.coef) == n) or n == 0:
            raise ValueError("SunEvidenceModel: features, mean, scale and coef must have the same, positive length")
        if set(self.features) - set(FEATURES):
            raise ValueError(f"SunEvidenceModel: unknown features {sorted(set(self.features) - set(FEATURES))}")
        if not all(np.isfinite(v) and v > 0 for v in self.scale):
            raise ValueError("SunEvidenceModel: every scale must be positive and finite")
        if not all(np.isfinite(v) for v in (*self.mean, *self.coef, self.intercept)) or not 0 < self.threshold < 1:
            raise ValueError("SunEvidenceModel: coefficients must be finite and the threshold inside (0, 1)")

    @classmethod
    def load(cls, path: str | Path = DEFAULT_MODEL) -> SunEvidenceModel:
        d = json.loads(Path(path).read_text())
        return cls(
            tuple(d["features"]),
            tuple(float(v) for v in d["mean"]),
            tuple(float(v) for v in d["scale"]),
            tuple(float(v) for v in d["coef"]),
            float(d["intercept"]),
            float(d["threshold"]),
            dict(d.get("provenance", {})),
        )

    def to_dict(self) -> dict:
        return {
            "features": list(self.features),
            "mean": list(self.mean),
            "scale": list(self.scale),
            "coef": list(self.coef),
            "intercept": self.intercept,
            "threshold": self.threshold,
            "provenance": self.provenance,
        }

    def probability(self, features: dict[str, float]) -> float:
        f = np.array([features[k] for k in self.features], float)
        z = self.intercept + float(np.dot(self.coef, (f - np.array(self.mean)) / np.array(self.scale)))
        return float(1.0 / (1.0 + np.exp(-np.clip(z, -50.0, 50.0))))


@functools.lru_cache(maxsize=4)
def load_sun_evidence_model(path: str = str(DEFAULT_MODEL)) -> SunEvidenceModel:
    """The shipped model (read once per process; a JSON file, never executable)."""
    return SunEvidenceModel.load(path)


def direct_sun_probability(image_rgb_uint8: np.ndarray, model: SunEvidenceModel | None = None) -> float:
    """p(direct sunlight lights the scene) for one photo, from :func:`sun_evidence_features`."""
    model = model or load_sun_evidence_model()
    return model.probability(sun_evidence_features(image_rgb_uint8))


def decide_direct_sun(
    probability: float, threshold: float | None = None, model: SunEvidenceModel | None = None
) -> bool:
    """The sun decision: ``probability`` at or above ``threshold`` (None: the model's own threshold)."""
    if threshold is None:
        threshold = (model or load_sun_evidence_model()).threshold
    return bool(probability >= threshold)


def asymmetric_threshold(probability: np.ndarray, truth: np.ndarray, min_precision: float) -> float:
    """The threshold t that maximises recall of ``probability >= t`` subject to precision >= ``min_precision`` on
    labelled photos (``truth`` 1: direct sun): a false sun costs more than a missed one, so precision is the
    constraint and recall what is left to gain. Among thresholds of equal recall the highest is taken (fewest
    false suns). Candidates are the observed probabilities; where none reaches the precision, a threshold above every
    probability (no sun at all) is returned. (N,) float and (N,) bool/int -> float in (0, 1]."""
    p, y = np.asarray(probability, float), np.asarray(truth).astype(bool)
    if p.shape != y.shape or p.ndim != 1 or not np.all(np.isfinite(p)):
        raise ValueError(f"asymmetric_threshold: need two (N,) arrays of finite values, got {p.shape} and {y.shape}")
    if not 0.0 < min_precision <= 1.0:
        raise ValueError(f"asymmetric_threshold: min_precision must be in (0, 1], got {min_precision}")
    best_recall, best_t = -1.0, float(np.nextafter(max(float(p.max(initial=0.0)), 0.0), 2.0))
    for t in np.unique(p)[::-1]:  # descending: the first of equal recall is the highest threshold
        pred = p >= t
        tp = int(np.sum(pred & y))
        if tp / int(pred.sum()) >= min_precision and tp / max(int(y.sum()), 1) > best_recall:
            best_recall, best_t = tp / max(int(y.sum()), 1), float(t)
    return min(best_t, 1.0)


def wilson_interval(successes: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a proportion (scipy's ``binomtest``); (0, 1) without trials."""
    if trials <= 0:
        return 0.0, 1.0
    from scipy.stats import binomtest

    ci = binomtest(int(successes), int(trials)).proportion_ci(confidence_level=confidence, method="wilson")
    return float(ci.low), float(ci.high)
