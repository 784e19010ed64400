"""Generation time per pool image of each study arm, read from the study logs committed beside the tables (the
study logs a running mean every 10 images; the last one of a complete pool is its mean, warm-up included).

    python scripts/pool_generation_times.py results/study_core/logs results/study_probe/logs \
        --out results/study_core/generation_times.md

The runs shared two cores with a training on the other one, so the figures are what a user sees beside other work,
not a benchmark (``results/bench`` has those)."""

import argparse
import gzip
import re
import statistics
from collections import defaultdict
from pathlib import Path

LINE = re.compile(r"INFO detection_eval\.study: (\w+): (\d+)/(\d+) pool images, ([0-9.]+) s/image")


def pool_means(folder: Path) -> dict[tuple[str, int], list[tuple[float, str]]]:
    """{(arm, pool size): [(s/image of a complete pool, log name), ...]} over the folder's logs."""
    out = defaultdict(list)
    for path in sorted(folder.glob("*.log*")):
        text = gzip.open(path, "rt").read() if path.suffix == ".gz" else path.read_text()
        for arm, done, total, s in LINE.findall(text):
            if done == total:
                out[(arm, int(total))].append((float(s), path.name))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folders", nargs="+", type=Path)
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    rows = defaultdict(list)
    for folder in a.folders:
        for key, vals in pool_means(folder).items():
            rows[key] += [(s, f"{folder.parent.name}/{name}") for s, name in vals]
    lines = [
        "# Generation time per pool image",
        "",
        "```bash",
        "python scripts/pool_generation_times.py " + " ".join(str(f) for f in a.folders) + f" --out {a.out}",
        "```",
        "",
        (__doc__.split("\n\n")[2]).replace("\n", " "),
        "",
        "| arm | pool images | pools | s / image (median) | range |",
        "|---|---|---|---|---|",
    ]
    for (arm, n), vals in sorted(rows.items()):
        s = [v for v, _ in vals]
        lines.append(f"| {arm} | {n} | {len(s)} | {statistics.median(s):.1f} | {min(s):.1f}-{max(s):.1f} |")
    a.out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
