"""Cancelled divided differences: exact identity, exact limit, accuracy near the diagonal."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
import sympy as sp

from helpers import special_helpers
from methodgen.symbolic.divdiff import divided_difference
from methodgen.problem.special import to_elementary

s = sp.Symbol("s", positive=True)
a, b = sp.symbols("a b", positive=True)
k = sp.Symbol("k", positive=True)

FUNCS = [
    -k / sp.sqrt(s),
    s**2 - s,
    s * sp.exp(-s),
    sp.sin(s) ** 2,
    s ** sp.Rational(3, 2),
    s ** sp.Rational(-2, 3),
    sp.tanh(s),
    sp.cosh(s) / (1 + s),
]


@pytest.mark.parametrize("f", FUNCS, ids=str)
def test_identity_and_limit_are_exact(f):
    d = divided_difference(f, s, a, b)
    ident = to_elementary(d) * (b - a) - (f.subs(s, b) - f.subs(s, a))
    assert sp.simplify(ident.rewrite(sp.exp)) == 0
    # The diagonal value is a plain substitution (no 0/0 left) and equals f'.
    assert sp.simplify(d.subs(b, a) - sp.diff(f, s).subs(s, a)) == 0


def test_log_identity():
    d = divided_difference(sp.log(s), s, a, b)
    ident = to_elementary(d) * (b - a) - (sp.log(b) - sp.log(a))
    assert sp.simplify(sp.expand_log(ident.rewrite(sp.log), force=True)) == 0


def _numeric(expr, vals):
    """Evaluate with the printer and the helpers that generated code uses."""
    from methodgen.codegen.lower import VectorPrinter
    fn = sp.lambdify((a, b), expr, modules=[special_helpers(), "numpy"], printer=VectorPrinter)
    return fn(*vals)


@pytest.mark.parametrize("f", [sp.exp(-s) * s, -1 / sp.sqrt(s), sp.sin(s) ** 2], ids=str)
def test_accurate_near_the_diagonal_where_the_naive_quotient_is_not(f):
    """Numerical: relative error vs 50-digit mpmath at gaps 1e-2 … 1e-15."""
    d = divided_difference(f, s, a, b)
    fm = sp.lambdify(s, f, "mpmath")
    mpmath.mp.dps = 50
    x0 = 0.7
    worst_stable, worst_naive = 0.0, 0.0
    for gap in [1e-2, 1e-5, 1e-8, 1e-11, 1e-13, 1e-15]:
        x1 = x0 * (1 + gap)
        exact = (fm(mpmath.mpf(x1)) - fm(mpmath.mpf(x0))) / (mpmath.mpf(x1) - mpmath.mpf(x0))
        stable = float(_numeric(d, (np.float64(x0), np.float64(x1))))
        fn = sp.lambdify(s, f, "numpy")
        naive = (fn(x1) - fn(x0)) / (x1 - x0)
        worst_stable = max(worst_stable, abs(stable - float(exact)) / abs(float(exact)))
        worst_naive = max(worst_naive, abs(naive - float(exact)) / abs(float(exact)))
    assert worst_stable < 1e-14
    # Negative control: the naive quotient loses ~eps/gap and the check sees it.
    assert worst_naive > 1e-3
    # Exactly on the diagonal the stable form is finite and equals f'.
    on = float(_numeric(d, (np.float64(x0), np.float64(x0))))
    assert on == pytest.approx(float(sp.diff(f, s).subs(s, x0)), rel=1e-14)
