"""Shared fixtures: a tiny synthetic detection set written as a real YOLO-txt folder."""

from __future__ import annotations

import numpy as np
import pytest

from detection_eval.data import write_classes, write_yolo_sample


def make_synthetic_image(rng: np.random.Generator, size: int, n_objects: int):
    """Textured background with ``n_objects`` orange, white-striped 'cones' (filled triangles on a base) whose
    boxes are known exactly."""
    import cv2

    image = rng.integers(40, 140, (size, size, 3), dtype=np.uint8)
    image = cv2.GaussianBlur(image, (5, 5), 0)
    boxes = []
    for _ in range(n_objects):
        for _attempt in range(50):
            w = int(rng.integers(size // 6, size // 3))
            h = int(w * rng.uniform(1.2, 1.8))
            x0, y0 = int(rng.integers(0, size - w)), int(rng.integers(0, size - h))
            cand = np.array([x0, y0, x0 + w, y0 + h], float)
            if all(cand[2] <= b[0] or cand[0] >= b[2] or cand[3] <= b[1] or cand[1] >= b[3] for b in boxes):
                break
        tri = np.array([[x0 + w // 2, y0], [x0, y0 + h - 1], [x0 + w - 1, y0 + h - 1]], np.int32)
        cv2.fillConvexPoly(image, tri, (255, 110, 0))
        cv2.line(image, (x0 + w // 4, y0 + h // 2), (x0 + 3 * w // 4, y0 + h // 2), (255, 255, 255), max(2, h // 10))
        ys, xs = np.nonzero(
            np.all(image[y0 : y0 + h, x0 : x0 + w] == (255, 110, 0), -1)
            | np.all(image[y0 : y0 + h, x0 : x0 + w] == (255, 255, 255), -1)
        )
        boxes.append(np.array([x0 + xs.min(), y0 + ys.min(), x0 + xs.max() + 1, y0 + ys.max() + 1], float))
    return image, np.array(boxes).reshape(-1, 4)


@pytest.fixture(scope="session")
def tiny_yolo_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny_yolo")
    rng = np.random.default_rng(0)
    for i in range(4):
        image, boxes = make_synthetic_image(rng, 128, n_objects=1 + i % 2)
        write_yolo_sample(root, f"img_{i}", image, boxes, np.zeros(len(boxes), np.int64), jpeg_quality=98)
    write_classes(root, ("cone",))
    return root


@pytest.fixture()
def weights(tmp_path):
    """A tiny untrained detector's checkpoint (one class, ``cone``), seeded."""
    import torch

    from detection_eval.config import DetectorConfig, ModelConfig, TrainConfig
    from detection_eval.model import Detector
    from detection_eval.train import save_checkpoint

    torch.manual_seed(0)
    cfg = DetectorConfig(
        model=ModelConfig(backbone="cspdarknet", pretrained=False, width=0.125, depth=0.33),
        train=TrainConfig(img_size=64),
    )
    path = tmp_path / "w.pt"
    save_checkpoint(path, Detector(cfg).eval(), ["cone"])
    return path
