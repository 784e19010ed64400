"""The images, datasets and transforms the transform benchmarks share (``bench_transform``, ``bench_loader``,
``bench_fast_stages``, ``bench_family_speed``): TraCon roads at a fixed size, a flat cone sprite for albumentations'
``OverlayElements``, the Compose every arm runs in, a map-style dataset that decodes as a training set does, and a
transform that only appends boxes (the Compose's own cost of new boxes)."""

from __future__ import annotations

import os

os.environ.setdefault("NO_ALBUMENTATIONS_UPDATE", "1")

import albumentations as A  # noqa: E402
import cv2  # noqa: E402
import numpy as np  # noqa: E402

from aias_augment.core.config import data_root  # noqa: E402


def tracon_images(n: int, size: tuple[int, int]) -> list[np.ndarray]:
    files = sorted((data_root() / "tracon" / "images" / "train").glob("*.jpg"))
    if len(files) < n:
        raise SystemExit(f"need {n} TraCon images under {data_root()}/tracon/images/train, found {len(files)}")
    return [
        cv2.resize(cv2.cvtColor(cv2.imread(str(f)), cv2.COLOR_BGR2RGB), size, interpolation=cv2.INTER_AREA)
        for f in files[:n]
    ]


def cone_sprite() -> tuple[np.ndarray, np.ndarray]:
    """A cone crop and its mask for OverlayElements: the cone rendered flat (albedo) at 120 px."""
    from aias_augment.apply.render import linear_to_srgb, render_object
    from aias_augment.assets.asset import default_asset
    from aias_augment.core.geometry import Intrinsics

    K = Intrinsics(300.0, 300.0, 63.5, 63.5, 128, 128)
    T = np.eye(4)
    T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    cone = default_asset("traffic_cone")
    T[:3, 3] = [0.0, cone.height_m / 2, 300.0 * cone.height_m / 110.0]
    rl = render_object(cone, T, K, ssaa=1, with_normals=False)
    ys, xs = np.nonzero(rl.alpha > 0.5)
    crop = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
    rgb = (linear_to_srgb(rl.albedo_linear[crop]) * 255).round().astype(np.uint8)
    return rgb, (rl.alpha[crop] > 0.5).astype(np.uint8)


def compose_for(t) -> A.Compose:
    return A.Compose([t], bbox_params=A.BboxParams(format="coco", label_fields=["labels"]), seed=7)


class Images:
    """Map-style dataset as a training set reads it: each item decoded from its JPEG and resized to 320x320 (no
    boxes), then ``transform`` (or none)."""

    def __init__(self, paths, transform):
        self.paths, self.transform = [str(p) for p in paths], transform

    def __len__(self):
        return len(self.paths)

    def __getitem__(self, i):
        import torch

        img = cv2.resize(
            cv2.cvtColor(cv2.imread(self.paths[i]), cv2.COLOR_BGR2RGB), (320, 320), interpolation=cv2.INTER_AREA
        )
        if self.transform is not None:
            img = self.transform(image=img, bboxes=np.zeros((0, 4)), labels=[])["image"]
        return torch.from_numpy(np.ascontiguousarray(img)).permute(2, 0, 1)


class AppendBoxes(A.DualTransform):
    """The Compose's own cost of a transform that adds boxes, and nothing else: at ``p``, two fixed new boxes
    (labelled "traffic_cone" through the Compose's label manager, as InsertObjects labels its boxes) appended, no
    pixel changed. The ``boxes_only`` loader arm: the most any insertion transform inside an albumentations
    Compose can reach (the Compose then filters, checks, converts and decodes the new boxes, as it does for any
    transform's boxes)."""

    _targets = (
        A.core.type_definitions.Targets.IMAGE,
        A.core.type_definitions.Targets.MASK,
        A.core.type_definitions.Targets.BBOXES,
    )
    _ROWS = np.array([[0.1, 0.5, 0.2, 0.7], [0.4, 0.6, 0.45, 0.8]], np.float32)

    def apply(self, img, **params):
        return img

    def apply_to_mask(self, mask, **params):
        return mask

    def apply_to_bboxes(self, bboxes, **params):
        codes = self.get_processor("bboxes").label_manager.process_field("bboxes", "labels", ["traffic_cone"] * 2)
        return np.hstack((self._ROWS, codes)).astype(np.float32)

    def get_transform_init_args_names(self):
        return ()


def decoded(paths) -> list[np.ndarray]:
    """The items' images as the dataset decodes them (what ``InsertObjects.warm`` must see to hit the same keys)."""
    return [
        cv2.resize(cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB), (320, 320), interpolation=cv2.INTER_AREA)
        for p in paths
    ]


def set_cv2_threads(n: int, worker_id: int) -> None:
    cv2.setNumThreads(n)
