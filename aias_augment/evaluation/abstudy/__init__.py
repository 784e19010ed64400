"""The human A/B study: raters see two versions of the same scene and pick the more realistic one.

``aias-abstudy build`` pairs the outputs of ``aias-augment`` runs on the same inputs (one folder per method, an
"arm"), randomises left and right, and keeps the answer key apart; ``aias-abstudy serve`` serves the study on
localhost (FastAPI on uvicorn, votes in SQLite with WAL, a plain HTML/JS/CSS page, nothing from a CDN);
``aias-abstudy report`` prints the human score of each method against the baseline with a Wilson 95 % interval and
the agreement of each rater.

A study folder holds ``study.json`` (the pairs as the page sees them: ids, left/right media, no arms), ``key.json``
(the held-back answer key: which arm is left and right in each pair; never served), ``media/`` (content-addressed
copies of the images or clip frames, so no file name tells an arm) and ``votes.sqlite``.

Only ``build`` and ``report`` are imported by this package; the server (FastAPI) is imported when it is used.
"""

from aias_augment.evaluation.abstudy.build import StudyError, build_study, load_study
from aias_augment.evaluation.abstudy.report import compute_report, format_report, wilson_interval

__all__ = ["StudyError", "build_study", "load_study", "compute_report", "format_report", "wilson_interval"]
