"""YOLO datasets in the Ultralytics layout: reading the input's splits and class names, writing labels, the other
splits and ``data.yaml``.

The layout (Ultralytics' ``check_det_dataset``): ``data.yaml`` names a root (``path``, default the yaml's folder) and
per split a folder of images (``train: images/train``); each image's labels are the ``.txt`` of the same stem in the
folder whose last ``images`` path component is ``labels`` (``images/train/a.jpg`` -> ``labels/train/a.txt``), one
``class cx cy w h`` line per box, normalised to the image size; a missing or empty file is an image without objects.
``names`` is a list, or a mapping from class index to name.
"""

from __future__ import annotations

import logging
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import yaml

from aias_augment.adapters.boundary import InputError
from aias_augment.cli.manifest import write_file
from aias_augment.core.config_files import load_yaml_file

log = logging.getLogger(__name__)
IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp"}
SPLIT_KEYS = ("train", "val", "test")


@dataclass(frozen=True)
class YoloSplit:
    """One split of a YOLO dataset: its name, its images folder and its labels folder."""

    name: str
    images: Path
    labels: Path


@dataclass(frozen=True)
class YoloDataset:
    """A YOLO dataset as found on disk: its splits (in ``data.yaml`` order, else sorted) and class names (None
    when it does not say)."""

    splits: tuple[YoloSplit, ...]
    names: tuple[str, ...] | None = None
    data_yaml: Path | None = None

    def split(self, name: str | None) -> YoloSplit:
        """The split ``name``; None: ``train`` when there is one, else the only split. Otherwise InputError."""
        known = [s.name for s in self.splits]
        if name is None:
            name = "train" if "train" in known or len(known) != 1 else known[0]
        for s in self.splits:
            if s.name == name:
                return s
        raise InputError(f"--split {name!r}: the dataset's splits are {known}; name one of them")


def labels_dir_for(images_dir: Path) -> Path:
    """Ultralytics' rule: the last path component named ``images`` becomes ``labels``; without one, the labels lie
    beside the images."""
    parts = list(Path(images_dir).parts)
    for i in range(len(parts) - 1, -1, -1):
        if parts[i] == "images":
            parts[i] = "labels"
            return Path(*parts)
    return Path(images_dir)


def class_names_of(data: dict, where: str) -> tuple[str, ...] | None:
    """``names`` of a data.yaml: a list, or a mapping {0: name, 1: name, ...} with every index from 0."""
    names = data.get("names")
    if names is None:
        return None
    if isinstance(names, dict):
        try:
            by_index = {int(k): str(v) for k, v in names.items()}
        except (TypeError, ValueError):
            raise InputError(f"{where}: 'names' keys must be class indices 0, 1, ...") from None
        if sorted(by_index) != list(range(len(by_index))):
            raise InputError(f"{where}: 'names' must give every class index from 0, got {sorted(by_index)}")
        return tuple(by_index[i] for i in range(len(by_index)))
    if isinstance(names, list):
        return tuple(str(n) for n in names)
    raise InputError(f"{where}: 'names' must be a list or a mapping of class index to name")


def _split_from_yaml(root: Path, key: str, value, where: str) -> YoloSplit:
    if isinstance(value, list):
        if len(value) != 1:
            raise InputError(f"{where}: '{key}' lists {len(value)} folders; give one folder per split")
        value = value[0]
    images = Path(str(value))
    if not images.is_absolute():
        rel, images = str(value), root / images
        if not images.exists() and rel.startswith("../"):  # as Ultralytics reads Roboflow's exports
            images = root / rel[3:]
    if images.is_file():
        raise InputError(f"{where}: '{key}: {value}' is a list file; give the split's images folder instead")
    if not images.is_dir():
        raise InputError(f"{where}: '{key}: {value}' is not a folder ({images})")
    return YoloSplit(key, images, labels_dir_for(images))


def read_yolo_dataset(path: str | Path) -> YoloDataset:
    """The YOLO dataset at ``path``: a data.yaml, a folder holding one, a folder with ``images/<split>/`` folders,
    or a plain folder of images (one split, ``train``). Unreadable or inconsistent: InputError."""
    p = Path(path)
    yaml_path = p if p.is_file() and p.suffix.lower() in (".yaml", ".yml") else None
    if yaml_path is None and p.is_dir() and (p / "data.yaml").is_file():
        yaml_path = p / "data.yaml"
    if yaml_path is not None:
        data = load_yaml_file(yaml_path)  # bounded: size, UTF-8, alias expansion (ConfigFileError, an InputError)
        if not isinstance(data, dict):
            raise InputError(f"{yaml_path}: expected a mapping (path, train, val, names)")
        root = Path(str(data.get("path") or "."))
        root = root if root.is_absolute() else yaml_path.parent / root
        splits = tuple(
            _split_from_yaml(root, k, data[k], str(yaml_path)) for k in SPLIT_KEYS if data.get(k) is not None
        )
        if not splits:
            raise InputError(f"{yaml_path}: no split folders (train, val, test)")
        return YoloDataset(splits, class_names_of(data, str(yaml_path)), yaml_path)
    if not p.is_dir():
        raise InputError(f"--yolo {p}: not a folder or a data.yaml")
    if (p / "images").is_dir():
        subs = sorted(d for d in (p / "images").iterdir() if d.is_dir())
        if subs:
            return YoloDataset(tuple(YoloSplit(d.name, d, p / "labels" / d.name) for d in subs))
    return YoloDataset((YoloSplit("train", p, labels_dir_for(p)),))


