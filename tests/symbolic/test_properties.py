"""Property-based tests on random polynomial Hamiltonians (degree ≤ 4, 1–3 degrees of freedom)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import methodgen as mg
from helpers import oracle_namespace

NAMES = {1: (["q"], ["p"]), 2: (["x", "y"], ["px", "py"]), 3: (["x", "y", "z"], ["px", "py", "pz"])}


@st.composite
def polynomial_hamiltonians(draw):
    d = draw(st.integers(1, 3))
    qn, pn = NAMES[d]
    syms = [sp.Symbol(n, real=True) for n in qn + pn]
    # A positive-definite quadratic part keeps orbits bounded near 0 ...
    H = sum(sp.Rational(draw(st.integers(1, 4)), 2) * s**2 for s in syms)
    # ... plus up to four random monomials of degree 1..4 with small rational coefficients.
    for _ in range(draw(st.integers(0, 4))):
        powers = [draw(st.integers(0, 2)) for _ in syms]
        if not 0 < sum(powers) <= 4:
            continue
        coeff = sp.Rational(draw(st.integers(-3, 3)), draw(st.integers(1, 4)))
        H += coeff * sp.Mul(*[s**k for s, k in zip(syms, powers)])
    method = draw(st.sampled_from(["midpoint", "avf", "gonzalez", "itoh-abe"]))
    return mg.Hamiltonian(H, q=qn, p=pn, name="prop"), method


SETTINGS = settings(max_examples=20, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@SETTINGS
@given(polynomial_hamiltonians(), st.integers(0, 2**32 - 1))
def test_generated_code_against_oracles(tmp_path, sys_method, seed):
    system, method = sys_method
    scheme = mg.discretize(system, method)
    mod = mg.generate(scheme, tmp_path / f"prop_{abs(hash((system.fingerprint(), method)))}.py")
    rng = np.random.default_rng(seed)
    n = len(scheme.unknowns)
    d2 = 2 * system.dim

    # 1. residual == lambdify oracle at random finite points
    y0 = rng.uniform(-0.5, 0.5, size=(8, d2))
    z = rng.uniform(-0.05, 0.05, size=(8, n))
    oracle = sp.lambdify(list(scheme.unknowns) + list(system.y) + [scheme.h], list(scheme.residual),
                         modules=[oracle_namespace(), "numpy"])
    with np.errstate(all="ignore"):
        want = np.array([oracle(*z[i], *y0[i], 0.1) for i in range(8)], dtype=float)
    got = mod.residual(z, y0, 0.1)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-13)

    # 2. finite input never yields NaN: residual, Jacobian, and a step (or a clear error)
    assert np.all(np.isfinite(got)) and np.all(np.isfinite(mod.jacobian(z, y0, 0.1)))
    try:
        traj = mod.integrate(y0[0], 0.01, 50)
    except (mod.ConvergenceError, mod.ResolutionError, mod.NonFiniteError) as exc:
        assert np.all(np.isfinite(exc.trajectory))
        return
    assert np.all(np.isfinite(traj))

    # 3. the discrete-gradient identity holds to round-off along the run (energy methods)
    H = mod.hamiltonian(traj)
    scale = np.max(np.abs(mod.hamiltonian(y0))) + 1.0
    if scheme.traits.discrete_gradient:
        assert np.max(np.abs(H - H[0])) <= 1e-13 * scale
