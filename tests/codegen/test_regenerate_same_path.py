"""A compiled module regenerated at the same path runs its own machine code, never the previous one's.

The compiled route once translated a module's kernels from its text, read through
``linecache``, which keeps a file's first text for the life of the process: the second
Hamiltonian generated at ``osc.py`` ran the first one's kernels (energy-momentum's H went
2.25 -> 2.50 under a method that keeps H exactly).  Now it prints the machine code from the
kernel IR the module holds as data (methodgen.codegen.kir), keyed by the tree's digest.

Each case generates several Hamiltonians of one shape in a row at one path, compiled, and
compares each run with the numpy module of the same scheme (an independent route: printed
Python, no machine code).  The negative control keys the machine code by something other than
the tree (the kernel's name) and shows the same comparison catches the stale code.
"""

from __future__ import annotations

import json
import linecache
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen import kernelsource, llvmcache, llvmkernels

pytest.importorskip("llvmlite")

Y0 = np.array([1.0, 1.0])
#: compiled and numpy runs of the same scheme agree to round-off (seen: <= 7e-15 over 100
#: steps); a stale kernel differs by O(0.1)
TOL = 1e-11


def _osc(k, shape="quartic"):
    if shape == "quadratic":      # (Kahan's method needs a quadratic vector field)
        return mg.Hamiltonian(f"p**2/2 + {k}*q**2/2", q=["q"], p=["p"], name="osc")
    return mg.Hamiltonian(f"p**2/2 + {k}*q**4/4 + q**2/2", q=["q"], p=["p"], name="osc")


def _pendulum(g):
    return mg.Hamiltonian(f"(px**2 + py**2)/2 + {g}*y", q=["x", "y"], p=["px", "py"],
                          constraints=["x**2 + y**2 - 1"], name="osc")


PENDULUM_Y0 = np.array([0.479425538604203, -0.8775825618903728, 0.8775825618903728, 0.479425538604203])


def _runs(tmp_path, systems, method, y0, steps=100, h=0.1, **kw):
    """For each system in turn, generated at ONE compiled path: (compiled, numpy) trajectories."""
    out = []
    for i, system in enumerate(systems):
        scheme = mg.discretize(system, method, **kw)
        comp = mg.generate(scheme, tmp_path / "osc.py", backend="numba")
        ref = mg.generate(scheme, tmp_path / f"osc_numpy_{i}.py")
        out.append((comp.integrate(y0, h=h, steps=steps), ref.integrate(y0, h=h, steps=steps)))
    return out


def _assert_fresh(runs):
    for i, (comp, ref) in enumerate(runs):
        err = float(np.max(np.abs(comp - ref)))
        assert err < TOL, f"system {i} of the row: compiled run differs from numpy by {err:.3g}"


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


_SLOW = pytest.mark.slow
#: every method family; by default one per step kind (implicit Newton, explicit, collocation
#: stages, linearly implicit, composition), the families sharing a kind with slow
FAMILIES = [
    ("energy-momentum", {}, "quartic", (3, 5, 7)),
    ("stormer-verlet", {}, "quartic", (3, 5)),
    ("gauss", {"stages": 2}, "quartic", (3, 5)),
    ("kahan", {}, "quadratic", (2, 5)),
    ("energy-momentum", {"order": 4}, "quartic", (3, 5)),
    pytest.param("midpoint", {}, "quartic", (3, 5), marks=_SLOW),
    pytest.param("trapezoidal", {}, "quartic", (3, 5), marks=_SLOW),
    pytest.param("avf", {}, "quartic", (3, 5), marks=_SLOW),
    pytest.param("gonzalez", {}, "quartic", (3, 5), marks=_SLOW),
    pytest.param("itoh-abe", {}, "quartic", (3, 5), marks=_SLOW),
    pytest.param("energy-collocation", {"stages": 2}, "quartic", (3, 5), marks=_SLOW),
    pytest.param("stormer-verlet-projected", {}, "quartic", (3, 5), marks=_SLOW),
]


@pytest.mark.parametrize("method,kw,shape,ks", FAMILIES)
def test_regenerated_module_runs_its_own_kernels(tmp_path, private_cache, method, kw, shape, ks):
    _assert_fresh(_runs(tmp_path, [_osc(k, shape) for k in ks], method, Y0, **kw))


