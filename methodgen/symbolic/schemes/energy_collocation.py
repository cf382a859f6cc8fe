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

When H is a polynomial, f(u(σ)) is a polynomial in σ of known degree and the
integrals use a Gauss–Legendre rule with just enough nodes to be *exact* for it
(m = ⌈((D + 1)s)/2⌉, D the degree of f): H is preserved exactly by the method
(round-off in the module), and ``verify`` proves it from exact lemmas.  (Symbolic
σ-integration gives the same equations but is ~40x slower to derive on an 8-DOF
FPU chain and 2.5x larger to emit.)  Otherwise the integrals use ``2s + 2`` nodes:
H is then kept only to the quadrature error (``Traits.approximate``, numerical
certificates).  Nodes of the collocation polynomial: exact radicals for s ≤ 3;
for s = 4 the exact roots rounded to float64 and used as exact binary rationals —
energy does not depend on them, the order conditions hold to ~1e-16.  The quadrature
rule (:mod:`methodgen.symbolic.schemes.quadrature`, at most 128 nodes) and the tables
``Λ_i(x_k)``, ``w_k ℓ_j(x_k)``, ``1/b_j``, ``b_j`` are computed at 60 digits and
rounded to float64 once (:func:`coefficient_tables`); ``verify`` certifies those
floats, not only the ideal rule.  The tables keep the symmetry relations of the method
exactly (mirror entries defined from their partners) and the stage sums are evaluated in a
fixed order, so the float64 step stays symmetric: H shows no linear drift in long runs
(:data:`MEASURED_DRIFT`; rounded entry by entry it drifted ~1e-19 per step).

References
----------
.. [Hai10] E. Hairer, Energy-preserving variant of collocation methods, JNAIAM 5 (2010) 73–84.
.. [CMO09] E. Celledoni, R. I. McLachlan, D. I. McLaren, B. Owren, G. R. W. Quispel,
   W. M. Wright, Energy-preserving Runge–Kutta methods, M2AN 43 (2009) 645–649.
