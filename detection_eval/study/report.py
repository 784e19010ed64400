"""The study's tables and plots: means with 95 % intervals, paired differences by seed, size histograms."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np

from detection_eval.data import DetectionSet
from detection_eval.study.arms import ARM_FLAGS, PER_SEED_ARMS, uses_pool
from detection_eval.study.config import StudyConfig, repo_path
from detection_eval.study.run_table import RUNS_FILE, collect_runs, metrics_dir, write_run_record
from detection_eval.study.runs import nan_to_none
from detection_eval.study.splits import real_box_height_fractions

log = logging.getLogger("detection_eval.study")


MAX_PICTURE_SIDE = 1600


def save_figure(fig, path: Path, dpi: int = 120) -> None:
    """The figure as a JPEG (quality 90) of at most :data:`MAX_PICTURE_SIDE` pixels on its longer side."""
    dpi = min(dpi, MAX_PICTURE_SIDE / max(fig.get_size_inches()))
    fig.savefig(path, dpi=dpi, pil_kwargs={"quality": 90})


def mean_ci95(values) -> tuple[float, float]:
    """Mean and half-width of the two-sided 95% Student-t interval (nan half-width for fewer than 2 values)."""
    from scipy import stats

    v = np.asarray([x for x in values if x is not None], np.float64)
    if v.size == 0:
        return float("nan"), float("nan")
    if v.size < 2:
        return float(v.mean()), float("nan")
    return float(v.mean()), float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))


METRIC_COLUMNS = (
    ("AP", "AP50:95"),
    ("AP50", "AP50"),
    ("AP_small", "AP_S"),
    ("AP_medium", "AP_M"),
    ("AP_large", "AP_L"),
)


def group_of(row: dict) -> str:
    """Table row label: the arm, with its amount of inserted images when it has one."""
    return row["arm"] if row.get("amount") is None else f"{row['arm']} n={row['amount']}"


def paired_deltas(rows: list[dict], group: str, other: str, key: str = "AP", split: str = "metrics") -> list[float]:
    """``group`` minus ``other`` per seed, over the seeds both have (same seed = same thinned real subset);
    ``split`` "metrics" (val) or "dev_metrics"."""
    a = {r["seed"]: (r.get(split) or {}).get(key) for r in rows if group_of(r) == group}
    b = {r["seed"]: (r.get(split) or {}).get(key) for r in rows if group_of(r) == other}
    return [a[s] - b[s] for s in sorted(a) if s in b and a[s] is not None and b[s] is not None]


def summarize(rows: list[dict], reference: str = "original") -> tuple[str, dict]:
    """Markdown table: per arm (and amount) mean ± 95 % t-interval over seeds of each metric, and the paired
    differences of AP50:95 to ``reference`` and, for inserted arms, to ``naive_paste`` at the same amount."""
    groups = list(dict.fromkeys(group_of(r) for r in rows))
    summary = {}
    fmt = lambda m, h: "n/a" if math.isnan(m) else (f"{m:.3f}" if math.isnan(h) else f"{m:.3f} ± {h:.3f}")
    head = (
        "| arm | seeds | train images (real + inserted) | "
        + " | ".join(c[1] for c in METRIC_COLUMNS)
        + f" | ΔAP50:95 vs {reference} (paired) | ΔAP50:95 vs naive_paste (paired) | dev AP50:95 | "
        f"dev ΔAP50:95 vs {reference} | train s/run | train img/s |"
    )
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for g in groups:
        rs = sorted((r for r in rows if group_of(r) == g), key=lambda r: r["seed"])
        arm, amount = rs[0]["arm"], rs[0].get("amount")
        s = {"arm": arm, "amount": amount, "seeds": [r["seed"] for r in rs]}
        for key, _ in METRIC_COLUMNS:
            s[key] = mean_ci95([r["metrics"][key] for r in rs])
        s["delta_AP"] = (
            mean_ci95(paired_deltas(rows, g, reference)) if arm != reference else (float("nan"), float("nan"))
        )
        naive = f"naive_paste n={amount}"
        s["delta_AP_vs_naive"] = (
            mean_ci95(paired_deltas(rows, g, naive))
            if arm not in (reference, "naive_paste") and naive in groups
            else (float("nan"), float("nan"))
        )
        s["dev_AP"] = mean_ci95([(r.get("dev_metrics") or {}).get("AP") for r in rs])
        s["dev_delta_AP"] = (
            mean_ci95(paired_deltas(rows, g, reference, split="dev_metrics"))
            if arm != reference
            else (float("nan"), float("nan"))
        )
        s["train_seconds"] = float(np.median([r["train_seconds"] for r in rs]))
        s["train_images_per_second"] = float(np.median([r["train_images_per_second"] for r in rs]))
        real = int(np.median([r["real_images"] for r in rs]))
        ins = int(np.median([r.get("inserted_images", 0) for r in rs]))
        summary[g] = s
        dn = fmt(*s["delta_AP_vs_naive"]) if not math.isnan(s["delta_AP_vs_naive"][0]) else "—"
        lines.append(
            f"| {g} | {len(rs)} | {real} + {ins} | "
            + " | ".join(fmt(*s[k]) for k, _ in METRIC_COLUMNS)
            + f" | {fmt(*s['delta_AP']) if arm != reference else '—'} | {dn} | {fmt(*s['dev_AP'])} | "
            f"{fmt(*s['dev_delta_AP']) if arm != reference else '—'} | {s['train_seconds']:.0f} | "
            f"{s['train_images_per_second']:.2f} |"
        )
    return "\n".join(lines) + "\n", summary


def plot_summary(rows: list[dict], path: Path, reference: str = "original") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = list(dict.fromkeys(group_of(r) for r in rows))
    fig, axes = plt.subplots(1, 2, figsize=(4 + 1.6 * len(groups), 4))
    for ax, (key, title) in zip(axes, (("AP", "AP50:95"), ("AP50", "AP50"))):
        for x, g in enumerate(groups):
            vals = [r["metrics"][key] for r in rows if group_of(r) == g]
            m, h = mean_ci95(vals)
            ax.scatter([x] * len(vals), vals, color="0.6", s=14, zorder=2)
            ax.errorbar(
                [x],
                [m],
                yerr=[[0 if math.isnan(h) else h]] * 2,
                fmt="o",
                color="C0" if g == reference else "C1",
                capsize=6,
                markersize=7,
                zorder=3,
            )
        ax.set_xticks(range(len(groups)), groups, rotation=20)
        ax.set_title(f"TraCon val {title} (mean, 95% CI; grey = seeds)")
        ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)
    plt.close(fig)


def plot_amounts(rows: list[dict], path: Path, reference: str = "original") -> bool:
    """Paired ΔAP50:95 to ``reference`` (mean, 95 % CI, seeds as dots) against the number of inserted images, one
    line per pool arm with at least two amounts or sharing an amount with one that has; False when nothing to draw."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    arms = list(dict.fromkeys(r["arm"] for r in rows if r.get("amount") is not None))
    if len({r["amount"] for r in rows if r.get("amount") is not None}) < 2:
        return False
    fig, ax = plt.subplots(figsize=(7, 4.2))
    for k, arm in enumerate(arms):
        amounts = sorted({r["amount"] for r in rows if r["arm"] == arm and r.get("amount") is not None})
        pts = []
        for a in amounts:
            d = paired_deltas(rows, f"{arm} n={a}", reference)
            if d:
                m, h = mean_ci95(d)
                pts.append((a, m, 0.0 if math.isnan(h) else h, d))
        if not pts:
            continue
        off = 1.0 + 0.03 * (k - (len(arms) - 1) / 2)  # a small multiplicative offset so the bars do not overlap
        xs = [a * off for a, *_ in pts]
        ax.errorbar(
            xs,
            [m for _, m, _, _ in pts],
            yerr=[h for *_, h, _ in pts],
            fmt="o-",
            capsize=5,
            color=f"C{k}",
            label=f"{arm} (seeds: {', '.join(str(len(d)) for *_, d in pts)})",
        )
        for x, (_, _, _, d) in zip(xs, pts):
            ax.scatter([x] * len(d), d, color=f"C{k}", s=10, alpha=0.35)
    ax.axhline(0, color="0.3", lw=1)
    ax.set_xscale("log")
    ticks = sorted({r["amount"] for r in rows if r.get("amount") is not None})
    ax.set_xticks(ticks, [str(t) for t in ticks])
    ax.minorticks_off()
    ax.set_xlabel("inserted images per run (beside the real subset's 219 images)")
    ax.set_ylabel(f"paired ΔAP50:95 vs {reference}")
    ax.set_title("TraCon val: gain by amount of inserted data (mean, 95% CI)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)
    plt.close(fig)
    return True


def plot_size_histograms(cfg: StudyConfig, train: DetectionSet, val: DetectionSet, path: Path) -> dict:
    """Box height / image height of real train, real val and each arm's pool; returns their medians."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    series = {"real train": real_box_height_fractions(train), "real val": real_box_height_fractions(val)}
    for arm in ARM_FLAGS:  # every pool generated so far (the other study configs' arms too; per-seed pools pooled)
        arm_dir = repo_path(cfg.cache_dir) / arm
        files = (
            sorted(arm_dir.glob("seed*/pool/manifest.json"))
            if arm in PER_SEED_ARMS
            else [arm_dir / "pool" / "manifest.json"]
        )
        heights = [
            h for mf in files if mf.exists() for e in json.loads(mf.read_text()) for h in e.get("box_heights_frac", [])
        ]
        if uses_pool(arm) and heights:
            series[f"{arm} pool"] = heights
    fig, ax = plt.subplots(figsize=(7, 4))
    bins = np.linspace(0, 1, 41)
    for k, (name, v) in enumerate(series.items()):
        if len(v):
            ax.hist(
                v,
                bins=bins,
                density=True,
                histtype="step",
                lw=1.8,
                color=f"C{k}",
                label=f"{name} (n={len(v)}, median {np.median(v):.2f})",
            )
    ax.set_xlabel("box height / image height")
    ax.set_ylabel("density")
    ax.set_title("Object sizes: real cones vs inserted")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)
    plt.close(fig)
    return {k: float(np.median(v)) for k, v in series.items() if len(v)}


def write_summary(
    cfg: StudyConfig, config_path: str, command: str, train: DetectionSet | None = None, val: DetectionSet | None = None
) -> str:
    results = repo_path(cfg.results_dir)
    all_rows = collect_runs(cfg)
    rows = [r for r in all_rows if r["arm"] in ARM_FLAGS]
    if not rows:
        raise FileNotFoundError(f"no run results in {results / RUNS_FILE} or {metrics_dir(cfg)}")
    order = {a: i for i, a in enumerate(ARM_FLAGS)}
    rows.sort(key=lambda r: (order[r["arm"]], r.get("amount") or 0, r["seed"]))
    table, summary = summarize(rows, cfg.reference_arm)
    plot_summary(rows, results / "ap_by_arm.jpg", cfg.reference_arm)
    r0 = rows[0]
    gen = {}
    for a in dict.fromkeys(r["arm"] for r in rows):
        per_image = [
            r["generation_seconds_per_image"]
            for r in rows
            if r["arm"] == a and r.get("generation_seconds_per_image") is not None
        ]
        if per_image:
            gen[a] = float(np.median(per_image))
    note = (
        f"Detector: `{r0['detector']['model']['backbone']}` (width {r0['detector']['model']['width']}), "
        f"{r0['img_size']} px, {r0['iterations']} iterations x batch {r0['batch_size']} per run, "
        f"{r0.get('threads', 1)} CPU thread(s) per run. Evaluated on TraCon val ({r0['metrics']['num_images']} "
        f"images, {r0['metrics']['num_gt']} cones) with pycocotools. Mean ± half-width of the 95% Student-t "
        f"interval over seeds; Δ columns are paired by seed (seed k of every arm trains on the same thinned "
        f"real subset, redrawn per seed, so its variance is inside the interval).\n"
    )
    if gen:
        note += (
            "Offline generation, median seconds per inserted image: "
            + ", ".join(f"{a} {s:.1f}" for a, s in gen.items())
            + ".\n"
        )
    total = sum(r["train_seconds"] + r.get("eval_seconds", 0.0) for r in rows)
    note += (
        f"Training and evaluation time summed over the {len(rows)} runs: {total / 60:.0f} min of one CPU "
        f"thread each (wall time about half of that with one process per core, see the README).\n"
    )
    md = (
        f"# Detection study: TraCon cones\n\nReproduce: `aias-study --config {config_path}` (generate, train, "
        f"summarize); this table was written by `{command}`.\n\n{note}\n{table}\n"
        f"![AP by arm](ap_by_arm.jpg)\n"
    )
    if plot_amounts(rows, results / "ap_by_amount.jpg", cfg.reference_arm):
        md += "\n![gain by amount of inserted data](ap_by_amount.jpg)\n"
    if train is not None and val is not None:
        medians = plot_size_histograms(cfg, train, val, results / "size_histograms.jpg")
        md += (
            "\nObject sizes (median box height / image height): "
            + ", ".join(f"{k} {v:.3f}" for k, v in medians.items())
            + "\n\n![sizes](size_histograms.jpg)\n"
        )
    (results / "table.md").write_text(md)
    write_run_record(cfg, config_path, command, all_rows)
    (results / "summary.json").write_text(
        json.dumps(
            nan_to_none(
                {a: {k: (list(v) if isinstance(v, tuple) else v) for k, v in s.items()} for a, s in summary.items()}
            ),
            indent=1,
        )
    )
    return md
