"""The run manifest of an offline augmentation (``<out>/manifest.json``): what the output folder was made from and
what the run writes there.

The *run key* (package version, seed, preset, config hash, options, the ordered list of input paths) must match for
a rerun to resume; a different key is refused (:class:`ManifestMismatch`) unless ``overwrite``, which deletes the
files the previous manifest lists (``outputs``), and only those. Each input also has a content hash (image bytes,
label file bytes, the item's boxes and labels): a record is reused only when its ``input_hash`` equals the current
one and it is not a skip, so a fixed input is redone and a failed item is retried on resume, and the result equals a
fresh run (each image draws from ``default_rng([seed, index])``).

Every file is written through a temporary file in its own folder inside ``out``, named with the run's
``temp_prefix`` (``.aias-tmp-<run id>-``, recorded in the manifest), then renamed into place; start-up cleanup
removes files with that prefix and no other. ``complete`` turns true only after the last output is in place.
``--out`` may neither hold nor lie inside an input (:func:`check_out_apart`).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import signal
import socket
from dataclasses import asdict
from pathlib import Path

from aias_augment import __version__
from aias_augment.core.errors import AiasError, InputError

FINAL_OUTPUTS = ("annotations.json", "report.json", "summary.json", "contact_sheet.png")
"""Written at the end of a run, from the records; removed when a run (re)starts, so a folder never holds stale ones."""

TEMP_TAG = ".aias-tmp-"
KILL_HOOK = "AIAS_TEST_KILL_AFTER_WRITES"
"""Test hook: ``k`` kills this process (SIGKILL) at the k-th write step (a temporary file written, a rename done)."""


class ManifestMismatch(AiasError, RuntimeError):
    """The output folder holds another run."""


def file_hash(path) -> str:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError as e:
        return f"unreadable: {type(e).__name__}"
    return h.hexdigest()


def config_hash(cfg) -> str:
    return hashlib.sha256(json.dumps(asdict(cfg), sort_keys=True, default=str).encode()).hexdigest()


def item_hash(item) -> str:
    """Content hash of one input: image bytes, label file bytes, the item's boxes, labels, K and problems."""
    h = hashlib.sha256(file_hash(item.path).encode())
    label_file = item.meta.get("label_file") if item.meta else None
    if label_file:
        h.update(file_hash(label_file).encode())
    h.update(
        json.dumps(
            [
                item.bboxes_xywh,
                item.labels,
                item.K,
                item.stereo_right,
                item.baseline_m,
                item.meta.get("yolo_rows"),
                getattr(item, "problems", None),
                getattr(item, "invalid", None),
            ],
            default=str,
        ).encode()
    )
    if item.stereo_right:
        h.update(file_hash(item.stereo_right).encode())
    return h.hexdigest()


def build_manifest(
    items,
    cfg,
    seed: int,
    preset: str | None = None,
    options: dict | None = None,
    hashes: list[str] | None = None,
    outputs: list[str] | tuple[str, ...] = (),
) -> dict:
    """The manifest of a run over ``items`` (``hashes``: their :func:`item_hash`, computed when not given).
    ``outputs``: every path (relative to ``out``) the run may write, the only ones ``--overwrite`` removes later.
    ``run_id`` is a digest of the run key, so the same run has the same id (and temporary-file prefix) on resume."""
    hashes = hashes if hashes is not None else [item_hash(it) for it in items]
    m = {
        "package": "aias-augment",
        "version": __version__,
        "seed": int(seed),
        "preset": preset,
        "config_hash": config_hash(cfg),
        "options": options or {},
        "inputs": [{"path": it.path, "sha256": h} for it, h in zip(items, hashes)],
    }
    run_id = hashlib.sha256(json.dumps(run_key(m), sort_keys=True, default=str).encode()).hexdigest()[:12]
    return {**m, "run_id": run_id, "temp_prefix": f"{TEMP_TAG}{run_id}-", "outputs": list(outputs), "complete": False}


def run_key(m: dict) -> dict:
    return {
        "version": m.get("version"),
        "seed": m.get("seed"),
        "preset": m.get("preset"),
        "config_hash": m.get("config_hash"),
        "options": m.get("options"),
        "inputs": [i["path"] for i in m.get("inputs", [])],
    }


def _describe(old: dict, new: dict) -> str:
    a, b = run_key(old), run_key(new)
    diffs = [
        f"{k}: {a[k]!r} -> {b[k]!r}" for k in ("version", "seed", "preset", "config_hash", "options") if a[k] != b[k]
    ]
    if a["inputs"] != b["inputs"]:
        first = next(
            (i for i, (x, y) in enumerate(zip(a["inputs"], b["inputs"])) if x != y),
            min(len(a["inputs"]), len(b["inputs"])),
        )
        diffs.append(f"inputs: {len(a['inputs'])} -> {len(b['inputs'])} images, first difference at #{first}")
    return "; ".join(diffs)


