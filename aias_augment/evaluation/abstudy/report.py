"""Results of a study: the human score of each method against its opponent (the baseline), rater agreement, CSV.

- **Human score** (as in the paper: the share of wins against the baseline) = votes preferring the method / decisive
  votes; "cannot tell" votes are counted and shown but are not decisive. The 95 % interval is Wilson's score
  interval; p is the two-sided exact sign test against 50 %. Both treat votes as independent, which votes of one
  rater on several pairs are not quite: read them as a guide, more raters tighten them honestly.
- **Agreement of a rater** = the share of their decisive votes that match the majority of the *other* raters on the
  same pair (pairs where the others are tied or absent are not compared). **Pairwise agreement** = the share of
  (pair, two raters) combinations in which both gave the same answer ("cannot tell" included).
- **Left share** = decisive votes for the left side: far from 50 % means a position bias (the build balances which
  side the baseline is on, so a biased rater adds noise, not a shift).
"""

from __future__ import annotations

import csv
import io
import math
from collections import defaultdict

from aias_augment.evaluation.abstudy.build import Study, orient

Z95 = 1.959963984540054


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float] | tuple[None, None]:
    """Wilson score interval for k successes in n trials; (None, None) for n = 0."""
    if n <= 0:
        return None, None
    if not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    p = k / n
    den = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    lo = 0.0 if k == 0 else max(0.0, centre - half)  # exact at the ends (no rounding past 0 or 1)
    hi = 1.0 if k == n else min(1.0, centre + half)
    return lo, hi


def sign_test_p(k: int, n: int) -> float | None:
    """Two-sided exact binomial test of k of n against p = 0.5 (the sum of outcomes no more likely than k)."""
    if n <= 0:
        return None
    logp = [math.lgamma(n + 1) - math.lgamma(i + 1) - math.lgamma(n - i + 1) - n * math.log(2) for i in range(n + 1)]
    cut = logp[k] + 1e-9
    return min(1.0, sum(math.exp(v) for v in logp if v <= cut))


def _winner(vote: dict) -> str | None:
    return {"left": vote["left_arm"], "right": vote["right_arm"]}.get(vote["choice"])


def compute_report(study: Study, votes: list[dict]) -> dict:
    """The whole result as a dict (the JSON the results page shows and ``format_report`` prints)."""
    arms, baseline = study.arms, study.baseline
    votes = [v for v in votes if v["pair_id"] in study.pairs]
    comp: dict[tuple[str, str], dict] = {}
    for pid, k in study.key.items():
        m, o = orient(arms, baseline, k["left"], k["right"])
        comp.setdefault(
            (m, o), {"method": m, "opponent": o, "pairs": 0, "votes": 0, "wins": 0, "losses": 0, "ties": 0}
        )["pairs"] += 1
    for v in votes:
        m, o = orient(arms, baseline, v["left_arm"], v["right_arm"])
        row = comp[(m, o)]
        row["votes"] += 1
        w = _winner(v)
        row["wins" if w == m else "losses" if w == o else "ties"] += 1
    rows = []
    for row in comp.values():
        n = row["wins"] + row["losses"]
        lo, hi = wilson_interval(row["wins"], n)
        rows.append(
            {
                **row,
                "decisive": n,
                "score": row["wins"] / n if n else None,
                "ci_low": lo,
                "ci_high": hi,
                "p_value": sign_test_p(row["wins"], n),
            }
        )
    rows.sort(key=lambda r: (r["opponent"] != baseline, arms.index(r["method"]), arms.index(r["opponent"])))

    by_pair: dict[str, dict[str, str]] = defaultdict(dict)
    for v in votes:
        by_pair[v["pair_id"]][v["rater"]] = v["choice"]
    raters = []
    for rater in sorted({v["rater"] for v in votes}):
        mine = [v for v in votes if v["rater"] == rater]
        decisive = [v for v in mine if v["choice"] != "tie"]
        agree = compared = 0
        for v in decisive:
            others = [c for r, c in by_pair[v["pair_id"]].items() if r != rater and c != "tie"]
            n_left = others.count("left")
            if others and 2 * n_left != len(others):
                compared += 1
                agree += v["choice"] == ("left" if 2 * n_left > len(others) else "right")
        raters.append(
            {
                "rater": rater,
                "votes": len(mine),
                "ties": len(mine) - len(decisive),
                "left_share": (sum(v["choice"] == "left" for v in decisive) / len(decisive) if decisive else None),
                "agreement": agree / compared if compared else None,
                "compared": compared,
                "median_ms": _median([v["ms"] for v in mine if v.get("ms") is not None]),
            }
        )
    same = combos = 0
    for choices in by_pair.values():
        cs = list(choices.values())
        for i in range(len(cs)):
            for j in range(i + 1, len(cs)):
                combos += 1
                same += cs[i] == cs[j]
    return {
        "title": study.meta.get("title"),
        "kind": study.meta.get("kind"),
        "baseline": baseline,
        "arms": arms,
        "design": study.meta.get("design"),
        "pairs": len(study.pairs),
        "votes": len(votes),
        "raters": raters,
        "comparisons": rows,
        "pairwise_agreement": {"same": same, "combinations": combos, "rate": same / combos if combos else None},
    }


