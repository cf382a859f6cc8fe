"""Claim 6: Kahan's method for quadratic vector fields (cubic H).

* The one-step (RK) form ``Δ = 2h f(y0 + Δ/2) - h/2 (f(y0) + f(y0 + Δ))`` and the
  Jacobian form ``(I - h/2 f'(y0)) Δ = h f(y0)`` are the same polynomial
  equation in Δ: ``R_RK(Δ) - (AΔ - b)`` expands to 0, for a quadratic f with
  generic (symbolic) coefficients in dimension n and for the user's f.
* Modified energy and volume form [CMOQ 2013, Prop. 2 and 3]: with
  ``A(y) = I - h/2 f'(y)`` and ``f = J∇H`` quadratic,

      H̃(y) = H(y) + h/3 ∇H(y)ᵀ A(y)⁻¹ f(y)       is preserved, and
      dy / det A(y)                              is preserved,
  i.e. ``det(∂y1/∂y0) = det A(y1) / det A(y0)``.  Both are rational identities
  in (y0, h) once ``y1 = y0 + h A(y0)⁻¹ f(y0)`` is written out; they are
  reduced with ``cancel``.
"""

from __future__ import annotations

import itertools

import sympy as sp

from ..derive import gradient, vector_field
from ..schemes.base import STEP
from .common import REF_KAHAN, at, system_domain
from .exact import Domain, certify
from .report import Certificate

__all__ = ["forms_agree_generic", "forms_agree_user", "modified_energy", "modified_volume", "modified_energy_fast",
           "modified_energy_expr"]


def _forms_difference(f: sp.Matrix, y, h) -> sp.Matrix:
    n = len(y)
    D = sp.symbols(f"D1:{n + 1}", real=True)
    Dv = sp.Matrix(D)
    shift = lambda c: {a: a + c * d for a, d in zip(y, D)}
    rk = Dv - 2 * h * f.xreplace(shift(sp.Rational(1, 2))) + h / 2 * (f + f.xreplace(shift(1)))
    A = sp.eye(n) - h / 2 * f.jacobian(sp.Matrix(y))
    return rk - (A * Dv - h * f)


def forms_agree_generic(n: int) -> Certificate:
    """RK form ≡ Jacobian form for a quadratic f with symbolic coefficients, dimension n."""
    y = sp.symbols(f"y1:{n + 1}", real=True)
    h = sp.Symbol("h", real=True)
    f = []
    for i in range(n):
        terms = [sp.Symbol(f"a{i + 1}")] + [sp.Symbol(f"b{i + 1}_{j + 1}") * y[j] for j in range(n)]
        terms += [sp.Symbol(f"c{i + 1}_{j + 1}{k + 1}") * y[j] * y[k]
                  for j, k in itertools.combinations_with_replacement(range(n), 2)]
        f.append(sp.Add(*terms))
    return certify(f"Kahan: one-step RK form and Jacobian form (I - h/2 f'(y0))Δ = h f(y0) are the "
                   f"same equation for every quadratic f (generic coefficients, n = {n})",
                   _forms_difference(sp.Matrix(f), y, h), Domain(), REF_KAHAN)


def forms_agree_user(system) -> Certificate:
    """RK form ≡ Jacobian form for the user's f = J∇H."""
    return certify("Kahan: RK form and Jacobian form agree for this f = J∇H",
                   _forms_difference(vector_field(system), system.y, STEP),
                   system_domain(system), REF_KAHAN)


def _kahan_step(system):
    y = sp.Matrix(system.y)
    f = vector_field(system)
    A = sp.eye(len(y)) - STEP / 2 * f.jacobian(y)
    y1 = y + STEP * A.LUsolve(f)
    return [sp.cancel(v) for v in y1], A


def modified_energy_expr(system) -> sp.Expr:
    """``H̃(y) = H + h/3 ∇Hᵀ (I - h/2 f')⁻¹ f`` (CMOQ 2013)."""
    y = sp.Matrix(system.y)
    f = vector_field(system)
    A = sp.eye(len(y)) - STEP / 2 * f.jacobian(y)
    return system.H + STEP / 3 * (gradient(system).T * A.LUsolve(f))[0, 0]