LOCK_NAME = ".aias-augment.lock"


class OutputBusy(ManifestMismatch):
    """Another run holds the output folder."""


@contextlib.contextmanager
def output_lock(out: Path):
    """Hold ``out``'s run lock (an advisory ``flock`` on ``out/.aias-augment.lock``, released by the kernel when the
    holder exits or is killed, so a killed run never leaves a stale lock). A second run into the same folder is
    refused at start (:class:`OutputBusy`), before it touches anything."""
    out.mkdir(parents=True, exist_ok=True)
    f = open(out / LOCK_NAME, "a+")
    try:
        try:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.seek(0)
            holder = f.read().strip() or "another process"
            raise OutputBusy(
                f"{out} is being written by another aias-augment run ({holder}); wait for it to "
                "finish or use another --out"
            ) from None
        f.seek(0)
        f.truncate()
        f.write(f"pid {os.getpid()} on {socket.gethostname()}")
        f.flush()
        yield
    finally:
        f.close()


def image_name(index: int, source: str, suffix: str = ".png") -> str:
    """The output image of input ``index`` (``source`` its path): ``images/<image_name>``."""
    return f"{index:06d}_{Path(source).stem}{suffix}"


def planned_outputs(sources) -> list[str]:
    """Every path (relative to ``out``) an image run over ``sources`` (input paths, in order) may write."""
    per_item = [p for i, s in enumerate(sources) for p in (f"records/{i:06d}.json", f"images/{image_name(i, s)}")]
    return [*per_item, *FINAL_OUTPUTS, "manifest.json"]


def read_manifest(out: Path) -> dict | None:
    """``out/manifest.json`` if an aias-augment run wrote it (a readable mapping naming the package), else None."""
    try:
        m = json.loads((Path(out) / "manifest.json").read_text())
    except (OSError, ValueError, RecursionError):  # RecursionError: nested too deep (not a manifest we wrote)
        return None
    return m if isinstance(m, dict) and m.get("package") == "aias-augment" else None


def recorded_sun_now(out) -> str | None:
    """The concrete UTC that the run in ``out`` resolved ``--sun-from LAT,LON,now,HEADING`` to, or None."""
    sun = ((read_manifest(Path(out)) or {}).get("options") or {}).get("sun_from") or {}
    return sun.get("utc") if isinstance(sun, dict) and sun.get("utc_given") == "now" else None


def check_out_apart(out, inputs) -> None:
    """``out`` must neither be, hold, nor lie inside any input: ``inputs`` are (what, path) pairs (e.g.
    ("--images", "ds/images")), compared as resolved real paths (symlinks followed). InputError naming both."""
    real_out = Path(os.path.realpath(out))
    for what, path in inputs:
        if not path:
            continue
        real = Path(os.path.realpath(path))
        if real == real_out:
            relation = "is"
        elif real_out.is_relative_to(real):
            relation = "lies inside"
        elif real.is_relative_to(real_out):
            relation = "holds"
        else:
            continue
        shown = f"{path} ({real})" if str(real) != str(path) else str(path)
        raise InputError(
            f"--out {out} {relation} {what} {shown}: choose an --out that neither holds nor lies inside any input"
        )


_write_steps = 0


def _write_step() -> None:
    """One durable step of a write (see :data:`KILL_HOOK`)."""
    global _write_steps
    kill_at = os.environ.get(KILL_HOOK)
    if kill_at:
        _write_steps += 1
        if _write_steps >= int(kill_at):
            os.kill(os.getpid(), signal.SIGKILL)


def write_file(dest: Path, temp_prefix: str, write) -> None:
    """Write ``dest`` atomically: ``write(tmp)`` fills ``<temp_prefix><name>`` in ``dest``'s folder, which is then
    renamed over ``dest``; a killed run leaves ``dest`` as it was and, at most, the temporary file."""
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_name(temp_prefix + dest.name)
    tmp.unlink(missing_ok=True)  # a leftover (or a link placed there) is replaced, never written through
    try:
        write(tmp)
        _write_step()
        os.replace(tmp, dest)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _write_step()


def write_json(dest: Path, obj, temp_prefix: str) -> None:
    """:func:`write_file` of ``json.dumps(obj)``."""

    def put(tmp: Path) -> None:
        with open(tmp, "x") as f:
            f.write(json.dumps(obj))

    write_file(dest, temp_prefix, put)