"""

from __future__ import annotations

from functools import lru_cache

import sympy as sp

from ..compensate import grouped
from ..derive import invariants, vector_field
from ...errors import InputError
from ...problem.problem import Hamiltonian
from ..stages import StageSystem
from .base import STEP, Scheme, Traits
from .gauss import _f64
from .quadrature import DPS, MAX_NODES, gauss_legendre, gauss_legendre_f64

#: Measured float64 drift of H per step (slope of the mean of H − H0 over 64 phases of
#: p²/2 + q²/2 + q⁴/4 on |y0| = 1, h = 0.1, 20000 steps, numpy backend, default solver;
#: AVF on the same run: 1.3e-20, i.e. none).  s = 2, 3, 4: none, after the consistent
#: rounding and the fixed evaluation order below; before, s = 2 drifted 1.5e-19 per step
#: and s = 3 8.9e-19.  s = 1 still drifts (1.4e-19; compensated stage sums did not change
#: it) -- the `avf` method is the same method without that drift.  Measured figures
#: (tests/test_energy_collocation.py checks s = 2), not computed here.  Remeasured with the
#: stage loops (methodgen.symbolic.stages; the expanded stage system on the same run: 1.5e-21, 3.5e-21,
#: 1.1e-20 -- the same order, i.e. no drift either way).
MEASURED_DRIFT = {1: 1.4e-19, 2: 7.3e-21, 3: -5.4e-21, 4: 1.4e-20}
_DRIFTS = (1,)   # the stage counts whose module still drifts


def drift_note(stages: int) -> str:
    """What was measured of H's float64 drift, as stated wherever exact H is claimed."""
    d = MEASURED_DRIFT[stages]
    where = "p²/2 + q²/2 + q⁴/4, h = 0.1, mean over 64 phases"
    if stages in _DRIFTS:
        return (f"in float64 H drifts linearly: {d:.1e} per step measured ({where}); "
                "the avf method does not")
    return f"in float64 no linear drift of H measured (slope {d:.1e} per step, {where})"


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
        # exact binary rationals of the float64 roots (energy does not depend on the nodes),
        # the upper half as 1 − the lower: symmetric nodes, so the method stays symmetric
        low = [sp.Rational(float(sp.N(r, 30))) for r in roots[: s // 2]]
        mid = [sp.Rational(1, 2)] if s % 2 else []
        roots = low + mid + [1 - r for r in reversed(low)]
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


def quadrature(m: int) -> tuple:
    """The m-node Gauss–Legendre rule on [0, 1]: ``((x_k, w_k), …)`` as 60-digit mpmath numbers
    (:func:`methodgen.symbolic.schemes.quadrature.gauss_legendre`)."""
    return gauss_legendre(m)


@lru_cache(maxsize=None)
def _mp_coefficients(expr) -> tuple:
    """Coefficients of a polynomial in σ (highest first) as 60-digit mpmath numbers."""
    import mpmath as mp

    with mp.workdps(DPS):
        return tuple(mp.mpf(str(sp.N(c, DPS + 10))) for c in sp.Poly(expr, SIGMA).all_coeffs())


def _at(expr, x):
    """The polynomial ``expr`` in σ at the mpmath number x (Horner, 60 digits)."""
    import mpmath as mp

    with mp.workdps(DPS):
        return mp.polyval(list(_mp_coefficients(expr)), x)


def _snap(v) -> float:
    """``float(v)``, with the 60-digit round-off of an exact zero (|v| < 1e-50: ℓ_j(x_k) = 0
    when a quadrature node is a collocation node) written as 0, not as 1e-62."""
    return 0.0 if abs(v) < 1e-50 else float(v)


def coefficient_tables(stages: int, m: int, consistent: bool = True) -> dict:
    """The numbers the module uses, each computed at 60 digits and rounded to float64 once.

    Returns
    -------
    dict
        ``nodes``, ``weights``: the m-node rule (floats); ``path[k][i] = Λ_i(x_k)`` (the
        stage points ``u(x_k) = y0 + Σ_i Λ_i(x_k) Z_i``); ``quad[j][k] = w_k ℓ_j(x_k)``;
        ``inv_b[j] = 1/b_j`` and ``b[j]`` -- all float.
    consistent : bool
        Round the mirror entries so the symmetry relations hold exactly (default);
        False rounds every entry on its own (the negative control: H drifts).
    """
    c, ell, Lam, b = basis(stages)
    rule = quadrature(m)
    nodes, weights = gauss_legendre_f64(m)
    s, m = stages, len(rule)
    # The method is symmetric because its nodes are: x_(m+1-k) = 1 − x_k, ℓ_j(1 − σ) =
    # ℓ_(s+1-j)(σ), so  b_j = b_(s+1-j),  w_k ℓ_j(x_k) = w_(m+1-k) ℓ_(s+1-j)(x_(m+1-k))  and
    # Λ_i(x_(m+1-k)) = b_i − Λ_(s+1-i)(x_k).  Rounded one by one, the floats break these
    # relations by an ulp; the step is then not quite symmetric and H drifts linearly in long
    # runs.  So the first half is rounded and the mirror entries are *defined* by the
    # relations, exactly (see _mirror_pair).
    b64 = [float(sp.N(bj, DPS)) for bj in b]
    inv_b = [float(1 / sp.N(bj, DPS)) for bj in b]
    quad = [[_snap(w * _at(ell[j], x)) for x, w in rule] for j in range(s)]
    exact_path = [[_at(L, x) for L in Lam] for x, _ in rule]
    if not consistent:
        return {"nodes": nodes, "weights": weights, "path": tuple(tuple(_snap(v) for v in r) for r in exact_path),
                "quad": tuple(tuple(r) for r in quad), "inv_b": tuple(inv_b), "b": tuple(b64)}
    for j in range(s // 2):
        b64[s - 1 - j], inv_b[s - 1 - j] = b64[j], inv_b[j]
    for j in range(s):
        for k in range(m):
            if (j, k) > (s - 1 - j, m - 1 - k):          # the mirror of an entry set before
                quad[j][k] = quad[s - 1 - j][m - 1 - k]
    path = [[None] * s for _ in range(m)]
    for k in range(m):
        for i in range(s):
            if path[k][i] is not None:
                continue
            mk, mi = m - 1 - k, s - 1 - i               # Λ_i(x_k) + Λ_(s+1-i)(x_(m+1-k)) = b_i
            path[k][i], path[mk][mi] = _mirror_pair(exact_path[k][i], exact_path[mk][mi], b64[i])
    return {"nodes": nodes, "weights": weights, "path": tuple(tuple(r) for r in path),
            "quad": tuple(tuple(r) for r in quad), "inv_b": tuple(inv_b), "b": tuple(b64)}


def _mirror_pair(u, v, total: float) -> tuple[float, float]:
    """Floats ``(a, c)`` near the exact ``u``, ``v`` (``u + v = total``) with ``a + c == total``
    exactly in real arithmetic: ``a`` is rounded on a grid coarse enough for ``total − a``
    to be a float as well (a few ulp at most; exact zeros stay zeros).  ``u is v`` (the
    middle entry, ``2a = total``) gives ``total/2``."""
    from fractions import Fraction
    import math

    if u is v:
        return total / 2, total / 2
    if abs(u) < 1e-50 and abs(v - total) < 1e-50:
        return 0.0, total
    if abs(v) < 1e-50 and abs(u - total) < 1e-50:
        return total, 0.0
    T = Fraction(total)
    U = Fraction(float(u)) if abs(u) >= 1e-50 else Fraction(0)
    # grid: a power of two at least the ulp of the largest of |u|, |v|, |total|
    g = Fraction(2) ** (math.frexp(max(abs(float(u)), abs(float(v)), abs(total)))[1] - 53)
    for _ in range(8):
        a = round(U / g) * g
        c = T - a
        if float(a) == a and float(c) == c:
            return float(a), float(c)
        g *= 2
    raise ArithmeticError(f"no float pair for {u}, {v} summing to {total}")   # pragma: no cover


def field_degree(system: Hamiltonian) -> int | None:
    """Total degree of ``f = J∇H`` in y (None if f is not a polynomial with y-free coefficients)."""
    deg = 0
    for fi in vector_field(system):
        if not fi.is_polynomial(*system.y):
            return None
        poly = sp.Poly(fi, *system.y)
        if poly.free_symbols_in_domain & set(system.y):
            return None
        deg = max(deg, poly.total_degree())
    return deg


def nodes_needed(stages: int, degree: int) -> int:
    """Gauss–Legendre nodes that integrate ``ℓ_j(σ) f(u(σ))`` exactly: its degree in σ is at
    most ``(s − 1) + degree·s`` and an m-node rule is exact up to degree 2m − 1."""
    return max(1, -(-((stages - 1) + degree * stages + 1) // 2))


def build(system: Hamiltonian, stages: int = DEFAULT_STAGES, *, consistent: bool = True) -> Scheme:
    """The scheme; ``consistent=False`` (tests only) rounds the tables entry by entry."""
    c, ell, Lam, b = basis(stages)
    n = 2 * system.dim
    h = STEP
    f = vector_field(system)
    y0 = list(system.y)
    Z = [[sp.Symbol(f"_z{j + 1}_{v.name}", real=True) for v in y0] for j in range(stages)]
    degree = field_degree(system)
    exact = degree is not None
    # A Gauss–Legendre rule with enough nodes is exact for a polynomial field (the integrand
    # is a polynomial in σ of known degree) -- far cheaper than expanding the integral
    # symbolically, and the same f(u(x_k)) serve every j.  Otherwise 2s + 2 nodes.
    m = nodes_needed(stages, degree) if exact else 2 * stages + 2
    if m > MAX_NODES:
        raise InputError(f"energy-collocation: f = J∇H has degree {degree}, so exact quadrature with "
                         f"stages={stages} needs {m} Gauss–Legendre nodes; at most {MAX_NODES} are offered "
                         "(use fewer stages or a discrete-gradient method)")
    tab = coefficient_tables(stages, m, consistent)
    # Evaluation order, fixed with `grouped` (opaque to SymPy's distribution of numbers over
    # sums): the stage value u_k = y + (Σ_i Λ_i(x_k) Z_i) -- the small sum first, one rounding
    # onto y --, then f(u_k) as a whole, then Σ_k w_k ℓ_j(x_k) f(u_k).  Left to SymPy, the
    # weights were distributed into the stage sums (0.5·(p + a z1 + b z2) → 0.5 p + 0.5a z1 +
    # 0.5b z2), so y was added to one stage term before the other: the step was no longer
    # symmetric in float64 and H drifted linearly (see MEASURED_DRIFT).  These expressions are
    # the scheme's (verify reads them); the module evaluates the same tables with loops over the
    # stages (methodgen.symbolic.stages, `stage_system` below) in the same order for u_k, the sum over
    # the nodes taken in mirror pairs.
    U = [{v: grouped(v + grouped(sp.Add(*[_f64(tab["path"][k][i]) * Z[i][iv] for i in range(stages)])))
          for iv, v in enumerate(y0)} for k in range(m)]
    FU = [[grouped(fi.xreplace(Uk)) for fi in f] for Uk in U]
    integral = [[grouped(sp.Add(*[_f64(tab["quad"][j][k]) * FU[k][i] for k in range(m)])) for i in range(n)]
                for j in range(stages)]
    if exact:
        how = (f"{m}-node Gauss–Legendre quadrature, exact for this polynomial field (degree {degree} in y: "
               f"the integrand has degree ≤ {(stages - 1) + degree * stages} in σ)")
    else:
        how = f"{m}-node Gauss–Legendre quadrature (H not a polynomial: H kept to the quadrature error)"
    residual = sp.Matrix([Z[j][i] - h * _f64(tab["inv_b"][j]) * integral[j][i]
                          for j in range(stages) for i in range(n)])
    increment = sp.Matrix([sp.Add(*[_f64(tab["b"][j]) * Z[j][i] for j in range(stages)]) for i in range(n)])
    guess = sp.Matrix([h * _f64(tab["b"][j]) * f[i] for j in range(stages) for i in range(n)])   # F_j ≈ f(y0)
    traits = Traits(order=2 * stages, symmetric=True, symplectic=False, energy_preserving=exact,
                    preserved=("H",) if exact else (), solve="newton",
                    approximate=() if exact else ("H",),
                    notes=(f"{stages}-stage energy-preserving collocation at Gauss nodes; {how}",)
                    + ((f"H exact in exact arithmetic; {drift_note(stages)}",) if exact else ()))
    return Scheme(system=system, method=NAME, traits=traits,
                  unknowns=tuple(z for row in Z for z in row), residual=residual, guess=guess,
                  increment=increment, invariants=invariants(system),
                  description=(f"energy-preserving collocation, s = {stages}: u(σ) = y0 + Σ Λ_k(σ) Z_k, "
                               "Z_j = (h/b_j) ∫ ℓ_j f(u), y1 = y0 + Σ b_j Z_j"),
                  resolution=None, fixed_point=True,
                  options=(() if stages == DEFAULT_STAGES else (("stages", stages),)),
                  structure={"kind": "energy-collocation", "stages": stages, "exact": exact,
                             "degree": degree, "nodes": m, "tables": tab, "ell": ell, "Lam": Lam, "b": b,
                             "sigma": SIGMA, "Z": Z},
                  # the module's stage loops (the same tables, the same evaluation order:
                  # u_k = y0 + (Σ_i Λ_i(x_k) Z_i), R_j = Z_j − h (1/b_j) Σ_k w_k ℓ_j(x_k) f(u_k))
                  stage_system=StageSystem(field=tuple(f), state=tuple(y0), stages=stages,
                                           weights=tuple(tuple(float(x) for x in row) for row in tab["quad"]),
                                           points=tuple(tuple(float(x) for x in row) for row in tab["path"]),
                                           scale=tuple(float(x) for x in tab["inv_b"])))
