"""The study's config: datasets, arms, seeds, amounts, detector, the insertion settings of its pools."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

from aias_augment.core.config import CONFIG_DIR, REPO_ROOT, data_root, from_dict
from detection_eval.inherit import load_inherited
from detection_eval.study.arm_table import ARM_FLAGS

log = logging.getLogger("detection_eval.study")


@dataclass(frozen=True)
class InsertionStudyConfig:
    preset: str = "fast"  # aias_augment configs/presets/<preset>.yaml
    harmonize_method: str = "camera"  # pinned, so every arm and seed uses the same harmonizer
    categories: tuple[str, ...] = ("traffic_cone",)
    min_objects: int = 1
    max_objects: int = 3
    pool_size: int = 200  # inserted images generated once per arm (backgrounds cycle when larger
    # than the 199 empty road images); every run draws its share from it
    pool_seed: int = 0  # copy j uses default_rng([pool_seed, j]) in every arm: paired copies
    max_side_px: int = 640  # backgrounds are downscaled to this before insertion (we train at 320)
    match_real_sizes: bool = True  # target box heights drawn from the labelled train boxes' heights (as a
    # fraction of image height): inserted objects cover the real sizes

    def __post_init__(self):
        if self.pool_size < 1:
            raise ValueError(f"pool_size must be >= 1, got {self.pool_size}")


@dataclass(frozen=True)
class StudyConfig:
    dataset: str = "tracon"  # folder under $AIAS_DATA (or an absolute path)
    class_names: tuple[str, ...] = ("cone",)
    train_split: str = "train"
    val_split: str = "val"
    keep_fraction: float = 0.1  # of the train images that contain cones
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    arms: tuple[str, ...] = ("original", "inserted", "naive_paste")
    amounts: tuple[int, ...] = (200,)  # inserted images added per run (an axis: a gain may need enough cones)
    detector: str = "lite0_320"  # configs/detector/<name>.yaml
    max_iters: int | None = None  # overrides the detector config: the per-run budget
    insertion: InsertionStudyConfig = field(default_factory=InsertionStudyConfig)
    cache_dir: str = "out/study/cache"
    runs_dir: str = "runs/study"  # weights (not committed)
    results_dir: str = "out/study/result"  # runs.jsonl, table, plots, run.json (a study commits its own result/)
    reference_arm: str = "original"
    # A development split carved out of train before anything else (fixed draw, seed ``dev_seed``): no arm trains on
    # it, every run is scored on it beside val, and settings are chosen on it, never on val.
    dev_cone_images: int = 0
    dev_empty_images: int = 0
    dev_seed: int = 0
    online_p: float = 0.5  # inserted_online: probability that a training sample gets insertions

    def __post_init__(self):
        unknown = [a for a in self.arms if a not in ARM_FLAGS]
        if unknown:
            raise ValueError(f"unknown arms {unknown}; known: {list(ARM_FLAGS)}")
        if not 0 < self.keep_fraction <= 1:
            raise ValueError(f"keep_fraction must lie in (0, 1], got {self.keep_fraction}")
        if len(set(self.seeds)) != len(self.seeds) or not self.seeds:
            raise ValueError(f"seeds must be distinct and non-empty, got {self.seeds}")
        if not self.amounts or any(a < 1 or a > self.insertion.pool_size for a in self.amounts):
            raise ValueError(
                f"amounts must lie in [1, insertion.pool_size={self.insertion.pool_size}], got {self.amounts}"
            )


def repo_path(p: str) -> Path:
    return Path(p) if Path(p).is_absolute() else REPO_ROOT / p


def dataset_root(cfg: StudyConfig) -> Path:
    p = Path(cfg.dataset)
    return p if p.is_absolute() else data_root() / p


def load_study_config(path: str | Path) -> StudyConfig:
    """Load a study config (its ``_base_`` files merged under it: :mod:`detection_eval.inherit`); a relative path
    not found from the working folder is taken from the repository root (``studies/detection/core/config.yaml``);
    a bare name is looked up in ``configs/study/``."""
    p = Path(path)
    if not p.exists() and not p.is_absolute() and (REPO_ROOT / p).exists():
        p = REPO_ROOT / p
    if not p.exists() and not p.suffix:
        p = CONFIG_DIR / "study" / f"{path}.yaml"
    if not p.exists():
        raise FileNotFoundError(f"study config not found: {path}")
    return from_dict(StudyConfig, load_inherited(p), where=str(p))
