"""``aias-abstudy``: a human A/B study of insertion methods (raters pick the more realistic of two versions).

aias-abstudy build --arms out/naive_paste out/full out/no_shadow --design all-pairs --out out/study_ab
aias-abstudy serve out/study_ab [--host 127.0.0.1] [--port 8000]
aias-abstudy report out/study_ab [--csv results.csv] [--votes-csv votes.csv] [--json]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from aias_augment.core.arg_parser import OneLineArgumentParser
from aias_augment.core.logs import add_logging_args, configure_logging, log_level
from aias_augment.evaluation.abstudy.build import DESIGNS, StudyError, build_study, load_study
from aias_augment.evaluation.abstudy.report import compute_report, format_report, results_csv, votes_csv


def _report(a) -> int:
    from aias_augment.evaluation.abstudy.store import VoteStore

    study = load_study(a.study)
    db = Path(a.study) / "votes.sqlite"
    votes = VoteStore(db).votes() if db.exists() else []
    rep = compute_report(study, votes)
    print(json.dumps(rep, indent=1) if a.json else format_report(rep))
    if a.csv:
        Path(a.csv).write_text(results_csv(rep))
    if a.votes_csv:
        Path(a.votes_csv).write_text(votes_csv(study, votes))
    return 0


def main(argv=None) -> int:
    ap = OneLineArgumentParser(
        prog="aias-abstudy", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="pair the outputs of aias-augment runs on the same inputs into a study")
    b.add_argument("--arms", nargs="+", required=True, help="aias-augment output folders, one per method")
    b.add_argument("--names", nargs="+", help="arm names (default: the folder names)")
    b.add_argument("--baseline", help="the arm every method is compared with (default: the first)")
    b.add_argument(
        "--design",
        choices=DESIGNS,
        default="baseline",
        help="baseline: each arm vs the baseline; all-pairs: every two arms",
    )
    b.add_argument("--seed", type=int, default=0, help="left/right, pair order and pair ids")
    b.add_argument("--title", help="shown on the page")
    b.add_argument("--out", required=True)
    b.add_argument("--force", action="store_true", help="rebuild a study that has no votes yet")
    s = sub.add_parser("serve", help="serve a study on localhost")
    s.add_argument("study")
    s.add_argument("--host", default="127.0.0.1")
    s.add_argument("--port", type=int, default=8000, help="0: any free port (the URL is printed)")
    r = sub.add_parser("report", help="print the human score per method and the rater agreement")
    r.add_argument("study")
    r.add_argument("--csv", help="write the comparison table as CSV")
    r.add_argument("--votes-csv", help="write every vote with its answer key as CSV")
    r.add_argument("--json", action="store_true", help="print the report as JSON")
    add_logging_args(ap, subcommands=sub.choices.values())
    a = ap.parse_args(argv)
    configure_logging(a)
    try:
        if a.cmd == "build":
            summary = build_study(
                a.arms,
                a.out,
                names=a.names,
                baseline=a.baseline,
                design=a.design,
                seed=a.seed,
                title=a.title,
                force=a.force,
            )
            print(json.dumps(summary, indent=1))
            return 0
        if a.cmd == "serve":
            from aias_augment.evaluation.abstudy.server import serve

            load_study(a.study)  # a clear error before the server starts
            serve(a.study, a.host, a.port, logging.getLevelName(log_level(a)).lower())  # uvicorn's names
            return 0
        return _report(a)
    except StudyError as e:
        print(f"aias-abstudy: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
