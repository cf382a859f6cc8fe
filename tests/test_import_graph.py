"""The package's import graph: no import cycle.

Every ``import`` of a methodgen module inside methodgen -- at the top of a module or inside a
function -- is an edge; a strongly connected component of more than one module is a cycle.
There is none (the last, through the compiled runtime's modules, went with the numba loop).
The negative control adds one upward edge and sees it caught.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "methodgen"

#: cycles still in the package (each component must lie inside one of these): none
KNOWN_CYCLES = ()


def _modules() -> dict:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = p.relative_to(ROOT.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = p
    return out


def import_graph() -> dict:
    """``{module: set of methodgen modules it imports}`` (top-level and function-level imports)."""
    mods = _modules()
    graph = {m: set() for m in mods}
    for m, path in mods.items():
        package = m if path.name == "__init__.py" else m.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = package.split(".")[:len(package.split(".")) - node.level + 1]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            graph[m].update(t for t in targets if t in mods and t != m)
    return graph


def cycles(graph: dict) -> list[set]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index, low, on, stack, out = {}, {}, set(), [], []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = set()
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.add(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(comp)
    return out


def _unexpected(graph) -> list[set]:
    return [c for c in cycles(graph) if not any(c <= known for known in KNOWN_CYCLES)]


def test_no_import_cycle():
    graph = import_graph()
    assert len(graph) > 50 and "methodgen.schemes.energy_momentum" in graph
    assert _unexpected(graph) == []


@pytest.mark.parametrize("edge", [("methodgen.problem", "methodgen.derive"),
                                  ("methodgen.series", "methodgen.compositions")])
def test_negative_control_an_added_upward_import_is_caught(edge):
    graph = import_graph()
    a, b = edge
    assert b not in graph[a]
    graph[a].add(b)
    assert any(a in c and b in c for c in _unexpected(graph))
