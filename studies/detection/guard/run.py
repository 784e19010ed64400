"""The guard: the core table's inserted arm (60 images) with the defaults of the code that runs it, 5 paired seeds,
to pair with the core table's committed inserted runs.

    python -m studies.detection.guard                      # generate the pool, train the 5 runs, summarize
    python -m studies.detection.guard --stage summarize    # the table, plots and run.json from result/runs.jsonl

Arguments are those of ``aias-study`` (``--stage``, ``--arms``, ``--seeds``, ``--amounts``); the config is
this folder's ``config.yaml``.
"""

from pathlib import Path

from detection_eval.study.cli import run_study_folder


def main(argv: list[str] | None = None) -> int:
    return run_study_folder(Path(__file__).resolve().parent, argv)
