"""The package's layering, checked by import-linter (the layers contract is in pyproject.toml),
and the modules of a package free of import circles, checked on grimp's import graph."""

import subprocess
import sys
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parents[1]

#: packages whose modules must import one another without a circle (each subpackage
#: included)
ACYCLIC = ("vlpcal",)


def test_import_layers_are_kept():
    exe = Path(sys.executable).parent / "lint-imports"
    out = subprocess.run([str(exe)], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "0 broken" in out.stdout


def circle(graph, package: str) -> list[str]:
    """A circle of imports between the children of ``package`` (a child standing for itself
    and everything under it, imports inside functions included), as the children it goes
    through, the first repeated last; empty when there is none."""
    children = sorted(graph.find_children(package))

    def members(child):
        return {child} | set(graph.find_descendants(child) if graph.find_children(child)
                             else ())

    owner = {m: c for c in children for m in members(c)}
    edges = {c: sorted({owner[i] for m in members(c)
                        for i in graph.find_modules_directly_imported_by(m)
                        if i in owner and owner[i] != c}) for c in children}
    state, path = {}, []

    def visit(c):
        state[c] = "open"
        path.append(c)
        for d in edges[c]:
            if state.get(d) == "open":
                return path[path.index(d):] + [d]
            if d not in state and (found := visit(d)):
                return found
        state[c] = "done"
        path.pop()
        return []

    for c in children:
        if c not in state and (found := visit(c)):
            return found
    return []


@pytest.mark.parametrize("package", ACYCLIC)
def test_a_package_has_no_import_circle(package):
    graph = grimp.build_graph("vlpcal", cache_dir=None)
    packages = [package] + sorted(m for m in graph.find_descendants(package)
                                  if graph.find_children(m))
    circles = {p: c for p in packages if (c := circle(graph, p))}
    assert not circles, "; ".join(" → ".join(c) for c in circles.values())


def test_a_circle_is_found():
    graph = grimp.ImportGraph()
    for m in ("p", "p.a", "p.b", "p.c"):
        graph.add_module(m)
    graph.add_import(importer="p.a", imported="p.b")
    graph.add_import(importer="p.b", imported="p.c")
    assert circle(graph, "p") == []
    graph.add_import(importer="p.c", imported="p.a")
    assert circle(graph, "p") == ["p.a", "p.b", "p.c", "p.a"]
