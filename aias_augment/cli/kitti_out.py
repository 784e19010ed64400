"""``--export-3d kitti``: KITTI-3D labels of the inserted objects beside an offline run's output.

``kitti/label_2/<stem>.txt`` holds one line per inserted, labelled object (:func:`aias_augment.core.kitti3d.label_line`:
its 3D box from the record's placement, its 2D box the visible-mask box of the other outputs) and a ``DontCare`` line
per object of the input (no 3D box is known for those); ``kitti/calib/<stem>.txt`` the image's camera
(``P2 = [K | 0]``); ``kitti/image_2/<stem>.<ext>`` the output image (a hard link when possible, else a copy).
"""

from __future__ import annotations

import logging
from collections import Counter
from pathlib import Path

from aias_augment.cli.yolo_io import place_file, write_text
from aias_augment.core.kitti3d import (
    box_from_pose,
    calib_text,
    dontcare_line,
    label_line,
    occlusion_level,
    truncation,
)

log = logging.getLogger(__name__)


def _xyxy(box_xywh) -> list[float]:
    x, y, w, h = (float(v) for v in box_xywh)
    return [x, y, x + w, y + h]


def record_lines(rec: dict, label_of) -> tuple[list[str], Counter, float]:
    """The label_2 lines of one record, counts by kind (objects, dontcare, and objects left as DontCare for want of
    a 3D box) and the largest tilt from upright (degrees) of its boxes."""
    counts: Counter = Counter()
    lines, tilt = [], 0.0
    for box, ins in zip(rec["boxes"], rec["inserted"]):
        if not ins:
            lines.append(dontcare_line(_xyxy(box)))
            counts["dontcare"] += 1
    for p, a in zip(rec["placements"], rec["annotations"]):
        if a["visible_box_xywh"] is None or a.get("decoy") or p.get("decoy"):
            continue
        if not p.get("box_in_object_m"):
            lines.append(dontcare_line(_xyxy(a["visible_box_xywh"])))
            counts["no 3D box in the record (DontCare)"] += 1
            continue
        box3d = box_from_pose(p["cam_from_object"], p["box_in_object_m"])
        tilt = max(tilt, box3d.tilt_deg)
        type_name = "_".join(str(label_of(p["category"])).split())
        trunc = truncation(p["amodal_box_xyxy"], rec["width"], rec["height"])
        lines.append(
            label_line(type_name, box3d, _xyxy(a["visible_box_xywh"]), trunc, occlusion_level(a["visibility"]))
        )
        counts["objects"] += 1
    return lines, counts, tilt


def kitti_paths(image_name: str) -> list[str]:
    """The paths (relative to ``out``) written for the output image ``images/<image_name>``."""
    stem, name = Path(image_name).stem, Path(image_name).name
    return [f"kitti/label_2/{stem}.txt", f"kitti/calib/{stem}.txt", f"kitti/image_2/{name}"]


def write_kitti(out: Path, records: list[dict], label_of, temp_prefix: str) -> dict:
    """``kitti/{label_2,calib,image_2}`` of every written record (:func:`kitti_paths`). A record without the
    camera (``camera_K``) is left out and counted. Returns report.json's account."""
    root = out / "kitti"
    counts: Counter = Counter()
    max_tilt = 0.0
    for rec in records:
        stem = Path(rec["file_name"]).stem
        if rec.get("camera_K") is None:
            counts["images without the camera in the record (left out)"] += 1
            continue
        lines, c, tilt = record_lines(rec, label_of)
        counts.update(c)
        max_tilt = max(max_tilt, tilt)
        write_text(root / "label_2" / f"{stem}.txt", "".join(line + "\n" for line in lines), temp_prefix)
        write_text(root / "calib" / f"{stem}.txt", calib_text(rec["camera_K"]), temp_prefix)
        place_file(out / "images" / rec["file_name"], root / "image_2" / Path(rec["file_name"]).name, temp_prefix)
        counts["images"] += 1
    if max_tilt > 1.0:
        log.warning(
            "kitti: boxes up to %.1f deg from upright in the camera frame (a tilted ground or camera): the devkit's "
            "upright boxes are approximate there",
            max_tilt,
        )
    return {**dict(sorted(counts.items())), "max_tilt_deg": round(max_tilt, 3)}
