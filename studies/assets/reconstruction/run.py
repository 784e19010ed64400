"""Reconstruction against exact truth: known meshes rendered from known views, reconstructed, compared.

For each object (the shared cone, barrel and cinder block, and an analytic 0.6 x 0.4 x 0.35 m crate) and each
number of views (8, 16, 32 on a golden-angle spiral, elevations 5-60 deg, 320 px, 40 deg field of view), the
project's renderer draws the object's albedo and coverage; the masks (coverage > 0.5), images and exact poses go to
:func:`aias_augment.assets.reconstruct.reconstruct`. Reported: Chamfer distance (mean of both directions' mean
nearest-surface distance, 20 000 area-sampled points per surface) relative to the object's largest extent, normal
consistency (mean |n . n'| at nearest points, both directions), F-score at 1 % and 2 % of that extent, texture PSNR
(sRGB, 4 held-out views at other azimuths and elevations, over the union of both silhouettes) and seconds.

With ``--unposed``, each object is also reconstructed without its poses
(:func:`aias_augment.assets.reconstruct.reconstruct_unposed`: COLMAP SfM, the ground plane's gauge, scaled to the
true height as the reference size). The object then stands on a textured floor (a 3 m square of smooth random
greys): SfM matches features, and a black backdrop gives none (with it no model registers). The reconstruction's
rotation about the vertical, which SfM cannot know, is aligned to the truth's (a 1-degree search minimising the mean
nearest-surface distance) before it is compared.

    python -m studies.assets.reconstruction --unposed --out studies/assets/reconstruction/result
"""

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from aias_augment.apply.render import linear_to_srgb, render_object
from aias_augment.assets.asset import Asset, default_asset, normalise_meshes
from aias_augment.assets.bank.thumbnails import look_at_cam_from_object
from aias_augment.assets.reconstruct import ReconstructConfig, View, reconstruct, reconstruct_unposed
from aias_augment.core.geometry import Intrinsics
from studies._shared.pictures import write_jpeg

SIZE, FOV = 320, 40.0


def crate() -> Asset:
    import trimesh
    from PIL import Image

    box = trimesh.creation.box((0.6, 0.4, 0.35))
    tri = box.vertices[box.faces].reshape(-1, 3)
    n = np.repeat(box.face_normals, 3, axis=0)
    # a planar UV per face from the two axes it spans; a wood-like striped texture
    uv = np.where(np.abs(n[:, :1]) > 0.5, tri[:, 1:3], np.where(np.abs(n[:, 1:2]) > 0.5, tri[:, [0, 2]], tri[:, :2]))
    uv = (uv + 0.5) % 1.0
    yy, xx = np.mgrid[0:64, 0:64]
    tex = np.stack([150 + 40 * np.sin(xx / 3.0), 100 + 30 * np.sin(xx / 3.0), 50 + 10 * (yy % 16 < 2)], -1)
    m = trimesh.Trimesh(
        tri,
        np.arange(len(tri)).reshape(-1, 3),
        visual=trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(np.clip(tex, 0, 255).astype(np.uint8))),
        process=False,
    )
    return Asset("crate", "crate", normalise_meshes([m]), "analytic box")


def cameras(asset: Asset, n: int, elevations=(5.0, 60.0), phase: float = 0.0):
    lo, hi = asset.bounds_m
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2)
    f = SIZE / 2 / np.tan(np.radians(FOV) / 2)
    dist = 1.25 * radius / np.sin(np.radians(FOV) / 2)
    intr = Intrinsics(f, f, (SIZE - 1) / 2, (SIZE - 1) / 2, SIZE, SIZE)
    out = []
    for i in range(n):
        az = np.radians(phase + i * 137.50776)
        el = np.radians(elevations[0] + (elevations[1] - elevations[0]) * (i + 0.5) / n)
        eye = centre + dist * np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        out.append((look_at_cam_from_object(eye, centre), intr))
    return out


