"""Every helper of templates/_special.py.j2 is available where a generated kernel calls it.

The scalar helpers' text lives in ``methodgen/codegen/special_helpers.py`` (their one source);
the template copies each into a module under its own guard, beside its numpy form.

A module defines exactly the helpers its kernels call (``ModuleIR.helpers``); the compiled
route translates the package's same helpers (``methodgen.codegen.special_helpers``) into the
kernels that call them.  Two ways to break this, both seen: a template block that defines a
helper under another helper's name (``_f_dsinc`` emitted with ``sinc``, which left the
numba-compiled module of the time without it: "Untyped global name '_f_dsinc'"), and a helper
scan that misses the loop templates' Jacobian terms (the only place ``dsinc`` appears in an
energy-momentum loop over ``cos(u_i - u_j)``).
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


# --- the compiled helpers (LLVM) -------------------------------------------------------

#: Arguments at which each helper is compared: around its thresholds and removable points.
SCALARS = [0.0, 1e-9, -3e-5, 9.999e-3, 1.0001e-2, -0.3, 0.7, 2.5]


def _compiled_helpers(tmp_path, names, without=()):
    """One function calling every helper of ``names`` on ``(x, y)``, compiled through LLVM IR
    with the helpers resolved as a compiled kernel resolves them (the package's
    ``special_helpers``, less ``without``): ``(call(x, y, out), plain twins module)``."""
    from methodgen.codegen import ktypes as kt
    from methodgen.codegen import llvmkernels as lk
    from methodgen.codegen import special_helpers

    plain = _plain_module(tmp_path, names)
    lines = ["def _call_all(xy, out):", "    x = xy[0]", "    y = xy[1]"]
    for i, name in enumerate(names):
        arity = len(inspect.signature(getattr(plain, f"_f_{name}")).parameters)
        lines.append(f"    out[{i}] = _f_{name}(" + ", ".join(["x", "y"][:arity]) + ")")
    mod = _load(tmp_path / f"call_all{len(without)}.py", "\n".join(lines) + "\n")
    names_in = {k: v for k, v in vars(special_helpers).items() if k.startswith("_f_") and k[3:] not in without}
    names_in["math"] = __import__("math")
    V = kt.float64[::1]
    ll = lk.compile_kernel(mod._call_all, kt.none(V, V), globals_=names_in, c_entry=True)
    return (lambda x, y, out: ll(np.array([x, y], dtype=float), out)), plain


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


def test_every_helper_compiles_and_agrees(tmp_path):
    """Numerical: each compiled helper equals its Python twin and its numpy (``_v_``) twin
    within 4 ulp (the compiled libm calls may differ in the last bits)."""
    pytest.importorskip("llvmlite")
    names = sorted(_template_names())
    call, plain = _compiled_helpers(tmp_path, names)
    out = np.empty(len(names))
    for x, y in _pairs():
        call(x, y, out)
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
    # value (Python's math raised OverflowError where compiled code returns inf, and numpy nan)
    from test_thin_barrier import THRESHOLD, _agree, _mp
    for x, y in THRESHOLD:
        call(x, y, out)
        for kind in ("expdd", "dexpdd"):
            want = _mp(kind, x, y)
            assert _agree(out[names.index(kind)], want), (kind, x, y, out[names.index(kind)], want)


def test_a_helper_missing_is_refused_by_name(tmp_path):
    """Negative control: a helper the compiled route cannot resolve (what the shared template
    block once did to ``_f_dsinc``) is refused by name, so the test above would see it."""
    from methodgen.codegen import llvmkernels as lk

    pytest.importorskip("llvmlite")
    names = sorted(_template_names())
    with pytest.raises(lk.Unsupported, match=r"in _call_all: call of _f_dsinc"):
        _compiled_helpers(tmp_path, names, without=("dsinc",))


@pytest.mark.parametrize("method", ["energy-momentum", "avf"])
def test_a_sinc_module_compiles_and_runs(method, monkeypatch, tmp_path):
    """H = p²/2 + sin(q)/q: its energy-momentum and AVF Jacobians call ``_f_dsincdd``, whose
    Gauss–Legendre nodes and weights are tuples.  The translator refused them ("_GL8_W is not a
    constant table"), so the compiled module failed on its first step (its fallback, the stepper
    run as Python, called the same refused kernel).  Now it runs: bitwise the stepper run as
    Python, and the numpy module's trajectory to round-off.  Control: a step one ulp longer
    changes the bits."""
    pytest.importorskip("llvmlite")
    system = Hamiltonian("p**2/2 + sin(q)/q", ["q"], ["p"], name="sincwell")
    scheme = mg.discretize(system, method)
    mod = mg.generate(scheme, tmp_path / f"sincwell_{method.replace('-', '_')}_numba.py", backend="numba")
    ref = mg.generate(scheme, tmp_path / f"sincwell_{method.replace('-', '_')}.py", backend="numpy")
    assert "_f_dsincdd" in open(mod.__file__).read()
    y0 = np.array([0.3, 0.1])
    got = mod.integrate(y0, 0.05, 200)
    np.testing.assert_allclose(got, ref.integrate(y0, 0.05, 200), rtol=0, atol=1e-12)
    monkeypatch.setenv("METHODGEN_STEPPER", "python")
    assert np.array_equal(mod.integrate(y0, 0.05, 200), got)
    monkeypatch.delenv("METHODGEN_STEPPER")
    assert not np.array_equal(mod.integrate(y0, np.nextafter(0.05, 1.0), 200), got)
