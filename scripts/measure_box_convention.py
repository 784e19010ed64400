"""How a dataset's labellers draw their boxes around the object: per side, how far the label lies outside the
instance's mask (GrabCut from the label box, ``aias_augment.assets.bank.lift.cut_out``), as a fraction of the box's
width or height. Inserted boxes are mask-tight; a dataset whose labels carry margins would need them too.

    python scripts/measure_box_convention.py --split train --out results/study_probe/box_convention.json

GrabCut starts from the label box (outside it is background), so a label that cuts into the object shows as a
margin of 0, never below: the numbers bound the labels' looseness from above only on that side.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from aias_augment.assets.bank.lift import LiftConfig, cut_out  # noqa: E402
from aias_augment.core.config import data_root  # noqa: E402
from detection_eval.data import load_yolo_dir, read_image_rgb  # noqa: E402

SIDES = ("left", "top", "right", "bottom")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--split", default="train")
    ap.add_argument("--out", default="results/study_probe/box_convention.json")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    ds = load_yolo_dir(data_root() / "tracon", a.split, names=("cone",))
    margins, rejected = [], {}
    for r in ds.records:
        if len(r.boxes_xyxy) == 0:
            continue
        img = read_image_rgb(r.image_path)
        for k, b in enumerate(r.boxes_xyxy):
            others = [r.boxes_xyxy[j] for j in range(len(r.boxes_xyxy)) if j != k]
            cut, why = cut_out(img, b, others, LiftConfig())
            if cut is None:
                rejected[why] = rejected.get(why, 0) + 1
            else:
                margins.append(cut.meta["label_margins_frac"])
    m = np.asarray(margins)
    report = {
        "command": f"python scripts/measure_box_convention.py --split {a.split} --out {a.out}",
        "dataset": f"TraCon {a.split}",
        "instances_measured": len(m),
        "rejected": rejected,
        "margin_frac_percentiles": {
            side: {str(q): round(float(np.percentile(m[:, i], q)), 4) for q in (10, 25, 50, 75, 90)}
            for i, side in enumerate(SIDES)
        },
        "seconds": round(time.perf_counter() - t0, 1),
    }
    Path(a.out).write_text(json.dumps(report, indent=1))
    print(json.dumps(report["margin_frac_percentiles"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
