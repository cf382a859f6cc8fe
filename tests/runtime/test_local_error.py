"""The local error estimate of the generated steppers (issue 13, item 1) and its advice (item 6).

Every generated stepper compares each step with its embedded partner on the chord
y0 -> y1 (see methodgen.codegen.lower.local_error_plan) and raises ResolutionError when the
estimate exceeds MAX_LOCAL_ERROR times the step.  The regression: Kepler from
apocentre at high eccentricity, one period, where a step straddling the pericentre
used to return a wrong orbit with exact invariants and no exception.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

import methodgen as mg
from methodgen.symbolic.derive import separable_split, vector_field

from conftest import SCENE_METHODS, marked, scene_y0

#: (eccentricity, step size) of the issue: one period from apocentre is round(2π/h) steps.
KEPLER_CASES = [(0.9, 0.05), (0.97, 0.01), (0.99, 0.001), (0.999, 0.1)]


def _apocentre(e):
    """Kepler (a = m = k = 1) at apocentre with eccentricity e."""
    return np.array([1 + e, 0.0, 0.0, 0.0, math.sqrt((1 - e) / (1 + e)), 0.0])


@pytest.fixture(scope="module")
def kepler_refs():
    """DOP853 (rtol 1e-12) after one period, per case."""
    def f(t, y):
        r3 = np.linalg.norm(y[:3]) ** 3
        return np.concatenate([y[3:], -y[:3] / r3])
    out = {}
    for e, h in KEPLER_CASES:
        steps = round(2 * math.pi / h)
        sol = solve_ivp(f, (0.0, steps * h), _apocentre(e), method="DOP853", rtol=1e-12, atol=1e-14)
        out[e, h] = (steps, sol.y[:, -1])
    return out


def _run(mod, y0, h, steps, **kw):
    try:
        return None, mod.integrate(y0, h, steps, **kw)
    except (mod.ConvergenceError, mod.ResolutionError, mod.NonFiniteError) as exc:
        return exc, None


def _rel_error(traj, ref):
    return float(np.max(np.abs(traj[-1] - ref)) / np.max(np.abs(ref)))


KEPLER_METHODS = mg.applicable_methods(mg.load_scene("kepler").system)


@pytest.mark.parametrize("method", KEPLER_METHODS)
def test_kepler_close_encounters_are_refused_or_right(method, modules, kepler, kepler_refs):
    """Every method that applies to Kepler, every case: a ResolutionError or the right orbit."""
    _, mod = modules(kepler, method)
    for e, h in KEPLER_CASES:
        steps, ref = kepler_refs[e, h]
        exc, traj = _run(mod, _apocentre(e), h, steps)
        if exc is None:
            assert _rel_error(traj, ref) < 1e-2, (method, e, h)
            continue
        assert isinstance(exc, mod.ResolutionError), (method, e, h, exc)
        # the step straddling (or reaching) the pericentre, half a period in
        assert abs(exc.step - steps / 2) < 0.05 * steps, (method, e, h, exc.step)
        assert exc.trajectory.shape == (exc.step + 1, 6) and np.all(np.isfinite(exc.trajectory))
        assert 0 < exc.suggested_h < h and f"use h <= {exc.suggested_h:g}" in str(exc)
        if exc.check == "local_error":
            assert exc.resolution > mod.MAX_LOCAL_ERROR
            assert "time transformation" in str(exc) and "close encounters" in str(exc)
        # Negative control: with the guards off the same run is wrong by the criterion an
        # accepted run must meet (or Newton fails) -- the refusal was not a false alarm.
        # (Second-order methods are off by > 0.3 here; the order-4 energy-collocation by 2-22%.)
        off, traj = _run(mod, _apocentre(e), h, steps, check_resolution=False)
        assert not isinstance(off, mod.ResolutionError)
        assert isinstance(off, mod.ConvergenceError) or _rel_error(traj, ref) > 1e-2, (method, e, h)


@pytest.mark.parametrize("method", ["energy-momentum", "stormer-verlet"])
def test_the_estimate_is_what_fires(method, modules, kepler, kepler_refs, monkeypatch):
    """Without the local error estimate (its limit set to infinity) the other guards --
    the Jacobian at the converged step and the explicit predictor -- let every one of
    these wrong orbits through, for energy-momentum with H and the angular momentum
    exact to round-off: the issue's reproduction."""
    _, mod = modules(kepler, method)
    for e, h in KEPLER_CASES:
        steps, ref = kepler_refs[e, h]
        exc, _ = _run(mod, _apocentre(e), h, steps)
        assert isinstance(exc, mod.ResolutionError) and exc.check == "local_error"
        with monkeypatch.context() as m:
            m.setattr(mod, "_LERR2", math.inf)
            off, traj = _run(mod, _apocentre(e), h, steps)
        assert off is None and _rel_error(traj, ref) > 0.3, (e, h, off)
        if method == "energy-momentum":
            H = mod.hamiltonian(traj)
            Lz = mod.invariants(traj)["Lz"]
            assert np.max(np.abs(H - H[0])) < 1e-12 and np.max(np.abs(Lz - Lz[0])) < 1e-12


