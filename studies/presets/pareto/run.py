"""Speed against accuracy per preset (issue 14): one table and a Pareto plot from the committed measurements, with the
edge error measured here on the render path each preset uses.

    python -m studies.presets.pareto --timing results/bench/transform_calls.json --out studies/presets/pareto/result

Columns: ms per 640x480 call on a new image (cold) and a seen one (warm, view cache in its steady state) from the
per-call benchmark (``bench_transform.py``); the edge error, mean |alpha - alpha_ref| over the pixels either touches,
against a 4x supersampled full render of the same pose (a traffic cone at 6-40 m, 640x480, f = 700 px), for the
layers the preset really composites: fast = the view cache (views rendered 2x supersampled, warped), balanced and
accurate = a full render at their ``ssaa``; the realism of the pipeline's cones on TraCon (Lite0-KID and the
two-sample AUC of ``studies/realism/arms/run.py``, where a preset was measured) and the study's cone AP gain (where a
preset was trained with). Writes ``presets.md`` and ``presets_pareto.jpg``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from studies._shared.pictures import save_figure_jpeg

REPO = Path(__file__).resolve().parents[3]

#: Where each preset's realism and study numbers come from (what has been measured; None: not measured).
REALISM = {
    "fast": (
        "studies/realism/arms/result/fast_preset/report.json",
        "inserted, fast preset (crease normals, seen-sky fill, 320 px lighting, tempered-sun shading)",
    ),
    "balanced": ("studies/realism/arms/result/report.json", "inserted, balanced preset"),
    "accurate": None,
}
STUDY = {
    "fast": ("studies/detection/lite0_320/result/summary.json", ("inserted n=60", "inserted_online")),
    "balanced": None,
    "accurate": None,
}
POSES = ((6.0, 0.2), (12.0, -1.0), (25.0, 1.5), (40.0, -2.0))


def edge_errors() -> dict:
    from aias_augment.apply.render import render_object
    from aias_augment.apply.view_cache import ViewCache, render_from_view_cache
    from aias_augment.assets.asset import default_asset
    from aias_augment.core.geometry import Intrinsics
    from aias_augment.pipeline.image import load_preset

    K = Intrinsics(700.0, 700.0, 319.5, 239.5, 640, 480)
    cone = default_asset("traffic_cone")
    out = {}
    for preset in ("fast", "balanced", "accurate"):
        cfg = load_preset(preset)
        errs = []
        for z, x in POSES:
            T = np.eye(4)
            T[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
            T[:3, 3] = [x, 1.5, z]
            ref = render_object(cone, T, K, ssaa=4, with_normals=False).alpha
            if cfg.render_method == "view_cache":
                got = render_from_view_cache(cone, T, K, cache=ViewCache())
                if got is None:
                    raise RuntimeError(f"view cache does not apply at z={z}")
                (x0, y0, x1, y1), layers = got
                a = np.zeros_like(ref)
                a[y0:y1, x0:x1] = layers.alpha
            else:
                a = render_object(cone, T, K, ssaa=cfg.ssaa, with_normals=False).alpha
            touched = (a > 0) | (ref > 0)
            errs.append(float(np.abs(a - ref)[touched].mean()))
        out[preset] = {
            "edge_alpha_mae": float(np.mean(errs)),
            "per_pose": errs,
            "layers": "view cache (2x views, warped)"
            if cfg.render_method == "view_cache"
            else f"full render, ssaa {cfg.ssaa}",
        }
    return out


def realism(preset: str) -> dict | None:
    src = REALISM.get(preset)
    if src is None or not (REPO / src[0]).exists():
        return None
    arms = json.loads((REPO / src[0]).read_text())["arms"]
    if src[1] not in arms:
        return None
    a = arms[src[1]]
    return {
        "kid": a["kid_crops"][0],
        "kid_sd": a["kid_crops"][1],
        "auc": a["auc_logreg_lite0"]["auc"],
        "auc_ci95": a["auc_logreg_lite0"]["ci95"],
        "source": f"{src[0]}: {src[1]}",
    }


def study_gain(preset: str) -> dict | None:
    src = STUDY.get(preset)
    if src is None or not (REPO / src[0]).exists():
        return None
    s = json.loads((REPO / src[0]).read_text())
    rows = s.get("arms", s)
    out = {}
    for name in src[1]:
        r = rows.get(name) if isinstance(rows, dict) else None
        if r and r.get("delta_AP") is not None:
            out[name] = {"mean": r["delta_AP"][0], "half_width": r["delta_AP"][1], "seeds": len(r["seeds"])}
    return out or None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--timing", default="results/bench/transform_calls.json")
    ap.add_argument("--out", default="studies/presets/pareto/result")
    a = ap.parse_args(argv)
    timing = json.loads((REPO / a.timing).read_text())["per_call"]
    edges = edge_errors()
    rows = []
    for p in ("fast", "balanced", "accurate"):
        rows.append(
            {
                "preset": p,
                "cold_ms": timing[f"{p}_cold"]["median_ms"],
                "warm_ms": timing[f"{p}_warm"]["median_ms"],
                "cold_cpu_ms": timing[f"{p}_cold"]["median_cpu_ms"],
                "warm_cpu_ms": timing[f"{p}_warm"]["median_cpu_ms"],
                **edges[p],
                "realism": realism(p),
                "study": study_gain(p),
            }
        )
    out = REPO / a.out
    out.mkdir(parents=True, exist_ok=True)
    cmd = "python -m studies.presets.pareto " + " ".join(argv if argv is not None else sys.argv[1:])
    (out / "presets.json").write_text(json.dumps({"command": cmd, "timing_source": a.timing, "rows": rows}, indent=1))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, key, label in (
        (axes[0], "warm_ms", "ms per call, image seen before (warm)"),
        (axes[1], "cold_ms", "ms per call, new image (cold)"),
    ):
        xs = [r[key] for r in rows]
        ys = [r["edge_alpha_mae"] for r in rows]
        ax.plot(xs, ys, "o-", color="tab:blue")
        for r, x, y in zip(rows, xs, ys):
            kid = f", KID {r['realism']['kid']:.3f}" if r["realism"] else ""
            ax.annotate(f"{r['preset']}{kid}", (x, y), textcoords="offset points", xytext=(6, 6))
        ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("edge error: alpha MAE vs 4x render")
        ax.grid(True, which="both", alpha=0.3)
    if "overlay" in timing:
        axes[0].axvline(timing["overlay"]["median_ms"] * 15, color="tab:red", ls="--", lw=1)
        axes[0].text(
            timing["overlay"]["median_ms"] * 15,
            max(r["edge_alpha_mae"] for r in rows),
            " 15x OverlayElements",
            color="tab:red",
            va="top",
        )
    axes[1].axvline(250, color="tab:red", ls="--", lw=1)
    axes[1].text(250, max(r["edge_alpha_mae"] for r in rows), " 250 ms", color="tab:red", va="top")
    fig.suptitle(
        "Presets: speed vs edge accuracy (lower left is better); annotated with the realism KID where measured"
    )
    fig.tight_layout()
    save_figure_jpeg(fig, out / "presets_pareto.jpg", dpi=110)

    def fmt_real(r):
        if not r:
            return "not measured"
        return f"KID {r['kid']:.3f} ± {r['kid_sd']:.3f}, AUC {r['auc']:.3f} [{r['auc_ci95'][0]:.3f}, {r['auc_ci95'][1]:.3f}]"

    def fmt_study(s):
        if not s:
            return "not trained with"
        return "; ".join(f"{k}: {v['mean']:+.3f} ± {v['half_width']:.3f} ({v['seeds']} seeds)" for k, v in s.items())

    lines = [
        "# Presets: speed against accuracy",
        "",
        f"Command: `{cmd.strip()}`; timings from `{a.timing}` "
        "(wall ms, medians; CPU in brackets); edge error measured by this script; realism and study numbers "
        "read from the files named in `presets.json`.",
        "",
        "| preset | layers | cold ms | warm ms | edge alpha MAE vs 4x | realism on TraCon (Lite0, lower KID / AUC nearer 0.5 is better) | study: ΔAP50:95 vs original |",
        "|---|---|---:|---:|---:|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['preset']} | {r['layers']} | {r['cold_ms']:.0f} ({r['cold_cpu_ms']:.0f}) | "
            f"{r['warm_ms']:.1f} ({r['warm_cpu_ms']:.1f}) | {r['edge_alpha_mae']:.3f} | {fmt_real(r['realism'])} | "
            f"{fmt_study(r['study'])} |"
        )
    lines += [
        "",
        "Realism sources (the pipeline changes between stops; KID differences below ~2 standard deviations are "
        "not resolved): " + "; ".join(f"{r['preset']}: `{r['realism']['source']}`" for r in rows if r["realism"]),
        "",
        "![Pareto](presets_pareto.jpg)",
        "",
    ]
    (out / "presets.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
