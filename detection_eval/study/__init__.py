"""The downstream study (paper sec. 5.4): does training on inserted cones raise cone detection mAP on TraCon val?

Arms (all share the seeded thinning of the real cones, so seed k of every arm starts from the same images):
- ``original``: TraCon train with the cone images thinned to ``keep_fraction`` (seeded) plus all empty road images.
- ``inserted``: original + copies of empty road images with cones inserted by ``aias_augment`` (full pipeline).
- ``naive_paste``: original + the same copies with cones pasted plainly at random 2D positions and sizes
  (3D Copy-Paste's 'random insertion' baseline).
- ``no_placement`` / ``no_shadow`` / ``no_lighting`` / ``no_harmonize``: the full pipeline with one stage off.

Augmented sets are generated offline once per arm and seed (rendering is slow on CPU) and cached as YOLO-txt folders
under ``cache_dir``; the copy of image i under seed k uses ``default_rng([seed, i])`` in every arm, so arms differ
only in the stage switches. The summary is a markdown table with mean and 95%
t-interval per arm, paired differences to ``original``, and a plot.

    aias-study --config studies/detection/core/config.yaml                    # the core table
    aias-study --config ... --stage generate | train | summarize              # one stage only
    python -m studies.detection.core --stage summarize                        # the same through the study's folder

Every run writes its metrics JSON under ``runs_dir/metrics`` while it trains; the summarize stage folds them into the
table's ``results_dir/runs.jsonl`` (one line per run) and writes the table, plots and ``run.json`` beside it.

Modules: :mod:`.config` (what a study runs), :mod:`.arms` (the arms, one table), :mod:`.splits` (dev split,
thinned subset), :mod:`.pools` (inserted images per arm), :mod:`.runs` (train and score one run), :mod:`.report`
(tables, plots), :mod:`.run_table` (the runs.jsonl of a table), :mod:`.cli` (``aias-study``, ``python -m detection_eval.study``).
"""
