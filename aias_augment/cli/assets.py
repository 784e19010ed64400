"""``aias-assets``: import | list | show | thumbnails for the asset bank.

aias-assets import [--sidecar DIR ...] [--force]      # load, validate and cache every mesh; writes the catalog
aias-assets list [--category traffic_cone] [--status rejected]
aias-assets show "sh3f:Scopia#cone"
aias-assets thumbnails --out out/assets/contact_sheet.png [--category dog rock] [--per-category 2]
aias-assets from-labels --yolo DIR --class-names cone --category traffic_cone --out BANK   # your own instances
aias-assets from-labels --input train.json --images DIR --label cone --category traffic_cone --out BANK
aias-assets box-convention --yolo DIR --class-names cone --label cone --out convention.json   # for --box-convention
aias-assets deform --category traffic_cone --count 8 --seed 0 --out BANK --sheet sheet.png   # dented, crushed...
aias-assets reconstruct --views views.json --category traffic_cone --out BANK   # from photos (visual hull; SfM if unposed)
"""

from __future__ import annotations

import argparse
import collections
import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

from aias_augment.assets.bank import AssetBank, catalog_path, discover_records, get_bank, import_records
from aias_augment.assets.bank.cache import MeshCache, default_cache_dir
from aias_augment.assets.bank.catalog import save_catalog
from aias_augment.assets.bank.sh3f import DEFAULT_SH3F_DIR
from aias_augment.assets.bank.taxonomy import load_taxonomy
from aias_augment.core.logs import add_logging_args, configure_logging

log = logging.getLogger(__name__)


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (``aias-assets <cmd>: error: ...``, exit 2): no usage block to scroll past."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def _int_in(lo: int, hi: int):
    """An argparse type: an integer in [lo, hi]."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"{v} is outside [{lo}, {hi}]")
        return v

    return parse


def _metres(text: str) -> float:
    """An argparse type: a height in metres, finite, in (0, 100]."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not 0 < v <= 100:  # NaN fails too
        raise argparse.ArgumentTypeError(f"{text} m is not a height in (0, 100] m")
    return v


def _fail(message: str) -> int:
    print(f"error: {message}", file=sys.stderr)
    return 2


def _bank_out(folder: Path) -> str | None:
    """Why ``folder`` cannot be a bank folder to append to (a file, an unreadable index), or None."""
    from aias_augment.assets.bank.db import BankError, check_folder

    try:
        check_folder(folder)
    except BankError as e:
        return f"--out {e}"
    return None


def _cmd_import(a) -> int:
    t0 = time.perf_counter()
    records, skipped = discover_records(
        sh3f_dir=a.sh3f_dir, gazebo_dir=a.gazebo_dir or "default", sidecar_dirs=tuple(a.sidecar), procedural=True
    )
    if a.limit:
        records = records[: a.limit]
    t_discover = time.perf_counter() - t0
    cache = MeshCache(a.cache_dir)
    out = import_records(records, cache, load_taxonomy(), force=a.force, progress=not a.quiet)
    t_total = time.perf_counter() - t0
    path = save_catalog(out, catalog_path(cache.root))
    status = collections.Counter(r.status for r in out)
    by_cat = collections.Counter(r.category for r in out if r.usable)
    summary = {
        "records": len(out),
        "status": dict(status),
        "skipped_entries": skipped,
        "usable_by_importer": dict(collections.Counter(r.importer for r in out if r.usable)),
        "textured": sum(bool(r.textured) for r in out if r.usable),
        "triangles_total": sum(r.triangle_count or 0 for r in out if r.usable),
        "categories": dict(by_cat.most_common()),
        "rejected": {r.id: r.notes[0] if r.notes else "" for r in out if r.status == "rejected"},
        "seconds_discover": round(t_discover, 3),
        "seconds_total": round(t_total, 3),
        "catalog": str(path),
    }
    print(json.dumps({k: v for k, v in summary.items() if k not in ("categories", "rejected")}, indent=1))
    print(f"{len(by_cat)} categories; rejected {status.get('rejected', 0)}; catalog -> {path}")
    if a.report:
        Path(a.report).parent.mkdir(parents=True, exist_ok=True)
        Path(a.report).write_text(json.dumps(summary, indent=1))
    return 0


def _bank(a) -> AssetBank:
    return get_bank(a.cache_dir)


def _fmt_dims(d) -> str:
    return "-" if d is None else "x".join(f"{v:.2f}" for v in d)


