"""Claim 5 (Exercise 2.1): the trapezoidal rule is conjugate to the midpoint rule.

With ``E_a(y) = y + a f(y)`` (explicit Euler), ``I_a`` (implicit Euler), the
midpoint rule is ``M_h = E_{h/2} ∘ I_{h/2}`` and the trapezoidal rule
``T_h = I_{h/2} ∘ E_{h/2}``, hence

    E_{h/2} ∘ T_h = M_h ∘ E_{h/2},      i.e.  T_h = E_{h/2}⁻¹ ∘ M_h ∘ E_{h/2}.

Proof by substitution, never by solving: let (y0, y1) satisfy the trapezoidal
equation, with ``F0 = f(y0)`` and ``F1 = f(y1)`` kept as unknown values, so
``y1 = y0 + h/2 (F0 + F1)``.  Put ``Y0 = E_a(y0)``, ``Y1 = E_a(y1)``.  The
argument of f in the midpoint equation, ``(Y0 + Y1)/2``, reduces to ``y1``
exactly, so ``f((Y0 + Y1)/2) = F1``, and the midpoint residual
``Y1 - Y0 - h F1`` reduces to 0.  f is a tuple of *undefined* functions of n
variables, so this holds for every vector field in dimension n.

For a wrong map (another ``a``), ``f((Y0 + Y1)/2)`` is f at a third point,
whose value is independent of F0 and F1 (f is arbitrary): it is given its own
symbol and the residual is refuted at a rational point.
"""

from __future__ import annotations

import time

import sympy as sp

from .common import REF_NOTES
from .exact import Domain, certify
from .report import Certificate

__all__ = ["conjugacy_certificate"]


def conjugacy_certificate(n: int, a=sp.Rational(1, 2)) -> Certificate:
    """Check ``E_{a h} ∘ T_h = M_h ∘ E_{a h}`` for an arbitrary f in dimension ``n``.

    Parameters
    ----------
    n : int
        Dimension of the phase space (>= 1).
    a : Rational
        Fraction of the step in the conjugating Euler map; 1/2 is the true one.
    """
    if n < 1:
        raise ValueError("dimension must be >= 1")
    t0 = time.perf_counter()
    a = sp.nsimplify(a)
    h = sp.Symbol("h", real=True)
    y0 = sp.symbols(f"y1:{n + 1}", real=True)
    F0 = sp.symbols(f"F0_1:{n + 1}", real=True)   # f(y0)
    F1 = sp.symbols(f"F1_1:{n + 1}", real=True)   # f(y1)
    f = [sp.Function(f"f{i + 1}") for i in range(n)]
    y1 = [sp.expand(y0[i] + h / 2 * (F0[i] + F1[i])) for i in range(n)]   # trapezoidal equation
    Y0 = [y0[i] + a * h * F0[i] for i in range(n)]
    Y1 = [y1[i] + a * h * F1[i] for i in range(n)]
    arg = tuple(sp.expand((u + v) / 2) for u, v in zip(Y0, Y1))
    at_y1 = {fi(*y1): F1[i] for i, fi in enumerate(f)}
    at_y0 = {fi(*y0): F0[i] for i, fi in enumerate(f)}
    fm = [fi(*arg) for fi in f]
    fm = [v.xreplace(at_y1).xreplace(at_y0) for v in fm]
    residual = sp.Matrix([Y1[i] - Y0[i] - h * fm[i] for i in range(n)])
    # f at any other point is an independent unknown value (f is arbitrary).
    others = {v: sp.Symbol(f"f{i + 1}_at_(Y0+Y1)/2", real=True)
              for i, v in enumerate(fm) if isinstance(v, sp.core.function.AppliedUndef)}
    expr = residual.xreplace(others)
    cert = certify(f"Ex. 2.1 (n = {n}, f arbitrary): with E(y) = y + {a}·h f(y), "
                   f"E ∘ T_h = M_h ∘ E, i.e. T_h = E⁻¹ ∘ M_h ∘ E"
                   + ("" if a == sp.Rational(1, 2) else " [deliberately wrong map]"),
                   expr, Domain(), f"{REF_NOTES}, Ex. 2.1",
                   details={"substitution": "trapezoidal equation y1 = y0 + h/2 (f(y0) + f(y1)); "
                                            "f(y0), f(y1) kept as unknowns F0, F1",
                            "f evaluated only at y0 and y1": not others})
    cert.method = "substitution of the trapezoidal equation + " + cert.method
    cert.seconds = time.perf_counter() - t0
    return cert
