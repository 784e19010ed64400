"""Per-seed val AP50:95 and paired differences of chosen arm pairs from a table's runs (markdown).

    python -m detection_eval.study.pairs studies/detection/core/result/runs.jsonl \
        --out studies/detection/core/result/pairs.md
    python -m detection_eval.study.pairs studies/detection/probe/result/runs.jsonl \
        studies/detection/probe_n200/result/runs.jsonl

Several tables are read as one study (the same seeds and splits, e.g. an amount axis run from its own config).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy import stats

from detection_eval.study.run_table import read_runs

ARMS = [
    "original",
    "inserted",
    "inserted n=200",
    "inserted_online",
    "naive_paste",
    "copy_paste",
    "lifted",
    "no_placement",
    "inserted_fixed_scale",
    "inserted_scene_scale",
    "inserted_neutral_ambient",
    "inserted_closeup_sizes",
    "inserted_closeup",
    "inserted_gazebo_cone",
    "inserted_decoys",
    "naive_paste_procedural",
    "naive_paste_procedural n=200",
    "inserted_procedural",
    "inserted_arranged",
    "inserted_anchor",
    "inserted_anchor n=200",
    "inserted_filtered",
    "inserted_edges",
    "inserted_no_anchor",
    "inserted_strong_contact",
    "inserted_mixed_naive",
    "inserted_mixed_naive n=200",
    "copy_paste n=200",
    "inserted_naive_share",
    "naive_paste_procedural_at_82ec856",
    "copy_paste_at_43dcde4",
]
PAIRS = [
    ("inserted", "original"),
    ("inserted", "naive_paste_procedural"),
    ("inserted", "copy_paste"),
    ("copy_paste", "original"),
    ("lifted", "original"),
    ("inserted", "lifted"),
    ("inserted_online", "original"),
    ("inserted_online", "inserted"),
    ("inserted n=200", "original"),
    ("inserted n=200", "inserted"),
    ("inserted n=200", "naive_paste_procedural n=200"),
    ("naive_paste_procedural n=200", "naive_paste_procedural"),
    ("inserted_mixed_naive", "inserted"),
    ("inserted_mixed_naive", "naive_paste_procedural"),
    ("inserted_mixed_naive n=200", "inserted n=200"),
    ("inserted_mixed_naive n=200", "naive_paste_procedural n=200"),
    ("inserted_mixed_naive n=200", "inserted_mixed_naive"),
    ("inserted_mixed_naive", "copy_paste n=200"),
    ("inserted_anchor n=200", "copy_paste n=200"),
    ("copy_paste n=200", "copy_paste"),
    ("copy_paste n=200", "original"),
    ("inserted_naive_share", "original"),
    ("inserted_naive_share", "inserted_mixed_naive"),
    ("inserted_naive_share", "inserted_anchor n=200"),
    ("inserted_naive_share", "naive_paste_procedural n=200"),
    ("inserted_naive_share", "copy_paste n=200"),
    ("naive_paste_procedural", "original"),
    ("lifted", "naive_paste"),
    ("copy_paste", "naive_paste"),
    ("lifted", "copy_paste"),
    ("inserted_gazebo_cone", "naive_paste"),
    ("inserted_gazebo_cone", "copy_paste"),
    ("inserted_gazebo_cone", "inserted_scene_scale"),
    ("inserted_scene_scale", "inserted_fixed_scale"),
    ("inserted_scene_scale", "naive_paste"),
    ("inserted_scene_scale", "original"),
    ("no_placement", "naive_paste"),
    ("inserted_fixed_scale", "naive_paste"),
    ("naive_paste", "original"),
    ("inserted_gazebo_cone", "inserted_neutral_ambient"),
    ("inserted_neutral_ambient", "naive_paste"),
    ("inserted_closeup_sizes", "inserted_neutral_ambient"),
    ("inserted_closeup_sizes", "naive_paste"),
    ("inserted_closeup", "inserted_gazebo_cone"),
    ("inserted_closeup", "naive_paste"),
    ("inserted_decoys", "inserted_gazebo_cone"),
    ("inserted_procedural", "inserted_gazebo_cone"),
    ("inserted_procedural", "naive_paste"),
    ("inserted_procedural", "naive_paste_procedural"),
    ("naive_paste_procedural", "naive_paste"),
    ("inserted_procedural", "original"),
    ("inserted_arranged", "inserted_procedural"),
    ("inserted_anchor", "original"),
    ("inserted_anchor", "inserted"),
    ("inserted_anchor", "copy_paste"),
    ("inserted_anchor", "naive_paste_procedural"),
    ("inserted_anchor n=200", "inserted_anchor"),
    ("inserted_anchor n=200", "naive_paste_procedural n=200"),
    ("inserted_anchor n=200", "original"),
    ("inserted_filtered", "inserted_anchor"),
    ("inserted_edges", "inserted_anchor"),
    ("inserted_filtered", "original"),
    ("inserted_edges", "original"),
    ("inserted_no_anchor", "inserted_anchor"),
    ("inserted_no_anchor", "inserted"),
    ("inserted_no_anchor", "original"),
    ("inserted_strong_contact", "inserted"),
    ("inserted_strong_contact", "inserted_anchor"),
    ("inserted_strong_contact", "naive_paste_procedural"),
    ("inserted_strong_contact", "copy_paste"),
    ("inserted_strong_contact", "inserted_procedural"),
    ("inserted", "inserted_procedural"),
    ("inserted_strong_contact", "original"),
    ("inserted", "naive_paste"),
    ("inserted_procedural", "naive_paste_procedural_at_82ec856"),
    ("naive_paste_procedural_at_82ec856", "naive_paste"),
    ("copy_paste_at_43dcde4", "naive_paste"),
    ("lifted", "copy_paste_at_43dcde4"),
    ("inserted_gazebo_cone", "copy_paste_at_43dcde4"),
    ("naive_paste_procedural", "naive_paste_procedural_at_82ec856"),
    ("copy_paste", "copy_paste_at_43dcde4"),
]


def pairs_markdown(tables: list[str]) -> str:
    """The per-seed table and the paired differences of :data:`PAIRS` over the runs of ``tables``."""
    lines: list[str] = []
    ap: dict[tuple[str, int], dict[str, float]] = {}
    runs = [r for t in tables for _, r in sorted(read_runs(Path(t)).items())]
    amounts: dict[str, set] = {}
    for r in runs:
        amounts.setdefault(r["arm"], set()).add(r.get("amount"))
    for r in runs:  # an arm run at several amounts: its smallest keeps the arm's name, the others say theirs
        label = r["arm"] if r.get("amount") in (None, min(amounts[r["arm"]])) else f"{r['arm']} n={r['amount']}"
        ap[(label, r["seed"])] = {"val": r["metrics"]["AP"], "dev": (r.get("dev_metrics") or {}).get("AP")}
    seeds = sorted({s for _, s in ap})
    lines.append("| arm | " + " | ".join(f"seed {s}" for s in seeds) + " | mean |")
    lines.append("|---|" + "---|" * (len(seeds) + 1))
    for a in ARMS:
        v = [ap.get((a, s), {}).get("val") for s in seeds]
        got = [x for x in v if x is not None]
        if not got:
            continue
        lines.append(
            f"| {a} | "
            + " | ".join("—" if x is None else f"{x:.3f}" for x in v)
            + f" | {np.mean(got):.3f} (n={len(got)}) |"
        )
    lines.append("")
    lines.append("| pair | seeds | val Δ per seed | val mean Δ [95 %] | dev mean Δ [95 %] |")
    lines.append("|---|---|---|---|---|")
    for a, b in PAIRS:
        both = [s for s in seeds if (a, s) in ap and (b, s) in ap]
        if not both:
            continue
        cells = []
        for split in ("val", "dev"):
            if any(ap[(x, s)][split] is None for x in (a, b) for s in both):
                cells.append("—")  # a study without a development split
                continue
            d = np.array([ap[(a, s)][split] - ap[(b, s)][split] for s in both])
            h = stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / np.sqrt(len(d)) if len(d) > 1 else float("nan")
            ci = f" [{d.mean() - h:+.3f}, {d.mean() + h:+.3f}]" if len(d) > 1 else " (one seed)"
            cells.append(f"{d.mean():+.3f}{ci}")
        per = " / ".join(f"{ap[(a, s)]['val'] - ap[(b, s)]['val']:+.3f}" for s in both)
        lines.append(f"| {a} − {b} | {len(both)} | {per} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("tables", nargs="+", help="runs.jsonl files read as one study")
    p.add_argument("--out", help="write the markdown here (default: print it)")
    args = p.parse_args(argv)
    missing = [t for t in args.tables if not Path(t).is_file()]
    if missing:
        p.error(f"no such runs.jsonl: {missing}")
    text = pairs_markdown(args.tables)
    if args.out:
        Path(args.out).write_text(text)
    else:
        print(text, end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
