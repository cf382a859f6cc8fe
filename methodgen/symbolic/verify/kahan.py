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

from ..derive import gradient, structure_matrix, vector_field
from ..schemes.base import STEP, is_quadratic_field
from .common import REF_KAHAN, at, system_domain
from .exact import Domain, certify
from .report import Certificate

__all__ = ["forms_agree_generic", "forms_agree_user", "modified_energy", "modified_volume", "modified_energy_fast",
           "modified_energy_expr", "modified_energy_structural", "modified_volume_structural"]


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


# --- structural path: a few small polynomial lemmas instead of one rational identity -------
#
# Solving for y1 and expanding H̃(y1) - H̃(y0) in QQ(y0, h) costs minutes already for
# 2 degrees of freedom.  CMOQ's argument needs only polynomial identities, each of
# which is decided by ``expand`` in seconds whatever the dimension.  With
# K(y) = f'(y)/2, A(y) = I - hK(y), J canonical and g̃ the polarised gradient
#
#     g̃(x, y) = 2∇H((x+y)/2) - (∇H(x) + ∇H(y))/2,
#
# the lemmas are
#   L0  f ≡ J∇H                                     (the field is Hamiltonian)
#   L1  K J + J Kᵀ ≡ 0                              (so (I+hK)J = J(I-hK)ᵀ)
#   L2  A(y0)Δ - h f(y0) ≡ Δ - h J g̃(y0, y0+Δ)       (Kahan's step = its symmetric form)
#   L3  (I + hK(y1))Δ - h f(y1) ≡ Δ - h J g̃(y0, y1)  (... = the adjoint step from y1)
#   L4  H(y1) - H(y0) ≡ (∇H(y0) + ∇H(y1) + g̃(y0, y1))ᵀΔ / 3  (Simpson's rule, cubic H)
#   L5  Jᵀ = -J                                     (so g̃ᵀJg̃ = 0)
#   L6  J ∂g̃/∂y1 (y0, y1) ≡ K(y0),  J ∂g̃/∂y0 (y0, y1) ≡ K(y1)
# (Δ = y1 - y0 throughout).  Energy: by L1, P = (I-hK)(I+hK) satisfies PJ = JPᵀ, so
# P⁻¹J is skew and H̃ is even in h: H̃_h - H̃_-h = (2h/3)∇Hᵀ P⁻¹ J ∇H = 0 (L0).  Hence
# H̃(y1) = H(y1) - ∇H(y1)ᵀ h(I+hK(y1))⁻¹ f(y1)/3 = H(y1) - ∇H(y1)ᵀΔ/3 by L3 and L2,
# H̃(y0) = H(y0) + ∇H(y0)ᵀΔ/3, and by L4, L2, L5 the difference is g̃ᵀΔ/3 = h g̃ᵀJg̃/3 = 0.
# Volume: differentiating Δ = hJg̃(y0, y1) with L6 gives (I - hK(y0)) ∂y1/∂y0 =
# I + hK(y1), and det(I + hK) = det(J(I - hK)ᵀJ⁻¹) = det A by L1.  Every step holds
# wherever the step is defined (I ± hK invertible at y0 and y1).

def _zero(M) -> bool:
    return all(sp.expand(e) == 0 for e in (M if isinstance(M, (list, tuple)) else list(M)))


def _lemmas(system, which: tuple[str, ...], theta=sp.Rational(1, 2)) -> dict[str, bool]:
    """Decide the named lemmas L0..L6 (see above) by ``expand``; {name: holds}.

    ``theta`` is the coefficient of ``A = I - θh f'``: Kahan's is 1/2; any other
    value is a different (non-symmetric) linearly implicit scheme, for which L2
    must fail — the negative control of the tests.
    """
    y = list(system.y)
    n, h = len(y), STEP
    Y = sp.Matrix(y)
    # J canonical; for a Poisson system its structure matrix S (the lemmas then hold only
    # for a constant S: methodgen.symbolic.verify.poisson.kahan_conditions)
    J = structure_matrix(system)
    f = vector_field(system)
    grad = gradient(system)
    K = f.jacobian(Y) / 2
    D = sp.symbols(f"_kD1:{n + 1}", real=True)
    Dv = sp.Matrix(D)
    X = sp.symbols(f"_kX1:{n + 1}", real=True)       # y1 as independent symbols (L4, L6)
    at_ = lambda e, pt: e.xreplace(dict(zip(y, pt)))

    def gt(a, b):
        mid = [(u + v) / 2 for u, v in zip(a, b)]
        return 2 * at_(grad, mid) - (at_(grad, a) + at_(grad, b)) / 2

    y1 = [u + d for u, d in zip(y, D)]
    out = {}
    for name in which:
        if name == "L0":
            out[name] = _zero(f - J * grad)
        elif name == "L1":
            out[name] = _zero(K * J + J * K.T)
        elif name == "L2":
            A = sp.eye(n) - 2 * theta * h * K
            out[name] = _zero(A * Dv - h * f - (Dv - h * J * gt(y, y1)))
        elif name == "L3":
            B = sp.eye(n) + h * at_(K, y1)
            out[name] = _zero(B * Dv - h * at_(f, y1) - (Dv - h * J * gt(y, y1)))
        elif name == "L4":
            g0, g1, g = grad, at_(grad, X), gt(y, X)
            dX = sp.Matrix([b - a for a, b in zip(y, X)])
            out[name] = _zero([at_(system.H, X) - system.H - ((g0 + g1 + g).T * dX)[0, 0] / 3])
        elif name == "L5":
            out[name] = J.T == -J
        elif name == "L6":
            g = gt(y, X)
            ok1 = _zero(J * g.jacobian(sp.Matrix(X)) - K)
            ok0 = _zero(J * g.jacobian(Y) - at_(K, X))
            out[name] = ok1 and ok0
        else:
            raise ValueError(name)
    return out


