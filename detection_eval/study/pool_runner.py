"""One pool copy through the CLI's offline runner: the job every ``aias-augment`` backend runs
(:func:`aias_augment.cli.offline_job.process_item`) makes the study's pipeline copies too, so a pool image is what
``aias-augment`` writes for the same background, seed and config.

The background is downscaled by the study first (``max_side_px``, INTER_AREA) and handed to the runner as a
lossless PNG in the pool's ``runner/`` folder; copy ``j`` is the runner's index ``j`` with ``seed = pool_seed``, so it
draws from ``default_rng([pool_seed, j])`` as every arm's copy ``j`` does; the runner encodes the JPEG (quality 95),
which the pool takes as it is (no second encoding).
"""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from aias_augment.cli.dataset_out import ImageOut
from aias_augment.cli.offline_job import Item, process_item
from aias_augment.core.errors import AiasError

POOL_JPEG_QUALITY = 95  # detection_eval.data.write_yolo_sample's default: every pool image is encoded alike


@dataclass
class PoolCopy:
    """One finished copy: its boxes (x0, y0, x1, y1 pixels), the stages' record, and either its pixels (to encode)
    or the JPEG the runner wrote (to move into the pool)."""

    boxes_xyxy: np.ndarray
    modules: dict
    height: int
    width: int
    image: np.ndarray | None = None
    jpeg: Path | None = None


class RunnerCopyFailed(AiasError, RuntimeError):
    """The runner skipped the copy; the message is its reason (logged and counted by the pool)."""


class RunnerMaker:
    """``make(image, j)`` of a pipeline arm: copy ``j`` of the background ``image`` (already downscaled) through
    :func:`process_item` with the arm's insertion config and asset ``bank``; the runner's files live in
    ``out/runner`` and are removed once the copy is taken."""

    def __init__(self, ins_cfg, bank, pool_seed: int, out: Path):
        self.ins_cfg, self.bank, self.pool_seed = ins_cfg, bank, pool_seed
        self.work = Path(out) / "runner"
        shutil.rmtree(self.work, ignore_errors=True)  # a killed run's leftovers: never reused as a record
        (self.work / "backgrounds").mkdir(parents=True)

    def __call__(self, image: np.ndarray, j: int, stem: str) -> PoolCopy:
        background = self.work / "backgrounds" / f"{stem}.png"
        if not cv2.imwrite(str(background), np.ascontiguousarray(image[..., ::-1])):
            raise OSError(f"cannot write {background}")
        try:
            rec = process_item(
                j,
                Item(path=str(background)),
                self.ins_cfg,
                self.pool_seed,
                str(self.work),
                bank=self.bank,
                image_out=ImageOut(format="jpg", jpeg_quality=POOL_JPEG_QUALITY),
            )
        finally:
            background.unlink(missing_ok=True)
            (self.work / "records" / f"{j:06d}.json").unlink(missing_ok=True)
        if "skipped" in rec:
            raise RunnerCopyFailed(rec["skipped"])
        b = np.asarray(rec["boxes"], np.float64).reshape(-1, 4)
        return PoolCopy(
            boxes_xyxy=np.c_[b[:, :2], b[:, :2] + b[:, 2:]],
            modules=json.loads(json.dumps(rec.get("modules", {}))),
            height=int(rec["height"]),
            width=int(rec["width"]),
            jpeg=self.work / "images" / rec["file_name"],
        )


def take_jpeg(copy: PoolCopy, image_path: Path) -> None:
    """Move the runner's JPEG to the pool's ``image_path`` (same file system: a rename)."""
    image_path.parent.mkdir(parents=True, exist_ok=True)
    os.replace(copy.jpeg, image_path)
