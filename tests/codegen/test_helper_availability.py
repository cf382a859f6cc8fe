"""Every helper of templates/_special.py.j2 is available where a generated kernel calls it.

The scalar helpers' text lives in ``methodgen/codegen/special_helpers.py`` (their one source);
the template copies each into a module under its own guard, beside its numpy form.

A module defines exactly the helpers its kernels call (``ModuleIR.helpers``); the numba
module compiles exactly those.  Two ways to break this, both seen: a template block that
defines a helper under another helper's name (``_f_dsinc`` emitted with ``sinc``, so
numba left it a plain Python function: "Untyped global name '_f_dsinc'"), and a helper
scan that misses the loop templates' Jacobian terms (the only place ``dsinc`` appears in
an energy-momentum loop over ``cos(u_i - u_j)``).
"""

from __future__ import annotations

import importlib.util
import inspect
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen.emit import _environment, emit_source
import dataclasses

from methodgen.codegen.lower import _helpers_called, lower
from methodgen.problem.problem import Hamiltonian
from methodgen.problem.special import SPECIAL_FUNCTIONS

TEMPLATES = Path(__file__).resolve().parents[2] / "templates"
DEF_RE = re.compile(r"^def _f_(\w+)\(", re.M)
GUARD_RE = re.compile(r'^\{% if "(\w+)" in ir.helpers %\}$', re.M)


def _template_names() -> set[str]:
    """The helpers the template has a guarded block for."""
    return set(GUARD_RE.findall((TEMPLATES / "_special.py.j2").read_text()))


def _render(helpers, source=None) -> str:
    env = _environment()
    tpl = env.from_string(source) if source is not None else env.get_template("_special.py.j2")
    return tpl.render(ir=SimpleNamespace(helpers=tuple(helpers)))


def _defined_apart(source=None) -> dict[str, set[str]]:
    """For each helper name: the ``_f_`` helpers the template defines when only it is asked for."""
    return {name: set(DEF_RE.findall(_render((name,), source))) for name in sorted(_template_names())}


def test_template_helpers_are_the_registered_ones():
    """The template's helpers, and the scalar forms in their one source, are exactly those
    SymPy functions print as (none forgotten)."""
    from methodgen.codegen import special_helpers

    registered = {v[1:] for v in SPECIAL_FUNCTIONS.values()}
    assert _template_names() == registered
    assert set(special_helpers.HELPERS) == registered


def test_each_helper_is_defined_under_its_own_name_only():
    """Rendering one helper defines that helper and no other: what a module defines is
    what it lists in ``ir.helpers``, hence what the numba module compiles."""
    for name, defined in _defined_apart().items():
        assert defined == {name}, (name, defined)


def test_shared_block_is_detected():
    """Negative control: the former shared guard (``sinc`` or ``dsinc``) fails the check above."""
    old = (TEMPLATES / "_special.py.j2").read_text()
    # Re-create the former block: dsinc defined inside sinc's guard.
    bad = old.replace('{% endif %}\n{% if "dsinc" in ir.helpers %}\n', "", 1)
    assert bad != old
    assert _defined_apart(bad)["sinc"] == {"sinc", "dsinc"}


def _cos_ring() -> Hamiltonian:
    return Hamiltonian("(v0**2 + v1**2 + v2**2)/2 - cos(u0 - u1) - cos(u1 - u2) - cos(u2 - u0)",
                       q=["u0", "u1", "u2"], p=["v0", "v1", "v2"], name="cosring")


@pytest.mark.parametrize("method", ["energy-momentum", "avf"])
def test_loop_module_defines_every_helper_it_calls(method):
    """The loop form of a ring of cos(u_i - u_j): every ``_f_``/``_v_`` call is defined."""
    src = emit_source(mg.discretize(_cos_ring(), method), backend="numpy")
    called = set(re.findall(r"\b_[fv]_(\w+)\(", src))
    defined = set(re.findall(r"^def _[fv]_(\w+)\(", src, re.M))
    assert "dsinc" in called
    assert called <= defined, called - defined


def test_helper_scan_without_jacobian_terms_misses_dsinc():
    """The helpers are read off the printed kernels, loops included.  Negative control: the
    Newton-matrix loops (the template's Jacobian terms) are the only caller of ``dsinc``;
    a scan without them misses it (the scan that left it out)."""
    scheme = mg.discretize(_cos_ring(), "energy-momentum")
    assert scheme.loops is not None and scheme.loops.looped
    ir = lower(scheme, "s", "m")
    assert "dsinc" in ir.helpers and ir.helpers == _helpers_called(ir.scalar, ir.vector)

    def without_jacobian(flavour):
        return {k: dataclasses.replace(v, loops=()) if k == "resjac" else v for k, v in flavour.items()}

    assert "dsinc" not in _helpers_called(without_jacobian(ir.scalar), without_jacobian(ir.vector))


