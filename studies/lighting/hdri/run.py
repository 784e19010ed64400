"""Evaluate lighting estimation on equirectangular HDR maps (EXR or Radiance .hdr; files or folders).

Three measurements per map:
1. Sun from the map (``sun.sun_from_envmap``) against an independent "brightest region": the argmax of the luminance
   of the 4x area-downsampled map blurred by a 1.5-pixel Gaussian (about 2 deg). Reports the angle between them.
2. SH irradiance: relative RMS error (luminance, over 256 Fibonacci normals) of the 9-coefficient SH irradiance against
   brute-force integration of the full map, (a) SH of the full map, (b) SH of the map without the sun + the sun as a
   directional light (what the estimator hands to the renderer).
3. Image cues: perspective crops with a known camera (pinhole, level roll, yaw all around the sun, pitch and field of
   view drawn per seed), exposed like a camera (median metering, clip, sRGB, 8 bit), run through
   ``sun.sun_cue_from_image``; azimuth error against the map's sun; single frames and all crops of a map fused in world
   coordinates (``sun.fuse_sun_cues``). Each crop is scored twice: the sky cue alone and the production
   estimator ``estimate.estimate_sun_direction`` (what ``estimate_lighting`` uses: tempered sky, cast-shadow axis,
   walls and shadow ends of ``sun_side``), the clip with ``estimate_sun_direction_clip``. Crops are made of the maps whose brightest light is a compact source above the
   horizon (< 0.05 sr, elevation > 0) and that are not named with ``--sunless`` (indoor lamps, street lights at night:
   sky cues do not apply there).

Usage: python -m studies.lighting.hdri /usr/share/blender/datafiles/studiolights/world --out studies/lighting/hdri/result
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from aias_augment.analyse.lighting import envmap as em
from aias_augment.analyse.lighting import sh, sun
from aias_augment.analyse.lighting.estimate import (
    LightingConfig,
    estimate_sun_direction,
    estimate_sun_direction_clip,
    lighting_from_envmap,
)
from aias_augment.core import hdr
from aias_augment.core.geometry import Intrinsics
from studies._shared.pictures import save_figure_jpeg


def find_maps(paths: list[str]) -> list[Path]:
    out = []
    for p in map(Path, paths):
        if p.is_dir():
            out += sorted(q for q in p.iterdir() if q.suffix.lower() in hdr.HDR_SUFFIXES)
        elif p.is_file():
            out.append(p)
        else:
            raise FileNotFoundError(p)
    if not out:
        raise SystemExit(f"no .exr/.hdr maps under {paths}")
    return out


def downsample(rad: np.ndarray, f: int) -> np.ndarray:
    h, w = rad.shape[:2]
    h2, w2 = h // f, w // f
    return rad[: h2 * f, : w2 * f].reshape(h2, f, w2, f, 3).mean(axis=(1, 3))


def brightest_region_direction(rad: np.ndarray) -> np.ndarray:
    f = max(1, rad.shape[0] // 128)
    small = hdr.luminance(downsample(rad, f))
    blurred = ndimage.gaussian_filter(small, 1.5, mode=("nearest", "wrap"))
    r, c = np.unravel_index(int(np.argmax(blurred)), blurred.shape)
    return em.pixel_directions(*small.shape)[r, c]


def sh_errors(rad: np.ndarray, found: sun.SunFromEnv, dominant: bool) -> dict:
    normals = sh.fibonacci_sphere(256)
    ref = hdr.luminance(sh.brute_force_irradiance(rad, normals))
    full = hdr.luminance(sh.sh_irradiance(sh.project_envmap_to_sh(rad), normals))
    ambient = sh.sh_irradiance(sh.project_envmap_to_sh(sun.remove_sun(rad, found)), normals)
    split = hdr.luminance(ambient + np.maximum(normals @ found.direction_in_env, 0.0)[:, None] * found.irradiance_rgb)

    def rel_rms(est):
        return float(np.sqrt(np.mean((est - ref) ** 2)) / max(np.sqrt(np.mean(ref**2)), 1e-12))

    # What the estimator hands to the renderer: ambient + sun when the sun is dominant, else SH of the whole map.
    return {
        "sh_full_rel_rms": rel_rms(full),
        "sh_ambient_plus_sun_rel_rms": rel_rms(split),
        "sh_estimator_rel_rms": rel_rms(split if dominant else full),
    }


def expose_ldr(rad: np.ndarray) -> np.ndarray:
    """Median metering to 0.18 (cameras meter on the scene, not on the sun), clip, sRGB, 8 bit."""
    s = 0.18 / max(float(np.median(hdr.luminance(rad))), 1e-8)
    return np.round(hdr.linear_to_srgb(rad * s) * 255.0).astype(np.uint8)


def azimuth_error_deg(d: np.ndarray, ref: np.ndarray) -> float:
    a, _ = em.direction_to_azimuth_elevation(d)
    b, _ = em.direction_to_azimuth_elevation(ref)
    return float(abs((np.rad2deg(a - b) + 180.0) % 360.0 - 180.0))


def crop_eval(
    rad: np.ndarray,
    sun_dir: np.ndarray,
    seeds: list[int],
    n_views: int,
    width: int,
    height: int,
    whiteness_weight: float | None = None,
    config: LightingConfig = LightingConfig(),
) -> dict:
    sun_az, sun_el = em.direction_to_azimuth_elevation(sun_dir)
    grid, _ = sun.sun_direction_grid()
    up = np.array([0.0, 0.0, 1.0])
    rows, fused = [], []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        cues, images, Ks, Rs = [], [], [], []
        for k in range(n_views):
            offset = 360.0 * k / n_views + rng.uniform(-10, 10)
            pitch = rng.uniform(0.0, 15.0)
            hfov = rng.uniform(60.0, 90.0)
            K = Intrinsics.from_fov(width, height, hfov)
            R = em.cam_from_env_look(sun_az + np.deg2rad(offset), np.deg2rad(pitch))
            img = expose_ldr(em.render_perspective(rad, K, R))
            t = time.perf_counter()
            kw = {} if whiteness_weight is None else {"whiteness_weight": whiteness_weight}
            cue = sun.sun_cue_from_image(img, K, R, up, grid, **kw)
            dt = time.perf_counter() - t
            t = time.perf_counter()
            # The production path: every cue estimate_lighting uses (sky tempered out of view, cast-shadow axis of the
            # ground box, walls and shadow ends where the ground shows cast shadows or the sun is seen). A panorama's
            # camera height is unknown; it only scales ground distances (the default 1.65 m is used).
            # Its own generator: the crops' draws (yaw, pitch, fov) must stay those of the sky-only protocol.
            est = estimate_sun_direction(img, K, R, {"up_in_world": up}, config=config)
            dt_side = time.perf_counter() - t
            side = est.side_cues[0]
            images.append(img)
            Ks.append(K)
            Rs.append(R)
            cues.append(cue)
            sun_in_cam = R @ sun_dir
            uv = (
                K.fx * sun_in_cam[0] / max(sun_in_cam[2], 1e-9) + K.cx,
                K.fy * sun_in_cam[1] / max(sun_in_cam[2], 1e-9) + K.cy,
            )
            in_view = bool(sun_in_cam[2] > 0 and 0 <= uv[0] < width and 0 <= uv[1] < height)
            # Does the crop carry a side cue? Walls in >= 2 orientations, or a shadow end with some evidence.
            has_facade = bool(side is not None and side.n_facade_samples >= 2 and side.facade_r2 > 0.0)
            has_shadow_end = bool(side is not None and side.shadow_end_confidence >= 0.05)

            def only(ll):
                return azimuth_error_deg(grid[int(np.argmax(ll))], sun_dir) if np.ptp(ll) > 0 else None

            rows.append(
                {
                    "seed": seed,
                    "yaw_offset_deg": round(offset, 2),
                    "pitch_deg": round(pitch, 2),
                    "hfov_deg": round(hfov, 2),
                    "sun_in_view": in_view,
                    "sun_visible_detected": cue.sun_visible,
                    "azimuth_error_deg": azimuth_error_deg(cue.direction_in_world, sun_dir),
                    "confidence": cue.confidence,
                    "seconds": dt,
                    "with_side_azimuth_error_deg": azimuth_error_deg(est.direction_in_world, sun_dir),
                    "with_side_confidence": est.confidence,
                    "side_seconds": dt_side,
                    "axis_strength": est.axis_strength,
                    "side_margin_nats": est.side_margin_nats,
                    "direct_sun_evidence": side is not None,
                    "facade_only_azimuth_error_deg": None if side is None else only(side.facade_loglik),
                    "shadow_end_only_azimuth_error_deg": None if side is None else only(side.shadow_end_loglik),
                    "facade_samples": 0 if side is None else side.n_facade_samples,
                    "facade_r2": 0.0 if side is None else side.facade_r2,
                    "bases": 0 if side is None else side.n_bases,
                    "shadow_end_confidence": 0.0 if side is None else side.shadow_end_confidence,
                    "has_facade_cue": has_facade,
                    "has_shadow_end_cue": has_shadow_end,
                }
            )
        f = sun.fuse_sun_cues(cues)
        clip = estimate_sun_direction_clip(images, Ks, Rs, {"up_in_world": up}, config=config)
        d_fc = clip.direction_in_world
        fused.append(
            {
                "seed": seed,
                "azimuth_error_deg": azimuth_error_deg(f.direction_in_world, sun_dir),
                "elevation_est_deg": float(np.rad2deg(em.direction_to_azimuth_elevation(f.direction_in_world)[1])),
                "elevation_true_deg": float(np.rad2deg(sun_el)),
                "confidence": f.confidence,
                "with_side_azimuth_error_deg": azimuth_error_deg(d_fc, sun_dir),
            }
        )
    return {"crops": rows, "fused": fused}


def side_summary(crops: list[dict], fused: list[float]) -> dict:
    """Azimuth errors of the sky + side-cue combination, and which crops carry a side cue."""
    e = "with_side_azimuth_error_deg"
    fac = [c for c in crops if c["has_facade_cue"]]
    end = [c for c in crops if c["has_shadow_end_cue"]]
    return {
        "all": summarize([c[e] for c in crops]),
        "sun_in_view": summarize([c[e] for c in crops if c["sun_in_view"]]),
        "sun_out_of_view": summarize([c[e] for c in crops if not c["sun_in_view"]]),
        "confidence_ge_0.5": summarize([c[e] for c in crops if c["with_side_confidence"] >= 0.5]),
        "coverage_confidence_ge_0.5": {
            "n": sum(c["with_side_confidence"] >= 0.5 for c in crops),
            "fraction": float(np.mean([c["with_side_confidence"] >= 0.5 for c in crops])) if crops else 0.0,
        },
        "crops_with_direct_sun_evidence": summarize([c[e] for c in crops if c["direct_sun_evidence"]]),
        "fused_clip": summarize(fused),
        "crops_with_facade_cue": summarize([c[e] for c in fac]),
        "crops_with_shadow_end_cue": summarize([c[e] for c in end]),
        "crops_without_side_cue_out_of_view": summarize(
            [c[e] for c in crops if not (c["has_facade_cue"] or c["has_shadow_end_cue"]) and not c["sun_in_view"]]
        ),
        "facade_only_on_crops_with_facade_cue": summarize([c["facade_only_azimuth_error_deg"] for c in fac]),
        "shadow_end_only_on_crops_with_shadow_end_cue": summarize(
            [c["shadow_end_only_azimuth_error_deg"] for c in end]
        ),
        "sky_only_on_crops_with_facade_cue": summarize([c["azimuth_error_deg"] for c in fac]),
        "sky_only_on_crops_with_shadow_end_cue": summarize([c["azimuth_error_deg"] for c in end]),
        "median_side_seconds_per_crop": float(np.median([c["side_seconds"] for c in crops])) if crops else 0.0,
        "risk_coverage": risk_coverage(crops, e, "with_side_confidence"),
        "risk_coverage_sky_only": risk_coverage(crops, "azimuth_error_deg", "confidence"),
    }


COVERAGES = (0.1, 0.25, 0.5, 0.75, 1.0)


def risk_coverage(crops: list[dict], error_key: str, confidence_key: str) -> list[dict]:
    """Median azimuth error of the most confident crops, for each fraction of the crops kept (``COVERAGES``): how the
    estimate's own confidence ranks its errors (a user keeps the frames above a confidence threshold)."""
    rows = sorted(crops, key=lambda c: -c[confidence_key])
    out = []
    for f in COVERAGES:
        k = max(1, int(round(f * len(rows))))
        if not rows:
            break
        kept = rows[:k]
        out.append(
            {
                "coverage": f,
                "n": k,
                "min_confidence": float(kept[-1][confidence_key]),
                **summarize([c[error_key] for c in kept]),
            }
        )
    return out