def _cmd_list(a) -> int:
    recs = _bank(a).records(a.category, usable_only=False)
    if a.status:
        recs = [r for r in recs if r.status == a.status]
    if a.json:
        print(json.dumps([r.to_json() for r in recs], indent=1))
        return 0
    for r in sorted(recs, key=lambda r: (r.category, r.id)):
        print(
            f"{r.category:16s} {_fmt_dims(r.dimensions_m):>17s} m  tris={r.triangle_count or '-':>7} "
            f"tex={'y' if r.textured else 'n'} {r.status:8s} {r.id}"
        )
    print(f"{len(recs)} assets", file=sys.stderr)
    return 0


def _cmd_show(a) -> int:
    bank = _bank(a)
    r = bank.record(a.id)
    print(json.dumps(r.to_json(), indent=1))
    asset = bank.load(a.id, np.random.default_rng(0))
    print(f"loaded: {len(asset.meshes)} parts, {asset.triangle_count} triangles, extents {asset.extents_m.round(3)} m")
    return 0


def _cmd_thumbnails(a) -> int:
    from aias_augment.apply.render import render_object
    from aias_augment.assets.bank.thumbnails import contact_sheet

    bank = _bank(a)
    cats = a.category or bank.categories()
    ids = []
    for c in cats:
        ids += [r.id for r in sorted(bank.records(c), key=lambda r: r.id)][: a.per_category]
    ids = ids[: a.limit]
    t0 = time.perf_counter()
    sheet, n_ok = contact_sheet(bank, ids, tile_px=a.size, columns=a.columns, render=render_object)
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    import cv2

    cv2.imwrite(str(a.out), sheet[..., ::-1])
    print(f"{n_ok}/{len(ids)} thumbnails in {time.perf_counter() - t0:.1f}s -> {a.out}")
    return 0


def _labelled_items(a, label: str, skipped: collections.Counter):
    """(path, image, boxes of ``label`` xyxy, the image's other boxes xyxy) for each image of ``--yolo`` or
    ``--input``/``--images`` with a box of ``label``; unreadable, corrupt (a truncated JPEG is not partly decoded),
    too large (pixel count from the header, above the package reader's ``DEFAULT_MAX_PIXELS``, before any decode)
    or invalid images counted by kind in ``skipped`` and logged. Raises InputError for an unreadable label source."""
    from aias_augment.cli.offline import items_from_coco, items_from_yolo, resolve_yolo_boxes
    from aias_augment.core.image_io import DEFAULT_MAX_PIXELS, ImageReadError, read_image

    items = items_from_yolo(a.yolo, class_names=a.class_names) if a.yolo else items_from_coco(a.input, a.images)

    def labelled():
        for it in items:
            if it.invalid:
                skipped[it.invalid.kind] += 1
                continue
            try:
                image = read_image(it.path, max_pixels=DEFAULT_MAX_PIXELS)
            except ImageReadError as e:
                skipped[e.kind] += 1
                log.warning("skipped: %s", e)
                continue
            resolve_yolo_boxes(it, image, a.class_names)
            boxes = [[x, y, x + w, y + h] for (x, y, w, h), lab in zip(it.bboxes_xywh, it.labels) if lab == label]
            others = [[x, y, x + w, y + h] for (x, y, w, h), lab in zip(it.bboxes_xywh, it.labels) if lab != label]
            if boxes:
                yield it.path, image, np.array(boxes, float), np.array(others, float).reshape(-1, 4)

    return labelled()