def yolo_label_text(boxes_xywh, class_ids, width: int, height: int) -> str:
    """YOLO lines ``class cx cy w h`` (normalised, six decimals) of pixel boxes ``[x, y, w, h]``."""
    lines = []
    for (x, y, w, h), c in zip(boxes_xywh, class_ids):
        cx, cy = (float(x) + float(w) / 2) / width, (float(y) + float(h) / 2) / height
        lines.append(f"{int(c)} {cx:.6f} {cy:.6f} {float(w) / width:.6f} {float(h) / height:.6f}")
    return "".join(line + "\n" for line in lines)


def write_text(dest: Path, text: str, temp_prefix: str) -> None:
    """``text`` written atomically (:func:`aias_augment.cli.manifest.write_file`)."""

    def put(tmp: Path) -> None:
        with open(tmp, "x") as f:
            f.write(text)

    write_file(dest, temp_prefix, put)


def place_file(src: Path, dst: Path, temp_prefix: str) -> str:
    """``dst`` made to hold ``src``'s bytes: a hard link when both are on one file system, else a copy (never a
    symbolic link: nothing written later into ``out`` can reach the user's file through a link we made; our own
    writes replace files by renaming, never write through them). Returns "linked", "copied" or "kept" (``dst``
    is already ``src``)."""
    if dst.exists() and os.path.samefile(src, dst):
        return "kept"
    how = []

    def put(tmp: Path) -> None:
        try:
            os.link(src, tmp)
            how.append("linked")
        except OSError:
            shutil.copyfile(src, tmp)
            how.append("copied")

    write_file(dst, temp_prefix, put)
    return how[0]


def split_files(split: YoloSplit) -> list[tuple[Path, Path | None]]:
    """(image, its label file or None) of every image directly in ``split``'s images folder, sorted."""
    images = sorted(q for q in split.images.iterdir() if q.is_file() and q.suffix.lower() in IMAGE_SUFFIXES)
    return [(img, lab if (lab := split.labels / (img.stem + ".txt")).is_file() else None) for img in images]


def copied_paths(split: YoloSplit) -> list[str]:
    """The paths (relative to ``out``) :func:`copy_split` writes."""
    out = []
    for img, lab in split_files(split):
        out.append(f"images/{split.name}/{img.name}")
        if lab is not None:
            out.append(f"labels/{split.name}/{lab.name}")
    return out


def copy_split(split: YoloSplit, out: Path, temp_prefix: str) -> dict:
    """The images of ``split`` and their label files, unchanged, into ``out/images/<name>`` and
    ``out/labels/<name>`` (:func:`place_file`). Returns counts by kind."""
    counts = {"images": 0, "labels": 0, "linked": 0, "copied": 0, "kept": 0}
    for img, lab in split_files(split):
        counts[place_file(img, out / "images" / split.name / img.name, temp_prefix)] += 1
        counts["images"] += 1
        if lab is not None:
            counts[place_file(lab, out / "labels" / split.name / lab.name, temp_prefix)] += 1
            counts["labels"] += 1
    return counts


def data_yaml_text(out: Path, names, augmented: str, others: list[str]) -> str:
    """Ultralytics ``data.yaml``: ``train`` the augmented split, each other split under its own key (``val``
    the augmented split when there is no other: Ultralytics requires one), ``names`` by class index."""
    data: dict = {"path": str(out.resolve()), "train": f"images/{augmented}"}
    for name in others:
        data[name if name in SPLIT_KEYS and name != "train" else f"split_{name}"] = f"images/{name}"
    note = ""
    if "val" not in data:
        data["val"] = f"images/{augmented}"
        note = "# no validation split in the input: val is the augmented split\n"
    data["names"] = {i: n for i, n in enumerate(names)}
    head = f"# aias-augment: split {augmented!r} augmented (report.json); the others copied unchanged\n"
    return head + note + yaml.safe_dump(data, sort_keys=False, allow_unicode=True)


def other_splits(dataset: YoloDataset | None, split: str) -> list[YoloSplit]:
    return [s for s in (dataset.splits if dataset else ()) if s.name != split]


def write_yolo(
    out: Path,
    records: list[dict],
    names: list[str],
    label_of,
    split: str,
    dataset: YoloDataset | None,
    temp_prefix: str,
) -> dict:
    """``labels/<split>/<stem>.txt`` of every written record (boxes in the record's order, class index in
    ``names`` of ``label_of(label, inserted)``), the dataset's other splits copied (:func:`copy_split`) and
    ``data.yaml``. Returns what report.json says of it."""
    index = {n: i for i, n in enumerate(names)}
    for rec in records:
        stem = Path(rec["file_name"]).stem
        ids = [index[label_of(lab, ins)] for lab, ins in zip(rec["labels"], rec["inserted"])]
        text = yolo_label_text(rec["boxes"], ids, rec["width"], rec["height"])
        write_text(out / "labels" / split / f"{stem}.txt", text, temp_prefix)
    others = other_splits(dataset, split)
    copied = {s.name: copy_split(s, out, temp_prefix) for s in others}
    for name, c in copied.items():
        log.info("split %s copied unchanged: %d images, %d label files", name, c["images"], c["labels"])
    write_text(out / "data.yaml", data_yaml_text(out, names, split, [s.name for s in others]), temp_prefix)
    return {"augmented_split": split, "copied_splits": copied, "names": list(names)}
