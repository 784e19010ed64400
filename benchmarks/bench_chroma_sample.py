"""The chroma-subsampling decision from a bounded sample of 8x8 blocks against the decision from every block.

    taskset -c 1 python -m benchmarks.bench_chroma_sample --out results/bench/chroma_sample.json

Photos: every 4th TraCon image (train and val), the DGP frames (2.4 MP) and the KITTI 06 snippet's frames; each as it
is and re-encoded at quality 60 with 4:2:0 and at quality 90 with 4:4:4 (OpenCV). For each, ``chroma_subsampled``
(every k-th block, at most ``CHROMA_MAX_BLOCKS``) against the same statistic on every block (the code before the
sample); on the lossless KITTI PNGs' re-encodes the truth is the encoder's sampling factor. Writes the counts and
the seconds of both.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.fft import dctn

from aias_augment.apply.harmonize.camera_pipeline import CHROMA_MAX_BLOCKS, EPS_GRAD, chroma_subsampled
from aias_augment.core.config import data_root
from aias_augment.core.image_io import read_image


def every_block(image_uint8: np.ndarray) -> bool:
    """The decision on every 8x8 block of the grid at (0, 0)."""
    rgb = image_uint8.astype(np.float64)

    def hf_ratio(ch: np.ndarray) -> float:
        h, w = (ch.shape[0] // 8) * 8, (ch.shape[1] // 8) * 8
        e = dctn(ch[:h, :w].reshape(h // 8, 8, w // 8, 8).transpose(0, 2, 1, 3), axes=(2, 3), norm="ortho") ** 2
        ac = e.sum(axis=(2, 3)) - e[:, :, 0, 0]
        return float(e[:, :, 4:, :].sum() + e[:, :, :4, 4:].sum()) / (float(ac.sum()) + EPS_GRAD)

    ry = hf_ratio(rgb @ np.array([0.299, 0.587, 0.114]))
    rc = hf_ratio(rgb @ np.array([-0.168736, -0.331264, 0.5]))
    return ry > 1e-3 and rc < 0.6 * ry


def encoded(img: np.ndarray, quality: int, sampling: int) -> np.ndarray:
    params = [cv2.IMWRITE_JPEG_QUALITY, quality, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, sampling]
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(img, cv2.COLOR_RGB2BGR), params)
    if not ok:
        raise SystemExit("bench_chroma_sample: cv2.imencode failed")
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("results/bench/chroma_sample.json"))
    a = ap.parse_args(argv)
    root = data_root()
    files = sorted((root / "tracon" / "images").rglob("*.jpg"))[::4]
    files += sorted((root / "dgp_scene").rglob("*.jpg")) + sorted((root / "kitti06_color_snippet").glob("*.png"))
    if not files:
        raise SystemExit(f"bench_chroma_sample: no photos under {root}")
    n = agree = truth_n = truth_ok = sampled_n = 0
    seconds = {"every_block": 0.0, "sampled": 0.0}
    differ = []
    for f in files:
        img = read_image(f)
        variants = [("as is", img, None)]
        variants.append(("q60 4:2:0", encoded(img, 60, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420), True))
        variants.append(("q90 4:4:4", encoded(img, 90, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444), False))
        lossless = f.suffix.lower() == ".png"
        for name, im, truth in variants:
            t0 = time.perf_counter()
            want = every_block(im)
            t1 = time.perf_counter()
            got = chroma_subsampled(im)
            seconds["every_block"] += t1 - t0
            seconds["sampled"] += time.perf_counter() - t1
            n += 1
            agree += got == want
            sampled_n += (im.shape[0] // 8) * (im.shape[1] // 8) > CHROMA_MAX_BLOCKS
            if got != want:
                differ.append(f"{f.name} {name}")
            if lossless and truth is not None:
                truth_n += 1
                truth_ok += got == truth
    result = {
        "command": "python -m benchmarks.bench_chroma_sample " + " ".join(sys.argv[1:] if argv is None else argv),
        "photos": len(files),
        "images": n,
        "images_sampled": sampled_n,
        "same_as_every_block": agree,
        "differ": differ,
        "lossless_reencodes_matching_the_encoder": [truth_ok, truth_n],
        "seconds": {k: round(v, 2) for k, v in seconds.items()},
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))
    return 0 if agree == n else 1


if __name__ == "__main__":
    sys.exit(main())