@pytest.mark.parametrize("method", ["rattle", pytest.param("shake", marks=_SLOW)])
def test_regenerated_constrained_module_runs_its_own_kernels(tmp_path, private_cache, method):
    _assert_fresh(_runs(tmp_path, [_pendulum(g) for g in (1.0, 3.0)], method, PENDULUM_Y0, h=0.05))


def test_energy_kept_after_regeneration(tmp_path, private_cache):
    """The reported case: energy-momentum keeps each Hamiltonian's own H to round-off."""
    for k in (3, 5, 7):
        H = _osc(k)
        mod = mg.generate(mg.discretize(H, "energy-momentum"), tmp_path / "osc.py", backend="numba")
        traj = mod.integrate(Y0, h=0.1, steps=200)
        e = mod.hamiltonian(traj)
        assert abs(e[0] - (0.5 + k / 4 + 0.5)) < 1e-15
        assert float(np.max(np.abs(e - e[0]))) < 1e-13, (k, float(np.max(np.abs(e - e[0]))))


def test_negative_control_a_key_without_the_tree_runs_stale_code(tmp_path, private_cache, monkeypatch):
    """With the machine code keyed by the kernel's name instead of its tree's digest, the same
    comparison fails: the second Hamiltonian is served the first one's code."""
    def by_name(fn):
        return "fn:" + getattr(fn, "py_func", fn).__name__

    monkeypatch.setattr(llvmcache, "_function_part", by_name)
    runs = _runs(tmp_path, [_osc(k) for k in (3, 5)], "energy-momentum", Y0)
    with pytest.raises(AssertionError, match="system 1 of the row"):
        _assert_fresh(runs)


def test_file_changed_since_import_is_not_translated(tmp_path, private_cache):
    """A function of a module imported by Python itself (no kernel IR) whose file has changed
    since: its text is refused (StaleSource), never translated; the unchanged file is accepted
    (control), not cacheable outside methodgen.  A generated module's function is refused
    outright: it is compiled from its kernel IR, never from its text."""
    path = tmp_path / "plain_mod.py"
    path.write_text("def f(x):\n    return 3.0 * x\n")
    sys.path.insert(0, str(tmp_path))
    try:
        import importlib
        mod = importlib.import_module("plain_mod")
        text, _, cacheable = kernelsource.source_of(mod.f)            # control: accepted
        assert "3.0" in text and not cacheable                        # (outside methodgen: not cached)
        path.write_text("def f(x):\n    return 5.0 * x\n")             # same size, same line
        linecache.checkcache(str(path))
        kernelsource._VERIFIED.clear()
        with pytest.raises(kernelsource.StaleSource, match="changed since"):
            kernelsource.source_of(mod.f)
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("plain_mod", None)
    gen = mg.generate(mg.discretize(_osc(3), "energy-momentum"), tmp_path / "osc.py", backend="numba")
    with pytest.raises(kernelsource.StaleSource, match="generated code"):
        kernelsource.source_of(gen._nb_res.py_func)


PROBE = textwrap.dedent("""
    import json, sys
    import numpy as np
    import methodgen as mg
    k, path, out = sys.argv[1], sys.argv[2], sys.argv[3]
    H = mg.Hamiltonian(f"p**2/2 + {k}*q**4/4 + q**2/2", q=["q"], p=["p"], name="osc")
    mod = mg.generate(mg.discretize(H, "energy-momentum"), path, backend="numba")
    np.save(out, mod.integrate(np.array([1.0, 1.0]), h=0.1, steps=100))
""")


def test_regenerated_across_processes(tmp_path, private_cache):
    """Process by process at one path (3, 5, then 3 again: its machine code from the disk
    cache): each runs its own Hamiltonian."""
    env = dict(os.environ, METHODGEN_CACHE=str(private_cache))
    for i, k in enumerate((3, 5, 3)):
        out = tmp_path / f"run{i}.npy"
        proc = subprocess.run([sys.executable, "-c", PROBE, str(k), str(tmp_path / "osc.py"), str(out)],
                              capture_output=True, text=True, env=env)
        assert proc.returncode == 0, proc.stderr[-3000:]
        scheme = mg.discretize(_osc(k), "energy-momentum")
        ref = mg.generate(scheme, tmp_path / f"osc_numpy_{i}.py").integrate(Y0, h=0.1, steps=100)
        err = float(np.max(np.abs(np.load(out) - ref)))
        assert err < TOL, (k, err)
    assert any(private_cache.joinpath("llvm").glob("*.o")), "the machine-code cache was not used"
