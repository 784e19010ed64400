"""The run manifest of an offline augmentation (``<out>/manifest.json``): what the output folder was made from.

The *run key* (package version, seed, preset, config hash, options, the ordered list of input paths) must match for
a rerun to resume; a different key is refused (:class:`ManifestMismatch`) unless ``overwrite``, which deletes the
previous run's outputs first. Each input also has a content hash (image bytes, label file bytes, the item's boxes
and labels): a record is reused only when its ``input_hash`` equals the current one and it is not a skip, so a
fixed input is redone and a failed item is retried on resume, and the result equals a fresh run (each image draws
from ``default_rng([seed, index])``).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import shutil
import socket
from dataclasses import asdict
from pathlib import Path

from aias_augment import __version__
from aias_augment.core.coco_io import atomic_write_json

RUN_OUTPUTS = (
    "records",
    "images",
    "annotations.json",
    "report.json",
    "summary.json",
    "contact_sheet.png",
    "manifest.json",
)

FINAL_OUTPUTS = ("annotations.json", "report.json", "summary.json", "contact_sheet.png")


class ManifestMismatch(RuntimeError):
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


def build_manifest(items, cfg, seed: int, preset: str | None = None, options: dict | None = None) -> dict:
    return {
        "package": "aias-augment",
        "version": __version__,
        "seed": int(seed),
        "preset": preset,
        "config_hash": config_hash(cfg),
        "options": options or {},
        "inputs": [{"path": it.path, "sha256": h} for it, h in zip(items, (item_hash(it) for it in items))],
    }


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


def prepare_output(out: Path, manifest: dict, overwrite: bool = False) -> dict[int, str]:
    """Check ``out`` against ``manifest`` and write it. Returns {index: input hash} of the previous run (empty for
    a new run): the records whose hash still matches may be reused."""
    out.mkdir(parents=True, exist_ok=True)
    mpath = out / "manifest.json"
    previous = {}
    if mpath.exists() or (out / "records").exists():
        old = None
        if mpath.exists():
            try:
                old = json.loads(mpath.read_text())
            except ValueError:
                old = None
        if old is not None and run_key(old) == run_key(manifest):
            previous = {i: x["sha256"] for i, x in enumerate(old["inputs"])}
        elif not overwrite:
            why = _describe(old, manifest) if old is not None else "no readable manifest.json (an older run?)"
            raise ManifestMismatch(f"{out} holds another run ({why}); use another --out, or --overwrite to replace it")
        else:
            for name in RUN_OUTPUTS:
                p = out / name
                if p.is_dir():
                    shutil.rmtree(p)
                elif p.exists():
                    p.unlink()
    for name in FINAL_OUTPUTS:  # rewritten at the end: a run killed before then leaves none (never a stale one)
        (out / name).unlink(missing_ok=True)
    # Temporary files of writes cut short by a kill (atomic_write_json's "<name>XXXX.tmp", write_rgb's "x.tmp.png").
    for sub, pattern in (("records", "*.tmp"), ("images", "*.tmp.*"), (".", "*.tmp"), (".", "*.check")):
        for p in (out / sub).glob(pattern):
            if p.is_file():
                p.unlink()
    atomic_write_json(mpath, manifest)
    return previous
