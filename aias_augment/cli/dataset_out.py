"""The output dataset in the user's format: which class the inserted objects are labelled as, which image format,
which layout (COCO, or YOLO in the Ultralytics layout), and the 3D labels.

- Labels: ``--label-as CATEGORY=CLASS`` labels an inserted category as one of the user's classes; without it, an
  input class that the project's taxonomy (``configs/taxonomy.yaml``, a category's ``names``) reads as an inserted
  category (``cone`` for ``traffic_cone``) is used for it. Records keep the project's category (replay needs it);
  the written labels are the user's.
- Images: ``keep`` writes a JPEG input as JPEG (at ``jpeg_quality``) and anything else as PNG; ``png`` is
  lossless. Re-encoding a JPEG changes the pixels that the insertion did not touch (by the codec's loss).
- Layouts: ``annotations.json`` (COCO) is always written; ``yolo`` adds ``labels/<split>/*.txt``, the input's other
  splits copied unchanged and ``data.yaml`` (:mod:`aias_augment.cli.yolo_io`); ``kitti`` 3D labels go to ``kitti/``
  (:mod:`aias_augment.cli.kitti_out`).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from aias_augment.adapters.boundary import InputError
from aias_augment.cli.manifest import FINAL_OUTPUTS, TEMP_TAG, write_file
from aias_augment.cli.yolo_io import YoloDataset, copied_paths, other_splits, write_yolo

log = logging.getLogger(__name__)
JPEG_SUFFIXES = (".jpg", ".jpeg")


@dataclass(frozen=True)
class ImageOut:
    """How output images are written: ``format`` "keep" (the input's: JPEG stays JPEG, the rest PNG), "png" or
    "jpg"; ``jpeg_quality`` 1..100; ``subdir`` the folder under ``images/`` (a YOLO split)."""

    format: str = "png"
    jpeg_quality: int = 95
    subdir: str = ""

    def __post_init__(self):
        if self.format not in ("keep", "png", "jpg"):
            raise InputError(f"--image-format {self.format!r}: keep, png or jpg")
        if not 1 <= int(self.jpeg_quality) <= 100:
            raise InputError(f"--jpeg-quality {self.jpeg_quality}: give 1..100 (95 keeps most detail)")

    def suffix(self, source: str) -> str:
        jpeg = self.format == "jpg" or (self.format == "keep" and Path(source).suffix.lower() in JPEG_SUFFIXES)
        return ".jpg" if jpeg else ".png"

    def file_name(self, index: int, source: str) -> str:
        """The image's name under ``images/``: ``[<subdir>/]<index>_<input stem><suffix>``."""
        name = f"{index:06d}_{Path(source).stem}{self.suffix(source)}"
        return f"{self.subdir}/{name}" if self.subdir else name

    def write(self, path: Path, image_rgb: np.ndarray, temp_prefix: str = TEMP_TAG) -> None:
        """Write atomically (:func:`aias_augment.cli.manifest.write_file`); JPEG at ``jpeg_quality``."""
        params = [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg_quality)] if path.suffix == ".jpg" else []
        ok, data = cv2.imencode(path.suffix, cv2.cvtColor(np.ascontiguousarray(image_rgb), cv2.COLOR_RGB2BGR), params)
        if not ok:
            raise OSError(f"cannot encode {path.name}")

        def put(tmp: Path) -> None:
            with open(tmp, "xb") as f:
                f.write(data.tobytes())

        write_file(path, temp_prefix, put)


@dataclass(frozen=True)
class LabelAs:
    """An inserted ``category`` written as ``label``, and why (``"--label-as"``, ``"--categories"`` or
    ``"taxonomy synonym"``)."""

    category: str
    label: str
    why: str


@dataclass(frozen=True)
class DatasetOutput:
    """What an offline run writes besides its records: the layout (``format`` "coco" or "yolo"), the images, the
    labels of inserted categories, the YOLO input (its other splits are copied) and ``export_3d`` (None or
    "kitti")."""

    format: str = "coco"
    image: ImageOut = field(default_factory=ImageOut)
    label_as: tuple[LabelAs, ...] = ()
    yolo_input: YoloDataset | None = None
    split: str = "train"
    export_3d: str | None = None

    def __post_init__(self):
        if self.format not in ("coco", "yolo"):
            raise InputError(f"--format {self.format!r}: coco or yolo")
        if self.export_3d not in (None, "kitti"):
            raise InputError(f"--export-3d {self.export_3d!r}: kitti")

    def label(self, category: str, inserted: bool = True) -> str:
        """The written label of a box: an inserted category as the user's class, the user's labels unchanged."""
        if inserted:
            for m in self.label_as:
                if m.category == category:
                    return m.label
        return category

    def manifest(self) -> dict:
        """What the run key holds of it (another layout, image format or label map is another run)."""
        return {
            "format": self.format,
            "image": [self.image.format, self.image.jpeg_quality, self.image.subdir],
            "label_as": [[m.category, m.label] for m in self.label_as],
            "split": self.split,
            "export_3d": self.export_3d,
        }

    def report(self) -> dict:
        """report.json's account of the labels and images."""
        return {
            "format": self.format,
            "image_format": self.image.format,
            "jpeg_quality": self.image.jpeg_quality,
            "labels": {m.category: {"as": m.label, "why": m.why} for m in self.label_as},
        }