def shoot(asset: Asset, cams) -> list[View]:
    views = []
    for T, intr in cams:
        L = render_object(asset, T, intr, ssaa=2, znear=0.01, zfar=1000.0, with_normals=False)
        rgb = np.clip(linear_to_srgb(L.albedo_linear) * 255 + 0.5, 0, 255).astype(np.uint8)
        views.append(View(rgb, L.alpha > 0.5, intr, T))
    return views


def surface_samples(asset: Asset, n: int, rng: np.random.Generator):
    V = [np.asarray(m.vertices, float) for m in asset.meshes]
    tri = np.concatenate([v[np.asarray(m.faces)] for v, m in zip(V, asset.meshes)])
    cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cr, axis=1) / 2
    keep = area > 0
    tri, cr, area = tri[keep], cr[keep], area[keep]
    idx = rng.choice(len(area), size=n, p=area / area.sum())
    ab = rng.uniform(size=(n, 2))
    ab = np.where(ab.sum(1, keepdims=True) > 1, 1 - ab, ab)
    t = tri[idx]
    pts = t[:, 0] + ab[:, :1] * (t[:, 1] - t[:, 0]) + ab[:, 1:] * (t[:, 2] - t[:, 0])
    normals = cr[idx] / np.linalg.norm(cr[idx], axis=1, keepdims=True)
    return pts, normals


def compare(truth: Asset, rec: Asset, rng) -> dict:
    from scipy.spatial import cKDTree

    size = float(truth.extents_m.max())
    pt, nt = surface_samples(truth, 20000, rng)
    pr, nr = surface_samples(rec, 20000, rng)
    d_rt, i_rt = cKDTree(pt).query(pr)
    d_tr, i_tr = cKDTree(pr).query(pt)
    out = {
        "chamfer_rel": float((d_rt.mean() + d_tr.mean()) / 2 / size),
        "normal_consistency": float(
            (np.abs(np.sum(nr * nt[i_rt], 1)).mean() + np.abs(np.sum(nt * nr[i_tr], 1)).mean()) / 2
        ),
    }
    for tau in (0.01, 0.02):
        p, r = float(np.mean(d_rt < tau * size)), float(np.mean(d_tr < tau * size))
        out[f"f_score_{int(tau * 100)}pct"] = 2 * p * r / max(p + r, 1e-9)
    return out


def psnr(truth: Asset, rec: Asset) -> tuple[float, list]:
    errs, pairs = [], []
    for T, intr in cameras(truth, 4, elevations=(15.0, 45.0), phase=61.0):
        a = render_object(truth, T, intr, ssaa=2, znear=0.01, zfar=1000.0, with_normals=False)
        b = render_object(rec, T, intr, ssaa=2, znear=0.01, zfar=1000.0, with_normals=False)
        m = (a.alpha > 0.5) | (b.alpha > 0.5)
        ia, ib = linear_to_srgb(a.albedo_linear), linear_to_srgb(b.albedo_linear)
        errs.append(np.mean((ia[m] - ib[m]) ** 2))
        pairs.append((ia, ib))
    return float(10 * np.log10(1.0 / max(np.mean(errs), 1e-12))), pairs