def summarize(errors: list[float]) -> dict:
    errors = [e for e in errors if e is not None]
    if not errors:
        return {"n": 0}
    e = np.asarray(errors)
    return {
        "n": int(e.size),
        "median_deg": float(np.median(e)),
        "mean_deg": float(e.mean()),
        "p75_deg": float(np.percentile(e, 75)),
        "frac_below_25deg": float(np.mean(e < 25.0)),
    }


def make_plot(report: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    names = list(report["maps"])
    sh_full = [report["maps"][n]["sh_full_rel_rms"] * 100 for n in names]
    sh_split = [report["maps"][n]["sh_ambient_plus_sun_rel_rms"] * 100 for n in names]
    x = np.arange(len(names))
    axes[0].bar(x - 0.2, sh_full, 0.4, label="SH of full map")
    axes[0].bar(x + 0.2, sh_split, 0.4, label="SH ambient + sun")
    axes[0].axhline(15, color="r", ls="--", lw=1, label="15 % target")
    axes[0].set_xticks(x, names, rotation=45)
    axes[0].set_ylabel("irradiance rel. RMS error (%)")
    axes[0].legend(fontsize=8)
    axes[1].bar(x, [report["maps"][n]["sun_vs_brightest_deg"] for n in names])
    axes[1].set_xticks(x, names, rotation=45)
    axes[1].set_ylabel("sun vs brightest region (deg)")
    for n in names:
        crops = report["maps"][n].get("image_cues", {}).get("crops", [])
        if crops:
            axes[2].scatter(
                [((c["yaw_offset_deg"] + 180) % 360) - 180 for c in crops],
                [c["azimuth_error_deg"] for c in crops],
                s=10,
                label=n,
            )
    axes[2].axhline(25, color="r", ls="--", lw=1)
    axes[2].set_xlabel("camera yaw - sun azimuth (deg)")
    axes[2].set_ylabel("image-cue azimuth error (deg)")
    axes[2].legend(fontsize=8)
    fig.tight_layout()
    save_figure_jpeg(fig, path, dpi=110)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("maps", nargs="+", help="equirectangular .exr/.hdr files or folders")
    ap.add_argument("--out", default="out/lighting", help="output folder (report.json, report.md, plot.jpg)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--views", type=int, default=12, help="crops per map and seed, spread all around the sun")
    ap.add_argument("--size", type=int, nargs=2, default=[480, 300], metavar=("W", "H"))
    ap.add_argument(
        "--whiteness-weight",
        type=float,
        default=None,
        help="weight of the sky colour cue in sun.sun_cue_from_image (default: the library default)",
    )
    ap.add_argument(
        "--production-colour-weight",
        type=float,
        default=None,
        help="LightingConfig.sky_colour_weight of the production estimator (default: the library default)",
    )
    ap.add_argument("--sunless", nargs="*", default=[], help="map names (stems) whose light is not the sun")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = {
        "command": "python -m studies.lighting.hdri " + " ".join(argv if argv is not None else sys.argv[1:]),
        "maps": {},
    }
    headline_single, headline_fused, headline_fused_side = [], [], []
    for path in find_maps(args.maps):
        rad = hdr.read_hdr_image(path)
        if rad.shape[1] != 2 * rad.shape[0]:
            print(f"skip {path}: not equirectangular ({rad.shape[1]}x{rad.shape[0]})")
            continue
        t = time.perf_counter()
        found = sun.sun_from_envmap(rad)
        t_sun = time.perf_counter() - t
        est = lighting_from_envmap(em.EnvironmentMap(rad))
        az, el = em.direction_to_azimuth_elevation(found.direction_in_env)
        entry = {
            "path": str(path),
            "sun_azimuth_deg": float(np.rad2deg(az)),
            "sun_elevation_deg": float(np.rad2deg(el)),
            "sun_solid_angle_sr": found.solid_angle_sr,
            "sun_irradiance_rgb": found.irradiance_rgb.tolist(),
            "sun_vs_brightest_deg": float(
                sun.angle_between_deg(found.direction_in_env, brightest_region_direction(rad))
            ),
            "dominant_sun": est.dominant_sun,
            "sun_sky_ratio": est.sun_sky_ratio,
            "sun_from_envmap_seconds": t_sun,
        }
        entry.update(sh_errors(rad, found, est.dominant_sun))
        entry["image_cue_eval"] = bool(path.stem not in args.sunless and found.solid_angle_sr <= 0.05 and el > 0)
        if entry["image_cue_eval"]:
            cfg = (
                LightingConfig()
                if args.production_colour_weight is None
                else LightingConfig(sky_colour_weight=args.production_colour_weight)
            )
            cues = crop_eval(
                rad, found.direction_in_env, args.seeds, args.views, *args.size, args.whiteness_weight, config=cfg
            )
            entry["image_cues"] = cues
            entry["image_cues_summary"] = {
                "all": summarize([c["azimuth_error_deg"] for c in cues["crops"]]),
                "sun_in_view": summarize([c["azimuth_error_deg"] for c in cues["crops"] if c["sun_in_view"]]),
                "sun_out_of_view": summarize([c["azimuth_error_deg"] for c in cues["crops"] if not c["sun_in_view"]]),
                "confident_ge_0.5": summarize(
                    [c["azimuth_error_deg"] for c in cues["crops"] if c["confidence"] >= 0.5]
                ),
                "fused_clip": summarize([f["azimuth_error_deg"] for f in cues["fused"]]),
                "median_seconds_per_crop": float(np.median([c["seconds"] for c in cues["crops"]])),
            }
            entry["with_side_cues_summary"] = side_summary(
                cues["crops"], [f["with_side_azimuth_error_deg"] for f in cues["fused"]]
            )
            headline_single += [c for c in cues["crops"]]
            headline_fused += [f["azimuth_error_deg"] for f in cues["fused"]]
            headline_fused_side += [f["with_side_azimuth_error_deg"] for f in cues["fused"]]
        report["maps"][path.stem] = entry
        print(
            f"{path.stem:12s} sun az {entry['sun_azimuth_deg']:7.1f} el {entry['sun_elevation_deg']:5.1f} "
            f"vs brightest {entry['sun_vs_brightest_deg']:5.2f} deg  dominant {est.dominant_sun!s:5s} "
            f"SH full {entry['sh_full_rel_rms']:.3f} split {entry['sh_ambient_plus_sun_rel_rms']:.3f}"
            + (
                f"  cue median {entry['image_cues_summary']['all']['median_deg']:.1f} deg"
                if "image_cues_summary" in entry
                else ""
            )
        )
    report["headline"] = {
        "image_cue_azimuth_all_crops": summarize([c["azimuth_error_deg"] for c in headline_single]),
        "image_cue_azimuth_sun_in_view": summarize(
            [c["azimuth_error_deg"] for c in headline_single if c["sun_in_view"]]
        ),
        "image_cue_azimuth_sun_out_of_view": summarize(
            [c["azimuth_error_deg"] for c in headline_single if not c["sun_in_view"]]
        ),
        "image_cue_azimuth_confident_ge_0.5": summarize(
            [c["azimuth_error_deg"] for c in headline_single if c["confidence"] >= 0.5]
        ),
        "coverage_confident_ge_0.5": float(np.mean([c["confidence"] >= 0.5 for c in headline_single]))
        if headline_single
        else 0.0,
        "image_cue_azimuth_fused_clips": summarize(headline_fused),
        "with_side_cues": side_summary(headline_single, headline_fused_side),
        "sh_full_rel_rms_max": max(m["sh_full_rel_rms"] for m in report["maps"].values()),
        "sh_ambient_plus_sun_rel_rms_max": max(m["sh_ambient_plus_sun_rel_rms"] for m in report["maps"].values()),
        "sh_estimator_rel_rms_max": max(m["sh_estimator_rel_rms"] for m in report["maps"].values()),
        "sun_vs_brightest_deg_max": max(m["sun_vs_brightest_deg"] for m in report["maps"].values()),
    }
    (out / "report.json").write_text(json.dumps(report, indent=1))
    make_plot(report, out / "plot.jpg")
    write_markdown(report, out / "report.md")
    print(json.dumps(report["headline"], indent=1))
    return 0


def write_markdown(report: dict, path: Path) -> None:
    h = report["headline"]
    lines = [
        "# Lighting evaluation on equirectangular HDR maps",
        "",
        f"Command: `{report['command']}`",
        "",
        "| map | sun az / el (deg) | solid angle (sr) | sun vs brightest (deg) | dominant sun | sun/sky ratio "
        "| SH full rel RMS | SH ambient+sun rel RMS | SH as used rel RMS | image-cue az err median (all / in view / out of view / fused) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, m in report["maps"].items():
        s = m.get("image_cues_summary")
        cue = (
            "-"
            if s is None
            else (
                f"{s['all']['median_deg']:.1f} / {s['sun_in_view'].get('median_deg', float('nan')):.1f}"
                f" / {s['sun_out_of_view'].get('median_deg', float('nan')):.1f}"
                f" / {s['fused_clip']['median_deg']:.1f}"
            )
        )
        lines.append(
            f"| {name} | {m['sun_azimuth_deg']:.1f} / {m['sun_elevation_deg']:.1f} | {m['sun_solid_angle_sr']:.4f} "
            f"| {m['sun_vs_brightest_deg']:.2f} | {m['dominant_sun']} | {m['sun_sky_ratio']:.2f} "
            f"| {m['sh_full_rel_rms'] * 100:.1f} % | {m['sh_ambient_plus_sun_rel_rms'] * 100:.1f} % "
            f"| {m['sh_estimator_rel_rms'] * 100:.1f} % | {cue} |"
        )

    def fmt(s):
        return (
            "n=0"
            if s["n"] == 0
            else (
                f"n={s['n']}, median {s['median_deg']:.1f} deg, p75 {s['p75_deg']:.1f} deg, "
                f"{s['frac_below_25deg'] * 100:.0f} % below 25 deg"
            )
        )

    evaluated = [n for n, m in report["maps"].items() if m.get("image_cue_eval")]
    lines += [
        "",
        f"Headline (image cues on crops of {', '.join(evaluated)}; single crops over all seeds):",
        "",
        f"- image-cue azimuth, all crops: {fmt(h['image_cue_azimuth_all_crops'])}",
        f"- sun in view: {fmt(h['image_cue_azimuth_sun_in_view'])}",
        f"- sun out of view: {fmt(h['image_cue_azimuth_sun_out_of_view'])}",
        f"- confidence >= 0.5 ({h['coverage_confident_ge_0.5'] * 100:.0f} % of crops): "
        f"{fmt(h['image_cue_azimuth_confident_ge_0.5'])}",
        f"- all crops of a map fused in world coordinates: {fmt(h['image_cue_azimuth_fused_clips'])}",
        "",
        "Production estimator `estimate_sun_direction` (sky, cast-shadow axis, walls, shadow ends; the code path of `estimate_lighting`):",
        "",
    ]
    ws = h["with_side_cues"]
    lines += [
        f"- {k.replace('_', ' ')}: {fmt(v)}"
        for k, v in ws.items()
        if isinstance(v, dict) and "median_deg" in v or (isinstance(v, dict) and v.get("n") == 0)
    ]
    lines += [
        "",
        "Risk-coverage: median azimuth error (deg) of the most confident crops, by the fraction kept "
        "(ranked by each estimator's own confidence):",
        "",
        "| crops kept | " + " | ".join(f"{100 * r['coverage']:.0f} %" for r in ws["risk_coverage"]) + " |",
        "|---|" + "---|" * len(ws["risk_coverage"]),
        "| production: median (min confidence) | "
        + " | ".join(f"{r['median_deg']:.1f} ({r['min_confidence']:.2f})" for r in ws["risk_coverage"])
        + " |",
        "| production: fraction below 25 deg | "
        + " | ".join(f"{100 * r['frac_below_25deg']:.0f} %" for r in ws["risk_coverage"])
        + " |",
        "| sky cue alone: median (min confidence) | "
        + " | ".join(f"{r['median_deg']:.1f} ({r['min_confidence']:.2f})" for r in ws["risk_coverage_sky_only"])
        + " |",
    ]
    lines += [
        "",
        "| map | production estimator: all / in view / out of view / fused | crops with wall cue (their median) | with shadow-end cue |",
        "|---|---|---|---|",
    ]
    for name, m in report["maps"].items():
        w = m.get("with_side_cues_summary")
        if w is None:
            continue
        lines.append(
            f"| {name} | {w['all'].get('median_deg', float('nan')):.1f} / "
            f"{w['sun_in_view'].get('median_deg', float('nan')):.1f} / "
            f"{w['sun_out_of_view'].get('median_deg', float('nan')):.1f} / "
            f"{w['fused_clip'].get('median_deg', float('nan')):.1f} | {w['crops_with_facade_cue']['n']} "
            f"(median {w['crops_with_facade_cue'].get('median_deg', float('nan')):.1f}) | "
            f"{w['crops_with_shadow_end_cue']['n']} (median {w['crops_with_shadow_end_cue'].get('median_deg', float('nan')):.1f}) |"
        )
    lines += [
        "",
        f"- SH irradiance rel. RMS, worst map: full map {h['sh_full_rel_rms_max'] * 100:.1f} %, "
        f"ambient + separate sun {h['sh_ambient_plus_sun_rel_rms_max'] * 100:.1f} %, as used by the estimator "
        f"(ambient + sun only where the sun is dominant) {h['sh_estimator_rel_rms_max'] * 100:.1f} % (target < 15 %)",
        f"- sun vs brightest region, worst map: {h['sun_vs_brightest_deg_max']:.2f} deg",
        "",
        "![plot](plot.jpg)",
        "",
    ]
    path.write_text("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
