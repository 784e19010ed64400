"""Import cycles inside a package: the module import graph (module-level and function-level imports, absolute and
relative) built with ``ast``, and its strongly connected components of more than one module (or a module importing
itself).

    python -m tools.import_cycles                 # aias_augment; exit 1 if there is a cycle or a private reach
    python -m tools.import_cycles detection_eval

An edge ``a -> b`` means a module ``a`` imports ``b`` (``from b import x`` where ``b.x`` is a submodule: to
``b.x``; a package's ``__init__`` is the module ``pkg``). Imports under ``if TYPE_CHECKING:`` are not edges.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def module_names(package: str, root: Path = ROOT) -> dict[str, Path]:
    """{dotted module name: file} of every .py under ``root/package``."""
    out = {}
    for f in sorted((root / package).rglob("*.py")):
        parts = list(f.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def _type_checking_lines(tree: ast.AST) -> set[int]:
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If):
            t = node.test
            name = t.id if isinstance(t, ast.Name) else t.attr if isinstance(t, ast.Attribute) else None
            if name == "TYPE_CHECKING":
                for sub in node.body:
                    for n in ast.walk(sub):
                        if hasattr(n, "lineno"):
                            lines.add(n.lineno)
    return lines


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> dict[str, int]:
    """{imported module of the package: first line} for the module ``name`` at ``path``."""
    tree = ast.parse(path.read_text(), str(path))
    skip = _type_checking_lines(tree)
    is_pkg = path.name == "__init__.py"
    here = name.split(".") if is_pkg else name.split(".")[:-1]
    out: dict[str, int] = {}

    def add(target: str, line: int):
        while target and target not in modules:  # a name inside a module: the module
            target = target.rpartition(".")[0]
        if target and target != name:
            out.setdefault(target, line)
        elif target == name and not is_pkg:
            out.setdefault(target, line)

    for node in ast.walk(tree):
        if getattr(node, "lineno", None) in skip:
            continue
        if isinstance(node, ast.Import):
            for a in node.names:
                add(a.name, node.lineno)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - node.level + 1] if node.level > 1 else here
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for a in node.names:
                sub = f"{mod}.{a.name}" if mod else a.name
                add(sub if sub in modules else mod, node.lineno)
    return out


def import_graph(package: str, root: Path = ROOT) -> dict[str, dict[str, int]]:
    modules = module_names(package, root)
    return {m: imports_of(m, f, modules) for m, f in modules.items()}


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """Strongly connected components with a cycle (Tarjan), each sorted, largest first."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        work = [(v, iter(sorted(graph.get(v, {}))))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph.get(w, {})))))
                    break
                if w in on:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == node:
                            break
                    if len(comp) > 1 or node in graph.get(node, {}):
                        out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out, key=lambda c: (-len(c), c))


def describe(comp: list[str], graph: dict[str, dict[str, int]]) -> list[str]:
    """The edges inside one component, as 'a:line -> b'."""
    inside = set(comp)
    return [f"{a}:{line} -> {b}" for a in comp for b, line in sorted(graph[a].items()) if b in inside]


def private_reaches(package: str, root: Path = ROOT) -> list[str]:
    """Imports of another module's private name (``from pkg.a import _helper`` in ``pkg.b``), as 'b:line -> a._helper'.
    A private name is the module's own business: what others need is public, under a name that says so."""
    modules = module_names(package, root)
    out = []
    for name, path in modules.items():
        is_pkg = path.name == "__init__.py"
        here = name.split(".") if is_pkg else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = here[: len(here) - node.level + 1] if node.level > 1 else here
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod not in modules or mod == name:
                continue
            out += [
                f"{name}:{node.lineno} -> {mod}.{a.name}"
                for a in node.names
                if a.name.startswith("_") and not a.name.startswith("__")
            ]
    return out


def main(argv=None) -> int:
    package = (argv if argv is not None else sys.argv[1:] or ["aias_augment"])[0]
    graph = import_graph(package)
    found = cycles(graph)
    print(f"{package}: {len(graph)} modules, {sum(len(v) for v in graph.values())} import edges, {len(found)} cycle(s)")
    for comp in found:
        print(f"\ncycle of {len(comp)}: {', '.join(comp)}")
        for e in describe(comp, graph):
            print("  " + e)
    private = private_reaches(package)
    print(f"{len(private)} import(s) of another module's private name")
    for line in private:
        print("  " + line)
    return 1 if found or private else 0


if __name__ == "__main__":
    sys.exit(main())
