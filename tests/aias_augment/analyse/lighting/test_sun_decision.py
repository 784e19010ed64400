"""The asymmetric sun decision: the rule, the threshold chooser against a brute-force count, the config's override
reaching the estimate, and the committed study's numbers reproduced from its estimates CSV and the label files."""

import csv
import itertools
import json
from pathlib import Path

import numpy as np
import pytest

from aias_augment.analyse.lighting.estimate import LightingConfig
from aias_augment.analyse.lighting.sun_evidence import (
    asymmetric_threshold,
    decide_direct_sun,
    direct_sun_probability,
    load_sun_evidence_model,
    wilson_interval,
)

from .test_sun_evidence import OVERCAST, SUNNY

STUDY = Path(__file__).resolve().parents[4] / "studies" / "lighting" / "sun_asymmetric" / "result"
BENCH = STUDY.parents[1] / "sun_benchmark" / "labels"


def test_decision_is_probability_at_or_above_threshold():
    assert decide_direct_sun(0.7, 0.7) and not decide_direct_sun(0.6999, 0.7)
    t = load_sun_evidence_model().threshold
    assert decide_direct_sun(t) and not decide_direct_sun(float(np.nextafter(t, 0.0)))


def _brute_force(p, y, m):
    """Every threshold among the probabilities (and one above them): (recall, threshold) of those with precision
    >= m, best recall then highest threshold."""
    ok = []
    for t in sorted(set(p)) + [max(p) + 1]:
        pred = [q >= t for q in p]
        tp = sum(a and b for a, b in zip(pred, y))
        if sum(pred) and tp / sum(pred) >= m:
            ok.append((tp / sum(y), t))
    return max(ok) if ok else None


@pytest.mark.parametrize("seed", range(6))
def test_threshold_maximises_recall_under_the_precision_floor(seed):
    rng = np.random.default_rng(seed)
    y = rng.random(40) < 0.5
    p = np.clip(0.35 * y + rng.random(40) * 0.65, 0, 1).round(3)
    t = asymmetric_threshold(p, y, 0.9)
    pred = p >= t
    best = _brute_force(list(p), list(y), 0.9)
    if best is None:
        assert not pred.any()
    else:
        assert pred.sum() and (pred & y).sum() / pred.sum() >= 0.9
        assert ((pred & y).sum() / y.sum(), t) == pytest.approx(best)


def test_threshold_without_any_precise_choice_decides_no_sun():
    p, y = np.array([0.2, 0.5, 0.9]), np.array([1, 0, 0])  # the most probable photo is overcast
    assert not np.any(p >= asymmetric_threshold(p, y, 0.9))
    with pytest.raises(ValueError, match="min_precision"):
        asymmetric_threshold(p, y, 0.0)


def test_wilson_interval_matches_its_formula():
    for k, n in itertools.product((0, 3, 17), (17, 40)):
        z, ph = 1.959964, k / n
        centre = (ph + z * z / (2 * n)) / (1 + z * z / n)
        half = z / (1 + z * z / n) * np.sqrt(ph * (1 - ph) / n + z * z / (4 * n * n))
        assert wilson_interval(k, n) == pytest.approx((centre - half, centre + half), abs=1e-6)


def test_config_threshold_decides_the_estimate():
    from aias_augment.analyse.analysis import analyse_scene
    from aias_augment.core.frame import Frame
    from aias_augment.pipeline.config import load_preset

    for img in (SUNNY, OVERCAST):
        p = direct_sun_probability(img)
        for t, expected in ((min(p * 1.01 + 1e-3, 0.999), False), (max(p * 0.99 - 1e-3, 1e-6), True)):
            est = analyse_scene(Frame(img, None), load_preset("fast", lighting_cfg={"sun_threshold": t})).lighting
            assert est.dominant_sun is expected and est.confidence == pytest.approx(p, abs=1e-3)
    with pytest.raises(ValueError, match="sun_threshold"):
        LightingConfig(sun_threshold=1.0)


def _labels() -> dict[tuple[str, int], tuple[int, int]]:
    out = {}
    for name, fname in (("benchmark", "labels.csv"), ("extra", "labels_extra.csv"), ("more", "labels_more.csv")):
        for r in csv.DictReader(open(BENCH / fname)):
            out[name, int(r["index"])] = (int(r["direct_sun"]), int(r.get("uncertain") or 0))
    return out


def test_shipped_decision_reproduces_the_study():
    """From the committed estimates (no analysis re-run) and the label files read here: the shipped threshold's
    precision and recall on each part are the report's, and on the dev part it is the highest recall whose precision
    reaches the report's floor (checked against every probability as a threshold)."""
    report = json.loads((STUDY / "report.json").read_text())
    labels = _labels()
    rows = list(csv.DictReader(open(STUDY / "estimates.csv")))
    assert len(rows) == len(labels) >= 200 and report["threshold"] == pytest.approx(load_sun_evidence_model().threshold)
    for preset in ("fast", "balanced"):
        for part in ("dev", "heldout"):
            tp = fp = fn = 0
            for r in rows:
                sun, uncertain = labels[r["set"], int(r["index"])]
                if uncertain or r["part"] != part:
                    continue
                decided = bool(int(r[f"{preset}_sun_possible"])) and decide_direct_sun(
                    float(r[f"{preset}_probability"])
                )
                tp, fp, fn = tp + (decided and sun), fp + (decided and not sun), fn + (not decided and sun)
            got = report[preset][part]
            assert (got["true_suns"], got["decided_sun"], got["sunny"]) == (tp, tp + fp, tp + fn)
            assert got["precision"] == pytest.approx(tp / (tp + fp), abs=5e-4)
            assert got["recall"] == pytest.approx(tp / (tp + fn), abs=5e-4)
    dev = [r for r in rows if r["part"] == "dev" and not labels[r["set"], int(r["index"])][1]]
    p = [float(r["balanced_probability"]) if int(r["balanced_sun_possible"]) else 0.0 for r in dev]
    y = [labels[r["set"], int(r["index"])][0] for r in dev]
    best = _brute_force(p, y, report["min_precision_on_dev"])
    assert report["balanced"]["dev"]["recall"] == pytest.approx(best[0], abs=5e-4)
    assert report["balanced"]["dev"]["precision"] >= report["min_precision_on_dev"]
