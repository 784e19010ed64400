"""Evaluation tools beside the pipeline: realism metrics (:mod:`.realism`) and the human A/B study app
(:mod:`.abstudy`)."""
