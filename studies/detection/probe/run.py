"""The near-zero probe: what does a detector learn from the inserted cones themselves, with 2 real cone images
and 60 inserted images per run? Settings are chosen on a development split carved out of train.

    python -m studies.detection.probe                      # generate the pools, train every run, summarize
    python -m studies.detection.probe --stage summarize    # the table, plots and run.json from result/runs.jsonl

Arguments are those of ``aias-study`` (``--stage``, ``--arms``, ``--seeds``, ``--amounts``); the config is
this folder's ``config.yaml``.
"""

from pathlib import Path

from detection_eval.study.cli import run_study_folder


def main(argv: list[str] | None = None) -> int:
    return run_study_folder(Path(__file__).resolve().parent, argv)
