"""Which cue makes fast's 320 px sun differ from the 640 px one: the three resolution-dependent parts of the image-cue
sun swapped one at a time between the two copies, on the development half of the labelled sunny photos.

For every development photo (``run.halves``), fast is analysed with the lighting on a 320 px copy and on the camera's
640 px copy (``160,640,320`` and ``160,640,640``: for photos up to 640 px wide the latter is balanced's own lighting).
The inputs ``estimate_lighting`` receives in each are kept (image, camera, ground mask, config) and the
frame is prepared from both; then the sun is taken (``image_cue_sun``) from a frame that mixes three groups, each from
the 320 (``l``) or the 640 (``h``) preparation:

- sky: the sky / sun-disc cue's copy (``analysis_width``: 320 against 400 px) and its linear radiance;
- measure: the lit / shadow measurement on the ground, its region and the cast-shadow axis (full copy: 320 or 640);
- side: the image the side cues (walls, shadow ends) run on (320 or 640 px; ``side_analysis_width`` 800).

``lll`` is fast today, ``hhh`` the 640 px lighting; each code gives the agreement with balanced's recorded direction.
The lighting takes no random draws (its pixel samples are evenly spaced): only the camera's RANSAC draws.

``--seeds``: instead, both lightings with other seeds of the analysis' generator (``ANALYSIS_SEED``: the camera's
RANSAC draws) against balanced's recorded direction: how far balanced's own computation agrees with itself when only
its random draws change.

    taskset -c 1 nice .venv/bin/python -m studies.lighting.fast_camera.cues              # result/cues.json
    taskset -c 1 nice .venv/bin/python -m studies.lighting.fast_camera.cues --seeds 1 2 3  # result/seeds.json
"""

import argparse
import dataclasses
import itertools
import json
import sys
from pathlib import Path
from unittest import mock

import numpy as np

import aias_augment.analyse.analysis as analysis
import aias_augment.analyse.lighting.sun_direction as sun_direction
from aias_augment.analyse.lighting.frame import prepare_frame
from aias_augment.core.frame import Frame
from studies.lighting.fast_camera.run import angle_deg, halves, sunny_rows, variant
from studies.lighting.sun_asymmetric.run import FORCED_THRESHOLD, load_photo

GROUPS = ("sky", "measure", "side")


def lighting_inputs(img: np.ndarray, cfg) -> tuple:
    """What ``estimate_lighting`` receives inside ``analyse_scene(img, cfg)``: (image, camera, meta, a copy of the
    config), and the analysis' sun direction (NaN where none)."""
    got = {}
    real = analysis.estimate_lighting

    def keep(image, intrinsics, cam_from_world, meta, envmap=None, *, config):
        got["inputs"] = (image, intrinsics, dict(meta), config)
        return real(image, intrinsics, cam_from_world, meta, envmap, config=config)

    with mock.patch.object(analysis, "estimate_lighting", keep):
        est = analysis.analyse_scene(Frame(img, None), cfg).lighting
    sun = est.sun_direction_in_cam if est.dominant_sun else np.full(3, np.nan)
    return got["inputs"], np.asarray(sun, float)


def mixed_suns(inputs: dict) -> dict[str, np.ndarray]:
    """The sun (camera frame; NaN at or below the horizon) of every mix of the groups, keyed ``sky measure side``."""
    prepared = {}
    for k, (image, K, meta, config) in inputs.items():
        prepared[k] = (prepare_frame(image, K, np.eye(3), meta, config), config)
    real_side = sun_direction.sun_side_cue
    out = {}
    for code in itertools.product("lh", repeat=3):
        sky, meas, side = (prepared[c][0] for c in code)
        ctx = dataclasses.replace(
            meas, small=sky.small, K_small=sky.K_small, linear_small=sky.linear_small, n_above_small=sky.n_above_small
        )

        def side_cue(image, K, up, grid, _side=side, **kw):
            return real_side(_side.img, _side.K, up, grid, **kw)

        with mock.patch.object(sun_direction, "sun_side_cue", side_cue):
            est = sun_direction.image_cue_sun([ctx], ctx.up_in_world, prepared[code[1]][1])
        d = ctx.R_cw @ est.direction_in_world
        out["".join(code)] = d if float(d @ ctx.up_in_cam) > 0.0 else np.full(3, np.nan)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--half", choices=("dev", "heldout"), default="dev")
    ap.add_argument("--seeds", type=int, nargs="*", default=None, help="other analysis seeds (instead of the mixes)")
    ap.add_argument("--out", type=Path, default=None, help="default: result/cues.json, with --seeds result/seeds.json")
    a = ap.parse_args(argv)
    out = a.out or Path("studies/lighting/fast_camera/result") / ("seeds.json" if a.seeds else "cues.json")
    rows = sunny_rows()
    cfgs = {k: variant(w, sun_threshold=FORCED_THRESHOLD) for k, w in (("l", "160,640,320"), ("h", "160,640,640"))}
    ang: dict[str, dict[str, float]] = {}
    for k, r in enumerate(halves(rows)[a.half]):
        b = np.array([r[f"balanced_sun_{x}"] for x in "xyz"])
        if not np.all(np.isfinite(b)):
            continue
        img = load_photo(r["photo"])
        inputs, suns = {}, {}
        if a.seeds:
            for seed in a.seeds:
                with mock.patch.object(analysis, "ANALYSIS_SEED", seed):
                    for c, cfg in cfgs.items():
                        suns[f"{c}_seed_{seed}"] = lighting_inputs(img, cfg)[1]
        else:
            for c, cfg in cfgs.items():
                inputs[c], suns[f"analysis_{c}"] = lighting_inputs(img, cfg)
            suns |= mixed_suns(inputs)
        for code, d in suns.items():
            ang.setdefault(code, {})[r["photo"]] = round(angle_deg(d, b), 2)
        print(f"[{k + 1}] {r['photo']} " + " ".join(f"{c}:{v[r['photo']]:.0f}" for c, v in ang.items()), flush=True)
    report = {
        "groups": "l: the lighting on the 320 px copy, h: on the 640 px one"
        + ("; seed: the analysis' generator" if a.seeds else "; code = sky, measure, side"),
        "half": a.half,
        "within_30_deg": {c: int(np.sum(np.array(list(v.values())) <= 30)) for c, v in ang.items()},
        "with_a_direction": {c: int(np.sum(np.isfinite(list(v.values())))) for c, v in ang.items()},
        "photos": len(next(iter(ang.values()))),
        "per_photo_deg": ang,
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1))
    print(json.dumps({k: v for k, v in report.items() if k != "per_photo_deg"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
