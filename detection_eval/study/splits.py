"""The real data of a run: the development split carved out of train, the thinned subset, the pool's backgrounds."""

from __future__ import annotations

import logging

import numpy as np

from detection_eval.data import DetectionSet

log = logging.getLogger("detection_eval.study")


def split_dev(train: DetectionSet, n_cone: int, n_empty: int, seed: int) -> tuple[DetectionSet, DetectionSet]:
    """(rest, dev): ``n_cone`` images with objects and ``n_empty`` without, drawn once with ``default_rng([seed,
    3])``, moved out of ``train`` into a development set that no arm trains on (its empty roads are no insertion
    backgrounds either)."""
    with_obj = [i for i, r in enumerate(train.records) if len(r.labels)]
    empty = [i for i, r in enumerate(train.records) if not len(r.labels)]
    if n_cone > len(with_obj) or n_empty > len(empty) or n_cone < 0 or n_empty < 0:
        raise ValueError(f"dev split of {n_cone} + {n_empty} images asked of {len(with_obj)} + {len(empty)}")
    rng = np.random.default_rng([seed, 3])
    dev = set(int(i) for i in rng.choice(with_obj, n_cone, replace=False)) | set(
        int(i) for i in rng.choice(empty, n_empty, replace=False)
    )
    rest = [i for i in range(len(train)) if i not in dev]
    return train.subset(rest), train.subset(sorted(dev))


def thin_cone_images(train: DetectionSet, keep_fraction: float, seed: int) -> tuple[DetectionSet, list[int]]:
    """Keep ``round(keep_fraction * n)`` of the images with objects (seeded) and every image without; also return
    the indices of the images without objects (the insertion backgrounds)."""
    with_obj = [i for i, r in enumerate(train.records) if len(r.labels)]
    empty = [i for i, r in enumerate(train.records) if not len(r.labels)]
    n_keep = max(1, round(keep_fraction * len(with_obj)))
    kept = np.random.default_rng([seed, 7]).choice(with_obj, n_keep, replace=False)
    return train.subset(sorted(int(i) for i in kept) + empty), empty


def pool_backgrounds(empty: list[int], pool_seed: int, n: int) -> list[int]:
    """Background of each of the ``n`` pool copies: a seeded order of the empty images, cycled when ``n`` exceeds
    them (copy j and copy j + len(empty) share a background, with different draws)."""
    order = np.random.default_rng([pool_seed, 11]).permutation(len(empty))
    return [empty[int(order[j % len(empty)])] for j in range(n)]


def pool_share(pool_size: int, amount: int, seed: int) -> list[int]:
    """Which pool copies a run with ``seed`` uses: ``amount`` of them, a seeded subset (all when amount == size)."""
    return sorted(int(j) for j in np.random.default_rng([seed, 13]).permutation(pool_size)[:amount])


def real_box_height_fractions(train: DetectionSet) -> tuple[float, ...]:
    """Box height / image height of every labelled box (the class's size distribution in the user's data)."""
    return tuple(
        float((r.boxes_xyxy[i, 3] - r.boxes_xyxy[i, 1]) / r.height) for r in train.records for i in range(len(r.labels))
    )
