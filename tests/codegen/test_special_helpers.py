"""The generated helpers against mpmath, near and at their removable points (numerical).

The exact side — that each helper's formula *is* the function the proofs use — is
proved by :mod:`methodgen.symbolic.verify.helpers` (tested at the end of this file, with
negative controls).  Here: floating-point accuracy of the emitted scalar (`_f_`) and
vector (`_v_`) helpers at gaps from 1e-1 down to 0.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
import sympy as sp

from helpers import special_helpers
from methodgen.problem.special import (DIVIDED_DIFFERENCES, atan_dd, atanc, dexp_dd, exp_dd, log_dd, sinc_dd, sinc_u,
                               sinhc, tan_dd)
from methodgen.symbolic.verify.helpers import _certificate, helper_certificate

MP = {"exp": mpmath.exp, "log": mpmath.log, "sin": mpmath.sin, "cos": mpmath.cos, "tan": mpmath.tan,
      "sinh": mpmath.sinh, "cosh": mpmath.cosh, "tanh": mpmath.tanh, "atan": mpmath.atan}
DERIV = {"exp": mpmath.exp, "log": lambda x: 1 / x, "sin": mpmath.cos, "cos": lambda x: -mpmath.sin(x),
         "tan": lambda x: 1 / mpmath.cos(x) ** 2, "sinh": mpmath.cosh, "cosh": mpmath.sinh,
         "tanh": lambda x: 1 / mpmath.cosh(x) ** 2, "atan": lambda x: 1 / (1 + x * x)}
GAPS = [1e-1, 1e-3, 1e-6, 1e-9, 1e-12, 1e-15, 0.0]
#: Base points: moderate, large, negative; for atan both sides of 1 + ab = 0.
POINTS = {"log": [0.3, 1.7, 40.0], "atan": [-3.0, -0.4, 0.0, 0.7, 5.0]}


def _exact(name, a, b):
    with mpmath.workdps(60):
        A, B = mpmath.mpf(a), mpmath.mpf(b)
        if A == B:
            return DERIV[name](A)
        return (MP[name](B) - MP[name](A)) / (B - A)


@pytest.mark.parametrize("name", sorted(f.__name__ for f in DIVIDED_DIFFERENCES if f is not sinc_u))
def test_divided_difference_helpers_accurate_near_and_on_the_diagonal(name):
    """Numerical: relative error ≤ 8 ulp of both flavours at gaps 1e-1 … 1e-15 and 0."""
    hs = special_helpers()
    f, v = hs[f"_f_{name}dd"], hs[f"_v_{name}dd"]
    worst = 0.0
    for a in POINTS.get(name, [-1.3, -0.2, 0.0, 0.45, 2.5]):
        for gap in GAPS:
            for b in (a + gap, a - gap):
                if name == "log" and b <= 0:
                    continue
                want = _exact(name, a, b)
                for got in (f(a, b), float(v(np.array([a]), np.array([b]))[0])):
                    worst = max(worst, abs(got - float(want)) / max(abs(float(want)), 1e-300))
    assert worst < 8 * np.finfo(float).eps, worst


def test_atan_helper_on_both_branches_and_across_the_branch_switch():
    """Numerical: far apart (1 + ab ≤ 0) the quotient branch; the switch 1 + ab = 0 itself."""
    hs = special_helpers()
    worst = 0.0
    for a, b in [(-3.0, 2.0), (2.0, -0.5), (-0.5, 2.0), (4.0, -0.25), (-1e3, 1e3), (1e-3, -1e3), (10.0, -10.0)]:
        want = float(_exact("atan", a, b))
        for got in (hs["_f_atandd"](a, b), float(hs["_v_atandd"](np.array([a]), np.array([b]))[0])):
            worst = max(worst, abs(got - want) / abs(want))
    assert worst < 8 * np.finfo(float).eps


def test_naive_quotient_fails_the_same_accuracy_check():
    """Negative control: the plain quotient loses ~eps/gap, and the check above would see it."""
    a = 0.45
    b = a + 1e-9
    naive = (math.atan(b) - math.atan(a)) / (b - a)
    want = float(_exact("atan", a, b))
    assert abs(naive - want) / want > 1e-9


def test_log_helper_is_nan_outside_the_domain():
    hs = special_helpers()
    for a, b in [(-1.0, -1.2), (-1.0, 0.5), (0.0, 1.0), (0.3, -0.3)]:
        assert math.isnan(hs["_f_logdd"](a, b))
        assert np.isnan(hs["_v_logdd"](np.array([a]), np.array([b]))[0])


@pytest.mark.parametrize("name", ["atanc", "datanc", "datandd"])
def test_new_derivative_helpers_match_mpmath(name):
    """Numerical: the Jacobian helpers of atan (relative 1e-13 incl. the series switch at 1e-2)."""
    hs = special_helpers()
    mpmath.mp.dps = 50
    if name == "datandd":
        pts = [(0.4, 0.4 + g) for g in (1e-1, 1e-3, 1e-8, 0.0)] + [(-3.0, 2.0), (2.0, 2.0)]
        for a, b in pts:
            A, B = mpmath.mpf(a), mpmath.mpf(b)
            want = (-A / (1 + A * A) ** 2 if A == B else
                    (1 / (1 + B * B) - (mpmath.atan(B) - mpmath.atan(A)) / (B - A)) / (B - A))
            for got in (hs["_f_datandd"](a, b), hs["_v_datandd"](np.array([a]), np.array([b]))[0]):
                assert abs(got - float(want)) <= 1e-13 * max(1.0, abs(float(want)))
        return
    fn = {"atanc": lambda x: mpmath.atan(x) / x if x else mpmath.mpf(1),
          "datanc": lambda x: (x / (1 + x * x) - mpmath.atan(x)) / x**2 if x else mpmath.mpf(0)}[name]
    for x in [0.0, 1e-9, 9.99e-3, 1.001e-2, 0.3, -2.0, 40.0]:
        want = float(fn(mpmath.mpf(x)))
        for got in (hs[f"_f_{name}"](x), hs[f"_v_{name}"](np.array([x]))[0]):
            assert abs(got - want) <= 1e-13 * max(1.0, abs(want))


#: The derivative helpers (x g'(x) - g(x))/x² of the g(x)/x helpers, in mpmath, and the
#: threshold below which each sums its Taylor series (templates/_special.py.j2).
DERIVATIVES = {
    "dsinc": (lambda x: (x * mpmath.cos(x) - mpmath.sin(x)) / x**2, 1.0),
    "dsinhc": (lambda x: (x * mpmath.cosh(x) - mpmath.sinh(x)) / x**2, 1.0),
    "datanc": (lambda x: (x / (1 + x * x) - mpmath.atan(x)) / x**2, 0.5),
    "datanhc": (lambda x: (x / (1 - x * x) - mpmath.atanh(x)) / x**2, 0.5),
    "ddsinc": (lambda x: (2 * mpmath.sin(x) - 2 * x * mpmath.cos(x) - x**2 * mpmath.sin(x)) / x**3, 3.0),
}
#: Their exact values at 0.
AT_ZERO = {"ddsinc": -1.0 / 3.0}


def _rel_err(fn, exact, xs):
    worst = 0.0
    for x in xs:
        with mpmath.workdps(60):
            want = float(exact(mpmath.mpf(x))) if x else 0.0
        got = fn(x)
        worst = max(worst, abs(got - want) / max(abs(want), 1e-300))
    return worst


def _switch_points(t):
    """Just below and just above the threshold t (and on it), both signs; plus small and 0."""
    below, above = np.nextafter(t, 0.0), np.nextafter(t, 2 * t)
    pts = [below, t, above, 0.999 * t, 1.001 * t, 1e-2, 1e-5, 1e-9]
    return [float(s * x) for x in pts for s in (1.0, -1.0)]


@pytest.mark.parametrize("name", sorted(DERIVATIVES))
def test_derivative_helpers_accurate_on_both_sides_of_their_series_switch(name):
    """Numerical: relative error ≤ 8 ulp (scalar and vector helper) just below, on and just
    above the series threshold, and down to 1e-9 and 0 (exactly 0 there)."""
    hs = special_helpers()
    exact, t = DERIVATIVES[name]
    xs = _switch_points(t)
    f, v = hs[f"_f_{name}"], hs[f"_v_{name}"]
    zero = AT_ZERO.get(name, 0.0)
    assert f(0.0) == zero and float(v(np.array([0.0]))[0]) == zero
    xs = [x for x in xs if x != 0.0]
    assert _rel_err(f, exact, xs) < 8 * np.finfo(float).eps
    assert _rel_err(lambda x: float(v(np.array([x]))[0]), exact, xs) < 8 * np.finfo(float).eps


@pytest.mark.parametrize("name", sorted(DERIVATIVES))
def test_quotient_below_the_switch_fails_the_same_check(name):
    """Negative control: the quotient branch used below the threshold (the former switch at
    1e-2 moved the switch there) loses ~eps/x² and the check above sees it."""
    hs = special_helpers()
    exact, t = DERIVATIVES[name]
    f = hs[f"_f_{name}"]
    quotient = {"dsinc": lambda x: (x * math.cos(x) - math.sin(x)) / (x * x),
                "dsinhc": lambda x: (x * math.cosh(x) - math.sinh(x)) / (x * x),
                "datanc": lambda x: (x / (1.0 + x * x) - math.atan(x)) / (x * x),
                "datanhc": lambda x: (x / (1.0 - x * x) - math.atanh(x)) / (x * x),
                "ddsinc": lambda x: (2.0 * math.sin(x) - 2.0 * x * math.cos(x)
                                     - x * x * math.sin(x)) / (x * x * x)}[name]
    xs = [1.0001e-2, 2e-2, 5e-2]
    assert _rel_err(quotient, exact, xs) > 100 * np.finfo(float).eps
    assert _rel_err(f, exact, xs) < 8 * np.finfo(float).eps
    # above the threshold the helper *is* the quotient, and that is accurate there
    assert all(f(x) == quotient(x) for x in (np.nextafter(t, 2 * t), 1.5 * t))
    assert _rel_err(quotient, exact, [np.nextafter(t, 2 * t)]) < 8 * np.finfo(float).eps


# --- the exact side: the helper certificates ------------------------------------------

@pytest.mark.parametrize("cls", sorted(set(DIVIDED_DIFFERENCES.values()) - {sinc_dd},
                                       key=lambda c: c.__name__)
                         + [sinc_u, sinhc, atanc], ids=lambda c: c.__name__)
def test_every_helper_is_proved_to_evaluate_its_defining_relation(cls):
    cert = helper_certificate(cls)
    assert cert.status == "proved", (cert.claim, cert.method)


def test_a_wrong_stable_form_is_refuted(monkeypatch):
    """Negative control: exp[a, b] with sinhc(b - a) instead of sinhc((b - a)/2)."""
    monkeypatch.setattr(exp_dd, "stable_form",
                        classmethod(lambda cls, a, b: sp.exp((a + b) / 2) * sinhc(b - a)))
    _certificate.cache_clear()
    try:
        cert = helper_certificate(exp_dd)
        assert cert.status == "refuted" and "counterexample" in cert.details
    finally:
        monkeypatch.undo()
        _certificate.cache_clear()


def test_a_wrong_exp_helper_form_is_not_proved(monkeypatch):
    """Negative control: the overflow-safe form of _expdd with 1 + exp(a - b) is not proved."""
    assert helper_certificate(exp_dd).status == "proved"
    monkeypatch.setattr(exp_dd, "helper_form",
                        classmethod(lambda cls, a, b: sp.exp(b) * (1 + sp.exp(a - b)) / (b - a)))
    _certificate.cache_clear()
    try:
        assert helper_certificate(exp_dd).status != "proved"
    finally:
        monkeypatch.undo()
        _certificate.cache_clear()


def test_a_wrong_atan_branch_is_refuted_inside_its_domain(monkeypatch):
    """Negative control: atanc(t) without the 1/(1+ab) factor."""
    monkeypatch.setattr(atan_dd, "branch_form", classmethod(lambda cls, a, b: atanc((b - a) / (1 + a * b))))
    _certificate.cache_clear()
    try:
        cert = helper_certificate(atan_dd)
        assert cert.status == "refuted"
        pt = cert.details["counterexample"]
        assert 1 + sp.Rational(pt["a"]) * sp.Rational(pt["b"]) > 0   # a point of the branch
    finally:
        monkeypatch.undo()
        _certificate.cache_clear()


def test_a_wrong_log_form_is_not_proved(monkeypatch):
    """Negative control: log[a, b] as atanhc((b-a)/(a+b))/(a+b) (factor 2 missing)."""
    from methodgen.problem.special import atanhc
    monkeypatch.setattr(log_dd, "stable_form",
                        classmethod(lambda cls, a, b: atanhc((b - a) / (a + b)) / (a + b)))
    _certificate.cache_clear()
    try:
        assert helper_certificate(log_dd).status != "proved"
    finally:
        monkeypatch.undo()
        _certificate.cache_clear()


def test_tan_form_proved_algebraically():
    """tan's addition formula is an identity wherever both sides are defined (not only near a)."""
    cert = helper_certificate(tan_dd)
    assert cert.status == "proved" and "derivative" not in cert.method


