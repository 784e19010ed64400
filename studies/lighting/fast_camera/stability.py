"""How far the sun direction of balanced's lighting computation moves when only the analysis' random draws change.

For every labelled sunny photo with a direction (``run.halves``: development and held-out), the 640 px lighting
(``160,640,640``: for photos up to 640 px wide, balanced's own computation) is run with the analysis' generator
seeded 0, 1, 2 and 3 (``ANALYSIS_SEED``); each seed's direction is compared with seed 0's. A direction that is a
property of the photo agrees with itself whatever the seed.

    taskset -c 0 python -m studies.lighting.fast_camera.stability --out result/stability/<name>.json
    python -m studies.lighting.fast_camera.stability --summarise result/stability/*.json
"""

import argparse
import json
import sys
from pathlib import Path
from unittest import mock

import numpy as np

import aias_augment.analyse.analysis as analysis
from studies.lighting.fast_camera.cues import lighting_inputs
from studies.lighting.fast_camera.run import angle_deg, halves, sunny_rows, variant
from studies.lighting.sun_asymmetric.run import FORCED_THRESHOLD, load_photo

SEEDS = (0, 1, 2, 3)


def directions() -> dict:
    rows = sunny_rows()
    cfg = variant("160,640,640", sun_threshold=FORCED_THRESHOLD)
    out = {}
    for half, part in halves(rows).items():
        for r in part:
            if not np.all(np.isfinite([r[f"balanced_sun_{x}"] for x in "xyz"])):
                continue
            img = load_photo(r["photo"])
            suns = []
            for seed in SEEDS:
                with mock.patch.object(analysis, "ANALYSIS_SEED", seed):
                    suns.append(lighting_inputs(img, cfg)[1].tolist())
            out[r["photo"]] = {"half": half, "suns": suns}
            moved = [round(angle_deg(np.array(s), np.array(suns[0])), 1) for s in suns[1:]]
            print(f"[{len(out)}] {r['photo']} seeds 1-3 vs 0: {moved} deg", flush=True)
    return out


def summary(per_photo: dict) -> dict:
    """Per half: photos, and for seeds 1-3 how many directions stay within 30 deg of seed 0's."""
    res = {}
    for half in ("dev", "heldout", "all"):
        rows = [v for v in per_photo.values() if half == "all" or v["half"] == half]
        res[half] = {
            "photos": len(rows),
            "within_30_deg_of_seed_0": [
                int(sum(angle_deg(np.array(v["suns"][k]), np.array(v["suns"][0])) <= 30 for v in rows))
                for k in range(1, len(SEEDS))
            ],
        }
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="write the per-photo directions and the summary here")
    ap.add_argument("--summarise", type=Path, nargs="*", help="print the summaries of these result files")
    a = ap.parse_args(argv)
    if a.summarise:
        for p in a.summarise:
            print(p.name, json.dumps(json.loads(p.read_text())["summary"]))
        return 0
    if a.out is None:
        ap.error("--out is required to run")
    per_photo = directions()
    report = {"summary": summary(per_photo), "seeds": list(SEEDS), "per_photo": per_photo}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(report, indent=1))
    print(json.dumps(report["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
