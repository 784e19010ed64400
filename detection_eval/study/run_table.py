"""A table's runs: one line per run in ``<results_dir>/runs.jsonl`` (committed), each the run's metrics with its name
under ``"run"``; a run being trained writes its own JSON under ``<runs_dir>/metrics/`` (with its claim file beside
it, not committed), and the summarize stage folds those into the table's lines."""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path

from detection_eval.study.config import StudyConfig, repo_path

RUNS_FILE = "runs.jsonl"


def metrics_dir(cfg: StudyConfig) -> Path:
    """Where a run being trained writes its metrics (and its claim): ``<runs_dir>/metrics``."""
    return repo_path(cfg.runs_dir) / "metrics"


def read_runs(path: Path) -> dict[str, dict]:
    """Run name -> metrics of a ``runs.jsonl`` (empty when the file does not exist); a line that is not a JSON
    object with a ``"run"`` name raises ``ValueError`` naming the file and line."""
    runs: dict[str, dict] = {}
    if not path.exists():
        return runs
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}:{n}: not JSON ({e.msg}); fix or remove the line") from None
        if not isinstance(row, dict) or not isinstance(row.get("run"), str):
            raise ValueError(f"{path}:{n}: expected an object with a 'run' name")
        runs[row["run"]] = row
    return runs


def write_runs(path: Path, runs: dict[str, dict]) -> None:
    """One line per run, sorted by name."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(json.dumps(runs[k]) + "\n" for k in sorted(runs)))


def finished_run(cfg: StudyConfig, name: str) -> dict | None:
    """The metrics of run ``name`` when it is done: in the table's ``runs.jsonl`` or under :func:`metrics_dir`."""
    local = metrics_dir(cfg) / f"{name}.json"
    if local.exists():
        return json.loads(local.read_text())
    return read_runs(repo_path(cfg.results_dir) / RUNS_FILE).get(name)


def collect_runs(cfg: StudyConfig) -> list[dict]:
    """The table's runs: its ``runs.jsonl`` with every run finished under :func:`metrics_dir` added (a run trained
    again replaces its line); the file is rewritten with them. Returns the rows."""
    path = repo_path(cfg.results_dir) / RUNS_FILE
    runs = read_runs(path)
    for p in sorted(metrics_dir(cfg).glob("*.json")):
        runs[p.stem] = {"run": p.stem, **{k: v for k, v in json.loads(p.read_text()).items() if k != "run"}}
    if runs:
        write_runs(path, runs)
    return list(runs.values())


def effective_config_sha256(cfg: StudyConfig) -> str:
    """The hash of the loaded config (its ``_base_`` files merged in), so an edit of a base changes it too."""
    import dataclasses

    text = json.dumps(dataclasses.asdict(cfg), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def write_run_record(cfg: StudyConfig, config_path: str, command: str, rows: list[dict]) -> dict:
    """``<results_dir>/run.json``: the command that wrote the table, the commit it ran at (``-dirty`` when tracked
    files differed), the config and its hash, and the seconds of training and scoring summed over the runs."""
    root = repo_path(".")
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=root,
            capture_output=True,
            text=True,
            timeout=10,
        )
        commit = head.stdout.strip() + ("-dirty" if dirty.stdout.strip() else "") if head.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        commit = None
    commits: dict[str, int] = {}
    for r in rows:
        c = str(r.get("code_commit", "unknown"))[:7]
        commits[c] = commits.get(c, 0) + 1
    record = {
        "command": command,
        "commit": commit,
        "config": config_path,
        "config_sha256": effective_config_sha256(cfg),
        "seconds": round(sum(r.get("train_seconds", 0.0) + r.get("eval_seconds", 0.0) for r in rows), 1),
        "runs": len(rows),
        "runs_by_commit": dict(sorted(commits.items())),
    }
    path = repo_path(cfg.results_dir) / "run.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=1) + "\n")
    return record
