"""Detection datasets: YOLO-txt folders and COCO json, read into one record type; writing YOLO-txt back.

Boxes in records are xyxy pixels of the original image. Labels are contiguous ``0..C-1``; ``category_ids`` maps them
to COCO category ids (``label + 1`` for YOLO data). Images are read without EXIF rotation, as the label files index
the stored pixel grid.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.image_io import image_size, read_image

from .boxes import xywh_to_xyxy, xyxy_to_xywh

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".webp")


@dataclass(frozen=True, eq=False)
class DetectionRecord:
    image_path: str
    width: int
    height: int
    boxes_xyxy: np.ndarray  # (N, 4) float64 pixels
    labels: np.ndarray  # (N,) int64 contiguous labels

    def __post_init__(self):
        if self.boxes_xyxy.shape != (len(self.labels), 4):
            raise ValueError(f"{self.image_path}: boxes {self.boxes_xyxy.shape} vs labels {self.labels.shape}")


@dataclass(frozen=True, eq=False)
class DetectionSet:
    records: tuple[DetectionRecord, ...]
    category_names: tuple[str, ...]
    category_ids: tuple[int, ...] = ()
    skipped: dict = field(default_factory=dict)  # reason -> count, for logged skips

    def __post_init__(self):
        if not self.category_ids:
            object.__setattr__(self, "category_ids", tuple(range(1, len(self.category_names) + 1)))
        if len(self.category_ids) != len(self.category_names):
            raise ValueError("category_ids and category_names differ in length")

    def __len__(self):
        return len(self.records)

    @property
    def num_boxes(self) -> int:
        return int(sum(len(r.labels) for r in self.records))

    def subset(self, indices) -> "DetectionSet":
        return DetectionSet(tuple(self.records[i] for i in indices), self.category_names, self.category_ids)

    def __add__(self, other: "DetectionSet") -> "DetectionSet":
        if other.category_names != self.category_names:
            raise ValueError(f"cannot join sets with categories {self.category_names} and {other.category_names}")
        return DetectionSet(self.records + other.records, self.category_names, self.category_ids)


def read_image_rgb(path: str | Path, min_long_side: int | None = None) -> np.ndarray:
    """Decode an image as upright RGB uint8 (H, W, 3) by the package's reader. With ``min_long_side`` a JPEG may be
    decoded at 1/2, 1/4 or 1/8 scale (much faster) as long as its longer side stays >= ``min_long_side``."""
    return read_image(path, min_long_side=min_long_side)


# ---------------------------------------------------------------- YOLO txt


def _yolo_dirs(root: Path, split: str | None) -> tuple[Path, Path]:
    root = Path(root)
    if root.name == "images" or root.parent.name == "images":  # given the image folder itself
        image_dir = root
        parts = list(root.parts)
        idx = len(parts) - 1 - parts[::-1].index("images")
        label_dir = Path(*parts[:idx], "labels", *parts[idx + 1 :])
    else:
        image_dir, label_dir = root / "images", root / "labels"
        if split:
            image_dir, label_dir = image_dir / split, label_dir / split
    if not image_dir.is_dir() or not label_dir.is_dir():
        raise ValueError(f"YOLO dataset needs {image_dir} and {label_dir} (give --split for split folders)")
    return image_dir, label_dir


def parse_yolo_label_file(path: Path, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """``class cx cy w h`` normalised per line -> xyxy pixels (N, 4), labels (N,). Bad lines raise ValueError."""
    boxes, labels = [], []
    for lineno, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip():
            continue
        parts = line.split()
        try:
            cls, cx, cy, w, h = int(parts[0]), *map(float, parts[1:5])
        except (ValueError, IndexError) as exc:
            raise ValueError(f"{path}:{lineno}: expected 'class cx cy w h', got {line!r}") from exc
        if len(parts) != 5 or cls < 0 or w <= 0 or h <= 0:
            raise ValueError(f"{path}:{lineno}: expected 'class cx cy w h' with w, h > 0, got {line!r}")
        boxes.append([(cx - w / 2) * width, (cy - h / 2) * height, (cx + w / 2) * width, (cy + h / 2) * height])
        labels.append(cls)
    return np.asarray(boxes, dtype=np.float64).reshape(-1, 4), np.asarray(labels, dtype=np.int64)


def load_yolo_dir(root: str | Path, split: str | None = None, names: tuple[str, ...] | None = None) -> DetectionSet:
    """Read ``root/images[/split]`` with ``root/labels[/split]`` (or an ``.../images/<split>`` folder directly).
    Images without a label file, and images whose header cannot be read, are skipped and counted (a missing file is
    not the same as 'no objects')."""
    image_dir, label_dir = _yolo_dirs(Path(root), split)
    records, skipped = [], {}
    for img in sorted(p for p in image_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES):
        label_path = label_dir / f"{img.stem}.txt"
        if not label_path.exists():
            skipped["no label file"] = skipped.get("no label file", 0) + 1
            continue
        try:
            w, h = image_size(img)
        except (OSError, ValueError, SyntaxError) as e:  # PIL: not an image, a broken header
            skipped["unreadable image"] = skipped.get("unreadable image", 0) + 1
            log.warning("skipping unreadable image %s: %s", img, " ".join(str(e).split()))
            continue
        boxes, labels = parse_yolo_label_file(label_path, w, h)
        records.append(DetectionRecord(str(img), w, h, boxes, labels))
    if skipped:
        log.warning("%s: skipped %s", image_dir, skipped)
    if not records:
        raise ValueError(f"no labelled images found in {image_dir}")
    max_label = max((int(r.labels.max()) for r in records if len(r.labels)), default=0)
    if names is None:
        names_file = Path(root) / "classes.txt"
        names = (
            tuple(names_file.read_text().split())
            if names_file.exists()
            else tuple(f"class_{i}" for i in range(max_label + 1))
        )
    if max_label >= len(names):
        raise ValueError(f"label {max_label} found but only {len(names)} category names given: {names}")
    return DetectionSet(tuple(records), tuple(names), skipped=skipped)


def format_yolo_labels(boxes_xyxy: np.ndarray, labels: np.ndarray, width: int, height: int) -> str:
    lines = []
    for (x0, y0, x1, y1), c in zip(np.asarray(boxes_xyxy, dtype=np.float64), labels):
        lines.append(
            f"{int(c)} {(x0 + x1) / 2 / width:.6f} {(y0 + y1) / 2 / height:.6f} "
            f"{(x1 - x0) / width:.6f} {(y1 - y0) / height:.6f}"
        )
    return "\n".join(lines) + ("\n" if lines else "")


def write_yolo_sample(
    root: str | Path,
    stem: str,
    image_rgb: np.ndarray,
    boxes_xyxy: np.ndarray,
    labels: np.ndarray,
    jpeg_quality: int = 95,
) -> DetectionRecord:
    """Write ``root/images/<stem>.jpg`` and ``root/labels/<stem>.txt``; returns the record as it would be read back."""
    root = Path(root)
    (root / "images").mkdir(parents=True, exist_ok=True)
    (root / "labels").mkdir(parents=True, exist_ok=True)
    h, w = image_rgb.shape[:2]
    img_path = root / "images" / f"{stem}.jpg"
    if not cv2.imwrite(
        str(img_path), cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality]
    ):
        raise ValueError(f"cannot write {img_path}")
    (root / "labels" / f"{stem}.txt").write_text(format_yolo_labels(boxes_xyxy, labels, w, h))
    return DetectionRecord(
        str(img_path), w, h, np.asarray(boxes_xyxy, np.float64).reshape(-1, 4), np.asarray(labels, np.int64)
    )


def write_classes(root: str | Path, names: tuple[str, ...]) -> None:
    Path(root, "classes.txt").write_text("\n".join(names) + "\n")


# ---------------------------------------------------------------- COCO json


def load_coco_json(path: str | Path, image_root: str | Path | None = None) -> DetectionSet:
    """Read a COCO detection json. ``image_root`` defaults to the json's folder (or its ``images/`` subfolder).
    Crowd annotations and boxes with non-positive size are skipped and counted."""
    path = Path(path)
    data = json.loads(path.read_text())
    for key in ("images", "annotations", "categories"):
        if key not in data:
            raise ValueError(f"{path}: not a COCO detection file (no '{key}')")
    cats = sorted(data["categories"], key=lambda c: c["id"])
    label_of = {c["id"]: i for i, c in enumerate(cats)}
    if image_root is None:
        image_root = path.parent
        first = data["images"][0]["file_name"] if data["images"] else ""
        if first and not (image_root / first).exists() and (image_root / "images" / first).exists():
            image_root = image_root / "images"
    by_image: dict[int, list] = {im["id"]: [] for im in data["images"]}
    skipped = {}
    for ann in data["annotations"]:
        x, y, w, h = ann["bbox"]
        if ann.get("iscrowd", 0) or w <= 0 or h <= 0:
            reason = "crowd" if ann.get("iscrowd", 0) else "empty box"
            skipped[reason] = skipped.get(reason, 0) + 1
            continue
        if ann["category_id"] not in label_of:
            raise ValueError(f"{path}: annotation {ann.get('id')} has unknown category {ann['category_id']}")
        by_image[ann["image_id"]].append((x, y, w, h, label_of[ann["category_id"]]))
    if skipped:
        log.warning("%s: skipped annotations %s", path, skipped)
    records = []
    for im in data["images"]:
        anns = np.asarray(by_image[im["id"]], dtype=np.float64).reshape(-1, 5)
        records.append(
            DetectionRecord(
                str(Path(image_root) / im["file_name"]),
                int(im["width"]),
                int(im["height"]),
                xywh_to_xyxy(anns[:, :4]),
                anns[:, 4].astype(np.int64),
            )
        )
    return DetectionSet(tuple(records), tuple(c["name"] for c in cats), tuple(c["id"] for c in cats), skipped)


def coco_gt_dict(dataset: DetectionSet) -> dict:
    """COCO ground truth for ``dataset``: image ids are 1-based record positions."""
    images, anns = [], []
    for i, r in enumerate(dataset.records, 1):
        images.append({"id": i, "file_name": Path(r.image_path).name, "width": r.width, "height": r.height})
        for box, label in zip(xyxy_to_xywh(r.boxes_xyxy), r.labels):
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": i,
                    "category_id": dataset.category_ids[int(label)],
                    "bbox": [float(v) for v in box],
                    "area": float(box[2] * box[3]),
                    "iscrowd": 0,
                }
            )
    cats = [{"id": cid, "name": n} for cid, n in zip(dataset.category_ids, dataset.category_names)]
    return {"images": images, "annotations": anns, "categories": cats}


def load_dataset(
    path: str | Path,
    split: str | None = None,
    names: tuple[str, ...] | None = None,
    image_root: str | Path | None = None,
) -> DetectionSet:
    """A ``.json`` path is COCO; a folder is YOLO txt."""
    p = Path(path)
    if p.suffix.lower() == ".json":
        return load_coco_json(p, image_root)
    if p.is_dir():
        return load_yolo_dir(p, split, names)
    raise ValueError(f"{path}: expected a COCO .json file or a YOLO dataset folder")