def _key(name: str) -> str:
    return " ".join(re.sub(r"[_\-]+", " ", name).strip().lower().split())


def taxonomy_category(name: str, known) -> str | None:
    """The project category that ``name`` means: itself when known, else the taxonomy category whose ``names``
    (whole-name regular expressions) match it (``_`` and ``-`` read as spaces, case ignored); None otherwise."""
    if name in known:
        return name
    from aias_augment.assets.bank.taxonomy import load_taxonomy

    key = _key(name)
    for cat, spec in load_taxonomy().categories.items():
        if key == _key(cat) or any(re.fullmatch(pat, key, re.IGNORECASE) for pat in spec.names):
            return cat
    return None


def canonical_categories(requested, known) -> tuple[tuple[str, ...], tuple[LabelAs, ...]]:
    """``--categories`` in the project's names: a name the taxonomy reads as a category (``cone``) becomes that
    category, labelled as the name the user gave. Names nothing matches are kept (the caller's check names them)."""
    cats, label_as = [], []
    for name in requested:
        cat = taxonomy_category(name, known) or name
        cats.append(cat)
        if cat != name:
            label_as.append(LabelAs(cat, name, "--categories"))
            log.info("--categories %s: inserting %s (the taxonomy's name for it), labelled %s", name, cat, name)
    return tuple(dict.fromkeys(cats)), tuple(label_as)


def resolve_label_as(specs, inserted, user_names, known, given: tuple[LabelAs, ...] = ()) -> tuple[LabelAs, ...]:
    """The label of each inserted category: ``--label-as CATEGORY=CLASS`` first (the category by its project name
    or a taxonomy synonym of one, InputError otherwise), then ``given`` (from :func:`canonical_categories`), then
    an input class the taxonomy reads as the category, when the input has no class of the category's own name."""
    out: dict[str, LabelAs] = {}
    for spec in specs or ():
        cat, sep, label = (s.strip() for s in spec.partition("="))
        if not sep or not cat or not label:
            raise InputError(f"--label-as {spec!r}: expected CATEGORY=CLASS, e.g. traffic_cone=cone")
        canon = taxonomy_category(cat, known)
        if canon not in inserted:
            raise InputError(f"--label-as {spec}: {cat!r} is not an inserted category; inserted: {list(inserted)}")
        if label not in (user_names or ()):
            log.info("--label-as %s: %r is not a class of the input; it is added as a new class", spec, label)
        out[canon] = LabelAs(canon, label, "--label-as")
    for m in given:
        out.setdefault(m.category, m)
    for cat in inserted:
        if cat in out or cat in (user_names or ()):
            continue
        for name in user_names or ():
            if taxonomy_category(name, ()) == cat:
                out[cat] = LabelAs(cat, name, "taxonomy synonym")
                log.info(
                    "inserted %s labelled as the input's class %r (a synonym in configs/taxonomy.yaml; "
                    "--label-as %s=NAME to choose another)",
                    cat,
                    name,
                    cat,
                )
                break
    return tuple(out[c] for c in inserted if c in out)


def written_records(records: list[dict]) -> list[dict]:
    """The records whose image went into the dataset (not skipped, no failed output check)."""
    return [r for r in records if "skipped" not in r and "output_errors" not in r]


def planned_outputs(sources, output: DatasetOutput) -> list[str]:
    """Every path (relative to ``out``) a run over ``sources`` (input paths, in order) may write with ``output``:
    records, images, the final files, the manifest, and the layouts' files (labels, copied splits, data.yaml,
    kitti/)."""
    from aias_augment.cli.kitti_out import kitti_paths

    paths = []
    for i, s in enumerate(sources):
        name = output.image.file_name(i, s)
        paths += [f"records/{i:06d}.json", f"images/{name}"]
        if output.format == "yolo":
            paths.append(f"labels/{output.split}/{Path(name).stem}.txt")
        if output.export_3d == "kitti":
            paths += kitti_paths(name)
    if output.format == "yolo":
        paths.append("data.yaml")
        for split in other_splits(output.yolo_input, output.split):
            paths += copied_paths(split)
    return [*paths, *FINAL_OUTPUTS, "manifest.json"]


