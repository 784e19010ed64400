"""The ``run.json`` beside a study's result: the command that made it, the commit, the config's hash and the
seconds it took, so that every committed figure names what produced it."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def _arg(argv: list[str], name: str) -> str | None:
    for i, a in enumerate(argv):
        if a == name and i + 1 < len(argv):
            return argv[i + 1]
        if a.startswith(name + "="):
            return a.split("=", 1)[1]
    return None


def _commit(folder: Path) -> str | None:
    """HEAD's hash, with ``-dirty`` when a tracked file outside ``folder`` (the run's own output) differs from it."""
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True)
        status = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO, capture_output=True, text=True
        )
    except (OSError, subprocess.CalledProcessError):
        return None
    own = folder.resolve()
    changed = [REPO / line[3:].split(" -> ")[-1] for line in status.stdout.splitlines() if line.strip()]
    dirty = any(not p.resolve().is_relative_to(own) for p in changed)
    return head.stdout.strip() + ("-dirty" if dirty else "")


def record_folder(package: str, argv: list[str]) -> Path:
    """Where a run's ``run.json`` goes: the ``--out`` folder (the folder holding ``--out`` when it names a file), or
    the study's own ``result/`` when no ``--out`` is given."""
    out = _arg(argv, "--out")
    if out is None:
        return REPO.joinpath(*package.split(".")) / "result"
    p = Path(out)
    return p.parent if p.suffix else p


def run_record(package: str, argv: list[str], seconds: float, folder: Path) -> dict:
    config = _arg(argv, "--config")
    digest = hashlib.sha256(Path(config).read_bytes()).hexdigest()[:16] if config and Path(config).is_file() else None
    return {
        "command": " ".join(["python", "-m", package, *argv]),
        "commit": _commit(folder),
        "config": config,
        "config_sha256": digest,
        "seconds": round(seconds, 1),
    }


def run_recorded(main: Callable[[], int | None], package: str) -> int:
    """Run a study's ``main`` and, when it succeeds, write ``run.json`` into its output folder."""
    argv = sys.argv[1:]
    t0 = time.perf_counter()
    rc = main() or 0
    folder = record_folder(package, argv)
    if rc == 0 and folder.is_dir() and not {"-h", "--help"} & set(argv):
        (folder / "run.json").write_text(
            json.dumps(run_record(package, argv, time.perf_counter() - t0, folder), indent=1) + "\n"
        )
    return rc
