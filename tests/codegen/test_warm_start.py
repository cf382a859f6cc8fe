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

mb = importlib.import_module("methodgen.codegen.build")   # the module (methodgen.build is the function)

ROOT = Path(__file__).resolve().parents[2]

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
                           "methodgen.symbolic.derive", "methodgen.symbolic.schemes", "methodgen.problem.problem",
                           "methodgen.codegen.lower", "methodgen.symbolic.verify")))}))
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
    assert "sympy" in cold["loaded"] and "methodgen.symbolic.schemes" in cold["loaded"]
    assert "methodgen.symbolic.derive" in cold["loaded"]
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
    pytest.importorskip("llvmlite")
    cache = tmp_path / "cache"
    cold = probe(cache, backend="numba")
    assert "sympy" in cold["loaded"]
    warm = probe(cache, backend="numba")
    assert warm["loaded"] == [] and warm["y"] == cold["y"] and warm["module"].endswith("_numba.py")


NUMBA_PROBE = r"""
import json, sys
sys.modules["numba"] = None          # any import of numba fails
import numpy as np
import methodgen as mg
mod = mg.build_text(sys.argv[1], ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="osc",
                    backend="numba")
y = mod.integrate(np.array([1.0, 0.0]), 0.1, 50)
try:
    import numba  # noqa: F401
    blocked = False
except ImportError:
    blocked = True
print(json.dumps({"y": y[-1].tolist(), "module": mod.__file__, "blocked": blocked,
                  "loaded": sorted(m for m in ("sympy", "jinja2") if m in sys.modules)}))
"""


def test_a_cached_compiled_module_runs_without_sympy_or_numba(tmp_path):
    """A cached compiled module on its compiled stepper (kernels and loop machine code from the
    caches) imports neither SymPy nor the templates' jinja2, and nothing of it needs numba (any
    import of numba fails in the probe).  Controls: the cold run does import SymPy, and the
    probe's block of numba works (an import of it there fails)."""
    pytest.importorskip("llvmlite")
    cache = tmp_path / "cache"
    env = {**os.environ, "METHODGEN_CACHE": str(cache), "PYTHONPATH": str(ROOT)}
    env.pop("METHODGEN_STEPPER", None)

    def run(**extra):
        out = subprocess.run([sys.executable, "-W", "ignore::RuntimeWarning", "-c", NUMBA_PROBE, H],
                             capture_output=True, text=True, env={**env, **extra}, cwd=tmp_path, check=True)
        return json.loads(out.stdout)

    cold = run()
    assert "sympy" in cold["loaded"] and cold["blocked"]
    warm = run()
    assert warm["loaded"] == [], warm["loaded"]
    assert warm["y"] == cold["y"] and warm["module"] == cold["module"] and warm["module"].endswith("_numba.py")