def write_outputs(
    out: Path, records: list[dict], output: DatasetOutput, categories: dict[str, int], temp_prefix: str = TEMP_TAG
) -> dict:
    """The layouts beyond ``annotations.json``: YOLO (class index = rank of the category id, so a YOLO input's
    classes keep their indices) and the 3D labels. Returns report.json's ``output`` section."""
    report = output.report()
    done = written_records(records)
    if output.format == "yolo":
        names = [n for n, _ in sorted(categories.items(), key=lambda t: t[1])]
        report["yolo"] = write_yolo(out, done, names, output.label, output.split, output.yolo_input, temp_prefix)
    if output.export_3d == "kitti":
        from aias_augment.cli.kitti_out import write_kitti

        report["kitti"] = write_kitti(out, done, output.label, temp_prefix)
    return report


def add_output_arguments(ap) -> None:
    """The output-format options of ``aias-augment`` (images and datasets)."""
    g = ap.add_argument_group("output dataset")
    g.add_argument(
        "--format",
        choices=("coco", "yolo"),
        default=None,
        help="the output's layout (default: the input's): coco (annotations.json) or yolo (the Ultralytics "
        "layout: images/<split>, labels/<split>, data.yaml with your class names; annotations.json beside it)",
    )
    g.add_argument(
        "--label-as",
        nargs="+",
        metavar="CATEGORY=CLASS",
        default=None,
        help="label an inserted category as your class (e.g. traffic_cone=cone); without it, an input class the "
        "taxonomy knows as the category's synonym is used (said in report.json)",
    )
    g.add_argument(
        "--image-format",
        choices=("keep", "png", "jpg"),
        default="keep",
        help="keep: JPEG in, JPEG out (at --jpeg-quality), else PNG; png: lossless. Re-encoding a JPEG also "
        "changes the pixels the insertion left untouched",
    )
    g.add_argument("--jpeg-quality", type=int, default=95, help="JPEG quality of written JPEGs (1..100)")
    g.add_argument(
        "--split",
        default=None,
        help="--yolo: the split to augment (default train); the others are copied unchanged and data.yaml "
        "trains on this one. --format yolo from another input: the split's name (default train)",
    )
    g.add_argument(
        "--export-3d",
        choices=("kitti",),
        default=None,
        help="also write KITTI-3D labels of the inserted objects (kitti/label_2, calib, image_2)",
    )


def output_from_args(a, inserted, user_names, known, given: tuple[LabelAs, ...], yolo_input) -> DatasetOutput:
    """The run's :class:`DatasetOutput` from the parsed options, the inserted categories, the input's class names
    (in order), the known categories, the labels :func:`canonical_categories` gave and the YOLO input (if any)."""
    fmt = a.format or ("yolo" if yolo_input is not None else "coco")
    if a.split is not None and yolo_input is None and fmt != "yolo":
        raise InputError(f"--split {a.split}: for --yolo inputs or --format yolo")
    split = yolo_input.split(a.split).name if yolo_input is not None else (a.split or "train")
    if fmt == "yolo":
        dup = sorted({n for n in user_names if list(user_names).count(n) > 1})
        if dup:
            raise InputError(f"class names {dup} appear twice: a YOLO class index would be ambiguous")
        if any(ch in split for ch in "/\\") or split in ("", ".", ".."):
            raise InputError(f"--split {split!r}: a plain folder name, e.g. train")
    if yolo_input is not None:  # the splits copied into --out too: it may hold none of them
        from aias_augment.cli.manifest import check_out_apart

        check_out_apart(
            a.out, [(f"--yolo {s.name} {kind}", str(d)) for s in yolo_input.splits for kind, d in _folders(s)]
        )
    label_as = resolve_label_as(a.label_as, tuple(inserted), tuple(user_names), known, given)
    return DatasetOutput(
        fmt,
        ImageOut(a.image_format, a.jpeg_quality, split if fmt == "yolo" else ""),
        label_as,
        yolo_input,
        split,
        a.export_3d,
    )


def yolo_names_from_rows(items) -> list[str]:
    """Class names "0".."n-1" for a YOLO input that names none (n: one more than its largest class index)."""
    ids = [int(float(r[0])) for it in items for r in it.meta.get("yolo_rows", [])]
    return [str(i) for i in range(max(ids, default=-1) + 1)]


def _folders(split) -> list[tuple[str, Path]]:
    return [("images", split.images), ("labels", split.labels)]
