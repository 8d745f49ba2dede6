"""The package's imports go one way, down the layers, and never round in a cycle.

Layers, higher first (a module may import its own folder and any lower layer, never a higher
one): devtools (the Makefile's checks, which import every module) > cli > api (the Python
API the commands also run through) > report > analysis, sweep,
identify (siblings: they may import each other only if no cycle of folders results) > config >
sim > model. The top-level modules (``errors``, ``units``,
``timing``, ``files``, ``hashing``, ``_numba``, ``__init__``) are below everything: any layer
may import them, they import nothing from the layers.

Every ``import`` / ``from ... import`` node counts, wherever it is (module level, inside a
function, under ``if TYPE_CHECKING``); relative imports are resolved, and ``from pkg import
name`` counts as an import of ``pkg.name`` when that is a module.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

PACKAGE = "ema_cli"
ROOT = Path(__file__).resolve().parents[2] / PACKAGE
LAYERS = {"devtools": 8, "cli": 7, "api": 6, "report": 5, "analysis": 4, "sweep": 4, "identify": 4,
          "acceptance": 4, "sensitivity": 4, "optim": 4, "tune": 4, "production": 4, "config": 3,
          "sim": 2, "model": 1}
"""Layer of each folder of the package; top-level modules are layer 0."""
TOP = ""  # the "folder" of the top-level modules


@dataclass(frozen=True)
class Edge:
    """``source`` (a module, defined in ``path``) imports ``target`` at ``line``."""

    source: str
    path: str
    line: int
    target: str

    def __str__(self) -> str:
        return f"{self.path}:{self.line} imports {self.target}"


def module_name(path: Path, root: Path, package: str = PACKAGE) -> str:
    """``ema_cli.sweep.run`` for ``<root>/sweep/run.py``; a package's ``__init__`` is the
    package itself."""
    parts = [package, *path.relative_to(root).with_suffix("").parts]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(tree: ast.AST, module: str, is_package: bool, modules: Mapping[str, bool]
             ) -> Iterable[tuple[int, str]]:
    """(line, imported module) for every import node in ``tree``, relative ones resolved."""
    here = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                yield node.lineno, sub if sub in modules else target


def scan(root: Path = ROOT, package: str = PACKAGE) -> tuple[dict[str, bool], list[Edge]]:
    """Every module under ``root`` (name -> is a package) and every import of a module of
    ``package`` in them."""
    files = sorted(root.rglob("*.py"))
    modules = {module_name(p, root, package): p.name == "__init__.py" for p in files}
    edges = []
    for p in files:
        name = module_name(p, root, package)
        tree = ast.parse(p.read_text(encoding="utf-8"), filename=str(p))
        rel = f"{package}/{p.relative_to(root).as_posix()}"
        for line, target in _imports(tree, name, p.name == "__init__.py", modules):
            if target == package or target.startswith(package + "."):
                edges.append(Edge(name, rel, line, target))
    return modules, list(dict.fromkeys(edges))  # one per line and module imported


def folder_of(module: str, modules: Mapping[str, bool]) -> str:
    """The folder (``sweep``) of a module, or TOP for the top-level modules."""
    parts = module.split(".")
    if len(parts) == 1 or len(parts) == 2 and not modules.get(module, False):
        return TOP  # the package's __init__, or a top-level module such as ema_cli.errors
    return parts[1]


def layer_violations(modules: Mapping[str, bool], edges: list[Edge],
                     layers: Mapping[str, int] = LAYERS) -> list[str]:
    """Imports of a higher layer, and modules in a folder that has no layer."""
    unknown = {folder_of(m, modules) for m in modules} - set(layers) - {TOP}
    problems = [f"{PACKAGE}/{f}: folder '{f}' has no layer; add it to LAYERS"
                for f in sorted(unknown)]
    for e in edges:
        src, dst = folder_of(e.source, modules), folder_of(e.target, modules)
        if src == dst or {src, dst} & unknown:
            continue  # the same folder; an unknown folder is reported above
        ls, ld = layers.get(src, 0), layers.get(dst, 0)
        if ld > ls:
            problems.append(f"{e} (layer {src or 'top'} {ls} imports {dst} {ld})")
    return problems


def strongly_connected(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components of ``graph`` (each sorted)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def cycle_through(graph: Mapping[str, set[str]], start: str, within: set[str]) -> list[str]:
    """A shortest cycle ``start -> ... -> start`` inside ``within`` (breadth first)."""
    prev: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for v in frontier:
            for w in sorted(graph.get(v, ())):
                if w not in within:
                    continue
                if w == start:
                    path = [v]
                    while path[-1] != start:
                        path.append(prev[path[-1]])
                    return [start, *reversed(path[:-1]), start] if v != start else [start, start]
                if w not in prev:
                    prev[w] = v
                    nxt.append(w)
        frontier = nxt
    raise AssertionError(f"{start} is on no cycle")


def cycles(graph: Mapping[str, set[str]]) -> list[list[str]]:
    """One cycle path per strongly connected component that has a cycle."""
    found = []
    for comp in strongly_connected(graph):
        v = comp[0]
        if len(comp) > 1 or v in graph.get(v, ()):
            found.append(cycle_through(graph, v, set(comp)))
    return found


def cycle_problems(modules: Mapping[str, bool], edges: list[Edge]) -> list[str]:
    """Import cycles between modules, and between the folders of the layers (siblings)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    where: dict[tuple[str, str], Edge] = {}
    folders: dict[str, set[str]] = {}
    folder_edge: dict[tuple[str, str], Edge] = {}
    for e in edges:
        graph.setdefault(e.source, set()).add(e.target)
        where.setdefault((e.source, e.target), e)
        src, dst = folder_of(e.source, modules), folder_of(e.target, modules)
        if src != dst and TOP not in (src, dst):
            folders.setdefault(src, set()).add(dst)
            folder_edge.setdefault((src, dst), e)
    problems = []
    for path in cycles(graph):
        steps = [str(where[a, b]) for a, b in zip(path, path[1:], strict=False)]
        problems.append("import cycle " + " -> ".join(path) + ": " + "; ".join(steps))
    for path in cycles(folders):
        steps = [str(folder_edge[a, b]) for a, b in zip(path, path[1:], strict=False)]
        problems.append("folder cycle " + " -> ".join(path) + ": " + "; ".join(steps))
    return problems


