"""Traits and certificates agree, as a property: a trait that verify can refute is a bug.

For random Hamiltonians — polynomial (separable or not, cubic ones so that Kahan's
claims apply), radial (so angular momenta are claimed) and non-polynomial from the
grammar — every method that applies is discretised and verified.  No certificate
may be refuted or fail its numerical tolerance, and every invariant the traits
list as ``preserved`` must have a certificate that is not refuted.  Claims may be
``undecided`` (budget), never wrong.

The negative control injects a false trait (midpoint "preserves" a quartic H) and
shows that verify refutes it, so this property can fail.
"""

from __future__ import annotations

from dataclasses import replace

import pytest
import sympy as sp
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

import methodgen as mg
from methodgen.errors import InputError, MethodNotApplicable

TIMEOUT = 20   # seconds per claim group: undecided beyond, never wrong
SETTINGS = dict(derandomize=True, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.data_too_large])
FAST = dict(phases=[Phase.explicit, Phase.reuse, Phase.generate])
NAMES = {1: (["q"], ["p"]), 2: (["x", "y"], ["px", "py"])}
UNARY = {"exp": lambda u: sp.exp(u / 2), "cos": sp.cos, "sin": sp.sin, "atan": sp.atan,
         "cosh": lambda u: sp.cosh(u / 2), "log": lambda u: sp.log(1 + u**2),
         "sqrt": lambda u: sp.sqrt(1 + u**2)}


def _coef(draw):
    return sp.Rational(draw(st.integers(-3, 3)), draw(st.integers(1, 3)))


@st.composite
def polynomial_systems(draw, max_degree=4):
    d = draw(st.integers(1, 2))
    qn, pn = NAMES[d]
    qs, ps = sp.symbols(qn, real=True), sp.symbols(pn, real=True)
    ys = list(qs) + list(ps)
    U = sp.Add(*[q**2 / 2 for q in qs])
    for _ in range(draw(st.integers(1, 3))):
        deg = draw(st.integers(2, max_degree))
        mono = sp.Mul(*[draw(st.sampled_from(list(qs))) for _ in range(deg)])
        U += _coef(draw) * mono
    T = sp.Add(*[p**2 / 2 for p in ps])
    if draw(st.booleans()):   # a non-separable cubic term couples q and p
        T += _coef(draw) * draw(st.sampled_from(list(qs))) * draw(st.sampled_from(list(ps)))**2 / 4
    H = T + U
    assume(H.free_symbols & set(ys))
    return mg.Hamiltonian(H, q=qn, p=pn, name="poly")


@st.composite
def radial_systems(draw):
    """H = |p|²/2 + V(x² + y²) with V a polynomial or a grammar function: q × p is claimed."""
    x, y = sp.symbols("x y", real=True)
    r2 = x**2 + y**2
    V = draw(st.sampled_from([lambda s: s / 2 + s**2 / 4, lambda s: sp.exp(-s / 2),
                              lambda s: -1 / sp.sqrt(1 + s), lambda s: sp.log(1 + s),
                              lambda s: sp.atan(s) + s / 2]))
    c = sp.Rational(draw(st.integers(1, 3)), draw(st.integers(1, 2)))
    H = (sp.Symbol("px", real=True)**2 + sp.Symbol("py", real=True)**2) / 2 + c * V(r2)
    return mg.Hamiltonian(H, q=["x", "y"], p=["px", "py"], name="radial")


@st.composite
def grammar_systems(draw):
    """H = Σp²/2 + Σ c·g(affine or coordinate) + q²/2: non-polynomial, 1-2 DOF."""
    d = draw(st.integers(1, 2))
    qn, pn = NAMES[d]
    qs, ps = sp.symbols(qn, real=True), sp.symbols(pn, real=True)
    U = sp.Add(*[q**2 / 2 for q in qs])
    for _ in range(draw(st.integers(1, 2))):
        g = UNARY[draw(st.sampled_from(sorted(UNARY)))]
        arg = draw(st.sampled_from(list(qs))) if d == 1 or draw(st.booleans()) else qs[0] - qs[1]
        U += _coef(draw) * g(arg)
    H = sp.Add(*[p**2 / 2 for p in ps]) + U
    return mg.Hamiltonian(H, q=qn, p=pn, name="grammar")


def schemes_of(system):
    out = []
    for method in mg.method_names():
        try:
            out.append(mg.discretize(system, method))
        except (MethodNotApplicable, InputError):
            continue
    return out


def check_traits_agree(system, methods=None):
    checked = 0
    for scheme in schemes_of(system):
        if methods and scheme.method not in methods:
            continue
        report = mg.verify(scheme, timeout=TIMEOUT)
        bad = [(c.status, c.claim, c.details.get("counterexample")) for c in report.certificates
               if not c.passed]
        assert not bad, f"{scheme.method} on H = {system.H}: {bad}"
        for name in scheme.traits.preserved:
            certs = [c for c in report.certificates if c.claim.startswith(f"{scheme.method}: {name}(y1)")
                     or (name == "H" and "discrete-gradient identity" in c.claim)]
            assert all(c.status != "refuted" for c in certs), (scheme.method, name)
        checked += 1
    return checked


@settings(max_examples=4, **FAST, **SETTINGS)
@given(polynomial_systems(max_degree=3))
def test_traits_agree_with_verify_on_random_cubic_h(system):
    """Cubic H: Kahan's modified energy and volume, midpoint/trapezoidal, discrete gradients."""
    assert check_traits_agree(system) >= 4


@settings(max_examples=3, **FAST, **SETTINGS)
@given(radial_systems())
def test_traits_agree_with_verify_on_random_radial_h(system):
    assert check_traits_agree(system, methods={"energy-momentum", "midpoint", "stormer-verlet",
                                               "gonzalez"}) >= 3


@settings(max_examples=3, **FAST, **SETTINGS)
@given(grammar_systems())
def test_traits_agree_with_verify_on_random_non_polynomial_h(system):
    assert check_traits_agree(system, methods={"avf", "gonzalez", "itoh-abe", "midpoint",
                                               "stormer-verlet", "energy-momentum"}) >= 3


@pytest.mark.slow
@settings(max_examples=25, **SETTINGS)
@given(st.one_of(polynomial_systems(), radial_systems(), grammar_systems()))
def test_traits_agree_with_verify_extended(system):
    check_traits_agree(system)


def test_negative_control_a_false_trait_is_refuted():
    """Midpoint does not keep a quartic H: claiming it must be refuted by verify."""
    system = mg.Hamiltonian("p**2/2 + q**4/4", q=["q"], p=["p"])
    scheme = mg.discretize(system, "midpoint")
    assert "H" not in scheme.traits.preserved
    lying = replace(scheme, traits=replace(scheme.traits, preserved=scheme.traits.preserved + ("H",),
                                           energy_preserving=True))
    report = mg.verify(lying, timeout=TIMEOUT)
    assert not report.ok
    with pytest.raises(AssertionError):
        _check_one(lying)


def _check_one(scheme):
    report = mg.verify(scheme, timeout=TIMEOUT)
    bad = [c.claim for c in report.certificates if not c.passed]
    assert not bad, bad
