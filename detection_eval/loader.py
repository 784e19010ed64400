"""Decoded-once image cache and deterministic batches for training.

Images are decoded once, downscaled so that the longer side equals the training size (the letterbox content), and
kept in memory; augmentation then works on these small arrays. Sample ``i`` of iteration ``t`` draws its randomness
from ``default_rng([seed, t, i])``, so a run is reproducible regardless of timing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np
import torch

from .boxes import Letterbox, letterbox_params
from .config import AugmentConfig
from .data import DetectionSet, read_image_rgb
from .losses import Targets
from .transforms import augment_sample

# (image, boxes_xyxy, labels, rng) -> (image, boxes_xyxy, labels): e.g. online object insertion.
SampleTransform = Callable[
    [np.ndarray, np.ndarray, np.ndarray, np.random.Generator], tuple[np.ndarray, np.ndarray, np.ndarray]
]


@dataclass(frozen=True, eq=False)
class CachedImage:
    image: np.ndarray  # letterbox content (no padding), RGB uint8
    boxes_xyxy: np.ndarray  # in ``image`` pixels
    labels: np.ndarray
    letterbox: Letterbox  # original pixels -> padded square of the training size


def cache_image(record, size: int) -> CachedImage:
    lb = letterbox_params(record.height, record.width, size)
    new_w, new_h = round(record.width * lb.scale), round(record.height * lb.scale)
    image = read_image_rgb(record.image_path, min_long_side=size)
    if image.shape[:2] != (record.height, record.width):
        ratio_h, ratio_w = image.shape[0] / record.height, image.shape[1] / record.width
        if abs(ratio_h - ratio_w) > 0.02 or ratio_w > 1.0 + 1e-9:  # reduced decode is 1/2, 1/4 or 1/8 of both
            raise ValueError(
                f"{record.image_path}: decoded {image.shape[1]}x{image.shape[0]}, "
                f"record says {record.width}x{record.height}"
            )
    interp = cv2.INTER_AREA if new_w < image.shape[1] else cv2.INTER_LINEAR
    image = cv2.resize(image, (new_w, new_h), interpolation=interp)
    # Labels rounded in normalised units can overhang the border by a fraction of a pixel: clip to the content.
    boxes = np.clip(record.boxes_xyxy * lb.scale, 0, [new_w, new_h, new_w, new_h])
    return CachedImage(image, boxes, record.labels, lb)


def cache_dataset(dataset: DetectionSet, size: int, memo: dict | None = None) -> list[CachedImage]:
    """Cached images of ``dataset``; ``memo`` (keyed by path and size) shares decoded images between runs."""
    if memo is None:
        return [cache_image(r, size) for r in dataset.records]
    out = []
    for r in dataset.records:
        key = (r.image_path, size)
        if key not in memo:
            memo[key] = cache_image(r, size)
        out.append(memo[key])
    return out


def pad_to_square(image: np.ndarray, lb: Letterbox) -> np.ndarray:
    from .boxes import PAD_VALUE

    canvas = np.full((lb.size, lb.size, 3), PAD_VALUE, dtype=np.uint8)
    x0, y0 = int(lb.pad_x), int(lb.pad_y)
    canvas[y0 : y0 + image.shape[0], x0 : x0 + image.shape[1]] = image
    return canvas


def images_to_tensor(images: list[np.ndarray]) -> torch.Tensor:
    """List of (S, S, 3) uint8 -> (B, 3, S, S) float in [0, 1]."""
    return torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).float().div_(255.0)


def collate_targets(boxes: list[np.ndarray], labels: list[np.ndarray]) -> Targets:
    g = max([len(b) for b in boxes] + [1])
    out_boxes = torch.zeros(len(boxes), g, 4)
    out_labels = torch.zeros(len(boxes), g, dtype=torch.long)
    for i, (b, lab) in enumerate(zip(boxes, labels)):
        out_boxes[i, : len(b)] = torch.as_tensor(b, dtype=torch.float32)
        out_labels[i, : len(b)] = torch.as_tensor(lab, dtype=torch.long)
    return Targets(out_boxes, out_labels, torch.tensor([len(b) for b in boxes], dtype=torch.long))


def epoch_items(cache: list[CachedImage], object_image_fraction: float) -> np.ndarray:
    """Indices making up one epoch. Images with objects are repeated ``round(r)`` times (at least once), with r chosen
    so that they make up ``object_image_fraction`` of the epoch (repeat-factor sampling, as LVIS does for rare
    classes); with a fraction of 0, or when they already make up that share, every image appears once."""
    has_obj = np.array([len(c.labels) > 0 for c in cache])
    n_obj, n_empty = int(has_obj.sum()), int((~has_obj).sum())
    repeat = 1
    if object_image_fraction > 0 and n_obj and n_obj / len(cache) < object_image_fraction:
        repeat = max(1, round(object_image_fraction * n_empty / ((1 - object_image_fraction) * n_obj)))
    counts = np.where(has_obj, repeat, 1)
    return np.repeat(np.arange(len(cache)), counts)


class TrainBatches:
    """Infinite deterministic stream of augmented batches over a cached dataset (epoch-wise shuffles)."""

    def __init__(
        self,
        cache: list[CachedImage],
        size: int,
        batch_size: int,
        augment: AugmentConfig,
        seed: int,
        sample_transform: SampleTransform | None = None,
        object_image_fraction: float = 0.0,
        synthetic_mask: np.ndarray | None = None,
        synthetic_fraction: float = 0.25,
    ):
        if not cache:
            raise ValueError("empty training set")
        self.cache, self.size, self.batch_size = cache, size, batch_size
        self.augment, self.seed, self.sample_transform = augment, seed, sample_transform
        synthetic = np.zeros(len(cache), bool) if synthetic_mask is None else np.asarray(synthetic_mask, bool)
        if synthetic.shape != (len(cache),):
            raise ValueError(f"synthetic_mask must have one entry per image ({len(cache)}), got {synthetic.shape}")
        real = np.flatnonzero(~synthetic)
        if not len(real):
            raise ValueError("no real images: synthetic images replace real empty ones, they cannot stand alone")
        self.synthetic = np.flatnonzero(synthetic)
        # One epoch of real images, as without synthetic data (indices into the cache)
        self.epoch_items = real[epoch_items([cache[i] for i in real], object_image_fraction)]
        empty_slots = np.array([len(cache[i].labels) == 0 for i in self.epoch_items])
        self.replace_prob = 0.0
        if len(self.synthetic) and synthetic_fraction > 0:
            if not empty_slots.any():
                raise ValueError("synthetic images take the slots of real images without objects; there are none")
            self.replace_prob = min(1.0, synthetic_fraction / empty_slots.mean())
        self._orders: dict[int, np.ndarray] = {}

    def _order(self, epoch: int) -> np.ndarray:
        """Epoch order: a seeded permutation of the real items (the same with or without synthetic images), then
        each slot of a real image without objects shows a synthetic image with probability ``replace_prob``."""
        if epoch not in self._orders:
            perm = np.random.default_rng([self.seed, 1_000_003, epoch]).permutation(len(self.epoch_items))
            order = self.epoch_items[perm]
            if self.replace_prob > 0:
                rng = np.random.default_rng([self.seed, 1_000_033, epoch])
                slots = np.flatnonzero([len(self.cache[i].labels) == 0 for i in order])
                slots = slots[rng.random(len(slots)) < self.replace_prob]
                picks = np.resize(rng.permutation(self.synthetic), len(slots))
                order = order.copy()
                order[slots] = picks
            self._orders = {epoch: order}
        return self._orders[epoch]

    def index_at(self, position: int) -> int:
        epoch, k = divmod(position, len(self.epoch_items))
        return int(self._order(epoch)[k])

    def _sample(self, idx: int, rng: np.random.Generator):
        c = self.cache[idx]
        image, boxes, labels = c.image, c.boxes_xyxy, c.labels
        if self.sample_transform is not None:
            image, boxes, labels = self.sample_transform(image, boxes, labels, rng)
        return image, boxes, labels

    def batch(self, iteration: int):
        images, boxes, labels = [], [], []
        for slot in range(self.batch_size):
            rng = np.random.default_rng([self.seed, iteration, slot])
            sample = self._sample(self.index_at(iteration * self.batch_size + slot), rng)
            extra = None
            if self.augment.mosaic_prob > 0:
                extra = [self._sample(int(j), rng) for j in rng.integers(0, len(self.cache), 3)]
            img, b, lab = augment_sample(*sample, self.size, self.augment, rng, extra)
            images.append(img)
            boxes.append(b)
            labels.append(lab)
        return images_to_tensor(images), collate_targets(boxes, labels)
