"""Warm start without SymPy (issue 25, item 3): ``build_text`` on a cached module.

A fresh process that finds its module through the index imports neither SymPy
nor the derivation code (checked in ``sys.modules``); the cold path does (the
negative control).  A stale module (another signature at the indexed path) is
rebuilt, never loaded.  Times are measured by ``benchmarks/warm_start.py``, not here.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import methodgen as mg
from methodgen.errors import InputError

mb = importlib.import_module("methodgen.build")   # the module (methodgen.build is the function)

ROOT = Path(__file__).resolve().parent.parent

H = "p**2/(2*m) + k*q**2/2"

PROBE = r"""
import json, sys
import numpy as np
import methodgen as mg
mod = mg.build_text(sys.argv[1], ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="osc",
                    backend=sys.argv[2])
y = mod.step(np.array([1.0, 0.0]), 0.1)
print(json.dumps({"y": list(map(float, y)), "module": mod.__file__,
                  "loaded": sorted(m for m in sys.modules if m == "sympy" or m.startswith(("sympy.", "jinja2",
                           "methodgen.derive", "methodgen.schemes", "methodgen.problem", "methodgen.lower",
                           "methodgen.verify")))}))
"""


def probe(cache: Path, text: str = H, backend: str = "numpy") -> dict:
    env = {**os.environ, "METHODGEN_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", PROBE, text, backend], capture_output=True, text=True, env=env,
                         cwd=cache.parent, check=True)
    return json.loads(out.stdout)


def test_a_cached_module_imports_and_runs_without_sympy(tmp_path):
    cache = tmp_path / "cache"
    cold = probe(cache)
    # Negative control: the cold path (nothing cached) derives, so SymPy and the schemes are loaded.
    assert "sympy" in cold["loaded"] and "methodgen.schemes" in cold["loaded"]
    assert "methodgen.derive" in cold["loaded"]
    warm = probe(cache)
    assert warm["loaded"] == [], warm["loaded"]
    assert warm["module"] == cold["module"] and warm["y"] == cold["y"]
    # The midpoint rule on y' = Ay (H = p²/2 + q², k = 2), h = 0.1: (I - hA/2)⁻¹(I + hA/2) y0.
    assert np.allclose(warm["y"], [0.995 / 1.005, -0.2 / 1.005], rtol=0, atol=1e-14)
    # Another text is another key: cold again (and its own module).
    other = probe(cache, "p**2/(2*m) + k*q**4/4")
    assert "sympy" in other["loaded"] and other["module"] != cold["module"]


@pytest.mark.slow
def test_a_cached_numba_module_imports_and_runs_without_sympy(tmp_path):
    """The numba backend (a cold compile of 10-40 s: slow); the numpy test above is its fast sibling."""
    pytest.importorskip("numba")
    cache = tmp_path / "cache"
    cold = probe(cache, backend="numba")
    assert "sympy" in cold["loaded"]
    warm = probe(cache, backend="numba")
    assert warm["loaded"] == [] and warm["y"] == cold["y"] and warm["module"].endswith("_numba.py")


def test_import_methodgen_itself_does_not_import_sympy(tmp_path):
    code = ("import sys, methodgen as mg; print(sorted(m for m in ('sympy', 'methodgen.schemes', "
            "'methodgen.derive', 'jinja2') if m in sys.modules)); mg.Hamiltonian; "
            "print('sympy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}).stdout.split("\n")
    assert out[0] == "[]" and out[1] == "True"   # the lazy name does import it on use


def test_lazy_names_are_the_real_ones():
    import methodgen.verify  # noqa: F401  (the subpackage must not shadow the function)
    from methodgen.problem import Hamiltonian
    from methodgen.verify import verify

    assert mg.Hamiltonian is Hamiltonian and mg.verify is verify and callable(mg.build)
    assert set(mg.__all__) <= set(dir(mg))
    with pytest.raises(AttributeError):
        mg.no_such_name  # noqa: B018


def _energy(mod, y=(1.0, 0.5)):
    return float(mod.hamiltonian(np.array(y)))


def test_a_stale_module_is_rebuilt_never_loaded(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    target = tmp_path / "cache" / "shared.py"
    a = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
    assert _energy(a) == pytest.approx(0.125 + 1.0)
    # Another system written to the same file: the index entry of A now points at B's module.
    b = mg.build_text("p**2/2", ["q"], ["p"], "midpoint", path=target)
    assert _energy(b) == pytest.approx(0.125)
    again = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
    assert _energy(again) == pytest.approx(1.125)   # rebuilt from A's text, not B's module


def test_stale_negative_control(tmp_path, monkeypatch):
    """With the signature check off, the warm path loads the wrong (stale) module."""
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    target = tmp_path / "cache" / "shared.py"
    mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
    mg.build_text("p**2/2", ["q"], ["p"], "midpoint", path=target)
    real = mb.file_status
    monkeypatch.setattr(mb, "file_status", lambda path, sig=None: real(path, None))
    wrong = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
    assert _energy(wrong) == pytest.approx(0.125)


def test_an_index_entry_not_written_by_this_user_is_ignored(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    mod_a = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="a")
    mod_b = mg.build_text("p**2/2", ["q"], ["p"], "midpoint", name="b")
    key = mb.text_key(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="a")
    entry = mb._index_file(key)
    data = json.loads(entry.read_text())
    data["entry"]["path"] = mod_b.__file__          # planted: points A's key at B's module
    data["entry"]["signature"] = _sig_of(mod_b.__file__)
    entry.write_text(json.dumps(data))
    assert mb._index_lookup(key) is None            # the tag no longer matches: not trusted
    got = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="a")
    assert _energy(got) == pytest.approx(_energy(mod_a))
    # Negative control: with the tag check off, the planted entry is followed.
    entry.write_text(json.dumps(data))
    monkeypatch.setattr(mb, "_index_tag", lambda root, body: data["tag"])
    assert _energy(mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0},
                                 name="a")) == pytest.approx(0.125)


def _sig_of(path) -> str:
    from methodgen.emit import HEADER_SIGNATURE

    for line in Path(path).read_text().splitlines():
        if line.startswith(HEADER_SIGNATURE):
            return line[len(HEADER_SIGNATURE):].strip()
    raise AssertionError("no signature line")


def test_build_text_takes_text_and_numbers_only(tmp_path, monkeypatch):
    import sympy as sp

    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    q, p = sp.symbols("q p")
    with pytest.raises(InputError, match="build_text takes"):
        mg.build_text(p**2 / 2 + q**2 / 2, ["q"], ["p"], "midpoint")
    with pytest.raises(InputError, match=r"params\[.m.\] is a Half"):
        mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": sp.Rational(1, 2), "k": 1.0})
