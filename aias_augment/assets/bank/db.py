"""A bank folder as a small database: mesh files (``NNNN.glb``) and their index ``bank.json``.

- Unique names: an entry's file name is the first ``NNNN.glb`` that neither the index lists nor the folder holds, so
  an append never overwrites a file; a file the index does not list is never touched, unless it holds exactly the
  bytes being appended (what a writer killed between its two steps leaves behind), then it is adopted.
- One writer at a time: every change happens under an exclusive ``fcntl.flock`` on ``.bank.lock`` in the folder, so
  concurrent ``deform`` / ``from-labels`` / ``reconstruct`` runs into one bank each land all their entries.
- Atomic and durable: each file is written to ``.aias-bank-<name>.tmp`` in the folder, flushed to disk and renamed
  over its name (``os.replace``); the mesh before the index, so the index never lists a file that is missing. Such
  temporary files only exist while their writer holds the lock: the next writer removes the ones a killed writer left.
- Idempotent: an entry identical to one already listed (the same mesh bytes, by SHA-256, and the same record) is not
  appended again, so a rerun of the same command leaves the bank as it was.
- A ``bank.json`` that is not an index (not JSON, not the layout below, two entries naming one file) is a
  :class:`BankError` naming the file, never repaired or overwritten.

Layout: ``{"category": str, "report": {"assets": [{"file": "NNNN.glb", "category", "height_m", "sha256", ...}],
"rejected": {reason: count}}, ...}``.

Test hook: ``AIAS_TEST_KILL_AFTER_WRITES=k`` kills this process (SIGKILL) right after its k-th durable write step
(a temporary file flushed, a rename done), 1-based, counted over the process.
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import signal
from pathlib import Path

from aias_augment.assets.references import inside
from aias_augment.core.errors import AiasError

INDEX_NAME = "bank.json"
LOCK_NAME = ".bank.lock"
TEMP_PREFIX = ".aias-bank-"
KILL_ENV = "AIAS_TEST_KILL_AFTER_WRITES"
_writes_done = 0


class BankError(AiasError, ValueError):
    """A bank folder that cannot be used as one: an unreadable or malformed ``bank.json``, a path that is not a
    folder."""


def _after_write_step() -> None:
    global _writes_done
    _writes_done += 1
    k = os.environ.get(KILL_ENV)
    if k and k.isdigit() and _writes_done == int(k):
        os.kill(os.getpid(), signal.SIGKILL)


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def durable_write(path: Path, data: bytes) -> None:
    """``data`` at ``path`` atomically: a temporary file in the same folder, flushed, renamed over ``path``."""
    tmp = path.parent / f"{TEMP_PREFIX}{path.name}.tmp"
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    _after_write_step()
    os.replace(tmp, path)
    _fsync_dir(path.parent)
    _after_write_step()


def check_folder(folder: str | Path) -> Path:
    """``folder`` as a bank folder path: a folder or nothing yet; its index, when there is one, readable
    (:func:`read_index`). Raises :class:`BankError`."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise BankError(f"{folder} is a file, not a bank folder: give a folder (it is created when missing)")
    read_index(folder)
    return folder


def read_index(folder: str | Path) -> dict:
    """The index of the bank folder ``folder`` (an empty one when it has none). Raises :class:`BankError` naming the
    file when it is not JSON or not a bank index."""
    index = Path(folder) / INDEX_NAME
    if not index.exists():
        return {"report": {"assets": [], "rejected": {}}}
    try:
        bank = json.loads(index.read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as e:  # RecursionError: nested too deep
        raise BankError(f"{index}: not a readable bank index ({type(e).__name__}: {e}); move it away or restore it")
    entries = bank.get("report", {}).get("assets") if isinstance(bank, dict) else None
    if not isinstance(entries, list) or not all(
        isinstance(e, dict) and isinstance(e.get("file"), str) and isinstance(e.get("category"), str) for e in entries
    ):
        raise BankError(
            f"{index}: not a bank index (needs report.assets: a list of entries with 'file' and 'category')"
        )
    names = [e["file"] for e in entries]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise BankError(f"{index}: entries {dup[:3]} are listed twice; repair the index")
    bad = [n for n in names if Path(n).is_absolute() or inside(Path(folder), n) in (None, Path(folder).resolve())]
    if bad:
        raise BankError(f"{index}: entry files must be relative paths inside the bank folder, got {bad[:3]}")
    rejected = bank["report"].get("rejected") or {}  # absent or empty ([] in hand-written indexes): none
    if not isinstance(rejected, dict):
        raise BankError(f"{index}: not a bank index (report.rejected must map reasons to counts)")
    bank["report"]["rejected"] = rejected
    return bank


@contextlib.contextmanager
def locked(folder: str | Path):
    """Hold the bank folder's exclusive lock (creating the folder); temporary files of killed writers removed."""
    folder = check_folder(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / LOCK_NAME, "a+b") as lock:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX)
        try:
            for stale in folder.glob(f"{TEMP_PREFIX}*.tmp"):
                stale.unlink()
            yield folder
        finally:
            fcntl.flock(lock.fileno(), fcntl.LOCK_UN)


def _write_index(folder: Path, bank: dict) -> None:
    durable_write(folder / INDEX_NAME, json.dumps(bank, indent=1).encode())


def _record(entry: dict) -> dict:
    return {k: v for k, v in entry.items() if k != "file"}


def append_entry(folder: str | Path, glb: bytes, entry: dict, header: dict | None = None) -> tuple[dict, bool]:
    """Append the mesh ``glb`` (GLB bytes) and its ``entry`` (category, height, source...) to the bank ``folder``
    under its lock. ``header``: top-level keys set when the index does not have them yet (its first category, the
    writer's config). Returns (the entry as listed, with ``file`` and ``sha256``; whether it was new): an identical
    entry already listed is returned as it is."""
    digest = hashlib.sha256(glb).hexdigest()
    record = {**{k: v for k, v in entry.items() if k != "file"}, "sha256": digest}
    with locked(folder) as folder:
        bank = read_index(folder)
        entries = bank["report"]["assets"]
        for e in entries:
            if _record(e) == json.loads(json.dumps(record)):
                return e, False
        taken = {e["file"] for e in entries}
        k = 0
        while True:
            name = f"{k:04d}.glb"
            k += 1
            if name in taken:
                continue
            path = folder / name
            if not path.exists():
                durable_write(path, glb)
                break
            if path.is_file() and hashlib.sha256(path.read_bytes()).hexdigest() == digest:
                break  # the same bytes, left by a writer killed before its index step: adopted
        full = {"file": name, **record}
        entries.append(full)
        for key, value in (header or {}).items():
            bank.setdefault(key, value)
        _write_index(folder, bank)
        return full, True


def set_rejected(folder: str | Path, rejected: dict[str, int], header: dict | None = None) -> None:
    """Record a writer's rejection counts in the index (each reason's count replaced) and its ``header`` keys the
    index lacks, under the lock; the index is rewritten only when that changes it."""
    with locked(folder) as folder:
        bank = read_index(folder)
        before = json.dumps(bank, sort_keys=True)
        bank["report"]["rejected"].update({str(k): int(v) for k, v in rejected.items()})
        for key, value in (header or {}).items():
            bank.setdefault(key, value)
        if json.dumps(bank, sort_keys=True) != before:
            _write_index(folder, bank)


def listed_files(folder: str | Path) -> list[str]:
    """The entry files the index of ``folder`` lists, in order."""
    return [e["file"] for e in read_index(folder)["report"]["assets"]]
