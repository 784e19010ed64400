"""Tiny detection sets for the study's tests."""

import numpy as np

from detection_eval.data import DetectionRecord, DetectionSet


def cone_set(n_with: int, n_without: int) -> DetectionSet:
    """``n_with`` 10x10 images with one cone box each, then ``n_without`` empty ones."""
    recs = [DetectionRecord(f"c{i}.jpg", 10, 10, np.array([[1.0, 1, 5, 5]]), np.array([0])) for i in range(n_with)]
    recs += [DetectionRecord(f"e{i}.jpg", 10, 10, np.zeros((0, 4)), np.zeros(0, np.int64)) for i in range(n_without)]
    return DetectionSet(tuple(recs), ("cone",))
