"""No import cycle inside the package: the module import graph (module- and function-level imports) of
``aias_augment`` has no strongly connected component of more than one module (scripts/import_cycles.py)."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _tool():
    spec = importlib.util.spec_from_file_location("import_cycles", ROOT / "scripts" / "import_cycles.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_no_import_cycle_in_aias_augment():
    tool = _tool()
    graph = tool.import_graph("aias_augment")
    found = tool.cycles(graph)
    assert not found, "import cycles:\n" + "\n".join(
        f"{', '.join(c)}:\n  " + "\n  ".join(tool.describe(c, graph)) for c in found
    )


def test_no_import_cycle_in_detection_eval():
    tool = _tool()
    assert tool.cycles(tool.import_graph("detection_eval")) == []


def test_the_tool_finds_cycles_through_function_level_and_relative_imports(tmp_path):
    """The graph is not vacuous: a package whose modules import each other (one inside a function, one relative,
    one through ``from pkg import submodule``) is one cycle; a TYPE_CHECKING import is not an edge."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .sub import b\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..c import x\n")
    (pkg / "c.py").write_text("import pkg.a\nx = 1\n")
    (pkg / "d.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .e import y\n")
    (pkg / "e.py").write_text("from .d import TYPE_CHECKING\ny = 1\n")
    tool = _tool()
    graph = tool.import_graph("pkg", tmp_path)
    assert graph["pkg.sub.b"] == {"pkg.c": 2}
    assert tool.cycles(graph) == [["pkg.a", "pkg.c", "pkg.sub.b"]]


def test_no_module_imports_another_modules_private_name():
    tool = _tool()
    for package in ("aias_augment", "detection_eval"):
        assert tool.private_reaches(package) == [], package


def test_the_study_scripts_and_benchmarks_use_only_public_names():
    """Of the package and of each other: a script that needs another script's helper imports it by a public name."""
    import ast

    found = []
    for folder in ("detection_eval", "scripts", "benchmarks"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.ImportFrom) and not (node.module or "").startswith("__"):
                    found += [f"{path.name}:{node.lineno} {a.name}" for a in node.names if a.name[:1] == "_"]
    assert [f for f in found if "__" not in f.split()[-1][:2]] == []


def test_the_tool_finds_a_private_name_imported_from_another_module(tmp_path):
    """Relative and absolute forms are both found; a module's own private names and dunders are not reaches."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("from .a import __doc__\n")
    (pkg / "a.py").write_text("def _helper():\n    pass\n")
    (pkg / "b.py").write_text("from .a import _helper\n")
    (pkg / "c.py").write_text("def f():\n    from pkg.a import _helper, __name__\n")
    tool = _tool()
    assert tool.private_reaches("pkg", tmp_path) == ["pkg.b:1 -> pkg.a._helper", "pkg.c:2 -> pkg.a._helper"]
