"""The repository's layout rules: every study folder has its README, its ``run.py`` (runnable with ``python -m``) and
its ``result/`` with a ``run.json``; no file or folder is named for when it was made; no Python file edits
``sys.path``; the committed results stay under 12 MB, their pictures JPEG of at most 1200 px on a side; every
relative link of their Markdown resolves."""

import ast
import json
import re
import subprocess
from pathlib import Path

from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
RESULT_LIMIT_BYTES = 12 * 1024 * 1024
MAX_SIDE = 1200
DATED = re.compile(r"(stop|session|run|idle)_?\d+", re.IGNORECASE)
PICTURES = {".png", ".jpg", ".jpeg", ".gif", ".bmp", ".tif", ".tiff", ".webp"}


def repo_files() -> list[Path]:
    """Tracked files and new files git does not ignore, as they are on disk."""
    out = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return [ROOT / p for p in sorted(set(out.split("\n"))) if p and (ROOT / p).is_file()]


def result_files() -> list[Path]:
    """The committed results: every study's ``result/`` and the ``results/`` folder."""
    return [
        p
        for p in repo_files()
        if p.relative_to(ROOT).parts[0] == "results"
        or (p.relative_to(ROOT).parts[0] == "studies" and "result" in p.relative_to(ROOT).parts)
    ]


def study_folders() -> list[Path]:
    """``studies/<area>/<study>/``: the folders two levels down, shared helpers and caches aside."""
    areas = [a for a in sorted((ROOT / "studies").iterdir()) if a.is_dir() and not a.name.startswith(("_", "."))]
    return [s for a in areas for s in sorted(a.iterdir()) if s.is_dir() and not s.name.startswith(("_", "."))]


def sys_path_edits(source: str) -> list[int]:
    """Lines where ``sys.path`` is changed: a method called on it, an assignment to it or to one of its items."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            targets = [node.func.value]
        elif isinstance(node, ast.Assign):
            targets = node.targets
        elif isinstance(node, ast.AugAssign):
            targets = [node.target]
        else:
            continue
        targets = [t.value if isinstance(t, ast.Subscript) else t for t in targets]
        if any(ast.unparse(t) == "sys.path" for t in targets):
            lines.append(node.lineno)
    return sorted(lines)


def test_every_study_has_its_readme_command_and_result():
    studies = study_folders()
    assert len(studies) >= 30
    missing = []
    for s in studies:
        for part in ("README.md", "run.py", "__main__.py", "__init__.py", "result/run.json"):
            if not (s / part).is_file():
                missing.append(f"{s.relative_to(ROOT)}/{part}")
    assert missing == []


def test_every_study_runs_as_a_module_through_its_main():
    """``python -m studies.<area>.<study>`` runs ``__main__.py``, which calls ``run.main`` (no import of the study
    here: the parse is enough to see the entry point)."""
    for s in study_folders():
        run = ast.parse((s / "run.py").read_text())
        assert any(isinstance(n, ast.FunctionDef) and n.name == "main" for n in run.body), s
        entry = (s / "__main__.py").read_text()
        assert "from .run import main" in entry and "main" in entry.split("import main", 1)[1], s


def test_every_run_json_names_its_command():
    for s in study_folders():
        record = json.loads((s / "result" / "run.json").read_text())
        module = ".".join(s.relative_to(ROOT).parts)
        assert f"-m {module}" in record["command"], s
        assert {"commit", "config_sha256", "seconds"} <= set(record), s


def test_no_file_or_folder_is_named_for_when_it_was_made():
    dated = [str(p.relative_to(ROOT)) for p in repo_files() if DATED.search(str(p.relative_to(ROOT)))]
    assert dated == []


def test_no_python_file_edits_sys_path():
    found = []
    for p in repo_files():
        if p.suffix == ".py":
            found += [f"{p.relative_to(ROOT)}:{n}" for n in sys_path_edits(p.read_text())]
    assert found == []


def test_the_committed_results_stay_under_12_mb():
    total = sum(p.stat().st_size for p in result_files())
    assert total < RESULT_LIMIT_BYTES, f"{total / 2**20:.1f} MiB of results"


def test_result_pictures_are_jpeg_of_at_most_1200_px():
    wrong = []
    for p in result_files():
        if p.suffix.lower() in PICTURES:
            with Image.open(p) as im:
                if im.format != "JPEG" or max(im.size) > MAX_SIDE:
                    wrong.append(f"{p.relative_to(ROOT)}: {im.format} {im.size}")
    assert wrong == []


def test_every_relative_link_in_the_results_and_studies_resolves():
    broken = []
    docs = [p for p in repo_files() if p.suffix == ".md" and p.relative_to(ROOT).parts[0] in ("studies", "results")]
    for md in docs + [ROOT / "README.md"]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", md.read_text()):
            if not re.match(r"[a-z]+:", target) and not (md.parent / target).exists():
                broken.append(f"{md.relative_to(ROOT)} -> {target}")
    assert broken == []


def test_the_sys_path_check_finds_each_form_of_edit():
    src = "import sys\nsys.path.insert(0, 'x')\nsys.path.append('y')\nsys.path[0] = 'z'\nsys.path += ['w']\n"
    assert sys_path_edits(src) == [2, 3, 4, 5]
    assert sys_path_edits("import sys\nprint(sys.path)\nx = 'sys.path.insert'\n") == []
