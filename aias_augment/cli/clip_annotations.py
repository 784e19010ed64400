"""A clip's annotations: the inserted objects' tracks and the clip's own labelled tracks, as COCO-video and MOT.

* COCO-video (``annotations.json``): one video; each image its ``video_id``, ``frame_id`` (0-based in the output)
  and ``frame_index`` (in the input); each annotation its ``track_id`` and ``visibility`` (visible / amodal pixels
  for an inserted object; for a labelled one the fraction of its box the inserted objects leave uncovered).
  Inserted objects: ``inserted: true``, the visible box, the visible mask as RLE, ``amodal_bbox``. Labelled
  objects: ``inserted: false``, their own box and class as given.
* MOTChallenge (``mot.txt``): ten columns, frames from 1, pixels from 1 (:mod:`aias_augment.core.track_labels`);
  labelled rows keep their box and conf, inserted ones conf 1.

Track ids: the labelled tracks keep theirs; the inserted objects take the ids after the largest of them, so the two
never collide.
"""

from __future__ import annotations

from dataclasses import dataclass

from aias_augment.apply.annotate import encode_rle
from aias_augment.core.coco_io import CocoBuilder
from aias_augment.core.track_labels import mot_line

__all__ = ["ClipAnnotations", "clip_annotations", "inserted_track_offset", "visibility_table"]


@dataclass
class ClipAnnotations:
    coco: dict
    mot_lines: list[str]
    boxes: list[list]  # per frame, the boxes drawn on the side-by-side video
    labels: list[list[str]]  # their labels
    inserted: list[list[bool]]  # whether each is inserted


def inserted_track_offset(labels: list[list] | None) -> int:
    """The inserted objects' track ids start after this: the largest labelled track id (0 without labels)."""
    return max((b.track_id for boxes in labels or [] for b in boxes), default=0)


def clip_annotations(
    video: dict, names: list[str], idx, results, categories: list[str], labels=None, labels_visibility=None
) -> ClipAnnotations:
    """The clip's COCO-video dataset and MOT lines (see the module docstring). ``video``: the COCO-video entry
    (name, width, height, fps); ``results``: one ClipInsertion per inserted object, ``categories`` theirs;
    ``labels``/``labels_visibility``: per frame the labelled boxes and their visibility, or None."""
    inserted_cats = list(dict.fromkeys(categories))
    coco = CocoBuilder({c: j + 1 for j, c in enumerate(inserted_cats)})
    coco.videos.append({"id": 1, **video})
    offset = inserted_track_offset(labels)
    out = ClipAnnotations({}, [], [], [], [])
    w, h = video["width"], video["height"]
    for i, name in enumerate(names):
        image_id = coco.add_image(f"frames/{name}.jpg", w, h, frame_index=int(idx[i]), video_id=1, frame_id=i)
        boxes, texts, flags = [], [], []
        for b, vis in zip(labels[i] if labels else [], labels_visibility[i] if labels else []):
            coco.add_box(image_id, b.category, b.box_xywh, track_id=b.track_id, visibility=round(float(vis), 4))
            out.mot_lines.append(mot_line(i, b.track_id, b.box_xywh, b.conf))
            boxes.append(b.box_xywh), texts.append(f"{b.category} {b.track_id}"), flags.append(False)
        for k, (r, cat) in enumerate(zip(results, categories)):
            box = r.boxes_xywh[i]
            if box is None:
                continue
            visible = r.masks[i] > 0.5
            coco.add_box(
                image_id,
                cat,
                box,
                segmentation=encode_rle(visible),
                area=float(visible.sum()),
                inserted=True,
                track_id=offset + k + 1,
                amodal_bbox=[float(v) for v in r.amodal_boxes_xywh[i]],
                visibility=round(float(r.visibilities[i]), 4),
            )
            out.mot_lines.append(mot_line(i, offset + k + 1, box))
            boxes.append(box), texts.append(cat), flags.append(True)
        out.boxes.append(boxes), out.labels.append(texts), out.inserted.append(flags)
    out.coco = coco.to_dict()
    return out


def visibility_table(labels, visibility) -> list[dict]:
    """Per labelled track: frames, frames in which an inserted object covers part of it, least visibility."""
    tracks: dict[int, dict] = {}
    for boxes, vis in zip(labels, visibility):
        for b, v in zip(boxes, vis):
            t = tracks.setdefault(b.track_id, {"track_id": b.track_id, "category": b.category, "frames": 0})
            t["frames"] += 1
            t["covered_frames"] = t.get("covered_frames", 0) + int(v < 1.0)
            t["min_visibility"] = round(float(min(t.get("min_visibility", 1.0), v)), 4)
    return [tracks[k] for k in sorted(tracks)]
