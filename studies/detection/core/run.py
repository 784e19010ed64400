"""The core table: do inserted cones raise a detector's AP on TraCon val when the real cone images are thinned to
10 %? The pipeline's defaults against naive paste, copy-paste of real cones and no insertion, 5 paired seeds.

    python -m studies.detection.core                      # generate the pools, train every run, summarize
    python -m studies.detection.core --stage summarize    # the table, plots and run.json from result/runs.jsonl

Arguments are those of ``aias-study`` (``--stage``, ``--arms``, ``--seeds``, ``--amounts``); the config is
this folder's ``config.yaml``.
"""

from pathlib import Path

from detection_eval.study.cli import run_study_folder


def main(argv: list[str] | None = None) -> int:
    return run_study_folder(Path(__file__).resolve().parent, argv)