# --- exp[a, b] far apart: no overflow where the value does not overflow -----------------

#: (a, b) of a thin barrier 10 exp(-(q/0.005)²) (exponents -40000 q²) and its mirror images.
FAR = [(-1600.0, 0.0), (0.0, -1600.0), (-3600.0, -400.0), (-160000.0, -152100.0), (-1000.0, -200.0),
       (-745.0, 700.0), (700.0, -745.0)]


def _exp_dd_exact(a, b):
    with mpmath.workdps(60):
        A, B = mpmath.mpf(a), mpmath.mpf(b)
        return float((mpmath.exp(B) - mpmath.exp(A)) / (B - A)) if A != B else float(mpmath.exp(A))


def _dexp_dd_exact(a, b):
    with mpmath.workdps(80):
        A, B = mpmath.mpf(a), mpmath.mpf(b)
        if A == B:
            return float(mpmath.exp(A) / 2)
        return float((mpmath.exp(B) - (mpmath.exp(B) - mpmath.exp(A)) / (B - A)) / (B - A))


def _close(got, want, ulps=8):
    return abs(got - want) <= ulps * np.finfo(float).eps * abs(want) + 1e-300


def test_exp_divided_difference_far_apart_does_not_overflow():
    """Numerical: exp[a, b] at a thin barrier's exponents (the value 6.25e-4, or an underflow
    to 0) within 8 ulp, scalar and vector, where exp((a+b)/2)·sinh((b-a)/2) is 0·inf."""
    hs = special_helpers()
    for a, b in FAR:
        want = _exp_dd_exact(a, b)
        assert _close(hs["_f_expdd"](a, b), want), (a, b)
        assert _close(float(hs["_v_expdd"](np.array([a]), np.array([b]))[0]), want), (a, b)


