#!/usr/bin/env python
"""Temporal consistency of inserted clips: flicker, box jitter and whether a detector keeps finding the object.

Three clips through ``aias-augment``'s clip path (``aias_augment.cli.clip.augment_clip``):

- ``posed``: KITTI 06, 20 frames with its published poses, a standing cone (lit by one fused sun).
- ``static``: the static-camera clip ``video/vtest.avi`` without poses (40 frames, stride 3), a standing cone.
- ``static, moving``: the same clip, a car driving through at 2 m/s.
- ``static, 3 objects``: the same clip with three standing cones (``--objects 3``), each scored as its own track
  (they may hide each other).

Per clip, over consecutive frames where the object shows at least 100 visible pixels in both:

- **flicker ratio**: median |change of log mean luminance| of the object's visible pixels (the output frame)
  divided by the same for the real background in a 15 px ring around it (the input frame). 1: the object's
  brightness changes as its surroundings do; above 1: it flickers.
- **colour change**: median |change| of the object's log R/G and log B/G (the colour transform is one per clip).
- **box jitter** (standing objects): the visible box's bottom centre minus the projection of the object's world
  contact point through the frame's pose (the camera's motion removed), its median frame-to-frame change in pixels,
  over frames where the amodal box lies fully in the image.
- **detector share**: the share of frames in which a detector trained on real cones (``--weights``, e.g.
  ``detection-eval train --config lite0_320_c --data $AIAS_DATA/tracon --split train``) finds the inserted cone
  (score >= 0.3, IoU >= 0.5 with its visible box). Cone clips only.

    python -m studies.video.temporal --weights runs/detector_real_s0/weights.pt --out studies/video/temporal/result
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

import cv2
import numpy as np

from aias_augment.cli.clip import ClipJob, augment_clip, read_cams_from_world, read_clip_frames
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics


def _lum(rgb: np.ndarray) -> np.ndarray:
    x = rgb.astype(np.float64) / 255.0
    lin = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    return lin


def clip_metrics(out: Path, inputs: list[np.ndarray], poses: np.ndarray | None, model=None, track: int = 1) -> dict:
    """The figures of the module docstring for one object (``track``) of a clip written by ``augment_clip``."""
    from pycocotools import mask as mask_utils

    coco = json.loads((out / "annotations.json").read_text())
    rec = json.loads((out / "record.json").read_text())
    by_image = {
        a["image_id"]: a for a in coco["annotations"] if a.get("inserted", True) and a.get("track_id", 1) == track
    }
    frames = sorted(coco["images"], key=lambda im: im["frame_id"])
    fx, fy, cx, cy, w, h = rec["intrinsics"]
    K = Intrinsics(fx, fy, cx, cy, int(w), int(h)).K
    contact = np.asarray(rec["objects"][track - 1]["contact_in_world"], float)
    moving = rec["job"].get("object_speed_mps", 0.0) > 0
    stats = []  # per frame: log lum obj, log lum ring, log R/G, log B/G, residual (2,), box, found
    ring_kernel = np.ones((31, 31), np.uint8)
    for k, im in enumerate(frames):
        a = by_image.get(im["id"])
        if a is None:
            stats.append(None)
            continue
        m = mask_utils.decode(a["segmentation"]).astype(bool)
        if m.sum() < 100:
            stats.append(None)
            continue
        outf = cv2.cvtColor(cv2.imread(str(out / im["file_name"])), cv2.COLOR_BGR2RGB)
        ring = cv2.dilate(m.astype(np.uint8), ring_kernel).astype(bool) & ~m
        o = _lum(outf[m]).mean(axis=0)
        r = _lum(inputs[k][ring]).mean(axis=0)
        lum = lambda c: 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]  # noqa: E731
        x, y, bw, bh = a["bbox"]
        box = (x, y, x + bw, y + bh)
        ax, ay, aw, ah = a["amodal_bbox"]
        residual = None
        if poses is not None and not moving and ax >= 0 and ay >= 0 and ax + aw <= w and ay + ah <= h:
            pc = poses[k][:3, :3] @ contact + poses[k][:3, 3]
            uv = (K @ pc)[:2] / pc[2]
            residual = np.array([x + bw / 2 - uv[0], y + bh - uv[1]])
        found = None
        if model is not None:
            import torch

            from detection_eval.boxes import box_iou
            from detection_eval.inference import predict_images

            net, cfg = model
            det = predict_images(net, [outf], net.cfg.train.img_size, cfg)[0]
            found = len(det["boxes"]) > 0 and bool(
                (
                    box_iou(
                        torch.as_tensor(det["boxes"], dtype=torch.float64), torch.tensor([box], dtype=torch.float64)
                    )
                    >= 0.5
                ).any()
            )
        stats.append(
            {
                "lum": np.log(lum(o) + 1e-6),
                "ring": np.log(lum(r) + 1e-6),
                "rg": np.log((o[0] + 1e-6) / (o[1] + 1e-6)),
                "bg": np.log((o[2] + 1e-6) / (o[1] + 1e-6)),
                "residual": residual,
                "found": found,
            }
        )
    d_obj, d_ring, d_rg, d_bg, jitter = [], [], [], [], []
    for s0, s1 in zip(stats[:-1], stats[1:]):
        if s0 is None or s1 is None:
            continue
        d_obj.append(abs(s1["lum"] - s0["lum"]))
        d_ring.append(abs(s1["ring"] - s0["ring"]))
        d_rg.append(abs(s1["rg"] - s0["rg"]))
        d_bg.append(abs(s1["bg"] - s0["bg"]))
        if s0["residual"] is not None and s1["residual"] is not None:
            jitter.append(float(np.linalg.norm(s1["residual"] - s0["residual"])))
    seen = [s for s in stats if s is not None]
    found = [s["found"] for s in seen if s["found"] is not None]
    med = lambda v: round(float(np.median(v)), 4) if v else None  # noqa: E731
    return {
        "frames": len(frames),
        "object_frames": len(seen),
        "pairs": len(d_obj),
        "object_dlog_luminance": med(d_obj),
        "ring_dlog_luminance": med(d_ring),
        "flicker_ratio": round(float(np.median(d_obj) / max(np.median(d_ring), 1e-4)), 2) if d_obj else None,
        "object_dlog_rg": med(d_rg),
        "object_dlog_bg": med(d_bg),
        "box_jitter_px": med(jitter),
        "box_jitter_pairs": len(jitter),
        "detector_share": round(float(np.mean(found)), 3) if found else None,
        "detector_frames": len(found),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("studies/video/temporal/result"))
    ap.add_argument("--work", type=Path, default=Path("out/temporal"))
    ap.add_argument("--weights", type=Path, default=None, help="a detector trained on real cones (detector share)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--clips", nargs="*", default=None, help="only these clips; the others kept from OUT/temporal.json")
    a = ap.parse_args(argv)
    root = data_root()
    seq, tripod = root / "kitti06_seq", root / "video" / "vtest.avi"
    vtest = dict(max_frames=40, stride=3, camera_height_m=8.0, fps=8.0)  # a first-floor camera, 8 frames/s as read
    jobs = {
        "posed": ClipJob(
            str(seq / "image_l"),
            str(seq / "calib.txt"),
            str(seq / "poses.txt"),
            str(a.work / "posed"),
            ("traffic_cone",),
            a.seed,
            max_frames=20,
        ),
        "static": ClipJob(str(tripod), None, None, str(a.work / "static"), ("traffic_cone",), a.seed, **vtest),
        "static, moving": ClipJob(
            str(tripod), None, None, str(a.work / "static_moving"), ("car",), a.seed, object_speed_mps=2.0, **vtest
        ),
        "static, 3 objects": ClipJob(
            str(tripod), None, None, str(a.work / "static_3"), ("traffic_cone",), a.seed, objects=3, **vtest
        ),
        # the posed clip's frames without their poses: estimated by stereo odometry from the right camera
        "unposed (stereo odometry)": ClipJob(
            str(seq / "image_l"),
            str(seq / "calib.txt"),
            None,
            str(a.work / "unposed"),
            ("traffic_cone",),
            a.seed,
            max_frames=20,
            stereo_right=str(seq / "image_r"),
        ),
    }
    unknown = set(a.clips or ()) - set(jobs)
    if unknown:
        ap.error(f"unknown clips {sorted(unknown)}; known: {sorted(jobs)}")
    model = None
    if a.weights is not None:
        import dataclasses

        from detection_eval.train import load_checkpoint

        net, _, _ = load_checkpoint(a.weights)
        model = (net, dataclasses.replace(net.cfg.inference, score_threshold=0.3))
    report = {"command": "python -m studies.video.temporal " + shlex.join(argv or sys.argv[1:]), "clips": {}}
    if a.clips is not None and (a.out / "temporal.json").exists():
        old = json.loads((a.out / "temporal.json").read_text())
        report["clips"] = {k: v for k, v in old["clips"].items() if not any(k.startswith(c) for c in a.clips)}
        report["command"] = old["command"] + "; then " + report["command"]
    for name, job in jobs.items():
        if a.clips is not None and name not in a.clips:
            continue
        rec = augment_clip(job)
        inputs, _ = read_clip_frames(job.input, job.start, job.max_frames, job.stride)
        if job.poses is not None or job.stereo_right is not None:  # camera motion removed with the published poses
            poses = np.asarray(read_cams_from_world(seq / "poses.txt" if job.poses is None else job.poses))
            poses = poses[job.start : job.start + len(inputs)]
        else:
            poses = np.repeat(np.eye(4)[None], len(inputs), axis=0)  # a static camera is its own world
        for track in range(1, job.objects + 1):
            m = clip_metrics(Path(job.out), inputs, poses, model if "traffic_cone" in job.categories else None, track)
            m["seconds_per_frame"] = round(rec["wall_s"] / max(rec["frames"], 1), 2)
            key = name if job.objects == 1 else f"{name}, track {track}"
            report["clips"][key] = m
            print(key, json.dumps(m), flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "temporal.json").write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