def test_import_methodgen_itself_does_not_import_sympy(tmp_path):
    code = ("import sys, methodgen as mg; print(sorted(m for m in ('sympy', 'methodgen.symbolic.schemes', "
            "'methodgen.symbolic.derive', 'jinja2') if m in sys.modules)); mg.Hamiltonian; "
            "print('sympy' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}).stdout.split("\n")
    assert out[0] == "[]" and out[1] == "True"   # the lazy name does import it on use


def test_lazy_names_are_the_real_ones():
    import methodgen.symbolic.verify  # noqa: F401  (the subpackage must not shadow the function)
    from methodgen.problem.problem import Hamiltonian
    from methodgen.symbolic.verify import verify

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
    real = mb.load_if_current
    monkeypatch.setattr(mb, "load_if_current", lambda path, sig: real(path, None))
    wrong = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
    assert _energy(wrong) == pytest.approx(0.125)


def test_an_index_entry_not_written_by_this_user_is_ignored(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    mod_a = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="a")
    mod_b = mg.build_text("p**2/2", ["q"], ["p"], "midpoint", name="b")
    key = mb.text_key(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="a")
    entry = mb._index_file(key)
    data = json.loads(entry.read_text())
    rel = Path(mod_b.__file__).relative_to((tmp_path / "cache").resolve()).as_posix()
    data["entry"]["where"] = {"in": "cache", "path": rel}   # planted: points A's key at B's module
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
    from methodgen.codegen.emit import HEADER_SIGNATURE

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


# --- the index never leads out of the cache (review item 1) ------------------------------------

def _plant(module: Path, marker: Path) -> None:
    """Replace ``module`` by an untagged copy that writes ``marker`` when run, with a recomputed content hash."""
    import hashlib

    from methodgen.codegen.emit import HEADER_CONTENT, untagged

    body = untagged(module.read_text()).partition("\n")[2]
    body += f"\nimport pathlib\npathlib.Path({str(marker)!r}).write_text('PLANTED CODE RAN')\n"
    module.write_text(HEADER_CONTENT + hashlib.sha256(body.encode()).hexdigest() + "\n" + body)


def test_a_copied_cache_never_runs_a_module_outside_it(tmp_path, monkeypatch):
    import shutil

    a, b, marker = tmp_path / "cA", tmp_path / "cB", tmp_path / "planted.txt"
    monkeypatch.setenv("METHODGEN_CACHE", str(a))
    built = Path(mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="o").__file__)
    key_a = mb.text_key(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="o")
    shutil.copytree(a, b, symlinks=True)
    _plant(built, marker)                           # A's module, now untagged code
    monkeypatch.setenv("METHODGEN_CACHE", str(b))
    key_b = mb.text_key(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="o")
    assert key_b != key_a                           # the cache root is part of the key
    # An entry in B, tagged with B's (copied) key, that names A's module — as the old index did
    # (absolute path) and as a relative path climbing out of the cache.
    for where in ({"in": "path", "path": str(built)}, {"in": "cache", "path": f"../cA/{built.name}"}):
        body = {"key": key_b, "where": where, "signature": _sig_of(built)}
        tag = mb._index_tag(b.resolve(), json.dumps(body, sort_keys=True))
        mb._index_file(key_b).write_text(json.dumps({"entry": body, "tag": tag}))
        assert mb._index_lookup(key_b) is None
        got = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="o")
        assert not marker.exists() and Path(got.__file__).parent == b.resolve()
    # Negative control: following the entry's path wherever it leads (the old lookup) runs the planted code.
    body = {"key": key_b, "where": {"in": "path", "path": str(built)}, "signature": _sig_of(built)}
    tag = mb._index_tag(b.resolve(), json.dumps(body, sort_keys=True))
    mb._index_file(key_b).write_text(json.dumps({"entry": body, "tag": tag}))
    monkeypatch.setattr(mb, "_located", lambda where, path: Path(where["path"]))
    mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, name="o")
    assert marker.read_text() == "PLANTED CODE RAN"


def test_an_entry_for_a_given_path_names_exactly_that_path(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    target = tmp_path / "out" / "mine.py"
    mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
    key = mb.text_key(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
    assert mb._index_lookup(key, target) == (target.resolve(), _sig_of(target))
    # The entry names another file: not followed (negative control: the entry as written is).
    entry = mb._index_file(key)
    data = json.loads(entry.read_text())
    data["entry"]["where"]["path"] = str(tmp_path / "elsewhere.py")
    data["tag"] = mb._index_tag((tmp_path / "cache").resolve(), json.dumps(data["entry"], sort_keys=True))
    entry.write_text(json.dumps(data))
    assert mb._index_lookup(key, target) is None


def test_index_tags_have_their_own_domain(tmp_path):
    """An index entry's tag is never the tag of a module with the same text (another HMAC domain)."""
    from methodgen.codegen.emit import _cache_key, _keyed_tag

    root = tmp_path / "cache"
    root.mkdir(mode=0o700)
    secret = _cache_key(root, create=True)
    body = '{"key": "x"}'
    assert mb._index_tag(root, body) != _keyed_tag(secret, "warm-index", body)
    assert mb._index_tag(root, body) == mb._index_tag(root, body)   # control: deterministic


# --- the key follows what the module depends on (items 2, 3, 9) --------------------------------

H2 = "(p1**2 + p2**2)/(2*m) + k*(q1 - q2)**2/2"


def test_the_order_of_params_and_invariants_reaches_the_module(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))

    def make(params, invariants):
        return mg.build_text(H2, ["q1", "q2"], ["p1", "p2"], "midpoint", params=params, invariants=invariants,
                             name="pair")

    mk, km = {"m": 1.0, "k": 2.0}, {"k": 2.0, "m": 1.0}
    ab, ba = {"P": "p1 + p2", "D": "2*p1 + 2*p2"}, {"D": "2*p1 + 2*p2", "P": "p1 + p2"}
    first = make(mk, ab)
    assert first.PARAM_NAMES == ("m", "k") and first.INVARIANT_NAMES[-2:] == ("P", "D")
    second = make(km, ba)                        # warm for neither: another order is another module
    assert second.PARAM_NAMES == ("k", "m") and second.INVARIANT_NAMES[-2:] == ("D", "P")
    assert second.SIGNATURE != first.SIGNATURE
    # Negative control: a key that sorts mappings (the old one) returns the first module for the second call.
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache2"))
    real = mb._tagged
    monkeypatch.setattr(mb, "_tagged", lambda v, what: real(dict(sorted(v.items())) if isinstance(v, dict) else v,
                                                            what))
    assert make(mk, ab).PARAM_NAMES == ("m", "k")
    assert make(km, ba).PARAM_NAMES == ("m", "k")   # wrong: build() gives ("k", "m")


def test_the_key_covers_build_py_and_the_sympy_that_would_be_imported(tmp_path, monkeypatch):
    args = (H, ["q"], ["p"], "midpoint")
    key = mb.text_key(*args)
    assert mb.text_key(*args) == key                       # control: the same inputs, the same key
    monkeypatch.setattr(mb, "_own_source_hash", lambda: "0" * 64)   # build.py edited
    assert mb.text_key(*args) != key
    monkeypatch.undo()
    # A SymPy on PYTHONPATH that shadows the installed one (and is not imported) changes the key.
    fake = tmp_path / "shadow" / "sympy"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('not a real sympy')\n")
    (fake / "release.py").write_text('__version__ = "0.0.1"\n')
    code = ("import sys, json, importlib, importlib.metadata as md; mb = importlib.import_module('methodgen.codegen.build');"
            "k = mb.text_key('p**2/2 + q**2/2', ['q'], ['p'], 'midpoint');"
            "print(json.dumps([k, md.version('sympy'), 'sympy' in sys.modules]))")

    def key_with(pythonpath):
        env = {**os.environ, "PYTHONPATH": pythonpath, "METHODGEN_CACHE": str(tmp_path / "c")}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                             check=True, cwd=tmp_path)
        return json.loads(out.stdout)

    plain, shadowed = key_with(str(ROOT)), key_with(os.pathsep.join([str(fake.parent), str(ROOT)]))
    assert plain[0] != shadowed[0] and not plain[2] and not shadowed[2]
    # Negative control: the installed metadata (what the old key read) does not see the shadowing copy.
    assert plain[1] == shadowed[1]


