"""The study's arms: each arm's insertion config (the table of their switches: :mod:`.arm_table`) and which arms
have a pool, per seed or online."""

from __future__ import annotations

import dataclasses
import logging
from typing import TYPE_CHECKING

from detection_eval.data import DetectionSet
from detection_eval.study.arm_table import ARM_FLAGS
from detection_eval.study.splits import real_box_height_fractions

if TYPE_CHECKING:
    from detection_eval.study.config import StudyConfig

log = logging.getLogger("detection_eval.study")


# Flags the study applies itself (not insertion-config overrides).
STUDY_FLAGS = ("closeup_crop", "copy_paste", "lifted", "realism_filter", "mix_pools")


# Arms whose pool is made per seed from that seed's thinned real subset (no other seed's real images leak in).
PER_SEED_ARMS = ("copy_paste", "lifted", "inserted_filtered")


# Arms whose insertions happen inside the training loop (``InsertObjects`` on each sample, new draws every epoch)
# instead of coming from the offline pool.
ONLINE_ARMS = ("inserted_online",)


def insertion_config_for_arm(cfg: StudyConfig, arm: str, train: DetectionSet):
    from aias_augment.pipeline.image import load_preset

    ic = cfg.insertion
    flags = {k: v for k, v in ARM_FLAGS[arm].items() if k not in STUDY_FLAGS}
    placement_flags = flags.pop("placement_cfg", {})  # fields of the placement config, on top of the preset's
    overrides = dict(
        categories=tuple(ic.categories),
        min_objects=ic.min_objects,
        max_objects=ic.max_objects,
        harmonize_method=ic.harmonize_method,
        **flags,
    )
    base = load_preset(ic.preset).placement_cfg
    if ic.match_real_sizes:
        fracs = tuple(f for f in real_box_height_fractions(train) if 0 < f <= 1)
        overrides["placement_cfg"] = dataclasses.replace(base, box_height_frac_samples=fracs)
        flags_of_arm = ARM_FLAGS[arm]
        if flags_of_arm.get("naive_paste") or flags_of_arm.get("placement") is False or flags_of_arm.get("naive_share"):
            # random 2D positions (naive paste, no placement) draw their sizes from the same distribution
            overrides["naive_height_frac_samples"] = fracs
    if placement_flags:
        overrides["placement_cfg"] = dataclasses.replace(overrides.get("placement_cfg", base), **placement_flags)
    return load_preset(ic.preset, **overrides)


def run_name(arm: str, seed: int, amount: int | None) -> str:
    return f"{arm}_seed{seed}" if amount is None else f"{arm}_n{amount}_seed{seed}"


def uses_pool(arm: str) -> bool:
    return ARM_FLAGS[arm] is not None and arm not in ONLINE_ARMS


def available_arms(arms) -> list[str]:
    """Arms whose insertion interface exists; the rest are skipped with a logged reason."""
    try:
        from aias_augment.pipeline.image import insert_into_image, load_preset  # noqa: F401

        return list(arms)
    except ImportError as exc:
        skipped = [a for a in arms if ARM_FLAGS[a] is not None]
        if skipped:
            log.warning("skipping arms %s: aias_augment.pipeline.image is not available (%s)", skipped, exc)
        return [a for a in arms if ARM_FLAGS[a] is None]
