"""``aias-augment``: offline augmentation of a COCO or YOLO dataset, a folder of unlabelled images, or one clip.

aias-augment --input train.json --images train/ --categories traffic_cone --per-image 2 --out train_aug/
aias-augment --images backgrounds/ --assets crate=meshes/crate.glb --per-image 2 --out bg_aug/
aias-augment --input clip.mp4 --camera calib.txt --poses poses.txt --categories traffic_cone --out clip_aug/
aias-augment --input tripod.avi --camera-height 4 --out clip_aug/     # a static camera: no poses (checked)
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from aias_augment.cli.augment_args import build_parser
from aias_augment.cli.offline import (
    IMAGE_SUFFIXES,
    coco_categories,
    items_from_coco,
    items_from_images,
    items_from_yolo,
    run,
)
from aias_augment.core.logs import configure_logging
from aias_augment.pipeline.image import load_preset


def main(argv=None) -> int:
    ap = build_parser(__doc__)
    a = ap.parse_args(argv)
    configure_logging(a)
    if not (a.input or a.yolo or a.images):
        ap.error("one of --input, --yolo or --images (a folder of unlabelled images) is required")
    if a.yolo and a.images:
        ap.error("--images goes with --input (a COCO json) or alone (unlabelled images), not with --yolo")
    from aias_augment.cli.clip import is_video_input

    if a.input and (a.camera or a.poses or is_video_input(a.input) or Path(a.input).is_dir()):  # a COCO json or a clip
        return _clip_main(ap, a)
    if a.input and not a.images:
        ap.error("--input needs --images")
    return _dataset_main(ap, a)


def _clip_main(ap, a) -> int:
    """A clip's options checked against each other (``ap.error``: exit 2), then :func:`~aias_augment.cli.clip.
    clip_command`."""
    if (a.poses or a.stereo_right) and not a.camera:
        ap.error("--poses and --stereo-right need --camera (a static camera's clip needs neither)")
    if a.poses and a.stereo_right:
        ap.error("--poses or --stereo-right: poses given, or estimated from the stereo pair, not both")
    given = [
        f
        for f, v in (
            ("--config", a.config),
            ("--assets", a.assets),
            ("--assets-bank", a.assets_bank),
            ("--sun-from", a.sun_from),
            ("--envmap", a.envmap),
        )
        if v
    ]
    if given:
        ap.error(f"{', '.join(given)}: for image datasets, not clips")
    from aias_augment.cli.clip import clip_command

    return clip_command(a)


def _dataset_main(ap, a) -> int:
    """An image dataset's run: every option checked before any image is read or any record written (exit 2), the
    run, and its exit code from the summary (:func:`_report`)."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.cli.manifest import ManifestMismatch

    clip_only = [
        f
        for f, v in (
            ("--objects", a.objects != 1),
            ("--object-speed", a.object_speed != 0),
            ("--object-start", a.object_start != 0),
            ("--object-accel", a.object_accel != 0),
            ("--topple", a.topple != 0),
            ("--labels", a.labels is not None),
            ("--labels-format", a.labels_format is not None),
            ("--labels-category", a.labels_category != "object"),
        )
        if v
    ]
    if clip_only:
        ap.error(f"{', '.join(clip_only)}: for clips (--input a video or a frame folder); images take --per-image")
    if (
        (a.per_image is not None and a.per_image < 0)
        or a.workers < 1
        or (a.limit is not None and a.limit < 1)
        or a.max_megapixels < 0
    ):
        ap.error("--per-image >= 0, --workers >= 1, --limit >= 1 and --max-megapixels >= 0 please")
    try:
        cfg, items, run_kw = _dataset_job(a)
        summary = run(items, cfg, a.seed, a.out, **run_kw)
    except (InputError, ManifestMismatch) as e:
        print(f"aias-augment: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:  # an unwritable or full --out, a path through a file: one line that says what to do
        where = f" ({e.filename})" if e.filename else ""
        print(
            f"aias-augment: error: {e.strerror or e}{where}: check that --out is a writable folder with free "
            "space; a rerun of the same command resumes",
            file=sys.stderr,
        )
        return 2
    return _report(a, summary, cfg)


def _dataset_job(a):
    """(config, items, run keywords) of an image dataset's run: every option checked here, before any image is read
    or any record written (``InputError``)."""
    from aias_augment.adapters.boundary import InputError, check_categories, known_categories
    from aias_augment.cli.dataset_out import canonical_categories, output_from_args, yolo_names_from_rows
    from aias_augment.cli.manifest import check_out_apart, recorded_sun_now
    from aias_augment.cli.offline import named_inputs
    from aias_augment.cli.yolo_io import read_yolo_dataset

    paths = asset_paths(a.assets, a.assets_bank)  # reads only: a bad spec is named as itself
    check_out_apart(a.out, named_inputs(a))  # before any write: nothing of the user's may be written over
    options = {"boxes": a.boxes}
    bank = None
    if paths:
        from aias_augment.assets.asset import AssetError, PathAssets

        try:
            bank = PathAssets(paths)
        except (AssetError, ValueError) as e:
            raise InputError(f"--assets: {e}") from None
        options["assets"] = asset_fingerprint(paths)  # a rerun with other meshes never reuses records
    facts = sun_facts(a.sun_from, None if a.overwrite else recorded_sun_now(a.out)) if a.sun_from else {}
    if facts:
        options["sun_from"] = {k: str(v) for k, v in facts.items()}
        if sun_is_now(a.sun_from):  # resolved once, recorded: a resume reuses that time
            options["sun_from"]["utc_given"] = "now"
    if a.envmap:
        from aias_augment.cli.manifest import file_hash

        facts["envmap"] = envmap_fact(a.envmap)
        options["envmap"] = [a.envmap, file_hash(a.envmap)]
    known = known_categories() | set(paths or {})
    requested, given_labels = canonical_categories(a.categories or (), known)  # cone -> traffic_cone
    cfg = insertion_config(a.preset, a.config, requested or None, a.per_image, paths, a.box_convention)
    # Categories your --assets give need not be built-in ones (as InsertObjects(assets=...)).
    unknown = [c for c in cfg.categories if c not in (paths or {})]
    if unknown:
        check_categories(unknown)
    yolo_in, class_names, input_categories = None, a.class_names, None
    if a.input:
        items = items_from_coco(a.input, a.images, box_policy=a.boxes)
        input_categories = coco_categories(a.input)
    elif a.yolo:
        yolo_in = read_yolo_dataset(a.yolo)
        split = yolo_in.split(a.split)
        class_names = a.class_names or (list(yolo_in.names) if yolo_in.names else None)
        items = items_from_yolo(str(split.images), str(split.labels), class_names, box_policy=a.boxes)
        class_names = class_names or yolo_names_from_rows(items)
    else:  # unlabelled background images: no boxes, the output holds only the inserted objects
        items = items_from_images(a.images)
    items = items[: a.limit] if a.limit else items
    if not items:
        raise InputError(f"no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in {a.yolo or a.images}")
    for it in items:
        it.meta.update(facts)
    user_names = list(input_categories or class_names or ())
    output = output_from_args(a, cfg.categories, user_names, known, given_labels, yolo_in)
    run_kw = dict(
        workers=a.workers,
        class_names=class_names,
        scene_cache=a.scene_cache,
        preset=a.preset,
        overwrite=a.overwrite,
        max_pixels=int(a.max_megapixels * 1e6) or None,
        options=options,
        backend=a.backend,
        ray_address=a.address,
        categories=input_categories,
        bank=bank,
        output=output,
    )
    return cfg, items, run_kw


def _report(a, summary: dict, cfg) -> int:
    """The run's summary on stdout and its exit code: 1 when no image was written or no object inserted anywhere
    (a warning when some images got none), else 0."""
    print(summary)
    if not summary["written"]:  # an empty dataset is a failure, whatever the reasons
        print(
            f"aias-augment: error: no image written: all {summary['images']} images were skipped; see "
            f"{a.out}/report.json",
            file=sys.stderr,
        )
        return 1
    if not summary["inserted"] and cfg.max_objects:  # a dataset without one new object is no augmentation
        print(
            f"aias-augment: error: no object inserted in any of the {summary['written']} images written; reasons "
            f"in {a.out}/report.json (nothing_inserted)",
            file=sys.stderr,
        )
        return 1
    if summary["nothing_inserted"]:
        print(
            f"aias-augment: WARNING: no object inserted in {summary['nothing_inserted']} of {summary['written']} "
            f"images written; reasons in {a.out}/report.json (nothing_inserted)",
            file=sys.stderr,
        )
    if summary["skipped"]:
        print(
            f"aias-augment: {summary['skipped']} of {summary['images']} images skipped; see {a.out}/report.json",
            file=sys.stderr,
        )
    return 0


MAX_ASSET_FOLDER_ENTRIES = 20000  # a folder of meshes, not a disk: the scan stops here with an error


def _mesh_files_in(folder: Path, spec: str, kinds: str) -> list[Path]:
    """The mesh files under ``folder`` (sorted, recursively), after visiting at most
    :data:`MAX_ASSET_FOLDER_ENTRIES` entries: a spec such as ``traffic_cone=/`` is refused, not scanned."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.assets.asset import MESH_SUFFIXES

    found, seen = [], 0
    for root, dirs, names in os.walk(folder):
        seen += len(dirs) + len(names)
        if seen > MAX_ASSET_FOLDER_ENTRIES:
            raise InputError(
                f"--assets {spec}: the folder {folder} holds more than {MAX_ASSET_FOLDER_ENTRIES} entries; "
                f"give a mesh file or a folder of meshes ({kinds})"
            )
        dirs.sort()
        found += [Path(root) / n for n in names if Path(n).suffix.lower() in MESH_SUFFIXES]
    return sorted(f for f in found if f.is_file())


def asset_paths(specs: list[str] | None, bank_dir: str | None = None) -> dict[str, list[str]] | None:
    """``--assets CATEGORY=PATH ...`` and ``--assets-bank DIR`` as :class:`aias_augment.assets.asset.PathAssets` takes
    them: {category: [mesh file or gazebo model folder, ...]}; a folder of meshes gives each mesh file in it (sorted,
    recursively). A malformed spec, a missing path, an unsupported file or a folder without meshes: InputError."""

    from aias_augment.adapters.boundary import InputError
    from aias_augment.assets.asset import MESH_SUFFIXES

    out: dict[str, list[str]] = {}
    kinds = ", ".join(sorted(MESH_SUFFIXES))
    for spec in specs or ():
        cat, sep, path = spec.partition("=")
        cat, path = cat.strip(), path.strip()
        if not sep or not cat or not path:
            raise InputError(f"--assets {spec!r}: expected CATEGORY=PATH (a mesh file or a folder of meshes)")
        p = Path(path)
        if p.is_dir() and (p / "model.sdf").is_file():  # a gazebo model folder is one asset
            files = [p]
        elif p.is_dir():
            files = _mesh_files_in(p, spec, kinds)
            if not files:
                raise InputError(f"--assets {spec}: no mesh files ({kinds}) in the folder {p}")
        elif p.is_file():
            if p.suffix.lower() not in MESH_SUFFIXES:
                raise InputError(f"--assets {spec}: {p} is not a mesh file ({kinds})")
            files = [p]
        else:
            raise InputError(f"--assets {spec}: no such file or folder: {p}")
        out.setdefault(cat, []).extend(str(f) for f in files)
    if bank_dir:
        from aias_augment.assets.bank.lift import bank_paths

        try:
            got = bank_paths(bank_dir)
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise InputError(f"--assets-bank {bank_dir}: {e}") from None
        missing = [q for qs in got.values() for q in qs if not Path(q).is_file()]
        if missing:
            raise InputError(f"--assets-bank {bank_dir}: bank.json names missing files: {missing[:3]}")
        for cat, qs in got.items():
            out.setdefault(cat, []).extend(qs)
    return out or None


def asset_fingerprint(paths: dict[str, list[str]]) -> dict[str, list[list[str]]]:
    """{category: [[path, sha256 of its bytes], ...]} for the run manifest (a folder asset: of every file under it,
    by relative path), so that changed meshes make another run, never a resumed one."""
    import hashlib

    from aias_augment.cli.manifest import file_hash

    def digest(p: Path) -> str:
        if not p.is_dir():
            return file_hash(p)
        h = hashlib.sha256()
        for f in sorted(q for q in p.rglob("*") if q.is_file()):
            h.update(f"{f.relative_to(p).as_posix()}\0{file_hash(f)}\0".encode())
        return h.hexdigest()

    return {cat: [[p, digest(Path(p))] for p in ps] for cat, ps in sorted(paths.items())}


SUN_NOW = ("now", "today")  # the times pandas reads as the current one


def sun_is_now(spec: str) -> bool:
    """``--sun-from``'s time is the current one (``now``)."""
    parts = spec.split(",")
    return len(parts) == 4 and parts[2].strip() in SUN_NOW


def sun_facts(spec: str, recorded_now: str | None = None) -> dict:
    """``--sun-from LAT,LON,UTC,HEADING`` as scene facts (``meta`` keys lat, lon, utc, heading_deg), checked by
    :meth:`aias_augment.core.scene_inputs.SceneInputs.checked` (ranges, an ISO time the solar position parses).
    A time of ``now`` is resolved here, once, to a concrete UTC in whole seconds: ``recorded_now`` (the time the
    run being resumed recorded) or the current time, so every image of a run has the same sun."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.core.scene_inputs import SceneInputs

    parts = [p.strip() for p in spec.split(",")]
    if len(parts) != 4:
        raise InputError(
            f"--sun-from {spec!r}: expected LAT,LON,UTC,HEADING (degrees, an ISO UTC time, the camera "
            "heading in degrees clockwise from north), e.g. 48.1,11.6,2024-06-01T12:00:00Z,90"
        )

    if parts[2] in SUN_NOW:
        from datetime import datetime, timezone

        parts[2] = recorded_now or datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")

    def number(v: str):
        try:
            return float(v)
        except ValueError:
            return v  # SceneInputs names it: "must be a number"

    try:
        facts = SceneInputs(
            lat=number(parts[0]), lon=number(parts[1]), utc=parts[2], heading_deg=number(parts[3])
        ).checked((1, 1))
    except ValueError as e:
        raise InputError(f"--sun-from {spec!r}: {e}") from None
    return facts.as_meta()


def envmap_fact(path: str):
    """``--envmap FILE`` as the scene fact ``envmap``: an :class:`EnvironmentMap` placed for a single image (whose
    world is the camera frame): the camera looks level at the map's centre column (env +x), env z up."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.analyse.lighting.envmap import cam_from_env_look
    from aias_augment.core.envmap import EnvironmentMap
    from aias_augment.core.scene_inputs import SceneInputs

    try:
        env = EnvironmentMap.from_file(path, world_from_env=cam_from_env_look(0.0))
        return SceneInputs(envmap=env).checked((1, 1)).envmap
    except (OSError, ValueError) as e:
        raise InputError(f"--envmap {path}: {' '.join(str(e).split())}") from None


def read_box_convention(path: str) -> list:
    """The ``box_convention`` margins of a JSON written by ``aias-assets box-convention`` (InputError otherwise;
    the values are checked by the config)."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.core.config_files import load_json_file

    data = load_json_file(path, f"--box-convention {path}")  # bounded, strict JSON; ConfigFileError: an InputError
    if not isinstance(data, dict) or not isinstance(data.get("box_convention"), list):
        raise InputError(
            f"--box-convention {path}: expected a mapping with a 'box_convention' list (left, top, right, bottom)"
        )
    return data["box_convention"]


def insertion_config(
    preset: str,
    config_file: str | None,
    categories,
    per_image: int | None,
    asset_paths=None,
    box_convention_file: str | None = None,
):
    """The run's :class:`InsertionConfig`: ``preset``, then ``config_file``'s fields (YAML; nested configs as
    mappings of some of their fields), then ``--categories`` / ``--per-image`` / ``--box-convention``. Checked by
    the typed config checker: an error names the file and the field (InputError)."""
    from aias_augment.adapters.boundary import InputError
    from aias_augment.core.config import ConfigError

    data: dict = {}
    if config_file:
        from aias_augment.core.config_files import load_yaml_file

        # bounded: size, UTF-8, alias expansion; its ConfigFileError is an InputError naming --config
        data = load_yaml_file(config_file, f"--config {config_file}") or {}
        if not isinstance(data, dict):
            raise InputError(
                f"--config {config_file}: expected a mapping of InsertionConfig fields, got {type(data).__name__}"
            )
    flags: dict = {}
    if categories:
        flags["categories"] = tuple(categories)
    elif "categories" not in data:
        flags["categories"] = tuple(sorted(asset_paths)) if asset_paths else ("traffic_cone",)
    per = per_image if per_image is not None else (None if "max_objects" in data else 2)
    if per is not None:
        flags["max_objects"] = per
        m = data.get("min_objects", 1)
        flags["min_objects"] = min(m, per) if isinstance(m, int) and not isinstance(m, bool) else m
    if box_convention_file:
        flags["box_convention"] = read_box_convention(box_convention_file)
    try:
        return load_preset(preset, **{**data, **flags})
    except ConfigError as e:
        raise InputError(str(e.from_source(config_file) if config_file else e)) from None
    except (TypeError, ValueError) as e:
        raise InputError(f"--config {config_file}: {e}" if config_file else str(e)) from None


if __name__ == "__main__":
    raise SystemExit(main())
