"""COCO json output: images, inserted and kept boxes, RLE masks, written atomically and validated by pycocotools."""

from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
from pathlib import Path

from pycocotools.coco import COCO


def atomic_write_json(path: str | Path, obj, indent: int | None = None) -> None:
    """Write JSON through a temporary file and rename, so a killed run never leaves a truncated file."""
    atomic_write_text(path, json.dumps(obj, indent=indent))


def atomic_write_text(path: str | Path, text: str) -> None:
    """Write ``text`` through a temporary file and rename, so a killed run never leaves a truncated file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


class CocoBuilder:
    """Accumulates a COCO dataset; category ids are assigned in order of first appearance unless given."""

    def __init__(self, categories: dict[str, int] | None = None):
        self.categories: dict[str, int] = dict(categories or {})
        self.images: list[dict] = []
        self.annotations: list[dict] = []
        self.videos: list[dict] = []  # COCO-video: images then carry video_id and frame_id

    def category_id(self, name: str) -> int:
        if name not in self.categories:
            self.categories[name] = max(self.categories.values(), default=0) + 1
        return self.categories[name]

    def add_image(self, file_name: str, width: int, height: int, **extra) -> int:
        image_id = len(self.images) + 1
        self.images.append(
            {"id": image_id, "file_name": file_name, "width": int(width), "height": int(height), **extra}
        )
        return image_id

    def add_box(
        self, image_id: int, category: str, bbox_xywh, *, segmentation=None, area=None, inserted=False, **extra
    ) -> None:
        x, y, w, h = (float(v) for v in bbox_xywh)
        ann = {
            "id": len(self.annotations) + 1,
            "image_id": image_id,
            "category_id": self.category_id(category),
            "bbox": [x, y, w, h],
            "area": float(area if area is not None else w * h),
            "iscrowd": 0,
            "inserted": bool(inserted),
            **extra,
        }
        if segmentation is not None:
            ann["segmentation"] = segmentation
        self.annotations.append(ann)

    def to_dict(self) -> dict:
        out = {
            "images": self.images,
            "annotations": self.annotations,
            "categories": [{"id": i, "name": n} for n, i in sorted(self.categories.items(), key=lambda t: t[1])],
        }
        if self.videos:
            out["videos"] = self.videos
        return out

    def write(self, path: str | Path) -> COCO:
        """Write and re-load with pycocotools (raises if the file is not a valid COCO dataset)."""
        atomic_write_json(path, self.to_dict())
        return load_coco(path)


def load_coco(path: str | Path) -> COCO:
    """pycocotools' ``COCO`` of a file (raises if it is not a valid COCO dataset), without its progress prints."""
    with contextlib.redirect_stdout(io.StringIO()):
        return COCO(str(path))
