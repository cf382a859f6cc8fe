"""Energy-preserving collocation ("AVF collocation", Hairer 2010) with ``s`` Gauss nodes.

The step is the polynomial ``u`` of degree s with ``u(0) = y0`` and

    u'(τh) = Σ_j ℓ_j(τ) F_j,      F_j = (1/b_j) ∫_0^1 ℓ_j(σ) f(u(σh)) dσ,      y1 = u(h),

where ``ℓ_j`` are the Lagrange polynomials of the Gauss nodes c_1..c_s and
``b_j = ∫_0^1 ℓ_j``.  With the unknowns ``Z_j = h F_j`` (small, like every
unknown here) and ``Λ_j(τ) = ∫_0^τ ℓ_j``:

    u(σ) = y0 + Σ_k Λ_k(σ) Z_k,    R_j = Z_j − (h/b_j) ∫_0^1 ℓ_j(σ) f(u(σ)) dσ = 0,    Δy = Σ_j b_j Z_j.

Energy is preserved for *any* polynomials ℓ_j, because ``f = J∇H``:
``H(y1) − H(y0) = ∫_0^1 ∇H(u)ᵀ u' dσ = Σ_j Z_jᵀ ∫ℓ_j ∇H(u) = −Σ_j (b_j/h) Z_jᵀ J Z_j = 0``
(J skew).  The Gauss nodes give order 2s [Hai10, Thm 1]; s = 1 is the AVF method.
The method is symmetric, not symplectic (for s ≥ 1 it is conjugate-symplectic
only up to high order), and keeps H and — for s = 1 … any — no other invariant in
general [Hai10; CMO09 for s = 1].

When H is a polynomial the integrals are computed *exactly* (the integrand is
a polynomial in σ), so H is preserved exactly, and ``verify`` proves it.
Otherwise the integrals use Gauss–Legendre quadrature with ``2s + 2`` nodes:
H is then kept only to the quadrature error (``Traits.approximate``, numerical
certificates).  Nodes: exact radicals for s ≤ 3; for s ≥ 4 the exact roots
rounded to float64 and used as exact binary rationals — energy stays exact
(it does not depend on the nodes), the order conditions hold to ~1e-16.

References
----------
.. [Hai10] E. Hairer, Energy-preserving variant of collocation methods, JNAIAM 5 (2010) 73–84.
.. [CMO09] E. Celledoni, R. I. McLachlan, D. I. McLaren, B. Owren, G. R. W. Quispel,
   W. M. Wright, Energy-preserving Runge–Kutta methods, M2AN 43 (2009) 645–649.
"""

from __future__ import annotations

from functools import lru_cache

import sympy as sp

from ..derive import invariants, vector_field
from ..errors import InputError
from ..problem import Hamiltonian
from .base import STEP, Scheme, Traits

NAME = "energy-collocation"
SUMMARY = ("energy-preserving (AVF) collocation, stages=s at Gauss nodes (symmetric, order 2s, "
           "exact H for polynomial H; s = 1..4)")
STAGES = (1, 2, 3, 4)
DEFAULT_STAGES = 2
SIGMA = sp.Symbol("_sigma", real=True)


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "energy-preserving collocation does not enforce constraints; use rattle or shake"
    return None


@lru_cache(maxsize=None)
def basis(s: int):
    """Nodes c (exact), Lagrange polynomials ℓ_j(σ), Λ_j(σ) = ∫_0^σ ℓ_j and b_j = ∫_0^1 ℓ_j (exact)."""
    from .gauss import legendre

    if isinstance(s, bool) or not isinstance(s, int) or s not in STAGES:
        raise InputError(f"stages must be one of {', '.join(map(str, STAGES))}, got {s!r}")
    roots = sorted(legendre(s).all_roots(), key=lambda r: float(sp.N(r, 30)))
    if any(isinstance(r, sp.CRootOf) for r in roots):
        # exact binary rationals of the float64 roots (energy does not depend on the nodes)
        roots = [sp.Rational(float(sp.N(r, 30))) for r in roots]
    c = [sp.radsimp(r) for r in roots]
    ell, Lam, b = [], [], []
    for j in range(s):
        lj = sp.Integer(1)
        for k in range(s):
            if k != j:
                lj *= (SIGMA - c[k]) / (c[j] - c[k])
        lj = sp.expand(lj)
        ell.append(lj)
        Lam.append(sp.expand(sp.integrate(lj, (SIGMA, 0, SIGMA))))
        b.append(sp.nsimplify(sp.integrate(lj, (SIGMA, 0, 1))) if s <= 3 else sp.integrate(lj, (SIGMA, 0, 1)))
    return tuple(c), tuple(ell), tuple(Lam), tuple(b)


