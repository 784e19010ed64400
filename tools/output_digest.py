"""Digests of the pipeline's outputs on a fixed reference set: the guard for refactors that must not change a byte.

Each case runs real images from the shared data (``$AIAS_DATA``, default ``../shared/data``) through a public door:

* ``insert_into_image``: KITTI 06 colour frames 12 and 17 (with their calibration K) and one TraCon image (with its
  YOLO boxes as existing boxes, no K);
* ``insert_bounded``: a 1920x1080 frame (DGP CAMERA_01, cropped to 16:9 and resized with INTER_AREA; 2.07 MP, so the
  analysis and plan run on a <= 2 MP copy) and the TraCon image (at or below the bound: the unbounded path);
* each of them with the presets ``fast`` and ``balanced`` and the seeds 0 and 1 (``np.random.default_rng(seed)``);
* the albumentations ``InsertObjects`` transform (fast preset, Compose seed 3) on the TraCon image, called twice;
* the clip door ``video.insert_into_clip``: 8 frames of KITTI 06 (ground-truth poses, calibration K), the default
  traffic cone, the clip lighting of ``estimate_lighting_clip``, seeds 0 and 1 (digest of all frames and boxes).

Per case it records the sha256 of the output image bytes (uint8, C order, with the shape) and of the boxes and labels
(boxes formatted to 1e-6). ``--write`` writes ``results/architecture/digests.json`` and its table
``results/architecture/README.md``; ``--check`` recomputes and compares with the committed json, exiting 1 and listing
the cases that differ.

    PYOPENGL_PLATFORM=egl python -m tools.output_digest --write
    PYOPENGL_PLATFORM=egl python -m tools.output_digest --check
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT_DIR = ROOT / "results" / "architecture"
DIGESTS = OUT_DIR / "digests.json"
PRESETS = ("fast", "balanced")
SEEDS = (0, 1)
TRACON_NAME = "cone (100)"
DGP_IMAGE = "dgp_scene/scene_01/rgb/CAMERA_01/15569195938415230.jpg"
CLIP_FRAMES = 8


def data_dir() -> Path:
    from aias_augment.core.config import data_root

    return Path(data_root())


def read_rgb(path: Path) -> np.ndarray:
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise FileNotFoundError(path)
    return np.ascontiguousarray(bgr[:, :, ::-1])


def kitti_frame(index: int):
    """(image, K 3x3) of KITTI 06 colour frame ``index`` (K from KITTI04-12.yaml, the snippet's calibration)."""
    from aias_augment.scenes.kitti import read_kitti_calib

    root = data_dir() / "kitti06_color_snippet"
    img = read_rgb(root / f"kitti06-{index}-color.png")
    intr, _ = read_kitti_calib(root / "KITTI04-12.yaml", img.shape[1], img.shape[0])
    return img, intr.K


def tracon_frame():
    """(image, existing boxes COCO xywh, labels) of one TraCon val image and its YOLO labels."""
    root = data_dir() / "tracon"
    img = read_rgb(root / "images" / "val" / f"{TRACON_NAME}.jpg")
    h, w = img.shape[:2]
    rows = np.loadtxt(root / "labels" / "val" / f"{TRACON_NAME}.txt", ndmin=2).reshape(-1, 5)
    cx, cy, bw, bh = rows[:, 1] * w, rows[:, 2] * h, rows[:, 3] * w, rows[:, 4] * h
    boxes = np.c_[cx - bw / 2, cy - bh / 2, bw, bh]
    return img, boxes, [f"tracon_{int(c)}" for c in rows[:, 0]]


def frame_1920x1080() -> np.ndarray:
    """A real 1920x1080 frame: DGP CAMERA_01 (1936x1216) centre-cropped to 16:9 rows and resized (INTER_AREA)."""
    img = read_rgb(data_dir() / DGP_IMAGE)
    h, w = img.shape[:2]
    ch = int(round(w * 9 / 16))
    top = (h - ch) // 2
    return cv2.resize(np.ascontiguousarray(img[top : top + ch]), (1920, 1080), interpolation=cv2.INTER_AREA)


def sha_image(img: np.ndarray) -> str:
    a = np.ascontiguousarray(np.asarray(img))
    h = hashlib.sha256(f"{a.shape}{a.dtype}".encode())
    h.update(a.tobytes())
    return h.hexdigest()


def sha_boxes(boxes, labels) -> str:
    b = np.asarray(boxes, float).reshape(-1, 4)
    rows = [[f"{v:.6f}" for v in r] for r in b]
    text = json.dumps({"boxes": rows, "labels": [str(x) for x in labels]}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def cases():
    """Yield (case name, thunk returning (image, boxes, labels, n_inserted))."""
    from aias_augment import insert_into_image, load_preset
    from aias_augment.pipeline.bounded import insert_bounded

    k12, K12 = kitti_frame(12)
    k17, K17 = kitti_frame(17)
    tracon, tracon_boxes, tracon_labels = tracon_frame()
    big = frame_1920x1080()

    def door(fn, img, boxes, labels, seed, cfg, **kw):
        def run():
            r = fn(img, boxes, labels, np.random.default_rng(seed), cfg, **kw)
            return r.image, r.bboxes, r.labels, len(r.inserted_labels)

        return run

    for preset in PRESETS:
        cfg = load_preset(preset)
        for seed in SEEDS:
            yield (
                f"insert_into_image/kitti06-12/{preset}/seed{seed}",
                door(insert_into_image, k12, None, None, seed, cfg, intrinsics=K12),
            )
            yield (
                f"insert_into_image/kitti06-17/{preset}/seed{seed}",
                door(insert_into_image, k17, None, None, seed, cfg, intrinsics=K17),
            )
            yield (
                f"insert_into_image/tracon/{preset}/seed{seed}",
                door(insert_into_image, tracon, tracon_boxes, tracon_labels, seed, cfg),
            )
            yield (
                f"insert_bounded/tracon/{preset}/seed{seed}",
                door(insert_bounded, tracon, tracon_boxes, tracon_labels, seed, cfg),
            )
            yield (
                f"insert_bounded/dgp-1920x1080/{preset}/seed{seed}",
                door(insert_bounded, big, None, None, seed, cfg),
            )

    def transform():
        import albumentations as A

        from aias_augment import InsertObjects

        tf = A.Compose(
            [InsertObjects(categories=["traffic_cone"], max_objects=2, p=1.0, preset="fast")],
            bbox_params=A.BboxParams(format="coco", label_fields=["labels"]),
            seed=3,
        )
        outs = [tf(image=tracon, bboxes=tracon_boxes, labels=tracon_labels) for _ in range(2)]
        return outs

    outs = []

    def call(i):
        def run():
            if not outs:
                outs.extend(transform())
            o = outs[i]
            return o["image"], o["bboxes"], o["labels"], len(o["labels"]) - len(tracon_labels)

        return run

    for i in range(2):
        yield f"InsertObjects/tracon/fast/compose-seed3/call{i}", call(i)

    for seed in SEEDS:
        yield f"insert_into_clip/kitti06-seq-8/seed{seed}", clip(seed)


def clip(seed: int):
    def run():
        from aias_augment.analyse.ground import prior_ground_plane
        from aias_augment.analyse.lighting.estimate import estimate_lighting_clip
        from aias_augment.assets.asset import default_asset
        from aias_augment.pipeline.clip import VideoInsertionConfig, insert_into_clip
        from aias_augment.scenes.kitti import open_kitti_sequence

        seq = open_kitti_sequence(data_dir() / "kitti06_seq")
        frames = [seq.frame(i).image for i in range(CLIP_FRAMES)]
        poses = np.stack([seq.cam_from_world(i) for i in range(CLIP_FRAMES)])
        rng = np.random.default_rng(seed)
        lighting = estimate_lighting_clip(frames, seq.intrinsics, poses)
        res = insert_into_clip(
            frames,
            seq.intrinsics,
            poses,
            rng,
            VideoInsertionConfig(lookahead_frames=6),
            asset=default_asset("traffic_cone"),
            ground_in_cam0=prior_ground_plane(1.65),
            lighting=lighting,
        )
        boxes = [b for b in res.boxes_xywh if b is not None]
        visible = [str(i) for i, b in enumerate(res.boxes_xywh) if b is not None]
        return np.stack(res.frames), boxes, visible, len(boxes)

    return run


def compute(verbose: bool = True) -> dict:
    out = {}
    t_all = time.perf_counter()
    for name, run in cases():
        t = time.perf_counter()
        img, boxes, labels, n = run()
        out[name] = {
            "image_sha256": sha_image(img),
            "boxes_sha256": sha_boxes(boxes, labels),
            "shape": list(np.asarray(img).shape),
            "n_boxes": int(len(labels)),
            "n_inserted": int(n),
        }
        if verbose:
            print(
                f"{time.perf_counter() - t:6.2f}s  {name}  {out[name]['image_sha256'][:12]} "
                f"{out[name]['boxes_sha256'][:12]}  inserted {n}",
                flush=True,
            )
    if verbose:
        print(f"total {time.perf_counter() - t_all:.1f}s", flush=True)
    return out


def write_table(digests: dict) -> None:
    lines = [
        "# Output digests of the reference set",
        "",
        "The guard for refactors that must keep the pipeline's outputs byte-identical: each case below is a real image",
        "through a public door (`insert_into_image`, `working_resolution.insert_bounded`, the `InsertObjects`",
        "transform) with a preset and a seed; the digests are sha256 of the output image bytes and of the output boxes",
        "(formatted to 1e-6) with their labels. `digests.json` holds them; the script and its inputs are described in",
        "its docstring (`tools/output_digest.py`).",
        "",
        "```",
        "PYOPENGL_PLATFORM=egl AIAS_DATA=../shared/data python -m tools.output_digest --write   # regenerate",
        "PYOPENGL_PLATFORM=egl AIAS_DATA=../shared/data python -m tools.output_digest --check   # exit 1 if any differs",
        "```",
        "",
        "Digests depend on the library versions (OpenCV, numpy, torch, the GL renderer): compare on one machine.",
        "The clip cases were also computed with the code of the commit that wrote the image baseline (8053f24): same",
        "digests.",
        "",
        "Replay: `insertion.replay.replay` of an `insert_bounded` record on the 1920x1080 frame is byte-identical (fast and",
        "balanced, `tests/aias_augment/pipeline/test_replay_bounded.py`): the record keeps the working resolution the door used",
        "(`working_resolution`: image size, analysis size, bound) and replay analyses the same <= 2 MP copy the same way",
        "(`insertion.working.WorkingResolution.analyse`). A record without the field replays as before, analysing the full",
        "frame (fast, seed 0: 29 204 pixels differ from the door's output, at most 8 levels; balanced: 46 250, at most 81).",
        "",
        "| case | output | boxes | inserted | image sha256 | boxes sha256 |",
        "|---|---|---|---|---|---|",
    ]
    for name, d in digests.items():
        sh = d["shape"]
        shape = f"{sh[-2]}x{sh[-3]}" + (f" x {sh[0]} frames" if len(sh) == 4 else "")
        lines.append(
            f"| `{name}` | {shape} | {d['n_boxes']} | {d['n_inserted']} | `{d['image_sha256'][:16]}` | "
            f"`{d['boxes_sha256'][:16]}` |"
        )
    (OUT_DIR / "README.md").write_text("\n".join(lines) + "\n")


def compare(expected: dict, got: dict) -> list[str]:
    """One line per case whose digests differ, or that is only in one of the two."""
    differ = []
    for name in sorted(set(expected) | set(got)):
        e, g = expected.get(name), got.get(name)
        if e is None or g is None:
            differ.append(f"{name}: {'new case' if e is None else 'missing case'}")
            continue
        what = [k for k in ("image_sha256", "boxes_sha256") if e[k] != g[k]]
        if what:
            differ.append(f"{name}: {', '.join(what)} differ")
    return differ


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    mode = ap.add_mutually_exclusive_group(required=True)
    mode.add_argument("--write", action="store_true", help="write results/architecture/digests.json and README.md")
    mode.add_argument("--check", action="store_true", help="recompute and compare with the committed digests")
    args = ap.parse_args(argv)
    if args.check:
        if not DIGESTS.exists():
            print(f"no {DIGESTS.relative_to(ROOT)}: run with --write first", file=sys.stderr)
            return 2
        expected = json.loads(DIGESTS.read_text())
    digests = compute()
    if args.write:
        OUT_DIR.mkdir(parents=True, exist_ok=True)
        DIGESTS.write_text(json.dumps(digests, indent=1) + "\n")
        write_table(digests)
        print(f"wrote {DIGESTS.relative_to(ROOT)} ({len(digests)} cases)")
        return 0
    differ = compare(expected, digests)
    if differ:
        print(f"{len(differ)} of {len(expected)} cases differ:")
        for line in differ:
            print("  " + line)
        return 1
    print(f"all {len(expected)} cases identical")
    return 0


if __name__ == "__main__":
    sys.exit(main())
