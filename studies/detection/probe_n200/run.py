"""The near-zero probe at 200 inserted images: does the probe's ranking hold with more inserted images?

    python -m studies.detection.probe_n200                      # generate the pools, train every run, summarize
    python -m studies.detection.probe_n200 --stage summarize    # the table, plots and run.json from result/runs.jsonl

Arguments are those of ``aias-study`` (``--stage``, ``--arms``, ``--seeds``, ``--amounts``); the config is
this folder's ``config.yaml``.
"""

from pathlib import Path

from detection_eval.study.cli import run_study_folder


def main(argv: list[str] | None = None) -> int:
    return run_study_folder(Path(__file__).resolve().parent, argv)
