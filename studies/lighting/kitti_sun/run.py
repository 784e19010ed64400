"""Which side of the camera the image-cue sun is on, on KITTI 06 colour frames (estimate_lighting, known camera).

Reference (read off the frames by eye, no metadata in the snippet): in frames 12-17 the facades facing the road from
the right are sunlit and the poles on the left cast shadows across the road to the right, so the sun is on the LEFT
(azimuth from the camera's forward axis, right positive, < 0). Prints and writes the estimated azimuth / elevation,
the side and the confidence per frame.

Usage: python -m studies.lighting.kitti_sun --out studies/lighting/kitti_sun/result
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from aias_augment.analyse.lighting.estimate import estimate_lighting
from aias_augment.core.config import data_root
from aias_augment.core.geometry import Intrinsics
from studies.lighting.kitti_shadow_depth import run as ek


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(data_root() / "kitti06_color_snippet"))
    ap.add_argument("--frames", type=int, nargs="+", default=[12, 13, 14, 17])
    ap.add_argument("--out", default="out/lighting")
    args = ap.parse_args(argv)
    rows = {}
    for idx in args.frames:
        img = ek.load_frame(Path(args.data), idx)
        K = Intrinsics(*ek.KITTI_K, img.shape[1], img.shape[0])
        est = estimate_lighting(img, K, meta={"ground_mask": ek.road_mask(K)})
        d = est.sun_direction_in_cam
        if d is None:
            rows[idx] = {"sun": None, "confidence": est.confidence}
            continue
        az = float(np.rad2deg(np.arctan2(d[0], d[2])))
        el = float(np.rad2deg(np.arcsin(np.clip(-d[1], -1, 1))))
        rows[idx] = {
            "azimuth_right_positive_deg": az,
            "elevation_deg": el,
            "side": "left" if az < 0 else "right",
            "correct_side": bool(az < 0),
            "confidence": est.confidence,
            "source": est.source,
        }
        print(
            f"frame {idx}: sun az {az:6.1f} deg (right +), el {el:5.1f}, side {rows[idx]['side']}, "
            f"confidence {est.confidence:.2f}"
        )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    cmd = "python -m studies.lighting.kitti_sun " + " ".join(argv if argv is not None else sys.argv[1:])
    (out / "kitti_sun.json").write_text(json.dumps({"command": cmd, "frames": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
