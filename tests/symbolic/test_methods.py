"""The method library: orders, energy preservation, removable singularities, Kahan, RATTLE/SHAKE."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

import methodgen as mg
from methodgen.symbolic.derive import vector_field
from methodgen.problem.special import to_elementary
from test_physics import observed_order


def _reference(system, y0, T, params=None):
    """DOP853 at tight tolerances on f = J∇H (documented reference for non-exact cases)."""
    f = sp.lambdify([list(system.y), list(system.params)], list(vector_field(system)), "numpy")
    pv = [system.param_values[k] for k in system.param_names]
    sol = solve_ivp(lambda t, y: np.array(f(y, pv), dtype=float), (0, T), y0, method="DOP853",
                    rtol=1e-13, atol=1e-14)
    return sol.y[:, -1]


ORDER_CASES = [
    ("henon-heiles", "midpoint", 2), ("henon-heiles", "trapezoidal", 2), ("henon-heiles", "kahan", 2),
    ("simple-pendulum", "avf", 2), ("simple-pendulum", "gonzalez", 2), ("simple-pendulum", "itoh-abe", 2),
    ("simple-pendulum", "energy-momentum", 2), ("simple-pendulum", "stormer-verlet", 2),
    ("double-well", "gonzalez", 2), ("double-well", "avf", 2), ("linear", "kahan", 2),
]


@pytest.mark.parametrize("scene, method, order", ORDER_CASES)
def test_observed_order(scene, method, order, modules):
    sc = mg.load_scene(scene)
    _, mod = modules(sc.system, method)
    T = 1.0
    ref = _reference(sc.system, np.array(sc.y0), T)
    hs = [0.1, 0.05, 0.025, 0.0125, 0.00625]
    errs = [np.max(np.abs(mod.integrate(np.array(sc.y0), h, int(round(T / h)))[-1] - ref)) for h in hs]
    assert abs(observed_order(hs, errs) - order) < 0.15, errs


def _pendulum_exact(y0, T, g=1.0, L=1.0):
    """Planar pendulum through its angle θ (θ'' = -g/L sin θ), mapped to Cartesian (q, p)."""
    x, y, px, py = y0
    th = np.arctan2(x, -y)
    om = (x * py - y * px) / L**2
    sol = solve_ivp(lambda t, u: [u[1], -g / L * np.sin(u[0])], (0, T), [th, om], method="DOP853",
                    rtol=1e-13, atol=1e-14)
    th, om = sol.y[:, -1]
    return np.array([L * np.sin(th), -L * np.cos(th), L * om * np.cos(th), L * om * np.sin(th)])


def test_itoh_abe_is_first_order_on_coupled_coordinates(modules, kepler):
    """Kepler couples the coordinates: Itoh–Abe is not symmetric there, and first order."""
    scheme, mod = modules(kepler, "itoh-abe")
    assert scheme.traits.order == 1 and not scheme.traits.symmetric
    y0 = np.array([0.4, 0, 0, 0, 1.6, 1.2])
    ref = _reference(kepler, y0, 0.5)
    hs = [0.02, 0.01, 0.005, 0.0025]
    errs = [np.max(np.abs(mod.integrate(y0, h, int(round(0.5 / h)))[-1] - ref)) for h in hs]
    assert abs(observed_order(hs, errs) - 1) < 0.15, errs


@pytest.mark.parametrize("method", ["rattle", "shake"])
def test_constrained_methods_are_second_order(method, modules):
    sc = mg.load_scene("pendulum")
    _, mod = modules(sc.system, method)
    T = 1.0
    ref = _pendulum_exact(np.array(sc.y0), T)
    hs = [0.1, 0.05, 0.025, 0.0125, 0.00625]
    errs = [np.max(np.abs(mod.integrate(np.array(sc.y0), h, int(round(T / h)))[-1] - ref)) for h in hs]
    assert abs(observed_order(hs, errs) - 2) < 0.15, errs


DG_METHODS = ["avf", "gonzalez", "itoh-abe", "energy-momentum"]


@pytest.mark.parametrize("method", DG_METHODS)
def test_discrete_gradients_preserve_nonpolynomial_energy(method, modules):
    sc = mg.load_scene("simple-pendulum")  # H = p²/2 - cos q
    _, mod = modules(sc.system, method)
    traj = mod.integrate(np.array(sc.y0), 0.05, 10_000)
    H = mod.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-13


@pytest.mark.parametrize("method", ["avf", "itoh-abe", "gonzalez"])
def test_discrete_gradients_preserve_kepler_energy(method, modules, kepler):
    _, mod = modules(kepler, method)
    traj = mod.integrate(np.array([0.4, 0, 0, 0, 1.6, 1.2]), 0.01, 10_000)
    H = mod.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-13


def test_energy_check_can_fail(modules):
    """Negative control: the midpoint rule and Störmer–Verlet on the same run fail the check."""
    sc = mg.load_scene("simple-pendulum")
    for method in ("midpoint", "stormer-verlet"):
        _, mod = modules(sc.system, method)
        H = mod.hamiltonian(mod.integrate(np.array(sc.y0), 0.05, 10_000))
        assert np.max(np.abs(H - H[0])) / abs(H[0]) > 1e-6


def _mp_oracle(scheme):
    """The residual with every removable-singularity function as its elementary quotient, in mpmath."""
    sy = scheme.system
    args = list(scheme.unknowns) + list(sy.y) + [scheme.h] + list(sy.params)
    return sp.lambdify(args, [to_elementary(r) for r in scheme.residual], "mpmath")


@pytest.mark.parametrize("scene, method", [(s, m) for s in ("simple-pendulum", "double-well")
                                           for m in DG_METHODS] + [("kepler", "energy-momentum")])
def test_removable_singularities_accurate_to_roundoff(scene, method, modules):
    """As y1 → y0 (and with single coordinates bitwise equal) the generated residual stays
    accurate to round-off against a 50-digit evaluation of the plain quotients."""
    sc = mg.load_scene(scene)
    scheme, mod = modules(sc.system, method)
    oracle = _mp_oracle(scheme)
    # The oracle evaluates plain quotients (f(b) - f(a))/(b - a): a gap of 1e-40 (standing in
    # for an exact zero) cancels 40 digits, so carry 90.
    mpmath.mp.dps = 90
    y0 = np.array(sc.y0) + 0.1
    pv = [sc.system.param_values[k] for k in sc.system.param_names]
    rng = np.random.default_rng(5)
    n = len(scheme.unknowns)
    h = 1.0
    worst = 0.0
    for gap in [1e-2, 1e-5, 1e-8, 1e-11, 1e-13, 1e-15, 0.0]:
        for zero_first in (False, True):
            z = gap * rng.uniform(0.5, 1.0, n)
            if zero_first:
                z[0] = 0.0
            got = mod.residual(z, y0, h)
            assert np.all(np.isfinite(got))
            zm = [mpmath.mpf(v) if v != 0 else mpmath.mpf("1e-40") for v in z]
            want = np.array([float(v) for v in oracle(*zm, *map(mpmath.mpf, y0), mpmath.mpf(h),
                                                         *map(mpmath.mpf, pv))])
            scale = max(np.max(np.abs(want)), 1.0)
            worst = max(worst, np.max(np.abs(got - want)) / scale)
    assert worst < 1e-14


def test_kahan_jacobian_form_equals_rk_form(tmp_path):
    for scene in ("henon-heiles", "linear"):
        sc = mg.load_scene(scene)
        jac = mg.discretize(sc.system, "kahan")
        rk = mg.discretize(sc.system, "kahan", form="rk")
        assert jac.traits.solve == "linear" and rk.traits.solve == "newton"
        mj = mg.generate(jac, tmp_path / f"{scene}_kj.py")
        mr = mg.generate(rk, tmp_path / f"{scene}_kr.py")
        y0 = np.array(sc.y0)
        np.testing.assert_allclose(mj.step(y0, 0.5), mr.step(y0, 0.5), rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(mj.integrate(y0, 0.1, 200), mr.integrate(y0, 0.1, 200),
                                   rtol=1e-12, atol=1e-13)
        # ... and Kahan is not the midpoint rule (the comparison can fail).
        mid = mg.generate(mg.discretize(sc.system, "midpoint"), tmp_path / f"{scene}_mid.py")
        if scene == "henon-heiles":
            assert np.max(np.abs(mid.step(y0, 0.5) - mj.step(y0, 0.5))) > 1e-6


def test_kahan_jacobian_form_refused_for_nonquadratic_field():
    sc = mg.load_scene("simple-pendulum")
    with pytest.raises(mg.MethodNotApplicable, match="quadratic vector field"):
        mg.discretize(sc.system, "kahan", form="jacobian")
    assert mg.discretize(sc.system, "kahan").traits.solve == "newton"


@pytest.mark.parametrize("scene", ["pendulum", "spherical-pendulum", "double-pendulum"])
def test_rattle_keeps_both_constraints_and_shake_does_not(scene, modules):
    sc = mg.load_scene(scene)
    y0 = np.array(sc.y0)
    results = {}
    for method in ("rattle", "shake"):
        _, mod = modules(sc.system, method)
        traj = mod.integrate(y0, 0.01, 10_000)
        g, v = mod.constraint_residuals(traj)
        results[method] = (np.max(np.abs(g)), np.max(np.abs(v)))
    assert results["rattle"][0] <= 1e-12 and results["rattle"][1] <= 1e-12
    assert results["shake"][0] <= 1e-12            # positions are constrained ...
    assert results["shake"][1] > 1e-8              # ... velocities are not (visibly larger)


@pytest.mark.parametrize("scene", ["pendulum", "double-pendulum"])
def test_rattle_is_symmetric_forward_then_backward(scene, modules):
    sc = mg.load_scene(scene)
    _, mod = modules(sc.system, "rattle")
    y0 = np.array(sc.y0)
    fwd = mod.integrate(y0, 0.01, 500)
    back = mod.integrate(fwd[-1], -0.01, 500)
    assert np.max(np.abs(back[-1] - y0)) < 1e-12
    # Negative control: SHAKE (unprojected velocities) does not return exactly.
    _, shake = modules(sc.system, "shake")
    fwd = shake.integrate(y0, 0.01, 500)
    back = shake.integrate(shake.project(fwd[-1]), -0.01, 500)
    assert np.max(np.abs(back[-1] - y0)) > 1e-10


def test_off_manifold_start_is_refused_with_a_fix(modules):
    sc = mg.load_scene("pendulum")
    _, mod = modules(sc.system, "rattle")
    bad = np.array([1.0, 0.1, 0.0, 1.0])
    with pytest.raises(ValueError, match="not on the constraint manifold.*project"):
        mod.integrate(bad, 0.01, 10)
    good = mod.project(bad)
    g, v = mod.constraint_residuals(good)
    assert np.max(np.abs(g)) < 1e-14 and np.max(np.abs(v)) < 1e-14
    assert np.all(np.isfinite(mod.integrate(good, 0.01, 10)))


def test_methods_refuse_what_they_cannot_do():
    sc = mg.load_scene("pendulum")
    with pytest.raises(mg.MethodNotApplicable, match="rattle"):
        mg.discretize(sc.system, "midpoint")
    with pytest.raises(mg.MethodNotApplicable, match="constraints"):
        mg.discretize(mg.load_scene("kepler").system, "rattle")
    nonsep = mg.Hamiltonian("p**2/2 + q**2/2 + q**2*p**2", q=["q"], p=["p"])
    with pytest.raises(mg.MethodNotApplicable, match="separable"):
        mg.discretize(nonsep, "stormer-verlet")