def modified_energy(system, Ht: sp.Expr | None = None) -> Certificate:
    """``H̃(y1) - H̃(y0)`` with y1 from the Jacobian form, reduced with cancel."""
    Ht = modified_energy_expr(system) if Ht is None else Ht
    y1, _ = _kahan_step(system)
    expr = at(Ht, system.y, y1) - Ht
    return certify(f"Kahan preserves the modified energy H̃ = {sp.sstr(sp.factor(Ht))}",
                   expr, system_domain(system), REF_KAHAN, shown=sp.Eq(sp.Symbol("Ht"), Ht),
                   details={"modified_energy": sp.sstr(Ht), "modified_energy_latex": sp.latex(Ht)})


def modified_volume(system) -> Certificate:
    """``det(∂y1/∂y0) = det A(y1) / det A(y0)``: the measure dy/det A(y) is preserved."""
    y1, A = _kahan_step(system)
    y = sp.Matrix(system.y)
    P = sp.Matrix(y1).jacobian(y)
    detA = A.det()
    expr = P.det() * detA - at(detA, system.y, y1)
    return certify("Kahan preserves the volume form dy / det(I - h/2 f'(y)): "
                   "det(∂y1/∂y0) det A(y0) = det A(y1)", expr, system_domain(system), REF_KAHAN,
                   details={"density": f"1/({sp.sstr(sp.factor(detA))})"})


# --- fast exact path: arithmetic in the rational-function field QQ(y, h, params) ---------

def _field_eval(expr, y, vals, K):
    """A polynomial in y (coefficients in h, params) evaluated at field elements ``vals``."""
    poly = sp.Poly(expr, *y)
    out = K.zero
    for monom, coeff in poly.terms():
        term = K.from_sympy(coeff)
        for v, e in zip(vals, monom):
            if e:
                term = term * v**e
        out = out + term
    return out


def _field_solve(A_rows, b, K):
    from sympy.polys.matrices import DomainMatrix
    n = len(b)
    A = DomainMatrix([list(r) for r in A_rows], (n, n), K)
    B = DomainMatrix([[v] for v in b], (n, 1), K)
    x = A.lu_solve(B)
    return [x[i, 0].element for i in range(n)]


def modified_energy_fast(system) -> Certificate | None:
    """``H̃(y1) = H̃(y0)`` decided by exact arithmetic in QQ(y0, h, params); None if not applicable."""
    import time
    t0 = time.perf_counter()
    y = list(system.y)
    h = STEP
    f = vector_field(system)
    if system.H.has(sp.Float):
        return None
    fp = f.jacobian(sp.Matrix(y))
    grad = gradient(system)
    gens = y + [h] + list(system.params)
    K = sp.QQ.frac_field(*gens)
    n = len(y)

    def Ht(vals):
        A = [[_field_eval((1 if i == j else 0) - h / 2 * fp[i, j], y, vals, K) for j in range(n)]
             for i in range(n)]
        fv = [_field_eval(fi, y, vals, K) for fi in f]
        x = _field_solve(A, fv, K)
        gv = [_field_eval(g, y, vals, K) for g in grad]
        return _field_eval(system.H, y, vals, K) + K.from_sympy(h / 3) * sum(
            (a * b for a, b in zip(gv, x)), K.zero), x

    y0 = [K.from_sympy(s) for s in y]
    H0, x0 = Ht(y0)
    y1 = [a + K.from_sympy(h) * b for a, b in zip(y0, x0)]
    H1, _ = Ht(y1)
    if not K.is_zero(H1 - H0):
        return None  # let the slow path find and report the counterexample
    Hexpr = modified_energy_expr(system)
    return Certificate(f"Kahan preserves the modified energy H̃ = {sp.sstr(sp.factor(Hexpr))}",
                       "proved", "Ht(y1) - Ht(y0), y1 = y0 + h (I - h/2 f'(y0))^-1 f(y0)",
                       r"\tilde H(y_1) - \tilde H(y_0)",
                       "exact rational-function arithmetic in QQ(y0, h, params) (cancel-free)",
                       time.perf_counter() - t0, REF_KAHAN,
                       {"modified_energy": sp.sstr(Hexpr), "modified_energy_latex": sp.latex(Hexpr)})
