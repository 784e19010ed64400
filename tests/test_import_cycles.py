"""The package's import graph: the import-linter contracts of pyproject.toml (the step folders import only downwards,
in the pipeline's order; the package never imports the research detector) hold, and no module import cycle runs
(grimp's graph: module-level, function-level and TYPE_CHECKING imports). Another module's private names are never
imported (tools/import_cycles.py)."""

import importlib.util
import sys
from pathlib import Path

import grimp
import networkx as nx
from importlinter import configuration
from importlinter.application.use_cases import create_report, read_user_options

configuration.configure()  # importlinter's readers and graph builder (what its CLI and importlinter.api set up)

ROOT = Path(__file__).resolve().parents[1]


def _imports_named(metadata) -> list[str]:
    """Every 'importer -> imported' pair a broken contract's report names (its nested dicts and lists)."""
    if isinstance(metadata, dict):
        own = [f"{metadata['importer']} -> {metadata['imported']}"] if {"importer", "imported"} <= set(metadata) else []
        return own + [s for v in metadata.values() for s in _imports_named(v)]
    if isinstance(metadata, (list, tuple)):
        return [s for v in metadata for s in _imports_named(v)]
    return []


def _broken_contracts(user_options) -> dict[str, list[str]]:
    """{contract name: the imports that break it} of the contracts that do not hold."""
    # The contract types as importlinter's CLI registers them (a report made through the API registers only these).
    user_options.session_options["contract_types"] = [
        "layers: importlinter.contracts.layers.LayersContract",
        "forbidden: importlinter.contracts.forbidden.ForbiddenContract",
    ]
    report = create_report(user_options, cache_dir=None)
    return {c.name: _imports_named(check.metadata) for c, check in report.get_contracts_and_checks() if not check.kept}


def test_the_import_contracts_hold():
    options = read_user_options(str(ROOT / "pyproject.toml"))
    assert {c["id"] for c in options.contracts_options} == {"layers", "no-detector"}
    assert [c["id"] for c in options.contracts_options if c.get("ignore_imports")] == []  # no exceptions listed
    assert _broken_contracts(options) == {}


def test_every_folder_of_the_package_is_in_a_layer():
    """A new step folder cannot escape the contract: every subpackage and module directly under aias_augment is named
    in one layer (``_data`` holds no Python)."""
    options = read_user_options(str(ROOT / "pyproject.toml"))
    (layers,) = [c for c in options.contracts_options if c["id"] == "layers"]
    named = {n.strip(" ()") for layer in layers["layers"] for part in layer.split("|") for n in part.split(":")}
    package = ROOT / "aias_augment"
    children = {p.stem for p in package.glob("*.py") if p.stem != "__init__"}
    children |= {p.name for p in package.iterdir() if (p / "__init__.py").exists()}
    assert children == named


def _package(tmp_path: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)


def test_the_layers_contract_breaks_on_an_upward_import(tmp_path, monkeypatch):
    """The contract as pyproject.toml writes it, on a package with the same folders: a function-level import of a
    higher layer (core -> pipeline) and a TYPE_CHECKING one (analyse -> apply) are each reported; without them it holds."""
    folders = ("cli", "adapters", "evaluation", "pipeline", "apply", "plan", "analyse", "scenes", "assets", "core")
    files = {"pkg/__init__.py": "", "pkg/version.py": "V = 1\n"}
    files |= {f"pkg/{f}/__init__.py": "" for f in folders}
    files["pkg/core/a.py"] = "import pkg.version\n"
    files["pkg/apply/b.py"] = "from pkg.core import a\n"
    _package(tmp_path, files)
    monkeypatch.syspath_prepend(str(tmp_path))
    options = read_user_options(str(ROOT / "pyproject.toml"))
    (layers,) = [c for c in options.contracts_options if c["id"] == "layers"]
    contract = {**layers, "containers": ["pkg"], "ignore_imports": []}
    options.session_options = {"root_packages": ["pkg"]}
    options.contracts_options = [contract]
    assert _broken_contracts(options) == {}
    _package(
        tmp_path,
        {
            "pkg/core/a.py": "import pkg.version\n\n\ndef f():\n    from pkg.pipeline import c\n",
            "pkg/pipeline/c.py": "",
            "pkg/analyse/d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.apply import b\n",
        },
    )
    for name in [m for m in sys.modules if m == "pkg" or m.startswith("pkg.")]:
        del sys.modules[name]
    (broken,) = _broken_contracts(options).values()
    assert "pkg.core.a -> pkg.pipeline.c" in broken and "pkg.analyse.d -> pkg.apply.b" in broken


def import_cycles(package: str) -> list[list[str]]:
    """The module import cycles of ``package`` (strongly connected components of more than one module), each
    sorted, with every import grimp finds (module-level, function-level, TYPE_CHECKING)."""
    graph = grimp.build_graph(package, cache_dir=None)
    g = nx.DiGraph()
    for m in graph.modules:
        g.add_node(m)
        g.add_edges_from((m, t) for t in graph.find_modules_directly_imported_by(m))
    return sorted(sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1)


def test_no_import_cycle_in_aias_augment():
    assert import_cycles("aias_augment") == []


def test_no_import_cycle_in_detection_eval():
    assert import_cycles("detection_eval") == []


def test_a_cycle_through_function_level_relative_and_type_checking_imports_is_found(tmp_path, monkeypatch):
    """The check is not vacuous: modules that import each other (one inside a function, one relative, one through
    ``from pkg import submodule``) are one cycle, and two joined by a TYPE_CHECKING import another."""
    _package(
        tmp_path,
        {
            "cyc/__init__.py": "",
            "cyc/a.py": "from .sub import b\n",
            "cyc/sub/__init__.py": "",
            "cyc/sub/b.py": "def f():\n    from ..c import x\n",
            "cyc/c.py": "import cyc.a\nx = 1\n",
            "cyc/d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .e import y\n",
            "cyc/e.py": "from . import d\ny = 1\n",
        },
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert import_cycles("cyc") == [["cyc.a", "cyc.c", "cyc.sub.b"], ["cyc.d", "cyc.e"]]


def _tool():
    spec = importlib.util.spec_from_file_location("import_cycles", ROOT / "tools" / "import_cycles.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_no_module_imports_another_modules_private_name():
    tool = _tool()
    for package in ("aias_augment", "detection_eval"):
        assert tool.private_reaches(package) == [], package


def test_the_study_scripts_and_benchmarks_use_only_public_names():
    """Of the package and of each other: a script that needs another script's helper imports it by a public name."""
    import ast

    found = []
    for folder in ("detection_eval", "studies", "benchmarks", "tools"):
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