def _oracle_rho(system, method, y0, y1, h):
    """|E|/|Δy| of one step by the formulas of methodgen.codegen.lower.local_error_plan, from lambdify."""
    sub = {s: system.param_values[s.name] for s in system.params}
    f = sp.lambdify([list(system.y)], list(vector_field(system).xreplace(sub)), "numpy")
    f0, f1, fm = (np.array(f(v), dtype=float) for v in (y0, y1, (y0 + y1) / 2))
    dy = y1 - y0
    d = system.dim
    if method in ("stormer-verlet", "rattle", "shake"):
        E, D = dy[:d] - h / 2 * (f0[:d] + f1[:d]), dy[:d]
    elif method == "trapezoidal":
        E, D = dy - h * fm, dy
    else:
        E, D = (dy - h / 2 * (f0 + f1)) * (0.5 if method == "kahan" else 1.0), dy
    return float(np.linalg.norm(E) / np.linalg.norm(D))


@pytest.mark.parametrize("scene_name,method", [
    ("kepler", "energy-momentum"), ("henon-heiles", "trapezoidal"), ("henon-heiles", "kahan"),
    ("double-well", "stormer-verlet"), ("pendulum", "rattle"), ("simple-pendulum", "gonzalez")])
def test_estimate_is_the_documented_formula_and_second_order(scene_name, method, modules, monkeypatch):
    """The estimate of the first step (read off the ResolutionError with a zero limit)
    equals the formula evaluated independently, and it is O(h²) relative to the step."""
    scene = mg.load_scene(scene_name)
    _, mod = modules(scene.system, method)
    y0 = mod.integrate(np.array(scene.y0), scene.h, 37)[-1]  # a generic point, not a symmetric one
    monkeypatch.setattr(mod, "_LERR2", 0.0)
    rhos = []
    for h in (scene.h / 2, scene.h / 4):
        exc, _ = _run(mod, y0, h, 1)
        assert isinstance(exc, mod.ResolutionError) and exc.check == "local_error" and exc.step == 0
        y1 = mod.integrate(y0, h, 1, check_resolution=False)[1]
        assert exc.resolution == pytest.approx(_oracle_rho(scene.system, method, y0, y1, h), rel=1e-6)
        rhos.append(exc.resolution)
    assert 3.0 < rhos[0] / rhos[1] < 5.0, rhos  # halving h quarters E/|Δy|


def test_linear_vector_fields_are_exempt(modules):
    """Figure 1 uses h·ω ≈ 5 on purpose: no estimate on a linear field, even at h·ω = 10."""
    scene = mg.load_scene("linear")
    for method in scene.methods:
        _, mod = modules(scene.system, method)
        assert mod.MAX_LOCAL_ERROR is None
        with pytest.warns(mod.ResolutionWarning, match="aliased"):   # exempt, but said
            mod.integrate(np.array(scene.y0), 2 * scene.h, 50)
    # Negative control: a nonlinear field at the same h·ω is refused.
    duffing = mg.Hamiltonian("p**2/2 + 13*q**2 + q**4", q=["q"], p=["p"], name="duffing_stiff")
    _, mod = modules(duffing, "midpoint")
    with pytest.raises(mod.ResolutionError):
        mod.integrate(np.array([1.0, 0.0]), 1.0, 50)


@pytest.mark.parametrize("scene_name,method", marked(SCENE_METHODS))
def test_no_false_alarm_on_the_built_in_scenes(scene_name, method, modules):
    """Every built-in scene with every method it lists, at its documented h (the first
    3000 steps; the whole runs are in the slow sweep below).  A scene with a time
    transformation runs its transformed system from its y0 on K = 0, in fictive time."""
    scene = mg.load_scene(scene_name)
    _, mod = modules(scene.run_system, method)
    mod.integrate(scene_y0(scene, mod), scene.h, min(scene.steps, 3000))


@pytest.mark.slow
def test_no_false_alarm_sweep(modules):
    """The whole documented runs of the built-in scenes and of every user problem in
    tests/user_problems with every method that applies (the issue's sweep)."""
    import glob
    from pathlib import Path
    targets = [(mg.load_scene(s), mg.load_scene(s).methods) for s in mg.scenes()]
    root = Path(__file__).resolve().parents[1] / "user_problems"
    for f in sorted(glob.glob(str(root / "*.toml"))):
        sc = mg.load_scene(f)
        targets.append((sc, mg.applicable_methods(sc.run_system)))
    for scene, methods in targets:
        for method in methods:
            _, mod = modules(scene.run_system, method)
            y0 = scene_y0(scene, mod)
            mod.integrate(y0, scene.h, scene.steps)
            mod.integrate(np.stack([y0, y0]), scene.h, min(scene.steps, 500))