def _integrate01(expr: sp.Expr) -> sp.Expr:
    """``∫_0^1 expr dσ`` for an expression polynomial in σ: ``Σ_k a_k / (k + 1)`` (exact; much
    faster than ``sympy.integrate`` on large coefficients)."""
    poly = sp.Poly(sp.expand(expr), SIGMA)
    return sp.Add(*[coeff / (k + 1) for (k,), coeff in poly.terms()])


def _is_polynomial(system: Hamiltonian) -> bool:
    return all(fi.is_polynomial(*system.y) for fi in vector_field(system))


def _quadrature(m: int):
    """Gauss–Legendre nodes and weights on [0, 1], float64-rounded as SymPy Floats."""
    x = sp.Symbol("x")
    P = sp.Poly(sp.legendre(m, 2 * x - 1), x)
    nodes = sorted((float(sp.N(r, 30)) for r in P.all_roots()))
    out = []
    for cx in nodes:
        # w_i = ∫_0^1 ℓ_i, by the standard formula 1 / ((1 - t²) P_m'(t)²) on [-1, 1], halved
        t = 2 * cx - 1
        dP = float(sp.diff(sp.legendre(m, x), x).subs(x, t))
        out.append((sp.Float(cx, 17), sp.Float(1.0 / ((1 - t * t) * dP * dP), 17)))
    return out


def build(system: Hamiltonian, stages: int = DEFAULT_STAGES) -> Scheme:
    c, ell, Lam, b = basis(stages)
    n = 2 * system.dim
    h = STEP
    f = vector_field(system)
    y0 = list(system.y)
    Z = [[sp.Symbol(f"_z{j + 1}_{v.name}", real=True) for v in y0] for j in range(stages)]
    u = {v: v + sp.Add(*[Lam[k] * Z[k][i] for k in range(stages)]) for i, v in enumerate(y0)}
    exact = _is_polynomial(system)
    if exact:
        fu = [sp.expand(fi.xreplace(u)) for fi in f]
        integral = [[_integrate01(ell[j] * fi) for fi in fu] for j in range(stages)]
        how = "exact integrals (H is a polynomial)"
    else:
        quad = _quadrature(2 * stages + 2)
        integral = [[sp.Add(*[w * ell[j].subs(SIGMA, x) * fi.xreplace({v: e.subs(SIGMA, x) for v, e in u.items()})
                              for x, w in quad]) for fi in f] for j in range(stages)]
        how = f"{2 * stages + 2}-node Gauss–Legendre quadrature (H not a polynomial: H kept to the quadrature error)"
    residual = sp.Matrix([Z[j][i] - h / b[j] * integral[j][i] for j in range(stages) for i in range(n)])
    increment = sp.Matrix([sp.Add(*[b[j] * Z[j][i] for j in range(stages)]) for i in range(n)])
    guess = sp.Matrix([h * b[j] * f[i] for j in range(stages) for i in range(n)])   # F_j ≈ f(y0)
    traits = Traits(order=2 * stages, symmetric=True, symplectic=False, energy_preserving=exact,
                    preserved=("H",) if exact else (), solve="newton",
                    approximate=() if exact else ("H",),
                    notes=(f"{stages}-stage energy-preserving collocation at Gauss nodes; {how}",))
    return Scheme(system=system, method=NAME, traits=traits,
                  unknowns=tuple(z for row in Z for z in row), residual=residual, guess=guess,
                  increment=increment, invariants=invariants(system),
                  description=(f"energy-preserving collocation, s = {stages}: u(σ) = y0 + Σ Λ_k(σ) Z_k, "
                               "Z_j = (h/b_j) ∫ ℓ_j f(u), y1 = y0 + Σ b_j Z_j"),
                  resolution=None, fixed_point=True,
                  options=(() if stages == DEFAULT_STAGES else (("stages", stages),)),
                  structure={"kind": "energy-collocation", "stages": stages, "exact": exact,
                             "ell": ell, "Lam": Lam, "b": b, "sigma": SIGMA, "Z": Z})