def _median(xs: list) -> float | None:
    xs = sorted(xs)
    if not xs:
        return None
    mid = len(xs) // 2
    return float(xs[mid]) if len(xs) % 2 else (xs[mid - 1] + xs[mid]) / 2


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def _table(header: list[str], rows: list[list[str]]) -> str:
    w = [max(len(str(c)) for c in col) for col in zip(header, *rows)]
    line = lambda cells: "  ".join(str(c).ljust(w[i]) if i == 0 else str(c).rjust(w[i]) for i, c in enumerate(cells))
    return "\n".join([line(header), line(["-" * x for x in w])] + [line(r) for r in rows])


def comparison_rows(rep: dict) -> tuple[list[str], list[list[str]]]:
    header = [
        "method",
        "vs",
        "pairs",
        "votes",
        "method preferred",
        "vs preferred",
        "cannot tell",
        "human score",
        "95 % CI (Wilson)",
        "p (sign test)",
    ]
    rows = [
        [
            r["method"],
            r["opponent"],
            r["pairs"],
            r["votes"],
            r["wins"],
            r["losses"],
            r["ties"],
            _pct(r["score"]),
            "-" if r["ci_low"] is None else f"{100 * r['ci_low']:.1f} - {100 * r['ci_high']:.1f} %",
            "-" if r["p_value"] is None else f"{r['p_value']:.3g}",
        ]
        for r in rep["comparisons"]
    ]
    return header, rows


def format_report(rep: dict) -> str:
    """The report as text tables (what ``aias-abstudy report`` prints)."""
    pa = rep["pairwise_agreement"]
    out = [
        f"{rep['title']}: {rep['pairs']} pairs ({rep['kind']}s), {len(rep['raters'])} raters, {rep['votes']} votes;"
        f" baseline {rep['baseline']}",
        "human score = share of decisive votes preferring the method ('cannot tell' not decisive)",
        "",
        _table(*comparison_rows(rep)),
        "",
    ]
    if rep["raters"]:
        out.append(
            _table(
                [
                    "rater",
                    "votes",
                    "cannot tell",
                    "left share",
                    "agrees with others' majority",
                    "compared",
                    "median s / vote",
                ],
                [
                    [
                        r["rater"],
                        r["votes"],
                        r["ties"],
                        _pct(r["left_share"]),
                        _pct(r["agreement"]),
                        r["compared"],
                        "-" if r["median_ms"] is None else f"{r['median_ms'] / 1000:.1f}",
                    ]
                    for r in rep["raters"]
                ],
            )
        )
        out.append(f"pairwise agreement: {_pct(pa['rate'])} of {pa['combinations']} (pair, two raters) combinations")
    else:
        out.append("no votes yet")
    return "\n".join(out)


def results_csv(rep: dict) -> str:
    """One row per comparison (numbers unformatted)."""
    buf = io.StringIO()
    cols = [
        "method",
        "opponent",
        "pairs",
        "votes",
        "wins",
        "losses",
        "ties",
        "decisive",
        "score",
        "ci_low",
        "ci_high",
        "p_value",
    ]
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rep["comparisons"]:
        w.writerow(["" if r[c] is None else r[c] for c in cols])
    return buf.getvalue()


def votes_csv(study: Study, votes: list[dict]) -> str:
    """Every vote with its answer key (which arm was left, right, and preferred)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["rater", "pair_id", "source", "left_arm", "right_arm", "choice", "preferred_arm", "ms", "created"])
    for v in votes:
        src = study.key.get(v["pair_id"], {}).get("source", "")
        w.writerow(
            [
                v["rater"],
                v["pair_id"],
                src,
                v["left_arm"],
                v["right_arm"],
                v["choice"],
                _winner(v) or "",
                "" if v["ms"] is None else v["ms"],
                f"{v['created']:.3f}",
            ]
        )
    return buf.getvalue()
