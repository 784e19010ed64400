"""The clip command's writers: the augmented frames, the COCO-video and MOT annotations, the side-by-side video,
the contact sheet and the record of one clip (:func:`write_clip`), each file atomically through
:class:`~aias_augment.cli.clip_output.ClipOutput`."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from aias_augment.cli.clip_output import ClipOutput
from aias_augment.core.report import skipped_stages
from aias_augment.core.viz import contact_sheet, draw_boxes
from aias_augment.pipeline.clip_objects import RenderedClip

if TYPE_CHECKING:
    from aias_augment.cli.clip_job import ClipInputs, ClipJob


def job_dict(job: ClipJob) -> dict:
    """``job`` as JSON-able values (tuples as lists), as the record and the manifest keep it."""
    return json.loads(json.dumps(dataclasses.asdict(job)))


def write_clip(output: ClipOutput, job: ClipJob, inputs: ClipInputs, clip: RenderedClip) -> dict:
    """Write the frames, the COCO-video and MOT annotations, the side-by-side video, the contact sheet and the
    record through ``output`` (each file atomically); returns the record."""
    from aias_augment.cli.clip_annotations import clip_annotations, inserted_track_offset
    from aias_augment.core.coco_io import load_coco

    names, idx, intr = inputs.names, inputs.idx, clip.intrinsics
    h, w = inputs.frames[0].shape[:2]
    video = {"name": Path(job.input).name, "width": w, "height": h, "fps": job.fps}
    cats = [c for c, _ in clip.objects]
    ann = clip_annotations(video, names, idx, clip.results, cats, inputs.labels, clip.labels_visibility)
    drawn = []
    for i, (name, img) in enumerate(zip(names, clip.frames)):
        output.write_image(f"frames/{name}.jpg", img)
        drawn.append(draw_boxes(img, ann.boxes[i], ann.labels[i], inserted=ann.inserted[i]))
    output.write_json("annotations.json", ann.coco, check=load_coco)  # pycocotools validates
    output.write_bytes("mot.txt", "".join(line + "\n" for line in ann.mot_lines).encode())
    output.write_with("side_by_side.mp4", lambda p: _write_side_by_side(p, inputs.frames, drawn, job.fps))
    picks = np.unique(np.linspace(0, len(drawn) - 1, min(6, len(drawn))).astype(int))
    output.write_image(
        "contact_sheet.jpg", contact_sheet([drawn[i] for i in picks], cols=3, titles=[names[i] for i in picks])
    )
    res = clip.results[0]
    offset = inserted_track_offset(inputs.labels)
    record = {
        "job": {k: v for k, v in job_dict(job).items() if k != "out"},  # the folder may move: not part of it
        "category": clip.objects[0][0],
        "asset": clip.objects[0][1].name,
        "asset_source": clip.objects[0][1].source,
        "asset_height_m": float(clip.objects[0][1].height_m),
        "frames": len(names),
        "frame_indices": idx.tolist(),
        "intrinsics": [intr.fx, intr.fy, intr.cx, intr.cy, w, h],
        "world_from_object": res.world_from_object.tolist(),
        "contact_in_world": res.contact_in_world.tolist(),
        "layer_params": clip.layer_params[0],
        "visible_frames": int(sum(b is not None for b in res.boxes_xywh)),
        "objects": [
            {
                "track_id": offset + k + 1,
                "category": cat,
                "asset": a.name,
                "asset_source": a.source,  # procedural: asset_meta["seed"] rebuilds the family member
                "asset_meta": a.meta,
                "asset_height_m": float(a.height_m),
                "world_from_object": r.world_from_object.tolist(),
                "contact_in_world": r.contact_in_world.tolist(),
                "layer_params": clip.placed_params[k],
                "draws": clip.draws[k],
                "topple": clip.plans[k].topple,
                "visible_frames": int(sum(b is not None for b in r.boxes_xywh)),
            }
            for k, ((cat, a), r) in enumerate(zip(clip.objects, clip.results))
        ],
        "skipped_objects": clip.skipped_objects,
        **({} if inputs.labels is None else {"labels": _labels_record(job, inputs, clip)}),
        **({} if clip.sun is None else {"sun": clip.sun}),
        **({"frame_params": clip.frame_params} if clip.frame_params else {}),  # the stage list's frame stages
        "modules": clip.notes,
        "skipped_stages": skipped_stages(clip.notes),
    }
    output.write_json("record.json", record)
    return record


def _labels_record(job: ClipJob, inputs: ClipInputs, clip: RenderedClip) -> dict:
    from aias_augment.cli.clip_annotations import visibility_table
    from aias_augment.core.track_labels import detect_format

    return {
        "format": job.labels_format or detect_format(job.labels),
        "boxes": sum(len(b) for b in inputs.labels),
        "outside_clip": inputs.labels_outside,
        "occluder_masks": clip.occluders,
        "tracks": visibility_table(inputs.labels, clip.labels_visibility),
    }


def _write_side_by_side(path: Path, originals: list[np.ndarray], augmented: list[np.ndarray], fps: float) -> None:
    """Original | augmented, one row per frame, as an mp4."""
    h, w = originals[0].shape[:2]
    scale = min(1.0, 960 / (2 * w))
    size = (int(2 * w * scale) // 2 * 2, int(h * scale) // 2 * 2)
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    if not writer.isOpened():
        raise OSError(f"cannot open a video writer for {path}")
    try:
        for a, b in zip(originals, augmented):
            pair = cv2.resize(np.concatenate([a, b], 1), size, interpolation=cv2.INTER_AREA)
            writer.write(np.ascontiguousarray(pair[..., ::-1]))
    finally:
        writer.release()
