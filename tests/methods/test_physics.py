"""Physics of the generated solvers: conservation laws and convergence order."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import methodgen as mg

KEPLER_Y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])  # e = 0.6, a = 1


@pytest.fixture(scope="module")
def kepler_runs(modules, kepler):
    out = {}
    for method in ("energy-momentum", "midpoint"):
        _, mod = modules(kepler, method)
        traj = mod.integrate(KEPLER_Y0, 0.01, 10_000)
        out[method] = (mod, traj)
    return out


def test_energy_momentum_preserves_energy_and_angular_momentum(kepler_runs):
    mod, traj = kepler_runs["energy-momentum"]
    inv = mod.invariants(traj)
    H = inv["H"]
    assert np.max(np.abs(H - H[0])) / abs(H[0]) <= 1e-12
    for name in ("Lx", "Ly", "Lz"):
        assert np.max(np.abs(inv[name] - inv[name][0])) <= 1e-12


def test_midpoint_does_not_preserve_kepler_energy(kepler_runs):
    """Negative control: the same check on the midpoint rule fails by orders of magnitude."""
    mod, traj = kepler_runs["midpoint"]
    H = mod.hamiltonian(traj)
    rel = np.max(np.abs(H - H[0])) / abs(H[0])
    assert rel > 1e-6
    # ... while it does preserve the quadratic invariant q × p (a symplectic RK property).
    inv = mod.invariants(traj)
    assert np.max(np.abs(inv["Lz"] - inv["Lz"][0])) <= 1e-12


def test_both_stay_on_the_orbit(kepler_runs):
    """Sanity of the physics, not just of the invariants: the orbit's period is 2π."""
    for method, (mod, traj) in kepler_runs.items():
        r = np.linalg.norm(traj[:, :3], axis=1)
        assert r.min() == pytest.approx(0.4, rel=1e-2), method
        assert r.max() == pytest.approx(1.6, rel=1e-2), method


def _kepler_reference(T):
    def f(t, y):
        q, p = y[:3], y[3:]
        return np.concatenate([p, -q / np.linalg.norm(q) ** 3])
    sol = solve_ivp(f, (0, T), KEPLER_Y0, method="DOP853", rtol=1e-13, atol=1e-14)
    return sol.y[:, -1]


def observed_order(hs, errs, floor=1e-11):
    """Least-squares slope of log(err) against log(h), dropping the round-off plateau."""
    hs, errs = np.asarray(hs), np.asarray(errs)
    keep = errs > floor
    assert keep.sum() >= 3, "too few points above the round-off floor"
    return np.polyfit(np.log(hs[keep]), np.log(errs[keep]), 1)[0]


@pytest.mark.parametrize("method", ["energy-momentum", "midpoint"])
def test_observed_order_two_on_kepler(method, modules, kepler):
    _, mod = modules(kepler, method)
    T = 1.0
    ref = _kepler_reference(T)
    hs = [0.1, 0.05, 0.025, 0.0125, 0.00625]
    errs = [np.max(np.abs(mod.integrate(KEPLER_Y0, h, int(round(T / h)))[-1] - ref)) for h in hs]
    order = observed_order(hs, errs)
    assert 1.9 < order < 2.1, (order, errs)


@pytest.mark.parametrize("method", ["midpoint", "energy-momentum"])
def test_observed_order_two_on_harmonic(method, modules, harmonic):
    _, mod = modules(harmonic, method)
    T = 2.0
    exact = np.array([np.cos(T), -np.sin(T)])
    hs = [0.2, 0.1, 0.05, 0.025]
    errs = [np.max(np.abs(mod.integrate([1.0, 0.0], h, int(round(T / h)))[-1] - exact)) for h in hs]
    assert 1.9 < observed_order(hs, errs) < 2.1


def test_order_fit_can_fail():
    """Negative control of the fit: first-order data is not called second order."""
    hs = np.array([0.1, 0.05, 0.025, 0.0125])
    assert observed_order(hs, 0.3 * hs) == pytest.approx(1.0)
    assert not (1.9 < observed_order(hs, 0.3 * hs) < 2.1)