def check(root: Path = ROOT, package: str = PACKAGE) -> list[str]:
    """Every layering problem under ``root`` (empty if the imports are clean)."""
    modules, edges = scan(root, package)
    return layer_violations(modules, edges) + cycle_problems(modules, edges)


# ------------------------------------------------------------------------------------ tests


def test_the_scan_sees_the_package():
    modules, edges = scan()
    assert {"ema_cli.cli.main", "ema_cli.sim.runner", "ema_cli.errors"} <= set(modules)
    found = {(e.source, e.target) for e in edges}
    assert ("ema_cli.sim.runner", "ema_cli.sim.kernel") in found
    assert ("ema_cli.optim.ga", "ema_cli.optim.operators") in found  # from pkg import mod
    assert folder_of("ema_cli.errors", modules) == TOP
    assert folder_of("ema_cli.cli", modules) == "cli"
    assert set(LAYERS) == {folder_of(m, modules) for m in modules} - {TOP}


def test_imports_go_down_the_layers():
    modules, edges = scan()
    problems = layer_violations(modules, edges)
    assert not problems, "imports of a higher layer:\n" + "\n".join(problems)


def test_no_import_cycles():
    modules, edges = scan()
    problems = cycle_problems(modules, edges)
    assert not problems, "\n".join(problems)


def _tree(root: Path, files: Mapping[str, str]) -> Path:
    pkg = root / PACKAGE
    for rel, text in files.items():
        path = pkg / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
        for parent in path.relative_to(pkg).parents:
            init = pkg / parent / "__init__.py"
            if not init.exists():
                init.write_text("")
    return pkg


CLEAN = {
    "errors.py": "",
    "model/x.py": "from ema_cli.errors import EmaError\n",
    "sim/run.py": "from ema_cli.model import x\nfrom . import tables\n",
    "sim/tables.py": "import ema_cli.model.x\n",
    "cli/main.py": "from ema_cli.sim.run import go\nfrom ema_cli import errors\n",
}


def test_a_clean_synthetic_tree_passes(tmp_path):
    assert check(_tree(tmp_path, CLEAN)) == []


def test_the_checker_flags_a_higher_layer_import(tmp_path):
    pkg = _tree(tmp_path, {
        **CLEAN,
        "model/x.py": "import os\n\n\ndef f():\n    from ema_cli.cli.main import app\n",
        "model/y.py": "from ..report import rundir\n",
        "report/rundir.py": "",
        "errors.py": "from ema_cli.sim import run\n",
    })
    problems = layer_violations(*scan(pkg))
    assert any(p.startswith("ema_cli/model/x.py:5 imports ema_cli.cli.main") for p in problems)
    assert any(p.startswith("ema_cli/model/y.py:1 imports ema_cli.report.rundir")
               for p in problems)
    assert any(p.startswith("ema_cli/errors.py:1 imports ema_cli.sim.run") for p in problems)
    assert len(problems) == 3, problems
    assert set(problems) <= set(check(pkg))  # (the upward imports close cycles as well)


def test_the_checker_flags_cycles_and_unknown_folders(tmp_path):
    pkg = _tree(tmp_path, {
        **CLEAN,
        "sweep/a.py": "from . import b\n",
        "sweep/b.py": "def f():\n    import ema_cli.sweep.a\n",
        "analysis/c.py": "from ema_cli.identify.d import g\n",
        "identify/d.py": "from ema_cli.analysis import c\n",
        "identify/e.py": "",
        "plugins/p.py": "",
    })
    problems = check(pkg)
    assert ("import cycle ema_cli.sweep.a -> ema_cli.sweep.b -> ema_cli.sweep.a: "
            "ema_cli/sweep/a.py:1 imports ema_cli.sweep.b; "
            "ema_cli/sweep/b.py:2 imports ema_cli.sweep.a") in problems
    assert any(p.startswith("import cycle ema_cli.analysis.c -> ema_cli.identify.d")
               for p in problems)
    assert any(p.startswith("folder cycle analysis -> identify -> analysis") for p in problems)
    assert any("folder 'plugins' has no layer" in p for p in problems)
    assert len(problems) == 4, problems


def test_siblings_may_import_each_other_without_a_cycle(tmp_path):
    pkg = _tree(tmp_path, {**CLEAN, "analysis/c.py": "from ema_cli.sweep.d import g\n",
                           "sweep/d.py": "from ema_cli.sim import run\n"})
    assert check(pkg) == []
