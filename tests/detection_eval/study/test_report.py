from __future__ import annotations

import math

import pytest

from detection_eval.study.report import mean_ci95, summarize


def test_mean_ci95_known_values():
    m, h = mean_ci95([1.0, 2.0, 3.0])
    assert m == pytest.approx(2.0)
    assert h == pytest.approx(4.302653 * 1.0 / math.sqrt(3), rel=1e-5)  # t(0.975, 2) * s / sqrt(n), s = 1
    assert math.isnan(mean_ci95([0.5])[1])


def test_summary_pairs_seeds_against_reference():
    def row(arm, seed, ap):
        return {
            "arm": arm,
            "seed": seed,
            "amount": None if arm == "original" else 60,
            "real_images": 219,
            "inserted_images": 0 if arm == "original" else 60,
            "train_seconds": 100.0,
            "train_images_per_second": 5.0,
            "metrics": {"AP": ap, "AP50": 2 * ap, "AP_small": None, "AP_medium": ap, "AP_large": ap},
        }

    rows = [row("original", s, 0.1 + 0.01 * s) for s in range(3)] + [
        row("inserted", s, 0.15 + 0.01 * s) for s in range(3)
    ]
    rows += [row("naive_paste", s, 0.13 + 0.02 * s) for s in range(3)]
    table, summary = summarize(rows)
    assert summary["inserted n=60"]["delta_AP"][0] == pytest.approx(0.05)
    assert summary["inserted n=60"]["delta_AP"][1] == pytest.approx(0.0, abs=1e-9)  # identical paired gains
    # vs naive paste: differences 0.02, 0.01, 0.00 -> mean 0.01, t(0.975, 2) * 0.01 / sqrt(3)
    assert summary["inserted n=60"]["delta_AP_vs_naive"][0] == pytest.approx(0.01)
    assert summary["inserted n=60"]["delta_AP_vs_naive"][1] == pytest.approx(4.302653 * 0.01 / math.sqrt(3), rel=1e-5)
    assert summary["original"]["AP"][0] == pytest.approx(0.11)
    assert "| inserted n=60 | 3 | 219 + 60 |" in table and "n/a" in table  # AP_small undefined everywhere