def _inside(out: Path, rel: str) -> Path | None:
    """``out / rel`` when ``rel`` is a plain relative path whose folder resolves inside ``out``, else None."""
    p = Path(rel)
    if p.is_absolute() or ".." in p.parts or not p.parts:
        return None
    path = out / p
    real_out = Path(os.path.realpath(out))
    return path if Path(os.path.realpath(path.parent)).is_relative_to(real_out) else None


def _remove_temp_files(out: Path, manifest: dict) -> None:
    """Files named with ``manifest``'s temporary prefix in ``out`` and in the folders of its outputs."""
    prefix = manifest.get("temp_prefix")
    if not (isinstance(prefix, str) and prefix.startswith(TEMP_TAG) and len(prefix) > len(TEMP_TAG)):
        return
    folders = {"."} | {str(Path(rel).parent) for rel in manifest.get("outputs", []) if isinstance(rel, str)}
    for rel in sorted(folders):
        entry = _inside(out, f"{rel}/-")  # a name in that folder: the folder itself must resolve inside out
        if entry is None or not entry.parent.is_dir():
            continue
        for f in entry.parent.iterdir():
            if f.name.startswith(prefix) and (f.is_file() or f.is_symlink()):
                f.unlink()


def _remove_outputs(out: Path, manifest: dict) -> None:
    """What ``manifest`` (a previous run's) lists, inside ``out``, and its temporary files; then its emptied
    folders. Nothing else."""
    listed = manifest.get("outputs")
    if not isinstance(listed, list):  # a manifest without the list: the paths an image run over its inputs writes
        listed = planned_outputs(i.get("path", "") for i in manifest.get("inputs", []))
    _remove_temp_files(out, manifest)
    folders = set()
    for rel in listed:
        path = _inside(out, rel) if isinstance(rel, str) else None
        if path is not None and (path.is_symlink() or path.is_file()):
            path.unlink()
            folders.add(path.parent)
    for folder in sorted(folders, key=lambda f: -len(f.parts)):
        if folder != out and not any(folder.iterdir()):
            folder.rmdir()


def _refuse_links_out(out: Path, outputs: list[str]) -> None:
    """Every folder the run writes in must resolve inside ``out`` (a link such as ``out/images -> ~/photos`` would
    lead the writes outside it)."""
    for folder in sorted({str(Path(rel).parent) for rel in outputs}):
        if _inside(out, f"{folder}/-") is None:
            raise InputError(
                f"{out / folder} leads outside --out {out} ({os.path.realpath(out / folder)}): a run writes only "
                "inside --out; use another --out"
            )


def _refuse_foreign(out: Path, outputs: list[str]) -> None:
    """A new run writes into ``out`` only where nothing is: a file in the way is someone else's."""
    taken = [rel for rel in outputs if (out / rel).exists() or (out / rel).is_symlink()]
    if taken:
        more = f" and {len(taken) - 1} more" if len(taken) > 1 else ""
        raise ManifestMismatch(
            f"{out} already holds {taken[0]}{more}, which no aias-augment manifest there lists; it is never "
            "written over: use another --out, or move those files away"
        )


def prepare_output(out: Path, manifest: dict, overwrite: bool = False) -> dict[int, str]:
    """Check ``out`` against ``manifest`` and write it (``complete: false``). The same run resumes: its final
    outputs and its temporary files are removed, its records kept. Another run (a different key) is refused unless
    ``overwrite``, which removes the files that run's manifest lists, and only those. A path this run writes that
    is taken by a file no manifest lists (the user's) is refused, never written over. Returns {index: input hash}
    of the previous run (empty for a new run)."""
    out.mkdir(parents=True, exist_ok=True)
    _refuse_links_out(out, manifest["outputs"])
    old = read_manifest(out)
    previous: dict[int, str] = {}
    if old is not None and run_key(old) == run_key(manifest):
        previous = {i: x["sha256"] for i, x in enumerate(old["inputs"])}
    elif old is not None and not overwrite:
        raise ManifestMismatch(
            f"{out} holds another run ({_describe(old, manifest)}); use another --out, or --overwrite to replace it"
        )
    else:
        if old is not None:
            _remove_outputs(out, old)
        _refuse_foreign(out, manifest["outputs"])
    write_json(out / "manifest.json", manifest, manifest["temp_prefix"])  # not complete, before removing finals
    for name in FINAL_OUTPUTS:  # rewritten at the end: a run killed before then leaves none (never a stale one)
        (out / name).unlink(missing_ok=True)
    _remove_temp_files(out, manifest)
    return previous


def mark_complete(out: Path, manifest: dict) -> None:
    """The last write of a run: the manifest with ``complete: true``, once every output is in place."""
    write_json(out / "manifest.json", {**manifest, "complete": True}, manifest["temp_prefix"])