def _cmd_from_labels(a) -> int:
    """Lift the labelled instances of one class into a bank folder (``aias_augment.assets.bank.lift``)."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.assets.bank.db import BankError
    from aias_augment.assets.bank.lift import LiftConfig, lift_instances

    label = a.label or (a.class_names[0] if a.class_names else a.category)
    skipped = collections.Counter()
    bad_out = _bank_out(a.out)
    if bad_out:
        return _fail(bad_out)
    try:
        labelled = _labelled_items(a, label, skipped)
    except InputError as e:
        return _fail(str(e))
    t0 = time.perf_counter()
    cfg = LiftConfig(min_box_px=a.min_box_px)
    try:
        _, report = lift_instances(labelled, a.category, a.out, cfg, height_m=a.height_m, mode=a.mode)
    except (BankError, OSError) as e:
        return _fail(str(e))
    summary = {
        "lifted": report.lifted,
        "rejected": dict(report.rejected),
        "images_skipped": dict(skipped),
        "seconds": round(time.perf_counter() - t0, 1),
        "bank": str(a.out),
    }
    print(json.dumps(summary, indent=1))
    if not report.lifted:
        print("error: no instance could be lifted (see 'rejected')", file=sys.stderr)
        return 1
    return 0


def _cmd_box_convention(a) -> int:
    """Measure how the labels of one class sit around their objects; write it as ``box_convention`` (JSON) for
    ``aias-augment --box-convention`` (``InsertionConfig.box_convention``)."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.assets.bank.lift import LiftConfig, measure_box_convention

    skipped = collections.Counter()
    t0 = time.perf_counter()
    if a.out.is_dir():
        return _fail(f"--out {a.out} is a folder: give the JSON file to write")
    try:
        margins, report = measure_box_convention(
            _labelled_items(a, a.label, skipped), LiftConfig(min_box_px=a.min_box_px)
        )
    except InputError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    out = {
        "box_convention": list(margins),
        "sides": ["left", "top", "right", "bottom"],
        "label": a.label,
        **report,
        "images_skipped": dict(skipped),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(out, indent=1))
    print(json.dumps({k: out[k] for k in ("box_convention", "instances_measured", "rejected")}, indent=1))
    return 0


