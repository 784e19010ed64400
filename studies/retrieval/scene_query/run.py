#!/usr/bin/env python
"""Retrieval benchmark of the scene query engine on the real frames of the shared data folder.

Database: KITTI 06 grey frames (every --kitti-every-th), the KITTI 06 colour snippet, vtest.avi frames (every
--video-every-th), the NYU RGB-D colour frames and the DGP scene's 9 camera images. Queries: every database frame
under seeded photometric, crop and crop+photometric perturbations. A query is answered correctly at rank 1 when the
top result is its source frame, or a frame of the same moment (KITTI colour frame k and grey frame k: another camera
of the same rig at the same time). Reports Recall@1/@5 with and without spatial re-ranking, per perturbation and clip,
and the query time (median over queries: feature extraction, search, total).

    python -m studies.retrieval.scene_query --data $AIAS_DATA --out studies/retrieval/scene_query/result
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.core.config import data_root
from aias_augment.scenes.retrieval.features import extract_features
from aias_augment.scenes.retrieval.index import FrameRef, QueryConfig, SceneIndex, build_index
from aias_augment.scenes.retrieval.sources import iter_frames, read_image


def database_frames(data: Path, kitti_every: int, video_every: int) -> list[tuple[FrameRef, np.ndarray]]:
    frames = []
    for ref, img in iter_frames(data / "kitti06_seq" / "image_l", every=kitti_every, clip="kitti06_seq"):
        frames.append((FrameRef(ref.clip, ref.frame, f"kitti06:{int(Path(ref.frame).stem):06d}"), img))
    snip = data / "kitti06_color_snippet"
    for p in sorted(snip.glob("kitti06-*-color.png")):
        k = int(p.name.split("-")[1])
        frames.append((FrameRef("kitti06_color_snippet", p.name, f"kitti06:{k:06d}"), read_image(p)))
    frames += list(iter_frames(data / "video" / "vtest.avi", every=video_every, clip="vtest"))
    frames += list(iter_frames(data / "nyu_rgbd" / "color", clip="nyu_rgbd"))
    for cam in sorted((data / "dgp_scene" / "scene_01" / "rgb").glob("CAMERA_*")):
        frames += [(FrameRef("dgp_scene", f"{cam.name}/{r.frame}"), im) for r, im in iter_frames(cam, clip="dgp")]
    return frames


def photometric(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    x = img.astype(np.float32) / 255.0
    x = np.clip(x * rng.uniform(0.7, 1.3) + rng.uniform(-0.12, 0.12), 0, 1) ** rng.uniform(0.6, 1.6)  # contrast, gain
    if x.ndim == 3:  # colour: per-channel white-balance shift
        x = np.clip(x * rng.uniform(0.85, 1.15, size=3), 0, 1)
    x = x * 255.0 + rng.normal(0, rng.uniform(2, 8), size=x.shape)  # sensor noise
    out = np.clip(x, 0, 255).astype(np.uint8)
    sigma = rng.uniform(0, 1.2)
    if sigma > 0.3:
        out = cv2.GaussianBlur(out, (0, 0), sigma)
    ok, enc = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(30, 71))])
    return cv2.imdecode(enc, cv2.IMREAD_UNCHANGED)


def crop(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    h, w = img.shape[:2]
    area = rng.uniform(0.4, 0.75)
    aspect = rng.uniform(0.8, 1.25)
    cw = int(np.clip(np.sqrt(area * aspect) * w, 32, w))
    ch = int(np.clip(np.sqrt(area / aspect) * h, 32, h))
    x0, y0 = int(rng.integers(0, w - cw + 1)), int(rng.integers(0, h - ch + 1))
    c = img[y0 : y0 + ch, x0 : x0 + cw]
    s = rng.uniform(0.7, 1.3)  # and a scale change
    return cv2.resize(c, (max(16, round(cw * s)), max(16, round(ch * s))), interpolation=cv2.INTER_AREA)


#: Example road regions (a user's clicks): frame index in the database order, rows and columns as image fractions.
ROAD_EXAMPLES = {
    "kitti06_seq": ((0.72, 1.0), (0.3, 0.7)),
    "dgp_scene": ((0.85, 1.0), (0.0, 0.3)),
    "vtest": ((0.42, 0.65), (0.55, 0.8)),
}


def named_words_road(index, frames) -> dict:
    """Learn `road` words from one example region per outdoor clip, then rank all frames by their road fraction."""
    examples, used = [], []
    for clip, ((r0, r1), (c0, c1)) in ROAD_EXAMPLES.items():
        d = next(i for i, (ref, _) in enumerate(frames) if ref.clip == clip)
        img = frames[d][1]
        h, w = img.shape[:2]
        m = np.zeros((h, w), bool)
        m[int(r0 * h) : int(r1 * h), int(c0 * w) : int(c1 * w)] = True
        examples.append((img, m))
        used.append(d)
    index.name_words("road", examples, n_words=128)
    frac = index.word_fraction(["road"])
    clips = sorted({r.clip for r in index.refs})
    indoor = np.array([r.clip == "nyu_rgbd" for r in index.refs])
    held_out = np.ones(len(frac), bool)
    held_out[used] = False  # the example frames themselves are not evaluated
    outdoor_min = float(frac[held_out & ~indoor].min())
    return {
        "examples": {frames[d][0].clip + "/" + frames[d][0].frame: ROAD_EXAMPLES[frames[d][0].clip] for d in used},
        "n_words": int(len(index.names["road"])),
        "mean_fraction_by_clip": {c: round(float(frac[[r.clip == c for r in index.refs]].mean()), 4) for c in clips},
        "indoor_max_fraction": round(float(frac[indoor].max()), 4),
        "outdoor_min_fraction_held_out": round(outdoor_min, 4),
        "indoor_frames_rank_last": bool(frac[indoor].max() < outdoor_min),
    }


PERTURBATIONS = {
    "photometric": photometric,
    "crop": crop,
    "crop+photometric": lambda im, rng: photometric(crop(im, rng), rng),
}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, default=data_root())
    p.add_argument("--out", type=Path, default=Path("studies/retrieval/scene_query/result"))
    p.add_argument("--kitti-every", type=int, default=2)
    p.add_argument("--video-every", type=int, default=40)
    p.add_argument("--words", type=int, default=2048)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--matching", choices=["words", "descriptors"], default="words")
    p.add_argument("--rerank", type=int, default=QueryConfig.rerank)
    p.add_argument("--index-out", type=Path, default=Path("out/retrieval/bench_index.npz"))
    p.add_argument("--named-words-only", action="store_true", help="only the named-words (road) evaluation")
    p.add_argument(
        "--index-in",
        type=Path,
        default=None,
        help="reuse an index built by an earlier run with the same data options (skips the build)",
    )
    a = p.parse_args(argv)
    cv2.setNumThreads(1)
    rng = np.random.default_rng(a.seed)

    frames = database_frames(a.data, a.kitti_every, a.video_every)
    if a.index_in:
        index = SceneIndex.load(a.index_in)
        if [r.key for r in index.refs] != [r.key for r, _ in frames]:
            raise SystemExit(f"{a.index_in} was built from other frames; rebuild without --index-in")
        timings = {**json.loads(a.index_in.with_suffix(".json").read_text()), "reused": str(a.index_in)}
    else:
        index, timings = build_index(frames, n_words=a.words, rng=rng, progress=True)
        t = time.perf_counter()
        index.save(a.index_out)
        timings["seconds_save"] = round(time.perf_counter() - t, 2)
        a.index_out.with_suffix(".json").write_text(json.dumps(timings))
    print(json.dumps(timings))

    a.out.mkdir(parents=True, exist_ok=True)
    nw = named_words_road(index, frames)
    (a.out / "named_words.json").write_text(json.dumps(nw, indent=1))
    print("named words road:", json.dumps(nw))
    if a.named_words_only:
        return 0
    cfg = QueryConfig(top_k=5, rerank=a.rerank, matching=a.matching)
    cfg_plain = QueryConfig(top_k=5, rerank=0)
    rows = []
    for qi, (ref, img) in enumerate(frames):
        for name, fn in PERTURBATIONS.items():
            q_img = fn(img, np.random.default_rng([a.seed, qi, len(name)]))
            t0 = time.perf_counter()
            feats = extract_features(q_img, index.feature_cfg)
            t1 = time.perf_counter()
            hits = index.query_features(feats, cfg)
            t2 = time.perf_counter()
            plain = index.query_features(feats, cfg_plain)
            rank = next((h.rank for h in hits if h.ref.key == ref.key), None)
            rank_plain = next((h.rank for h in plain if h.ref.key == ref.key), None)
            rows.append(
                {
                    "clip": ref.clip,
                    "frame": ref.frame,
                    "perturbation": name,
                    "rank": rank,
                    "rank_tfidf_only": rank_plain,
                    "top1": hits[0].ref.key if hits else None,
                    "top1_inliers": hits[0].inliers if hits else 0,
                    "n_features": len(feats),
                    "seconds_features": t1 - t0,
                    "seconds_search": t2 - t1,
                }
            )
        if (qi + 1) % 10 == 0:
            r1 = np.mean([r["rank"] == 1 for r in rows])
            print(f"{qi + 1}/{len(frames)} frames, {len(rows)} queries, running Recall@1 {r1:.3f}", flush=True)

    def recall(sel, k, key="rank"):
        sel = list(sel)
        return round(float(np.mean([r[key] is not None and r[key] <= k for r in sel])), 4) if sel else None

    summary = {
        "database_frames": len(frames),
        "queries": len(rows),
        "index": timings,
        "recall@1": recall(rows, 1),
        "recall@5": recall(rows, 5),
        "recall@1_tfidf_only": recall(rows, 1, "rank_tfidf_only"),
        "recall@5_tfidf_only": recall(rows, 5, "rank_tfidf_only"),
        "by_perturbation": {
            n: {
                "recall@1": recall([r for r in rows if r["perturbation"] == n], 1),
                "recall@1_tfidf_only": recall([r for r in rows if r["perturbation"] == n], 1, "rank_tfidf_only"),
            }
            for n in PERTURBATIONS
        },
        "by_clip": {
            c: {
                "queries": sum(r["clip"] == c for r in rows),
                "recall@1": recall([r for r in rows if r["clip"] == c], 1),
            }
            for c in sorted({r["clip"] for r in rows})
        },
        "query_seconds_median": {
            "features": round(statistics.median(r["seconds_features"] for r in rows), 4),
            "search_and_rerank": round(statistics.median(r["seconds_search"] for r in rows), 4),
            "total": round(statistics.median(r["seconds_features"] + r["seconds_search"] for r in rows), 4),
        },
        "failures": [
            {k: r[k] for k in ("clip", "frame", "perturbation", "rank", "top1", "top1_inliers")}
            for r in rows
            if r["rank"] != 1
        ],
        "named_words_road": nw,
        "command": "python -m studies.retrieval.scene_query " + " ".join(sys.argv[1:] if argv is None else argv),
        "config": {
            "kitti_every": a.kitti_every,
            "video_every": a.video_every,
            "words": a.words,
            "seed": a.seed,
            "query": dict(cfg.__dict__),
        },
    }
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "bench.json").write_text(json.dumps(summary, indent=1))
    md = [
        "# Scene retrieval benchmark",
        "",
        f"Command: `{summary['command']}`",
        "",
        f"- database: {len(frames)} real frames ({', '.join(summary['by_clip'])}); "
        f"{timings['features']} RootSIFT features, {timings['words']} words",
        f"- queries: {len(rows)} (each frame x {', '.join(PERTURBATIONS)})",
        f"- **Recall@1 = {summary['recall@1']}**, Recall@5 = {summary['recall@5']} "
        f"(tf-idf only, no spatial re-ranking: R@1 = {summary['recall@1_tfidf_only']})",
        f"- median query time: {summary['query_seconds_median']['total']} s "
        f"(features {summary['query_seconds_median']['features']} s, search + re-rank "
        f"{summary['query_seconds_median']['search_and_rerank']} s)",
        f"- index build: features {timings['seconds_features']} s, vocabulary {timings['seconds_vocabulary']} s, "
        f"index {timings['seconds_index']} s",
        "",
        "| perturbation | R@1 | R@1 tf-idf only |",
        "|---|---|---|",
    ]
    md += [f"| {n} | {v['recall@1']} | {v['recall@1_tfidf_only']} |" for n, v in summary["by_perturbation"].items()]
    md += ["", "| clip | queries | R@1 |", "|---|---|---|"]
    md += [f"| {c} | {v['queries']} | {v['recall@1']} |" for c, v in summary["by_clip"].items()]
    md += [
        "",
        "Named words `road` (one example region in a KITTI, a DGP and a vtest frame, see named_words.json): "
        "mean fraction of a frame's features on road words per clip: "
        + ", ".join(f"{c} {v}" for c, v in nw["mean_fraction_by_clip"].items())
        + f"; every indoor NYU frame ranks below every held-out outdoor frame: {nw['indoor_frames_rank_last']}.",
    ]
    (a.out / "bench.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    sys.exit(main())