def test_the_warm_path_refuses_what_the_cold_path_refuses(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    q2 = "p**2/(2*m) + q**2/2"
    mg.build_text(q2, ["q"], ["p"], "midpoint", params={"m": 1.0})        # cached with q = ["q"]
    with pytest.raises(InputError, match="q must be a list.*got the string 'q'"):
        mg.build_text(q2, "q", "p", "midpoint", params={"m": 1.0})
    with pytest.raises(InputError, match="constraints must be a list"):
        mg.build_text(q2, ["q"], ["p"], "midpoint", params={"m": 1.0}, constraints="q - 1")
    with pytest.raises(InputError, match="params must be a mapping"):
        mg.build_text(q2, ["q"], ["p"], "midpoint", params=[("m", 1.0)])
    # A value that looks like the old encoding of a float is its own key: the cold path refuses it.
    with pytest.raises(InputError, match="parameter 'm' must be a real number"):
        mg.build_text(q2, ["q"], ["p"], "midpoint", params={"m": {"float": "1.0"}})
    assert mb.text_key(q2, ["q"], ["p"], "m", params={"m": 1}) != mb.text_key(q2, ["q"], ["p"], "m",
                                                                               params={"m": True})

    # Negative control: the old encoding (list(q), floats as {"float": repr}) lets both through warm.
    def old_plain(value, what):
        if value is None or isinstance(value, (bool, int, str)):
            return value
        if isinstance(value, float):
            return {"float": repr(value)}
        if isinstance(value, dict):
            return {str(k): old_plain(v, what) for k, v in value.items()}
        return [old_plain(v, what) for v in value]

    monkeypatch.setattr(mb, "_tagged", old_plain)
    monkeypatch.setattr(mb, "_sequence", lambda value, what, example: list(value))
    mg.build_text(q2, ["q"], ["p"], "midpoint", params={"m": 1.0})
    assert mg.build_text(q2, "q", "p", "midpoint", params={"m": 1.0}).PARAM_NAMES == ("m",)
    assert mg.build_text(q2, ["q"], ["p"], "midpoint", params={"m": {"float": "1.0"}}).DEFAULT_PARAMS == {"m": 1.0}


# --- one read: the bytes checked are the bytes run (item 4) -------------------------------------

def test_a_module_replaced_between_check_and_import_is_never_imported(tmp_path, monkeypatch):
    import methodgen.codegen.emit as emit

    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    shared, other = tmp_path / "out" / "shared.py", tmp_path / "out" / "other.py"
    mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=shared)
    b_bytes = Path(mg.build_text("p**2/2", ["q"], ["p"], "midpoint", path=other).__file__).read_bytes()
    real = emit._classify

    def racing(path, text, expected):    # another process writes B's module right after each check
        status = real(path, text, expected)
        if Path(path) == shared.resolve():
            shared.write_bytes(b_bytes)
        return status

    monkeypatch.setattr(emit, "_classify", racing)
    got = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=shared)   # warm
    assert _energy(got) == pytest.approx(1.125)           # A's module: the bytes that were checked
    # Negative control: the old warm path (check the file, then import it in a second read) runs B.
    shared.write_bytes(b"")
    mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=shared)   # A again
    sig = _sig_of(shared)
    assert emit.file_status(shared, sig) == "ok"          # checked: A ... (and B written right after)
    assert _energy(emit.load_module(shared)) == pytest.approx(0.125)   # ... but B imported