_ENERGY_LEMMAS = ("L0", "L1", "L2", "L3", "L4", "L5")
_VOLUME_LEMMAS = ("L0", "L1", "L2", "L6")
_LEMMA_TEXT = {
    "L0": "f ≡ J∇H",
    "L1": "KJ + JKᵀ ≡ 0 (K = f'/2)",
    "L2": "A(y0)Δ - h f(y0) ≡ Δ - hJg̃(y0, y1)",
    "L3": "(I + hK(y1))Δ - h f(y1) ≡ Δ - hJg̃(y0, y1)",
    "L4": "H(y1) - H(y0) ≡ (∇H(y0) + ∇H(y1) + g̃)ᵀΔ/3",
    "L5": "Jᵀ = -J",
    "L6": "J∂g̃/∂y1 ≡ K(y0), J∂g̃/∂y0 ≡ K(y1)",
}


def _structural(system, which, claim, expression, argument, details, theta) -> Certificate | None:
    import time
    t0 = time.perf_counter()
    if not is_quadratic_field(system):
        return None
    held = _lemmas(system, which, theta)
    if not all(held.values()):
        return None   # not this structure: the caller reduces the whole identity instead
    method = (f"structural (CMOQ 2013): polynomial lemmas {'; '.join(f'{k}: {_LEMMA_TEXT[k]}' for k in which)} "
              f"reduced to 0 by expand, with g̃(x, y) = 2∇H((x+y)/2) - (∇H(x)+∇H(y))/2, Δ = y1 - y0; "
              f"{argument}")
    return Certificate(claim, "proved", expression, "", method, time.perf_counter() - t0, REF_KAHAN,
                       {"structural": True, "lemmas": list(which), **details})


def modified_energy_structural(system, theta=sp.Rational(1, 2)) -> Certificate | None:
    """``H̃(y1) = H̃(y0)`` from lemmas L0–L5 (any dimension); None if a lemma fails.

    ``theta``: see :func:`_lemmas` (1/2 is Kahan's method; other values are negative controls).
    """
    details = {"modified_energy": "H + h/3 * grad(H)^T (I - h/2 f'(y))^-1 f(y)",
               "modified_energy_latex": r"H + \tfrac{h}{3}\nabla H^\top (I - \tfrac{h}{2} f')^{-1} f"}
    if len(system.y) <= 2:   # one degree of freedom: the closed form is small enough to show
        Ht = modified_energy_expr(system)
        details = {"modified_energy": sp.sstr(Ht), "modified_energy_latex": sp.latex(Ht)}
    return _structural(
        system, _ENERGY_LEMMAS,
        "Kahan preserves the modified energy H̃ = H + h/3 ∇H(y)ᵀ (I - h/2 f'(y))⁻¹ f(y)",
        "Ht(y1) - Ht(y0), y1 = y0 + h (I - h/2 f'(y0))^-1 f(y0)",
        "H̃ is even in h (L0, L1: (I-hK)⁻¹ + (I+hK)⁻¹ = 2P⁻¹, P⁻¹J skew), so H̃(y1) = H(y1) - ∇H(y1)ᵀΔ/3 "
        "(L2, L3) and H̃(y0) = H(y0) + ∇H(y0)ᵀΔ/3; the difference is g̃ᵀΔ/3 = h g̃ᵀJg̃/3 = 0 (L4, L2, L5)",
        details, theta)


def modified_volume_structural(system, theta=sp.Rational(1, 2)) -> Certificate | None:
    """``det(∂y1/∂y0) det A(y0) = det A(y1)`` from lemmas L0, L1, L2, L6; None if one fails."""
    return _structural(
        system, _VOLUME_LEMMAS,
        "Kahan preserves the volume form dy / det(I - h/2 f'(y)): det(∂y1/∂y0) det A(y0) = det A(y1)",
        "det(dy1/dy0) det A(y0) - det A(y1)",
        "differentiating Δ = hJg̃(y0, y1) (L2) with L6: (I - hK(y0)) ∂y1/∂y0 = I + hK(y1), and "
        "det(I + hK) = det(J(I - hK)ᵀJ⁻¹) = det A (L1)",
        {"density": "1/det(I - h/2 f'(y))"}, theta)