def test_cos_ring_keeps_energy_on_numpy():
    """Numerical: the looped module runs and keeps H to round-off."""
    mod = mg.build(_cos_ring(), "energy-momentum", backend="numpy")
    Y = mod.integrate(np.array([0.1, 0.5, -0.3, 0.2, 0.0, -0.1]), 0.05, 40)
    H = mod.hamiltonian(Y)
    assert np.abs(H - H[0]).max() < 1e-14


# --- the compiled helpers (numba) ------------------------------------------------------

#: Arguments at which each helper is compared: around its thresholds and removable points.
SCALARS = [0.0, 1e-9, -3e-5, 9.999e-3, 1.0001e-2, -0.3, 0.7, 2.5]


def _numba_helper_module(tmp_path, compiled=None):
    """All helpers, compiled as numba_module.py.j2 compiles them (those in ``compiled``,
    default all), and one jitted function that calls every one of them (one compile for
    the lot)."""
    numba_tpl = (TEMPLATES / "numba_module.py.j2").read_text()
    # (the module's spelling is the same njit, applied lazily through methodgen.runtime.nbabi.jit)
    inline = re.search(r"^_inline = _rt\.jit\((.*)\)$", numba_tpl, re.M)
    inline = f"_inline = numba.njit({inline.group(1)})"
    loop = re.search(r"\{% for name in ir.helpers %\}\n.*?\{% endfor %\}\n", numba_tpl, re.S).group(0)
    names = sorted(_template_names())
    plain = _plain_module(tmp_path, names)
    calls = []
    for i, name in enumerate(names):
        arity = len(inspect.signature(getattr(plain, f"_f_{name}")).parameters)
        calls.append(f"    out[{i}] = _f_{name}(" + ", ".join(["x", "y"][:arity]) + ")")
    text = ("import math\nimport numba\nimport numpy\n" + inline + "\n" + _render(names)
            + _environment().from_string(loop).render(ir=SimpleNamespace(helpers=tuple(compiled or names)))
            + "\n\n@numba.njit(cache=True)\ndef _call_all(x, y, out):\n" + "\n".join(calls) + "\n")
    return _load(tmp_path / f"nb_helpers{len(compiled or names)}.py", text), plain, names


def _plain_module(tmp_path, names):
    text = "import math\nimport numpy\n" + _render(names)
    return _load(tmp_path / "py_helpers.py", text)


def _load(path, text):
    path.write_text(text)
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _pairs():
    for x in SCALARS:
        for y in (x, x + 1e-7, x + 0.4, -x + 0.05):
            yield x, y
    # the switches of _sincdd (|a|, |b| = 2; |b - a| = 1) and _ddsinc (|x| = 3)
    below2, above2, below1 = np.nextafter(2.0, 0.0), np.nextafter(2.0, 3.0), np.nextafter(1.0, 0.0)
    yield from [(below2, below2), (above2, above2), (below2, 1.5), (above2, 1.5), (2.5, 2.5 - below1),
                (2.5, 1.5), (np.nextafter(3.0, 0.0), 3.5), (np.nextafter(3.0, 4.0), 2.5)]


def test_every_helper_compiles_and_agrees_on_numba(tmp_path):
    """Numerical: each compiled helper equals its Python twin and its numpy (``_v_``) twin
    within 4 ulp (the compiled libm may differ in the last bits)."""
    pytest.importorskip("numba")
    nb, plain, names = _numba_helper_module(tmp_path)
    out = np.empty(len(names))
    for x, y in _pairs():
        nb._call_all(x, y, out)
        for i, name in enumerate(names):
            f, v = getattr(plain, f"_f_{name}"), getattr(plain, f"_v_{name}")
            arity = len(inspect.signature(f).parameters)
            args = (x, y)[:arity]
            if name in ("atanhc", "datanhc") and abs(x) >= 1:
                continue
            want = f(*args)
            vec = float(v(*[np.array([a]) for a in args])[0])
            for got in (out[i], vec):
                if np.isnan(want):
                    assert np.isnan(got), (name, args)
                else:
                    assert abs(got - want) <= 4 * np.spacing(abs(want)) + 1e-300, (name, args, got, want)
    # exp's divided differences at the overflow threshold: the compiled helpers give mpmath's
    # value (Python's math raised OverflowError where numba returned inf, and numpy nan)
    from test_thin_barrier import THRESHOLD, _agree, _mp
    for x, y in THRESHOLD:
        nb._call_all(x, y, out)
        for kind in ("expdd", "dexpdd"):
            want = _mp(kind, x, y)
            assert _agree(out[names.index(kind)], want), (kind, x, y, out[names.index(kind)], want)


def test_a_helper_left_uncompiled_is_the_reported_crash(tmp_path):
    """Negative control: a helper defined but not compiled (what the shared template block
    did to ``_f_dsinc``) is numba's "Untyped global name" error, so the test above would see it."""
    numba = pytest.importorskip("numba")
    names = sorted(_template_names())
    nb, _, _ = _numba_helper_module(tmp_path, [n for n in names if n != "dsinc"])
    with pytest.raises(numba.core.errors.TypingError, match="Untyped global name '_f_dsinc'"):
        nb._call_all(0.3, 0.4, np.empty(len(names)))