def floor_texture(rng: np.random.Generator, n: int = 512) -> np.ndarray:
    """(n, n) uint8: smooth random greys at two scales, a floor SfM can match."""
    fine = cv2.resize(rng.random((n // 8, n // 8)), (n, n), interpolation=cv2.INTER_CUBIC)
    coarse = cv2.resize(rng.random((n // 32, n // 32)), (n, n), interpolation=cv2.INTER_CUBIC)
    return np.clip((0.6 * fine + 0.4 * coarse) * 255, 0, 255).astype(np.uint8)


def on_floor(view: View, tex: np.ndarray, extent_m: float = 3.0) -> np.ndarray:
    """The view's image with the floor z = 0 (``tex`` over an ``extent_m`` square, tiled) behind the object."""
    h, w = view.mask.shape
    K, T = view.intrinsics, np.asarray(view.cam_from_object, float)
    R, t = T[:3, :3], T[:3, 3]
    uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = np.stack([(uu - K.cx) / K.fx, (vv - K.cy) / K.fy, np.ones_like(uu)], -1) @ R  # in the object frame
    c = -R.T @ t
    s = -c[2] / np.where(np.abs(rays[..., 2]) < 1e-9, 1e-9, rays[..., 2])  # eps: rays parallel to the floor
    P = c + s[..., None] * rays
    n = tex.shape[0]
    g = tex[((P[..., 1] / extent_m + 0.5) * n).astype(int) % n, ((P[..., 0] / extent_m + 0.5) * n).astype(int) % n]
    g = np.where(s > 0, g, 90)
    img = view.image_rgb.copy()
    img[~view.mask] = np.repeat(g[..., None], 3, -1)[~view.mask]
    return img


def rotated_about_z(asset: Asset, yaw: float) -> Asset:
    Rz = np.eye(4)
    Rz[:3, :3] = rotated_about_z_matrix(yaw)
    meshes = tuple(m.copy().apply_transform(Rz) for m in asset.meshes)
    return Asset(asset.name, asset.category, meshes, asset.source, asset.licence, asset.procedural, asset.meta)


def align_yaw(truth: Asset, rec: Asset, rng) -> tuple[Asset, float]:
    """``rec`` turned about z to the yaw (1-degree search) with the least mean distance from its surface to the
    truth's."""
    from scipy.spatial import cKDTree

    tree = cKDTree(surface_samples(truth, 5000, rng)[0])
    pr = surface_samples(rec, 3000, rng)[0]
    yaws = np.radians(np.arange(360.0))
    cost = [tree.query(pr @ rotated_about_z_matrix(y).T)[0].mean() for y in yaws]
    best = float(yaws[int(np.argmin(cost))])
    return rotated_about_z(rec, best), best


def rotated_about_z_matrix(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def write_views(views: list[View], folder: Path) -> None:
    """The views as image + mask PNGs and a ``views.json`` (K, cam_from_object, ground z = 0)."""
    folder.mkdir(parents=True, exist_ok=True)
    entries = []
    for i, v in enumerate(views):
        cv2.imwrite(str(folder / f"{i:03d}.png"), cv2.cvtColor(v.image_rgb, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(folder / f"{i:03d}_mask.png"), v.mask.astype(np.uint8) * 255)
        entries.append(
            {
                "image": f"{i:03d}.png",
                "mask": f"{i:03d}_mask.png",
                "K": v.intrinsics.K.tolist(),
                "cam_from_object": np.asarray(v.cam_from_object).tolist(),
            }
        )
    (folder / "views.json").write_text(json.dumps({"ground_z": 0.0, "views": entries}, indent=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("studies/assets/reconstruction/result"))
    ap.add_argument("--views", type=int, nargs="*", default=[8, 16, 32])
    ap.add_argument("--resolution", type=int, default=128)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--objects", nargs="*", default=None, help="a subset of cone barrel crate cinder_block")
    ap.add_argument("--unposed", action="store_true", help="also reconstruct without the poses (needs pycolmap)")
    ap.add_argument(
        "--views-out",
        type=Path,
        default=Path("out/reconstruct_views"),
        help="the cone's views as `aias-assets reconstruct` reads them",
    )
    a = ap.parse_args(argv)
    objects = {
        "cone": default_asset("traffic_cone"),
        "barrel": default_asset("barrel"),
        "crate": crate(),
        "cinder_block": default_asset("concrete_block"),
    }
    if a.objects:
        objects = {k: v for k, v in objects.items() if k in a.objects}
    rows, tiles = [], []
    a.out.mkdir(parents=True, exist_ok=True)
    for name, truth in objects.items():
        for n in a.views:
            rng = np.random.default_rng(a.seed)
            views = shoot(truth, cameras(truth, n))
            lo, hi = truth.bounds_m
            pad = 0.3 * (hi - lo)
            t0 = time.perf_counter()
            rec = reconstruct(
                views,
                lo - pad,
                hi + pad,
                category=truth.category,
                name=f"{name}_{n}",
                cfg=ReconstructConfig(a.resolution),
                render=render_object,
            )
            seconds = time.perf_counter() - t0
            # the poses are metric and share the truth's frame: compare in it (both rest on z = 0, centred in x/y)
            row = {"object": name, "views": n, "posed": True, "seconds": round(seconds, 1), **compare(truth, rec, rng)}
            row["texture_psnr_db"], pairs = psnr(truth, rec)
            row["coloured_vertex_share"] = rec.meta["coloured_vertex_share"]
            rows.append(row)
            print(json.dumps(row), flush=True)
            if a.unposed:
                tex = floor_texture(np.random.default_rng(a.seed))
                images = [on_floor(v, tex) for v in views]
                t0 = time.perf_counter()
                try:
                    rec_u = reconstruct_unposed(
                        images,
                        [v.mask for v in views],
                        views[0].intrinsics,
                        category=truth.category,
                        height_m=truth.height_m,
                        seed=a.seed,
                        name=f"{name}_{n}_unposed",
                        cfg=ReconstructConfig(a.resolution),
                        render=render_object,
                    )
                except ValueError as err:  # SfM registered too few views: a failed row, shown
                    row_u = {"object": name, "views": n, "posed": False, "failed": str(err)}
                else:
                    seconds = time.perf_counter() - t0
                    rec_u, _ = align_yaw(truth, rec_u, rng)
                    row_u = {
                        "object": name,
                        "views": n,
                        "posed": False,
                        "registered_views": rec_u.meta["registered_views"],
                        "seconds": round(seconds, 1),
                        **compare(truth, rec_u, rng),
                    }
                    row_u["texture_psnr_db"], _ = psnr(truth, rec_u)
                    row_u["coloured_vertex_share"] = rec_u.meta["coloured_vertex_share"]
                rows.append(row_u)
                print(json.dumps(row_u), flush=True)
                if n == max(a.views) and name == "cone":
                    write_jpeg(
                        a.out / "unposed_views_on_floor.jpg",
                        cv2.cvtColor(np.concatenate(images[:4], 1), cv2.COLOR_RGB2BGR),
                    )
            if n == max(a.views):
                tiles.append((name, pairs[0]))
                if name == "cone":
                    write_views(views, a.views_out / name)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "metrics.json").write_text(
        json.dumps(
            {
                "command": "python -m studies.assets.reconstruction "
                + " ".join(argv if argv is not None else sys.argv[1:]),
                "rows": rows,
            },
            indent=1,
        )
        + "\n"
    )
    lines = [
        "| object | views | poses | Chamfer / size | normal consistency | F@1 % | F@2 % | texture PSNR (dB) | s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        poses = "given" if r["posed"] else f"SfM ({r.get('registered_views', 0)} registered)"
        if "failed" in r:
            lines.append(f"| {r['object']} | {r['views']} | SfM | failed: {r['failed']} | | | | | |")
            continue
        lines.append(
            f"| {r['object']} | {r['views']} | {poses} | {100 * r['chamfer_rel']:.2f} % | "
            f"{r['normal_consistency']:.3f} | {r['f_score_1pct']:.3f} | {r['f_score_2pct']:.3f} | "
            f"{r['texture_psnr_db']:.1f} | {r['seconds']} |"
        )
    (a.out / "table.md").write_text("\n".join(lines) + "\n")
    sheet = []
    for name, (ia, ib) in tiles:
        row = np.concatenate([ia, ib], axis=1)
        row = np.clip(row * 255 + 0.5, 0, 255).astype(np.uint8)
        cv2.putText(
            row,
            f"{name}: truth | reconstruction ({max(a.views)} views)",
            (6, 16),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.45,
            (0, 0, 0),
            1,
            cv2.LINE_AA,
        )
        sheet.append(row)
    write_jpeg(a.out / "held_out_views.jpg", cv2.cvtColor(np.concatenate(sheet, axis=0), cv2.COLOR_RGB2BGR))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
