"""studies._shared.run_record: a study's run leaves run.json in its output folder with the command, the commit and
the seconds; nothing is written elsewhere."""

import hashlib
import json
import subprocess
import sys

from studies._shared.run_record import REPO, record_folder, run_recorded


def test_the_record_goes_to_the_out_folder_or_beside_an_out_file_or_to_the_studys_result(tmp_path):
    assert record_folder("studies.lighting.hdri", ["--out", str(tmp_path)]) == tmp_path
    assert record_folder("studies.lighting.hdri", [f"--out={tmp_path}/sheet.jpg"]) == tmp_path
    assert record_folder("studies.lighting.hdri", []) == REPO / "studies" / "lighting" / "hdri" / "result"


def test_a_run_writes_its_command_commit_and_seconds(tmp_path, monkeypatch):
    argv = ["--photos", "3", "--out", str(tmp_path), "--config", str(tmp_path / "c.yaml")]
    (tmp_path / "c.yaml").write_text("a: 1\n")
    monkeypatch.setattr(sys, "argv", ["__main__.py", *argv])
    seen = []
    assert run_recorded(lambda: seen.append(sys.argv[1:]) or 0, "studies.lighting.hdri") == 0
    record = json.loads((tmp_path / "run.json").read_text())
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout.strip()
    assert seen == [argv]
    assert record["command"] == "python -m studies.lighting.hdri " + " ".join(argv)
    assert record["commit"].split("-")[0] == head
    assert record["config_sha256"] == hashlib.sha256(b"a: 1\n").hexdigest()[:16]
    assert record["seconds"] >= 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.yaml", "run.json"]


def test_a_failed_run_leaves_no_record(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "argv", ["__main__.py", "--out", str(tmp_path)])
    assert run_recorded(lambda: 2, "studies.lighting.hdri") == 2
    assert list(tmp_path.iterdir()) == []
