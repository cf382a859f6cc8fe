"""The package's import graph: no import cycle, and no import from a later layer.

Every ``import`` of a methodgen module inside methodgen -- at the top of a module or inside a
function -- is an edge; a strongly connected component of more than one module is a cycle.
There is none (the last, through the compiled runtime's modules, went with the numba loop).

The package is laid out as the data flows: problem < symbolic < codegen < runtime < app
(:data:`LAYERS`), with ``errors`` and ``_version`` below all of them.  A module imports only
its own layer and the layers before it; the compiled runtime imports code generation (it
compiles a module's kernels when the module is loaded), never the other way round.  The
package's ``__init__`` (the public names, imported lazily) and ``__main__`` are the front
door, above every layer.  The negative controls add one edge and see it caught.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent / "methodgen"

#: cycles still in the package (each component must lie inside one of these): none
KNOWN_CYCLES = ()

#: the layer of each part of the package: a module may import its own layer and lower ones
LAYERS = {
    "methodgen.errors": 0, "methodgen._version": 0,
    "methodgen.problem": 1,
    "methodgen.symbolic": 2,
    "methodgen.codegen": 3,
    "methodgen.runtime": 4,
    "methodgen.app": 5,
    "methodgen": 6, "methodgen.__main__": 6,   # the front door: the public names, the CLI's entry
}


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
        for node in _imports(path, path.stat().st_mtime_ns):
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


@functools.lru_cache(maxsize=None)
def _imports(path: Path, mtime: int) -> list:
    """The import statements of one file (parsed once per version of the file)."""
    return [n for n in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
            if isinstance(n, (ast.Import, ast.ImportFrom))]


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
    assert len(graph) > 50 and "methodgen.symbolic.schemes.energy_momentum" in graph
    assert _unexpected(graph) == []


@pytest.mark.parametrize("edge", [("methodgen.problem.problem", "methodgen.symbolic.derive"),
                                  ("methodgen.symbolic.series", "methodgen.symbolic.compositions")])
def test_negative_control_an_added_upward_import_is_caught(edge):
    graph = import_graph()
    a, b = edge
    assert b not in graph[a]
    graph[a].add(b)
    assert any(a in c and b in c for c in _unexpected(graph))


def layer(module: str) -> int:
    """The layer of ``module``: that of the longest prefix in :data:`LAYERS` (every module has one)."""
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        found = LAYERS.get(".".join(parts[:k]))
        if found is not None:
            return found
    raise KeyError(f"{module} is in no layer: put it in one of methodgen's layer folders")


def upward(graph: dict) -> list[tuple[str, str]]:
    """The edges from a module to one of a later layer."""
    return sorted((a, b) for a, targets in graph.items() for b in targets if layer(b) > layer(a))


def test_every_module_is_in_a_layer():
    graph = import_graph()
    by_layer = {}
    for m in graph:
        by_layer.setdefault(layer(m), set()).add(m)
    # the top level holds only the front door and the leaves every layer uses
    assert {m for m in graph if m.count(".") == 1 and m not in LAYERS} == set()
    assert set(by_layer) == set(range(7)) and by_layer[0] == {"methodgen.errors", "methodgen._version"}


def test_no_upward_import():
    graph = import_graph()
    assert upward(graph) == []
    # the flow is one-directional: the runtime compiles kernels through code generation,
    # never the reverse; the symbolic layer imports neither
    assert "methodgen.codegen.llvmkernels" in graph["methodgen.runtime.fused"]
    assert not any(layer(b) >= 3 for b in graph["methodgen.symbolic.derive"])


@pytest.mark.parametrize("edge", [
    ("methodgen.problem.problem", "methodgen.symbolic.derive"),       # problem -> symbolic
    ("methodgen.symbolic.nbody", "methodgen.runtime.kepler_flow"),    # symbolic -> runtime
    ("methodgen.codegen.store", "methodgen.runtime.runio"),           # codegen -> runtime
    ("methodgen.codegen.build", "methodgen.app.cli"),                 # codegen -> app
    ("methodgen.runtime.stepper", "methodgen"),                       # a layer -> the front door
    ("methodgen.errors", "methodgen.problem.parse"),                  # the leaf -> a layer
])
def test_negative_control_an_upward_import_between_layers_is_caught(edge):
    graph = import_graph()
    a, b = edge
    assert b not in graph[a]
    graph[a].add(b)
    assert upward(graph) == [edge]     # caught, though it closes no cycle


def test_negative_control_an_upward_import_in_a_function_is_an_edge(tmp_path, monkeypatch):
    # an import hidden inside a function is an edge as much as one at the top of the module
    import shutil
    import sys

    root = tmp_path / "methodgen"
    shutil.copytree(ROOT, root, ignore=shutil.ignore_patterns("__pycache__"))
    derive = root / "symbolic" / "derive.py"
    derive.write_text(derive.read_text(encoding="utf-8")
                      + "\n\ndef _later():\n    from ..codegen import emit  # noqa: F401\n", encoding="utf-8")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", root)
    assert upward(import_graph()) == [("methodgen.symbolic.derive", "methodgen.codegen.emit")]
