"""The first detector's table (lite0_320): inserted, naive paste and no insertion at 20, 60 and 200 inserted
images, the close-up, online and procedural arms, and the ablations, 5 paired seeds.

    python -m studies.detection.lite0_320                      # generate the pools, train every run, summarize
    python -m studies.detection.lite0_320 --stage summarize    # the table, plots and run.json from result/runs.jsonl
    python -m studies.detection.lite0_320 --config ablations.yaml   # a part of the table: this folder's ablations.yaml

Arguments are those of ``aias-study`` (``--stage``, ``--arms``, ``--seeds``, ``--amounts``); the config is
this folder's ``config.yaml``.
"""

from pathlib import Path

from detection_eval.study.cli import run_study_folder


def main(argv: list[str] | None = None) -> int:
    return run_study_folder(Path(__file__).resolve().parent, argv)