def _cmd_deform(a) -> int:
    import cv2

    from aias_augment.assets.asset import AssetError, default_asset, load_asset
    from aias_augment.assets.bank.db import BankError
    from aias_augment.assets.deform import DeformConfig, apply_deformation, sample_deformation, write_variants

    t0 = time.perf_counter()
    bad_out = _bank_out(a.out)
    if bad_out:
        return _fail(bad_out)
    if a.sheet and a.sheet.is_dir():
        return _fail(f"--sheet {a.sheet} is a folder: give the image file to write")
    try:
        source = load_asset(a.asset, category=a.category) if a.asset else default_asset(a.category)
        cfg = DeformConfig(kinds=tuple(a.kinds or ()))
    except (AssetError, KeyError, ValueError, OSError) as e:
        return _fail(str(e).strip("'\""))
    rng = np.random.default_rng(a.seed)
    params = [sample_deformation(source, rng, cfg) for _ in range(a.count)]
    try:
        entries = write_variants(source, params, a.out)
    except (BankError, OSError) as e:
        return _fail(str(e))
    if a.sheet:
        from aias_augment.apply.render import render_object
        from aias_augment.assets.bank.thumbnails import render_thumbnail

        tiles = [(render_thumbnail(source, a.size, render=render_object), f"source {source.height_m:.2f} m")]
        for p, e in zip(params, entries):
            v = apply_deformation(source, p)
            tiles.append(
                (render_thumbnail(v, a.size, render=render_object), f"{e['file'][:4]} {p.kind} {v.height_m:.2f} m")
            )
        cols = min(len(tiles), 9)
        rows = -(-len(tiles) // cols)
        sheet = np.full((rows * (a.size + 16), cols * a.size, 3), 255, np.uint8)
        for i, (tile, text) in enumerate(tiles):
            r, c = divmod(i, cols)
            y, x = r * (a.size + 16), c * a.size
            sheet[y : y + a.size, x : x + a.size] = tile
            cv2.putText(
                sheet, text, (x + 3, y + a.size + 12), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (40, 40, 40), 1, cv2.LINE_AA
            )
        Path(a.sheet).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(a.sheet), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    kinds = collections.Counter(p.kind for p in params)
    print(
        json.dumps(
            {
                "variants": len(entries),
                "kinds": dict(kinds),
                "bank": str(a.out),
                "seconds": round(time.perf_counter() - t0, 1),
            },
            indent=1,
        )
    )
    return 0


def _cmd_reconstruct(a) -> int:
    from aias_augment.apply.render import render_object
    from aias_augment.assets.bank.db import BankError
    from aias_augment.assets.bank.folder import add_to_bank
    from aias_augment.assets.reconstruct import (
        ReconstructConfig,
        View,
        read_views,
        reconstruct,
        reconstruct_unposed,
        search_box,
    )

    t0 = time.perf_counter()
    bad_out = _bank_out(a.out)
    if bad_out:
        return _fail(bad_out)
    try:
        photos, ground_z = read_views(a.views)
        cfg = ReconstructConfig(
            resolution=a.resolution, max_faces=a.max_faces, texture_px=a.texture_px, refine=a.refine
        )
        if photos[0][3] is None:  # no poses: structure from motion, scaled to the given height
            if a.height_m is None:
                raise ValueError("views without cam_from_object need --height-m (SfM has no metric scale)")
            asset = reconstruct_unposed(
                [p[0] for p in photos],
                [p[1] for p in photos],
                photos[0][2],
                category=a.category,
                height_m=a.height_m,
                seed=a.seed,
                name=a.views.parent.name,
                cfg=cfg,
                render=render_object,
            )
        else:
            views = [View(*p) for p in photos]
            lo, hi = search_box(views)
            asset = reconstruct(
                views,
                lo,
                hi,
                category=a.category,
                name=a.views.parent.name,
                height_m=a.height_m,
                ground_z=ground_z,
                cfg=cfg,
                render=render_object,
            )
    except (ValueError, OSError, ImportError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    keys = (
        "resolution",
        "faces",
        "texture_px",
        "refinement",
        "coloured_vertex_share",
        "coloured_texel_share",
        "registered_views",
        "sfm_reprojection_error_px",
    )
    record = {"source": f"reconstruction of {a.views}", "views": len(photos)}
    try:
        entry = add_to_bank(a.out, asset, {**record, **{k: asset.meta[k] for k in keys if k in asset.meta}})
    except (BankError, OSError) as e:
        return _fail(str(e))
    print(json.dumps({**entry, "bank": str(a.out), "seconds": round(time.perf_counter() - t0, 1)}, indent=1))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """``aias-assets`` and its commands: the catalog's (import, list, show, thumbnails), your labels'
    (from-labels, box-convention) and new meshes' (deform, reconstruct)."""
    p = _Parser(prog="aias-assets", description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--cache-dir", type=Path, default=None, help=f"default $AIAS_CACHE or {default_cache_dir()}")
    p.add_argument("-v", "--verbose", action="store_true", help="the same as --log-level INFO")
    sub = p.add_subparsers(dest="cmd", required=True)
    _add_catalog_commands(sub)
    _add_label_commands(sub)
    _add_mesh_commands(sub)
    add_logging_args(p, default="ERROR", subcommands=sub.choices.values())
    return p


def _add_catalog_commands(sub) -> None:
    s = sub.add_parser("import", help="import, validate and cache every source; writes the catalog")
    s.add_argument("--sh3f-dir", type=Path, default=DEFAULT_SH3F_DIR)
    s.add_argument("--gazebo-dir", type=Path, default=None, help="default $AIAS_DATA/meshes/gazebo_models")
    s.add_argument("--sidecar", type=Path, nargs="*", default=[], help="folders of meshes with YAML sidecars")
    s.add_argument("--force", action="store_true", help="re-import even when cached")
    s.add_argument("--limit", type=_int_in(0, 10**9), default=0, help="only the first N records (debugging)")
    s.add_argument("--report", type=Path, default=None, help="write the import summary JSON here")
    s = sub.add_parser("list", help="list catalog records")
    s.add_argument("--category", default=None)
    s.add_argument("--status", default=None, choices=["pending", "ok", "repaired", "rejected"])
    s.add_argument("--json", action="store_true")
    s = sub.add_parser("show", help="one record, and load its mesh")
    s.add_argument("id")
    s = sub.add_parser("thumbnails", help="contact sheet of rendered thumbnails")
    s.add_argument("--out", type=Path, required=True)
    s.add_argument("--category", nargs="*", default=None)
    s.add_argument("--per-category", type=_int_in(1, 2000), default=1)
    s.add_argument("--limit", type=_int_in(1, 2000), default=120)
    s.add_argument("--size", type=_int_in(16, 512), default=160)
    s.add_argument("--columns", type=_int_in(1, 64), default=10)


def _add_label_commands(sub) -> None:
    s = sub.add_parser("from-labels", help="lift your own labelled instances of one class into insertable assets")
    src = s.add_mutually_exclusive_group(required=True)
    src.add_argument("--yolo", help="folder of images with YOLO txt labels (labels/ beside images/)")
    src.add_argument("--input", help="COCO json (with --images)")
    s.add_argument("--images", help="image folder for --input")
    s.add_argument("--class-names", nargs="*", default=None, help="YOLO class names by index")
    s.add_argument("--label", default=None, help="the label to lift (default: the first class name, or --category)")
    s.add_argument("--category", required=True, help="the category the assets are inserted as (e.g. traffic_cone)")
    s.add_argument("--out", type=Path, required=True, help="bank folder: NNNN.glb and bank.json")
    s.add_argument(
        "--mode",
        choices=("revolution", "card"),
        default=None,
        help="default: revolution for cones, drums, bollards, posts, barrels; card otherwise",
    )
    s.add_argument("--height-m", type=_metres, default=None, help="default: the middle of the category's height range")
    s.add_argument("--min-box-px", type=_int_in(4, 100_000), default=24)
    s = sub.add_parser(
        "box-convention", help="how your labels sit around their objects, for aias-augment --box-convention"
    )
    src = s.add_mutually_exclusive_group(required=True)
    src.add_argument("--yolo", help="folder of images with YOLO txt labels (labels/ beside images/)")
    src.add_argument("--input", help="COCO json (with --images)")
    s.add_argument("--images", help="image folder for --input")
    s.add_argument("--class-names", nargs="*", default=None, help="YOLO class names by index")
    s.add_argument("--label", required=True, help="the label whose boxes are measured (e.g. cone)")
    s.add_argument("--out", type=Path, required=True, help="JSON: box_convention [left, top, right, bottom]")
    s.add_argument("--min-box-px", type=_int_in(4, 100_000), default=24, help="smaller boxes are not measured")


def _add_mesh_commands(sub) -> None:
    s = sub.add_parser("deform", help="seeded dented, crushed, bent or knocked-over variants of a mesh into a bank")
    s.add_argument("--category", required=True, help="the category (its default mesh unless --asset)")
    s.add_argument("--asset", default=None, help="a mesh file or gazebo model folder to deform")
    s.add_argument(
        "--kinds", nargs="*", default=None, help="dent crush bend knocked_over fracture (default: the category's)"
    )
    # at most 256 variants a run: the contact sheet of 257 tiles of 512 px is then about 200 MB
    s.add_argument("--count", type=_int_in(1, 256), default=8, help="variants (1-256; more: another run, seed)")
    s.add_argument(
        "--seed",
        type=_int_in(0, 2**63 - 1),
        required=True,
        help="the seed of the draws (a variant replays from its record)",
    )
    s.add_argument("--out", type=Path, required=True, help="bank folder: NNNN.glb and bank.json (appended to)")
    s.add_argument("--sheet", type=Path, default=None, help="write a contact sheet (source + variants) here")
    s.add_argument("--size", type=_int_in(32, 512), default=160, help="contact sheet tile size (px, 32-512)")
    s = sub.add_parser("reconstruct", help="an asset from photos of an object, posed or not (visual hull, textured)")
    s.add_argument(
        "--views",
        type=Path,
        required=True,
        help="views.json: images, masks or boxes, K, cam_from_object (or none: SfM)",
    )
    s.add_argument("--seed", type=_int_in(0, 2**31 - 1), default=0, help="SfM's RANSAC and mapper seed (unposed views)")
    s.add_argument("--category", required=True)
    s.add_argument("--out", type=Path, required=True, help="bank folder: NNNN.glb and bank.json (appended to)")
    s.add_argument("--height-m", type=_metres, default=None, help="scale to this height (default: the poses' metres)")
    s.add_argument("--resolution", type=int, default=128, help="voxels along the longest side")
    s.add_argument(
        "--max-faces",
        type=int,
        default=None,
        help="decimate the hull to at most this many faces before texturing (quadric error; default: keep all)",
    )
    s.add_argument(
        "--texture-px",
        type=int,
        default=None,
        help="bake a texture atlas of this many texels a side (16-2048) from the views (default: vertex colours)",
    )
    s.add_argument(
        "--refine",
        action="store_true",
        help="move the hull inward where the views agree on the texture (photo-consistency; slower, helps "
        "textured concave objects: studies/assets/refinement/result/refinement.md)",
    )


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    a = p.parse_args(argv)
    if a.cmd in ("from-labels", "box-convention") and a.input and not a.images:
        p.error("--input needs --images")
    if a.verbose and a.log_level == "ERROR":
        a.log_level = "INFO"
    configure_logging(a, fmt="%(levelname)s %(message)s")
    return {
        "import": _cmd_import,
        "list": _cmd_list,
        "show": _cmd_show,
        "thumbnails": _cmd_thumbnails,
        "from-labels": _cmd_from_labels,
        "box-convention": _cmd_box_convention,
        "deform": _cmd_deform,
        "reconstruct": _cmd_reconstruct,
    }[a.cmd](a)


if __name__ == "__main__":
    sys.exit(main())