def test_load_module_refuses_another_signature(tmp_path, monkeypatch):
    from methodgen.codegen.emit import load_module
    from methodgen.errors import GenerationError

    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    path = Path(mg.build_text("p**2/2", ["q"], ["p"], "midpoint", path=tmp_path / "b.py").__file__)
    with pytest.raises(GenerationError, match="of another signature"):
        load_module(path, expected_signature="0" * 64)
    assert callable(load_module(path, expected_signature=_sig_of(path)).step)   # control: its own one


# --- an index that cannot be used means no warm start, not a failure (item 7) -------------------

def test_an_untrusted_cache_folder_does_not_stop_a_build_elsewhere(tmp_path, monkeypatch):
    from methodgen.codegen.emit import check_cache_folder
    from methodgen.errors import UntrustedCacheError

    cache = tmp_path / "cache"
    cache.mkdir()
    os.chmod(cache, 0o777)               # a cache others can write to
    monkeypatch.setenv("METHODGEN_CACHE", str(cache))
    target = tmp_path / "out" / "o.py"
    # The trouble is real: the index folder is refused (what the old lookup let through as an error) ...
    with pytest.raises(UntrustedCacheError):
        check_cache_folder(cache / mb.WARM_INDEX / "x.json")
    # ... and build() does not need the cache for a path elsewhere.
    assert callable(mg.build(mg.Hamiltonian(H, ["q"], ["p"], params={"m": 1.0, "k": 2.0}), "midpoint",
                             path=tmp_path / "out" / "b.py").step)
    for _ in range(2):
        with pytest.warns(RuntimeWarning, match="warm-start index cannot be used") as record:
            mod = mg.build_text(H, ["q"], ["p"], "midpoint", params={"m": 1.0, "k": 2.0}, path=target)
        assert _energy(mod) == pytest.approx(1.125)
        assert len([w for w in record if "warm-start index" in str(w.message)]) == 1
    assert not (cache / mb.WARM_INDEX).exists()


# --- the package's names (item 8) -------------------------------------------------------------

def test_every_public_name_and_submodule_is_an_attribute_in_a_fresh_process():
    code = r"""
import json, pkgutil, sys, types
import methodgen as mg
subs = sorted(m.name for m in pkgutil.iter_modules(mg.__path__) if not m.name.startswith("__"))
light = sorted(m for m in ("sympy", "jinja2", "methodgen.symbolic.schemes", "methodgen.symbolic.derive") if m in sys.modules)
bad = [n for n in mg.__all__ + subs if not hasattr(mg, n)]
kinds = {n: type(getattr(mg, n)).__name__ for n in ("problem", "symbolic", "codegen", "runtime", "app", "build",
                                                   "verify")}
print(json.dumps({"light": light, "bad": bad, "subs": subs, "kinds": kinds, "dir": dir(mg)}))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    got = json.loads(out.stdout)
    layers = ("problem", "symbolic", "codegen", "runtime", "app")
    assert got["light"] == [] and got["bad"] == [] and set(layers) <= set(got["subs"])
    # the layers are modules; build and verify are the functions (their modules are inside layers)
    assert got["kinds"] == {**{layer: "module" for layer in layers}, "build": "function", "verify": "function"}
    for helper in ("importlib", "types", "_sys", "_Package", "_LAZY"):
        assert helper not in got["dir"], helper
    assert set(mg.__all__) <= set(got["dir"])