# --- the numba backend: the same estimate, the same step ---------------------------------

@pytest.fixture(scope="module")
def kepler_numba(modules, kepler, tmp_path_factory):
    pytest.importorskip("llvmlite")
    scheme, np_mod = modules(kepler, "energy-momentum")
    path = tmp_path_factory.mktemp("numba_lerr") / "kepler_energy_momentum_numba.py"
    return np_mod, mg.generate(scheme, path, backend="numba")


@pytest.mark.slow
def test_numba_backend_raises_the_same(kepler_numba, kepler_refs):
    """(Compiles the Kepler module: ~10-20 s.  The default suite checks the compiled
    estimate on a small system in tests/test_stepper_domains.py.)"""
    np_mod, nb_mod = kepler_numba
    for e, h in KEPLER_CASES:
        steps, _ = kepler_refs[e, h]
        y0 = _apocentre(e)
        for Y in (y0, np.stack([[1.0, 0, 0, 0, 1.0, 0], y0, y0])):  # a circular orbit, then two
            a, _ = _run(np_mod, Y, h, steps)
            b, _ = _run(nb_mod, Y, h, steps)
            assert type(a).__name__ == type(b).__name__ == "ResolutionError"
            assert a.check == b.check == "local_error" and a.step == b.step
            assert b.resolution == pytest.approx(a.resolution, rel=1e-9)
            assert b.suggested_h == pytest.approx(a.suggested_h, rel=0.01) and b.suggested_h < h
            np.testing.assert_allclose(b.trajectory, a.trajectory, rtol=0, atol=1e-12)
            if Y.ndim == 2:
                assert "trajectories [1, 2]" in str(b)
        # the switch works in the compiled loop too
        off, _ = _run(nb_mod, y0, h, steps, check_resolution=False)
        assert not isinstance(off, nb_mod.ResolutionError)


@pytest.mark.slow
def test_numba_convergence_advice(kepler_numba):
    """maxiter too small with the residual already at round-off: "raise maxiter"."""
    for mod in kepler_numba:
        y0 = np.array(mg.load_scene("kepler").y0)
        with pytest.raises(mod.ConvergenceError) as err:
            mod.integrate(y0, 0.01, 10, maxiter=1)
        assert "raise maxiter" in str(err.value) and "smaller step size" not in str(err.value)


# --- advice that helps (item 6) ---------------------------------------------------------

def test_convergence_error_advice(modules, kepler):
    _, mod = modules(kepler, "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0)
    for Y in (y0, np.stack([y0, y0])):
        with pytest.raises(mod.ConvergenceError) as err:
            mod.integrate(Y, 0.01, 10, maxiter=1)
        assert err.value.residual_norm < 1e-10
        assert "raise maxiter" in str(err.value) and "smaller step size" not in str(err.value)
    # Negative control: a Newton iteration that really fails still asks for a smaller h.
    with pytest.raises(mod.ConvergenceError) as err:
        mod.integrate(np.array([0.05, 0, 0, 0, 0.1, 0]), 0.5, 50, check_resolution=False)
    assert "smaller step size" in str(err.value) and "raise maxiter" not in str(err.value)


def test_suggested_h_is_strictly_smaller(modules, kepler):
    _, mod = modules(kepler, "energy-momentum")
    # The issue: h*omega just above the limit used to print "use h <= 0.02" for h = 0.02.
    naive = f"{0.02 * mod.MAX_RESOLUTION / 2.0004:.3g}"
    assert float(naive) == 0.02  # (the old formula: the negative control of this test)
    for h in (0.02, 0.1, 1e-3, 0.5, 3.0, 1e-300, 1.7e308, -0.02):
        for factor in (0.9999, 0.5, 1e-3, 2.0, 0.0, math.nan, math.inf):
            value, text = mod._smaller_h(h, factor)
            assert 0.0 < value < abs(h) and float(text) == value, (h, factor, text)
    # The three guards, on real failures.
    y0 = np.array(mg.load_scene("kepler").y0)
    for kw in [dict(y0=np.array([0.05, 0, 0, 0, 0.1, 0]), h=0.5),   # Jacobian
               dict(y0=y0, h=0.5)]:                                 # local error
        with pytest.raises(mod.ResolutionError) as err:
            mod.integrate(kw["y0"], kw["h"], 50)
        e = err.value
        assert 0 < e.suggested_h < kw["h"] and f"use h <= {e.suggested_h:g}" in str(e)
