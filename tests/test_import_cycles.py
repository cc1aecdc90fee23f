"""planner/ and app/ have no import cycle, type-only and function-level imports included.

import-linter's layers contract keeps the sub-packages in order but says nothing of the
modules inside one sub-package, and Python runs a cycle as long as one of its imports sits
under ``if TYPE_CHECKING:`` or in a function. Here the module graph of planner/ is read from
the source with :mod:`ast`: every ``import`` and ``from ... import`` anywhere in a module (at
top level, under ``if TYPE_CHECKING:``, in a function) is an edge; ``from pkg import name``
points at the module ``pkg.name`` where that is a module, else at ``pkg`` (as grimp, which
import-linter uses, reads it).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def module_graph(root: Path, package: str) -> dict[str, set[str]]:
    """``{module: modules of package it imports}`` of the package directory ``root / package``."""
    files = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        is_pkg = parts[-1] == "__init__"
        name = ".".join(parts[:-1] if is_pkg else parts)
        files[name] = (path, is_pkg)
    graph: dict[str, set[str]] = {}
    for name, (path, is_pkg) in files.items():
        here = name if is_pkg else name.rpartition(".")[0]  # the package relative imports start from
        edges: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = here.split(".")
                    anchor = anchor[:len(anchor) - (node.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in files else base for alias in node.names]
            else:
                continue
            edges.update(t for t in targets if t in files and t != name)
        graph[name] = edges
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle through each strongly connected component of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
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
            if len(comp) > 1:
                components.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    found = []
    for comp in components:  # a shortest cycle through the component's first module (breadth first)
        members, start = set(comp), min(comp)
        prev: dict[str, str] = {}
        frontier = [start]
        while frontier and start not in prev:
            nxt = []
            for v in frontier:
                for w in sorted(graph[v] & members):
                    if w not in prev:
                        prev[w] = v
                        nxt.append(w)
            frontier = nxt
        path, v = [start], prev[start]
        while v != start:
            path.append(v)
            v = prev[v]
        found.append([start] + path[::-1])
    return found


def test_planner_has_no_import_cycle():
    graph = module_graph(ROOT, "planner")
    assert len(graph) > 50 and graph["planner.constraints.controller"] >= {"planner.constraints.composed",
                                                                          "planner.constraints.compiled"}
    found = cycles(graph)
    assert not found, "import cycles in planner/: " + "; ".join(" -> ".join(c) for c in found)


def test_app_has_no_import_cycle():
    """app/ (the service, its executors and workers, batches, the CLI, the editor) has no cycle,
    function level and type-only included: ``batch/cluster`` <-> ``batch/executors``,
    ``workers`` <-> ``worker_template`` and the editor's modules around its ``Session`` were
    broken (issue 34)."""
    graph = module_graph(ROOT, "app")
    assert len(graph) > 40 and graph["app.workers"] >= {"app.worker_template", "app.worker_process", "app.jobs"}
    assert "app.batch.cluster" in graph["app.batch.executors"] and "app.batch.base" in graph["app.batch.cluster"]
    found = cycles(graph)
    assert not found, "import cycles in app/: " + "; ".join(" -> ".join(c) for c in found)


def test_the_check_finds_a_type_only_cycle(tmp_path):
    """The graph reads imports under ``if TYPE_CHECKING:``, relative ones of every level and
    ``from pkg import module``: a package with such a cycle is reported."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .a import A\n")
    (pkg / "sub" / "a.py").write_text("from typing import TYPE_CHECKING\nfrom .. import c\n"
                                      "if TYPE_CHECKING:\n    from .b import B\nA = 1\n")
    (pkg / "sub" / "b.py").write_text("from ..c import C\nB = 2\n")
    (pkg / "c.py").write_text("def f():\n    from pkg.sub import a\nC = 3\n")
    graph = module_graph(tmp_path, "pkg")
    assert graph == {"pkg": set(), "pkg.c": {"pkg.sub.a"}, "pkg.sub": {"pkg.sub.a"},
                     "pkg.sub.a": {"pkg.c", "pkg.sub.b"}, "pkg.sub.b": {"pkg.c"}}
    assert cycles(graph) == [["pkg.c", "pkg.sub.a", "pkg.c"]]
    (pkg / "c.py").write_text("C = 3\n")
    assert cycles(module_graph(tmp_path, "pkg")) == []


def test_editor_has_no_import_cycle():
    """app/editor/ has no import cycle, type-only and function-level imports included: the
    session (``_session.py``) imports its files, preview, panel and scene, and each of those
    declares what it uses of the session as a protocol of its own (``FilesHost``,
    ``PreviewHost``, ``PanelActions``, ...) instead of importing it; the session declares what it
    takes of the server that made it (``SessionHost``). The graph is the whole of app/, so a
    cycle that leaves the editor and comes back through another app module counts too."""
    graph = module_graph(ROOT, "app")
    editor = sorted(m for m in graph if m == "app.editor" or m.startswith("app.editor."))
    # the graph is read: the session's imports, and a type-only one (the scene's GcodePreview)
    assert len(editor) > 15 and graph["app.editor._session"] >= {"app.editor._files", "app.editor._gui",
                                                                "app.editor._preview", "app.editor._scene"}
    assert "app.editor._preview" in graph["app.editor._scene"]

    def reach(start: set[str]) -> set[str]:
        seen, todo = set(start), list(start)
        while todo:
            for w in graph[todo.pop()] - seen:
                seen.add(w)
                todo.append(w)
        return seen

    looped = [m for m in editor if m in reach(graph[m])]
    around = {n for m in looped for n in reach(graph[m]) if m in reach(graph[n])}  # their components
    found = cycles({n: graph[n] & around for n in around})
    assert not looped, (f"modules of app/editor on an import cycle: {', '.join(looped)}; cycles: "
                        + "; ".join(" -> ".join(c) for c in found))
