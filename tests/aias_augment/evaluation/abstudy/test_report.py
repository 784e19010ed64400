import csv
import io
import math

import pytest

from aias_augment.evaluation.abstudy.build import build_study, load_study
from aias_augment.evaluation.abstudy.report import (
    compute_report,
    format_report,
    results_csv,
    sign_test_p,
    votes_csv,
    wilson_interval,
)
from tests.aias_augment.evaluation.abstudy.helpers import image_arms


def _wilson_by_bisection(k, n, z=1.959963984540054):
    """The Wilson interval as its definition: the p with |k/n - p| <= z sqrt(p (1 - p) / n)."""
    f = lambda p: (k / n - p) ** 2 - z * z * p * (1 - p) / n

    def root(lo, hi):
        for _ in range(200):
            mid = (lo + hi) / 2
            if (f(lo) > 0) == (f(mid) > 0):
                lo = mid
            else:
                hi = mid
        return (lo + hi) / 2

    ph = k / n
    return (0.0 if k == 0 else root(0.0, ph)), (1.0 if k == n else root(ph, 1.0))


@pytest.mark.parametrize("k,n", [(61, 100), (0, 10), (10, 10), (1, 3), (7, 19), (500, 1000)])
def test_wilson_matches_its_definition(k, n):
    lo, hi = wilson_interval(k, n)
    elo, ehi = _wilson_by_bisection(k, n)
    assert lo == pytest.approx(elo, abs=1e-9) and hi == pytest.approx(ehi, abs=1e-9)
    assert lo <= k / n <= hi


def test_wilson_known_value_and_edges():
    lo, hi = wilson_interval(61, 100)
    assert (round(lo, 4), round(hi, 4)) == (0.5120, 0.6998)  # by hand: centre 0.6059, half-width 0.0939
    assert wilson_interval(0, 0) == (None, None)
    with pytest.raises(ValueError):
        wilson_interval(5, 3)


def test_sign_test_against_enumeration():
    def brute(k, n):
        probs = [math.comb(n, i) / 2**n for i in range(n + 1)]
        return sum(p for p in probs if p <= probs[k] * (1 + 1e-12))

    for k, n in [(9, 10), (5, 10), (0, 7), (3, 7), (12, 20), (1, 1)]:
        assert sign_test_p(k, n) == pytest.approx(min(1.0, brute(k, n)), rel=1e-9)
    assert sign_test_p(9, 10) == pytest.approx(22 / 1024)
    assert sign_test_p(0, 0) is None


def _vote(study, rater, pid, choice):
    k = study.key[pid]
    return {
        "rater": rater,
        "pair_id": pid,
        "choice": choice,
        "left_arm": k["left"],
        "right_arm": k["right"],
        "ms": 1000,
        "created": 0.0,
    }


def _pick(study, pid, arm):
    """The side on which ``arm`` is shown in pair ``pid``."""
    return "left" if study.key[pid]["left"] == arm else "right"


def test_report_scores_and_agreement(tmp_path):
    build_study(image_arms(tmp_path, 3), tmp_path / "s", seed=1)
    s = load_study(tmp_path / "s")
    full = sorted(p for p, k in s.key.items() if "full" in (k["left"], k["right"]))
    shadow = sorted(p for p, k in s.key.items() if "no_shadow" in (k["left"], k["right"]))
    votes = []
    # ann and bob prefer full on every full pair; cy prefers naive paste on the first two, cannot tell on the rest
    for r in ("ann", "bob"):
        votes += [_vote(s, r, p, _pick(s, p, "full")) for p in full]
    votes += [_vote(s, "cy", p, _pick(s, p, "naive_paste")) for p in full[:2]]
    votes += [_vote(s, "cy", p, "tie") for p in full[2:]]
    # no_shadow: ann prefers it on 1 of 5 pairs
    votes += [_vote(s, "ann", p, _pick(s, p, "no_shadow" if i == 0 else "naive_paste")) for i, p in enumerate(shadow)]
    rep = compute_report(s, votes)
    rows = {(r["method"], r["opponent"]): r for r in rep["comparisons"]}
    f = rows[("full", "naive_paste")]
    assert (f["votes"], f["wins"], f["losses"], f["ties"], f["decisive"]) == (15, 10, 2, 3, 12)
    assert f["score"] == pytest.approx(10 / 12)
    assert (f["ci_low"], f["ci_high"]) == pytest.approx(wilson_interval(10, 12))
    ns = rows[("no_shadow", "naive_paste")]
    assert (ns["wins"], ns["losses"], ns["score"]) == (1, 4, pytest.approx(0.2))
    raters = {r["rater"]: r for r in rep["raters"]}
    # ann: 5 full pairs compared with the others' majority (bob agrees; cy agrees on none of the first two, but
    # bob + cy tie there -> not compared); no_shadow pairs have no other rater
    assert raters["ann"]["compared"] == 3 and raters["ann"]["agreement"] == 1.0
    assert raters["cy"]["compared"] == 2 and raters["cy"]["agreement"] == 0.0 and raters["cy"]["ties"] == 3
    assert raters["bob"]["votes"] == 5 and raters["bob"]["left_share"] == pytest.approx(
        sum(_pick(s, p, "full") == "left" for p in full) / 5
    )
    # pairwise agreement over (pair, two raters): each full pair has 3 raters -> 3 combinations, 5 pairs -> 15;
    # ann == bob everywhere (5), cy differs from both everywhere
    assert rep["pairwise_agreement"] == {"same": 5, "combinations": 15, "rate": pytest.approx(1 / 3)}
    text = format_report(rep)
    assert "full" in text and "83.3 %" in text and "55.2 - 95.3 %" in text
    table = list(csv.DictReader(io.StringIO(results_csv(rep))))
    assert table[0]["method"] == "full" and int(table[0]["wins"]) == 10
    rows_v = list(csv.DictReader(io.StringIO(votes_csv(s, votes))))
    assert len(rows_v) == len(votes)
    assert all(r["preferred_arm"] in (r["left_arm"], r["right_arm"], "") for r in rows_v)
    assert {r["preferred_arm"] for r in rows_v if r["rater"] == "bob"} == {"full"}


def test_report_without_votes(tmp_path):
    build_study(image_arms(tmp_path, 2), tmp_path / "s")
    rep = compute_report(load_study(tmp_path / "s"), [])
    assert rep["votes"] == 0 and rep["comparisons"][0]["score"] is None
    assert "no votes yet" in format_report(rep)