def test_the_sinhc_product_overflows_there():
    """Negative control: the former evaluation exp(m)·sinhc(δ) fails on the same points."""
    hs = special_helpers()
    with pytest.raises(OverflowError):
        math.exp(-800.0) * hs["_f_sinhc"](800.0)
    with np.errstate(all="ignore"):
        v = np.exp(np.array([-800.0])) * hs["_v_sinhc"](np.array([800.0]))
    assert not np.isfinite(v[0])
    assert _exp_dd_exact(-1600.0, 0.0) == pytest.approx(6.25e-4, rel=1e-12)


def test_exp_divided_difference_jacobian_helper():
    """Numerical: ∂/∂b exp[a, b] within 16 ulp (64 where the quotient branch cancels
    mildly, |b - a| just above 1) near and far from the diagonal, on both sides of its
    switch |b - a| = 1, and at a thin barrier."""
    hs = special_helpers()
    one_below = float(np.nextafter(1.0, 0.0))
    pts = [(0.3, 0.3), (0.3, 0.3 + 1e-9), (-2.0, -2.0 + one_below), (-2.0, -1.0), (-2.0, -1.0 + 1e-12),
           (1.0, 1.0 - one_below), (1.0, 0.0), (2.5, -4.0), (-4.0, 2.5)] + FAR
    for a, b in pts:
        want = _dexp_dd_exact(a, b)
        ulps = 64 if abs(b - a) >= 1.0 else 16
        assert _close(hs["_f_dexpdd"](a, b), want, ulps), (a, b, hs["_f_dexpdd"](a, b), want)
        assert _close(float(hs["_v_dexpdd"](np.array([a]), np.array([b]))[0]), want, ulps), (a, b)


def test_exp_divided_difference_jacobian_is_its_derivative():
    """Exact: ∂/∂b of exp_dd is dexp_dd, whose defining quotient is the derivative of exp_dd's."""
    a, b = sp.symbols("a b", real=True)
    d = sp.diff(exp_dd(a, b), b)
    assert d == dexp_dd(a, b) and sp.diff(exp_dd(a, b), a) == dexp_dd(b, a)
    assert sp.simplify(d.as_quotient() - sp.diff(exp_dd(a, b).as_quotient(), b)) == 0
