"""How a dataset's labellers draw their boxes around the object: per side, how far the label lies outside the
instance's mask (GrabCut from the label box, ``aias_augment.assets.bank.lift.cut_out``), as a fraction of the box's
width or height. Inserted boxes are mask-tight; a dataset whose labels carry margins would need them too.

    python -m studies.assets.box_convention --split train --out studies/assets/box_convention/result/box_convention.json

The same measurement on any labelled folder: ``aias-assets box-convention --yolo DIR --class-names cone --label
cone --out convention.json``, and ``aias-augment --box-convention convention.json`` makes inserted boxes follow it.

GrabCut starts from the label box (outside it is background), so a label that cuts into the object shows as a
margin of 0, never below: the numbers bound the labels' looseness from above only on that side.
"""

import argparse
import json
import sys
import time
from pathlib import Path

from aias_augment.assets.bank.lift import LiftConfig, measure_box_convention
from aias_augment.core.config import data_root
from detection_eval.data import load_yolo_dir, read_image_rgb


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--split", default="train")
    ap.add_argument("--out", default="studies/assets/box_convention/result/box_convention.json")
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    ds = load_yolo_dir(data_root() / "tracon", a.split, names=("cone",))
    items = ((r.image_path, read_image_rgb(r.image_path), r.boxes_xyxy) for r in ds.records if len(r.boxes_xyxy))
    margins, measured = measure_box_convention(items, LiftConfig())
    report = {
        "command": f"python -m studies.assets.box_convention --split {a.split} --out {a.out}",
        "dataset": f"TraCon {a.split}",
        "box_convention": list(margins),
        **measured,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    Path(a.out).write_text(json.dumps(report, indent=1))
    print(json.dumps(report["margin_frac_percentiles"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
