"""What decimating a reconstructed hull costs and saves: faces against accuracy, texture and render time.

The truth and views of ``studies/assets/reconstruction/run.py`` (the shared cone, barrel and cinder block and the analytic
crate, posed views on a golden-angle spiral). Each object is reconstructed once per face budget
(``ReconstructConfig.max_faces``: quadric decimation of the cleaned hull before texturing; "full" keeps marching
cubes' faces) and texture (vertex colours, or an atlas of ``--texture-px`` texels a side baked from the views:
``ReconstructConfig.texture_px``), and scored as there: Chamfer / size, normal consistency, F-score at 1 %, texture
PSNR on the held-out views. Also: the asset's GLB size, and the median time of 5 renders of the asset (albedo and depth, 320 px, 2x
supersampling) on this machine.

    python -m studies.assets.hull_decimation --out studies/assets/hull_decimation/result
"""

import argparse
import io
import json
import sys
import time
from pathlib import Path

import numpy as np
import trimesh

from aias_augment.apply.render import render_object
from aias_augment.assets.asset import default_asset
from aias_augment.assets.reconstruct import ReconstructConfig, reconstruct
from studies.assets.reconstruction import run as er


def render_ms(asset, cams, repeats: int = 5) -> float:
    T, intr = cams[0]
    render_object(asset, T, intr, ssaa=2, znear=0.01, zfar=1000.0, with_normals=False)  # the upload, once
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        render_object(asset, T, intr, ssaa=2, znear=0.01, zfar=1000.0, with_normals=False)
        times.append(time.perf_counter() - t0)
    return 1000 * float(np.median(times))


def glb_kib(asset) -> float:
    buf = io.BytesIO()
    trimesh.Scene(list(asset.meshes)).export(buf, file_type="glb")
    return buf.tell() / 1024


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("studies/assets/hull_decimation/result"))
    ap.add_argument("--views", type=int, default=32)
    ap.add_argument("--faces", type=int, nargs="*", default=[20000, 5000, 1500])
    ap.add_argument("--texture-px", type=int, nargs="*", default=[0, 1024], help="0: vertex colours")
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--objects", nargs="*", default=None, help="a subset of cone barrel crate cinder_block")
    a = ap.parse_args(argv)
    objects = {
        "cone": default_asset("traffic_cone"),
        "barrel": default_asset("barrel"),
        "crate": er.crate(),
        "cinder_block": default_asset("concrete_block"),
    }
    if a.objects:
        objects = {k: v for k, v in objects.items() if k in a.objects}
    rows = []
    for name, truth in objects.items():
        views = er.shoot(truth, er.cameras(truth, a.views))
        lo, hi = truth.bounds_m
        pad = 0.3 * (hi - lo)
        for budget, tex in [(b, t) for t in a.texture_px for b in [None, *a.faces]]:
            tex = tex or None
            rng = np.random.default_rng(a.seed)
            t0 = time.perf_counter()
            try:
                rec = reconstruct(
                    views,
                    lo - pad,
                    hi + pad,
                    category=truth.category,
                    name=f"{name}_{budget}",
                    cfg=ReconstructConfig(a.resolution, max_faces=budget, texture_px=tex),
                    render=render_object,
                )
            except ValueError as err:  # the budget cannot keep the hull closed: a failed row, shown
                rows.append(
                    {"object": name, "views": a.views, "max_faces": budget, "texture_px": tex, "failed": str(err)}
                )
                print(json.dumps(rows[-1]), flush=True)
                continue
            row = {
                "object": name,
                "views": a.views,
                "max_faces": budget,
                "texture_px": tex,
                "faces": rec.meta["faces"],
                # closed once the atlas's seam copies of a vertex are merged again
                "watertight": bool(all(trimesh.Trimesh(m.vertices, m.faces).is_watertight for m in rec.meshes)),
                "seconds": round(time.perf_counter() - t0, 1),
                **er.compare(truth, rec, rng),
            }
            row["texture_psnr_db"], _ = er.psnr(truth, rec)
            row["glb_kib"] = round(glb_kib(rec), 1)
            row["render_ms"] = round(render_ms(rec, er.cameras(truth, 4, elevations=(15.0, 45.0), phase=61.0)), 1)
            rows.append(row)
            print(json.dumps(row), flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    command = "python -m studies.assets.hull_decimation " + " ".join(argv if argv is not None else sys.argv[1:])
    (a.out / "decimation.json").write_text(json.dumps({"command": command, "rows": rows}, indent=1) + "\n")
    lines = [
        f"`{command}`",
        "",
        "| object | texture | faces (budget) | closed | Chamfer / size | normal consistency | F@1 % | texture PSNR (dB) "
        "| GLB KiB | render ms | reconstruct s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        budget = "full" if r["max_faces"] is None else str(r["max_faces"])
        tex = "vertex colours" if r["texture_px"] is None else f"atlas {r['texture_px']} px"
        if "failed" in r:
            lines.append(f"| {r['object']} | {tex} | — ({budget}) | failed: {r['failed']} | | | | | | | |")
            continue
        lines.append(
            f"| {r['object']} | {tex} | {r['faces']} ({budget}) | {'yes' if r['watertight'] else 'no'} | "
            f"{100 * r['chamfer_rel']:.2f} % | {r['normal_consistency']:.3f} | {r['f_score_1pct']:.3f} | "
            f"{r['texture_psnr_db']:.1f} | {r['glb_kib']:.0f} | {r['render_ms']:.1f} | {r['seconds']} |"
        )
    (a.out / "decimation.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
