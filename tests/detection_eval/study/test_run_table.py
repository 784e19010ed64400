"""A table's runs.jsonl: runs being trained are folded in by name, committed lines are kept, a finished run (in the
table or under runs_dir) is not trained again, and a broken line is a one-line error naming its file and line."""

from __future__ import annotations

import json

import pytest

from detection_eval.study.config import StudyConfig
from detection_eval.study.run_table import (
    RUNS_FILE,
    collect_runs,
    effective_config_sha256,
    finished_run,
    metrics_dir,
    read_runs,
    write_run_record,
)


def _cfg(tmp_path) -> StudyConfig:
    return StudyConfig(runs_dir=str(tmp_path / "runs"), results_dir=str(tmp_path / "result"))


def test_collect_folds_local_runs_into_the_table_and_keeps_committed_lines(tmp_path):
    cfg = _cfg(tmp_path)
    table = tmp_path / "result" / RUNS_FILE
    table.parent.mkdir()
    committed = {"run": "original_seed0", "arm": "original", "seed": 0, "metrics": {"AP": 0.3}}
    stale = {"run": "inserted_n60_seed0", "arm": "inserted", "seed": 0, "metrics": {"AP": 0.1}}
    table.write_text(json.dumps(committed) + "\n" + json.dumps(stale) + "\n")
    metrics_dir(cfg).mkdir(parents=True)
    fresh = {"arm": "inserted", "seed": 0, "amount": 60, "metrics": {"AP": 0.4}}
    (metrics_dir(cfg) / "inserted_n60_seed0.json").write_text(json.dumps(fresh))
    (metrics_dir(cfg) / "inserted_n60_seed1.json").write_text(json.dumps({**fresh, "seed": 1}))
    (metrics_dir(cfg) / "inserted_n60_seed1.running").write_text("123")  # a claim is not a run
    rows = collect_runs(cfg)
    assert sorted(r["run"] for r in rows) == ["inserted_n60_seed0", "inserted_n60_seed1", "original_seed0"]
    back = read_runs(table)  # an independent read of what was written: one line per run, sorted by name
    assert list(back) == sorted(back) and back["original_seed0"] == committed
    assert back["inserted_n60_seed0"] == {"run": "inserted_n60_seed0", **fresh}  # trained again: replaced
    assert [json.loads(line)["run"] for line in table.read_text().splitlines()] == sorted(back)


def test_a_finished_run_is_found_in_the_table_or_under_runs_dir(tmp_path):
    cfg = _cfg(tmp_path)
    assert finished_run(cfg, "original_seed0") is None
    (tmp_path / "result").mkdir()
    (tmp_path / "result" / RUNS_FILE).write_text(json.dumps({"run": "original_seed0", "arm": "original"}) + "\n")
    assert finished_run(cfg, "original_seed0")["arm"] == "original"
    metrics_dir(cfg).mkdir(parents=True)
    (metrics_dir(cfg) / "original_seed1.json").write_text(json.dumps({"arm": "original", "seed": 1}))
    assert finished_run(cfg, "original_seed1")["seed"] == 1


def test_a_broken_line_names_its_file_and_line(tmp_path):
    p = tmp_path / RUNS_FILE
    p.write_text(json.dumps({"run": "a"}) + "\n{not json\n")
    with pytest.raises(ValueError, match=r"runs.jsonl:2: not JSON") as e:
        read_runs(p)
    assert "\n" not in str(e.value)
    p.write_text(json.dumps({"arm": "original"}) + "\n")
    with pytest.raises(ValueError, match=r"runs.jsonl:1: expected an object with a 'run' name"):
        read_runs(p)


def test_run_record_names_command_config_hash_and_summed_seconds(tmp_path):
    cfg = _cfg(tmp_path)
    rows = [
        {"train_seconds": 100.0, "eval_seconds": 5.0, "code_commit": "abcdef0123"},
        {"train_seconds": 50.0, "code_commit": "abcdef0123"},
    ]
    rec = write_run_record(cfg, "studies/detection/x/config.yaml", "python -m studies.detection.x", rows)
    assert json.loads((tmp_path / "result" / "run.json").read_text()) == rec
    assert rec["seconds"] == 155.0 and rec["runs_by_commit"] == {"abcdef0": 2}
    assert rec["config_sha256"] == effective_config_sha256(cfg)
    assert effective_config_sha256(StudyConfig(max_iters=10)) != effective_config_sha256(StudyConfig(max_iters=11))
