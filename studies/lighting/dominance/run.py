"""Dominant-sun detection on real frames with known answers: sunny street (KITTI 06 colour, cast shadows: sun),
indoor dining room (NYU RGB-D: no sun), overcast campus video (vtest.avi, soft light, no cast shadows: no sun).

No ``indoor`` flag and no metadata are given: the decision comes from the image (lit vs shadowed ground, visible sky,
sun disc). Also times ``estimate_lighting`` per frame (median). With ``--grey-step N`` every N-th frame of the grey
KITTI 06 sequence (``kitti06_seq``, 1-channel PNGs replicated to RGB as the transform does; sunny, hard shadows) is a
fourth group. ``--widths``: 0 = the frame as given (the balanced / accurate presets' analysis), W > 0 = an
area-resampled copy W pixels wide with the intrinsics scaled, as the fast preset's cheap analysis
(``analysis_max_width`` 160) calls the estimator.

Usage: python -m studies.lighting.dominance --out studies/lighting/dominance/result [--grey-step 5 --widths 0 160]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from aias_augment.analyse.lighting.estimate import estimate_lighting
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics


def frames(root: Path, video_step: int, grey_step: int = 0):
    import cv2
    from PIL import Image

    kitti = root / "kitti06_color_snippet"
    K = Intrinsics(707.0912, 707.0912, 601.8873, 183.1104, 1226, 370)
    for i in (12, 13, 14, 17):
        yield (
            "kitti06 sunny street",
            f"kitti06-{i}",
            np.array(Image.open(kitti / f"kitti06-{i}-color.png").convert("RGB")),
            K,
            True,
        )
    if grey_step:
        for i in range(0, 51, grey_step):
            g = np.array(Image.open(root / "kitti06_seq" / "image_l" / f"{i:06d}.png"))
            yield "kitti06 grey sequence (sunny)", f"kitti06-grey-{i}", np.repeat(g[..., None], 3, 2), K, True
    K = Intrinsics(518.0, 519.0, 325.5, 253.5, 640, 480)
    for i in range(1, 6):
        img = np.array(Image.open(root / "nyu_rgbd" / "color" / f"{i}.png").convert("RGB"))
        yield "nyu indoor", f"nyu-{i}", img, K, False
    cap = cv2.VideoCapture(str(root / "video" / "vtest.avi"))
    n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    for f in range(0, n, video_step):
        cap.set(cv2.CAP_PROP_POS_FRAMES, f)
        ok, bgr = cap.read()
        if ok:
            yield "vtest overcast (camera unknown)", f"vtest-{f}", cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), None, False
    cap.release()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(data_root()))
    ap.add_argument("--video-step", type=int, default=100)
    ap.add_argument("--grey-step", type=int, default=0, help="also every N-th grey KITTI 06 frame (0: none)")
    ap.add_argument("--widths", type=int, nargs="+", default=[0], help="0: as given; W: a W px wide copy")
    ap.add_argument("--out", default="out/lighting")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    import cv2

    rows = []
    for group, name, img, K, expected in frames(Path(args.data), args.video_step, args.grey_step):
        for width in args.widths:
            im, Kw = img, K
            if width and img.shape[1] > width:  # as insertion.analyse: INTER_AREA copy, pixel centres kept
                h = max(1, int(round(img.shape[0] * width / img.shape[1])))
                im = cv2.resize(img, (width, h), interpolation=cv2.INTER_AREA)
                if K is not None:
                    sx, sy = width / K.width, h / K.height
                    Kw = Intrinsics(K.fx * sx, K.fy * sy, (K.cx + 0.5) * sx - 0.5, (K.cy + 0.5) * sy - 0.5, width, h)
            t = time.perf_counter()
            e = estimate_lighting(im, Kw)
            dt = time.perf_counter() - t
            rows.append(
                {
                    "group": group,
                    "frame": name,
                    "width": width,
                    "expected_sun": expected,
                    "dominant_sun": e.dominant_sun,
                    "sun_sky_ratio": e.sun_sky_ratio,
                    "confidence": e.confidence,
                    "source": e.source,
                    "seconds": dt,
                }
            )
            print(
                f"{name:18s} width {width or img.shape[1]:4d} expected {expected!s:5s} got {e.dominant_sun!s:5s} "
                f"ratio {e.sun_sky_ratio:5.2f} ({dt:.2f} s)",
                flush=True,
            )
    groups = {}
    for r in rows:
        g = groups.setdefault(r["group"], {}).setdefault(str(r["width"]), {"n": 0, "correct": 0})
        g["n"] += 1
        g["correct"] += int(r["dominant_sun"] == r["expected_sun"])
    report = {
        "command": "python -m studies.lighting.dominance " + " ".join(argv if argv is not None else sys.argv[1:]),
        "groups": groups,
        "rows": rows,
        "median_seconds": float(np.median([r["seconds"] for r in rows])),
    }
    (out / "dominance.json").write_text(json.dumps(report, indent=1))
    width_names = {w: ("as given" if w == 0 else f"{w} px copy") for w in args.widths}
    lines = [
        "# Dominant-sun detection on real frames",
        "",
        f"Command: `{report['command']}`",
        "",
        "| frames | expected | " + " | ".join(f"correct ({width_names[w]})" for w in args.widths) + " |",
        "|---|---|" + "---|" * len(args.widths),
    ]
    for gname, g in groups.items():
        exp = next(r["expected_sun"] for r in rows if r["group"] == gname)
        lines.append(
            f"| {gname} | {'sun' if exp else 'no sun'} | "
            + " | ".join(f"{g[str(w)]['correct']} / {g[str(w)]['n']}" for w in args.widths)
            + " |"
        )
    lines += ["", f"Median time of `estimate_lighting` per frame: {report['median_seconds']:.2f} s (CPU, shared)"]
    for w in args.widths:
        ts = [r["seconds"] for r in rows if r["width"] == w]
        lines[-1] += f"; {width_names[w]}: {float(np.median(ts)):.2f} s"
    lines[-1] += "."
    wrong = [r for r in rows if r["dominant_sun"] != r["expected_sun"]]
    if wrong:
        lines += ["", "Wrong decisions: " + ", ".join(f"{r['frame']} ({width_names[r['width']]})" for r in wrong) + "."]
    lines += [""]
    (out / "dominance.md").write_text("\n".join(lines))
    print(json.dumps(groups))
    return 0


if __name__ == "__main__":
    sys.exit(main())
