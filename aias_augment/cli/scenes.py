"""``aias-scenes``: index scene clips and query them by example image/region or by named visual words.

aias-scenes index --out scenes.npz $AIAS_DATA/kitti06_seq/image_l $AIAS_DATA/video/vtest.avi --every 5
aias-scenes query --index scenes.npz --image query.png [--region X Y W H] [--top 5]
aias-scenes name  --index scenes.npz --name road --image frame.png --region 300 250 600 120
aias-scenes query --index scenes.npz --words road          # clips dominated by road
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

from aias_augment.core.arg_parser import OneLineArgumentParser
from aias_augment.core.logs import add_logging_args, configure_logging
from aias_augment.scenes.retrieval.features import FeatureConfig
from aias_augment.scenes.retrieval.index import QueryConfig, SceneIndex, build_index
from aias_augment.scenes.retrieval.sources import iter_frames, read_image


def _count(lo: int):
    """An argparse type: a whole number >= ``lo``."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"{v} is below {lo}")
        return v

    return parse


def _cmd_index(a) -> int:
    sources = [iter_frames(s, every=a.every, max_frames=a.max_frames) for s in a.sources]
    cfg = FeatureConfig(max_side_px=a.max_side, n_features=a.features)
    index, timings = build_index(
        itertools.chain(*sources),
        n_words=a.words,
        feature_cfg=cfg,
        rng=np.random.default_rng(a.seed),
        progress=not a.quiet,
    )
    index.save(a.out)
    print(json.dumps({**timings, "index": str(a.out)}))
    return 0


def _print_hits(hits, as_json: bool, seconds: float) -> None:
    if as_json:
        print(
            json.dumps(
                {
                    "seconds": round(seconds, 4),
                    "hits": [
                        {
                            "rank": h.rank,
                            "clip": h.ref.clip,
                            "frame": h.ref.frame,
                            "score": round(h.score, 4),
                            "inliers": h.inliers,
                        }
                        for h in hits
                    ],
                },
                indent=1,
            )
        )
        return
    for h in hits:
        print(f"{h.rank:2d}  score={h.score:.4f}  inliers={h.inliers:4d}  {h.ref.clip}  {h.ref.frame}")
    print(f"({seconds:.3f} s)", file=sys.stderr)


def _cmd_query(a) -> int:
    index = SceneIndex.load(a.index)
    t = time.perf_counter()
    if a.words:
        hits = index.query_words(a.words, top_k=a.top)
    else:
        if a.image is None:
            raise ValueError("give --image (optionally --region) or --words")
        hits = index.query_image(
            read_image(a.image),
            QueryConfig(top_k=a.top, rerank=a.rerank),
            region_xywh=tuple(a.region) if a.region else None,
        )
    _print_hits(hits, a.json, time.perf_counter() - t)
    return 0


def _cmd_name(a) -> int:
    index = SceneIndex.load(a.index)
    if len(a.image) != len(a.region):
        raise ValueError("give one --region per --image")
    examples = []
    for path, (x, y, w, h) in zip(a.image, a.region):
        img = read_image(path)
        mask = np.zeros(img.shape[:2], bool)
        mask[y : y + h, x : x + w] = True
        examples.append((img, mask))
    words = index.name_words(a.name, examples, n_words=a.n_words)
    index.save(a.index)
    print(f"named {len(words)} visual words {a.name!r} in {a.index}")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = OneLineArgumentParser(prog="aias-scenes", description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    sub = p.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("index", help="build a persisted index of clips (folders of images, videos, images)")
    s.add_argument("sources", nargs="+", type=Path)
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--every", type=_count(1), default=1, help="take every N-th frame of each clip")
    s.add_argument("--max-frames", type=_count(1), default=None, help="per clip")
    s.add_argument("--words", type=_count(2), default=2048, help="vocabulary size (capped at features / 10)")
    s.add_argument("--features", type=_count(1), default=FeatureConfig.n_features)
    s.add_argument("--max-side", type=_count(16), default=FeatureConfig.max_side_px)
    s.add_argument("--seed", type=_count(0), default=0)
    s = sub.add_parser("query", help="query by an example image / region, or by named visual words")
    s.add_argument("--index", type=Path, required=True)
    s.add_argument("--image", type=Path)
    s.add_argument("--region", type=_count(0), nargs=4, metavar=("X", "Y", "W", "H"))
    s.add_argument("--words", nargs="*", default=None, help="named visual words (see `name`)")
    s.add_argument("--top", type=_count(1), default=5)
    s.add_argument("--rerank", type=_count(0), default=QueryConfig.rerank)
    s.add_argument("--json", action="store_true")
    s = sub.add_parser("name", help="name visual words from example regions (stored in the index)")
    s.add_argument("--index", type=Path, required=True)
    s.add_argument("--name", required=True)
    s.add_argument("--image", type=Path, action="append", required=True)
    s.add_argument("--region", type=_count(0), nargs=4, action="append", required=True, metavar=("X", "Y", "W", "H"))
    s.add_argument("--n-words", type=_count(1), default=64)
    add_logging_args(p, subcommands=sub.choices.values())
    a = p.parse_args(argv)
    configure_logging(a)
    try:
        return {"index": _cmd_index, "query": _cmd_query, "name": _cmd_name}[a.cmd](a)
    except (ValueError, OSError) as e:  # an unreadable index, image or clip: one line, exit 2
        p.exit(2, f"aias-scenes {a.cmd}: error: {' '.join(str(e).split())}\n")


if __name__ == "__main__":
    sys.exit(main())
