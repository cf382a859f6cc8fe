"""Gauss–Legendre collocation with ``s`` stages: symplectic, symmetric, order 2s.

    Z_i = h Σ_j a_ij f(y0 + Z_j)   (i = 1..s),      y1 = y0 + Σ_i d_i Z_i,   dᵀ = bᵀA⁻¹

The nodes c_i are the roots of the shifted Legendre polynomial P_s(2c − 1);
``A`` and ``b`` are *defined* by the simplifying assumptions C(s) and B(s)
(collocation): ``A V = C``, ``bᵀV = (1, 1/2, …, 1/s)`` with the Vandermonde
matrix ``V_ik = c_i^(k-1)`` and ``C_ik = c_i^k / k``.  The update through the
stage increments ``Z`` (``d = bᵀA⁻¹``) instead of ``h Σ b_i f(Y_i)`` saves s
evaluations of f and, as Hairer, McLachlan & Razakarivony (2008) recommend,
keeps the round-off of the update small.  The unknowns are the stage
increments ``Z_i`` (small, so Newton's stopping test loses few digits); the
start value is ``Z_i = c_i h f(y0)``.

Properties [HLW06, §II.1.3, §IV.2, §VI.4]: order 2s (B(2s), C(s), D(s));
symmetric; symplectic (``b_i a_ij + b_j a_ji = b_i b_j``), hence every quadratic
first integral is preserved.  H itself is preserved only when it is quadratic.
``s = 1`` is the implicit midpoint rule.

The coefficients are derived exactly from their definition (``coefficients``:
nodes as algebraic numbers — radicals or ``CRootOf`` — and A, b at 40 digits
from the exact nodes) and rounded to float64 in the equations;
:mod:`methodgen.symbolic.verify.collocation` proves B(2s), C(s), D(s) and the symplecticity
condition exactly, in rational arithmetic, from the one fact that the c_i are
the s distinct roots of the shifted Legendre polynomial.

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006.
.. [HMR08] E. Hairer, R. I. McLachlan, A. Razakarivony, Achieving Brouwer's law with
   implicit Runge–Kutta methods, BIT 48 (2008) 231–243.
"""

from __future__ import annotations

from functools import lru_cache

import mpmath as mp
import sympy as sp

from ..derive import invariants, vector_field
from ...errors import InputError
from ...problem.problem import Hamiltonian
from ..stages import StageSystem
from .base import STEP, Scheme, Traits, quadratic_invariants

NAME = "gauss"
SUMMARY = "Gauss–Legendre collocation, stages=s (symplectic, symmetric, order 2s; s = 1..6)"
STAGES = (1, 2, 3, 4, 5, 6)
DEFAULT_STAGES = 2
_X = sp.Symbol("x")
_DPS = 40


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "Gauss collocation does not enforce constraints; use rattle or shake"
    return None


def legendre(s: int) -> sp.Poly:
    """The shifted Legendre polynomial ``P_s(2x − 1)`` with integer coefficients."""
    return sp.Poly(sp.legendre(s, 2 * _X - 1), _X).primitive()[1]


@lru_cache(maxsize=None)
def coefficients(s: int) -> dict:
    """Exact nodes and high-precision A, b, d of the s-stage Gauss method.

    Returns
    -------
    dict
        ``nodes``: tuple of s SymPy algebraic numbers in increasing order;
        ``c``, ``b`` (s,), ``A`` (s, s), ``d`` (s,): mpmath numbers at 40 digits;
        ``poly``: the shifted Legendre polynomial.
    """
    if isinstance(s, bool) or not isinstance(s, int) or s not in STAGES:
        raise InputError(f"stages must be one of {', '.join(map(str, STAGES))}, got {s!r}")
    P = legendre(s)
    nodes = tuple(sorted(P.all_roots(), key=lambda r: float(sp.N(r, 30))))
    with mp.workdps(_DPS + 10):
        c = [mp.mpf(str(sp.N(r, _DPS + 10))) for r in nodes]
        V = mp.matrix([[ci ** k for k in range(s)] for ci in c])
        Cm = mp.matrix([[ci ** (k + 1) / (k + 1) for k in range(s)] for ci in c])
        A = Cm * V ** -1
        b = mp.matrix([[mp.mpf(1) / (k + 1) for k in range(s)]]) * V ** -1
        d = b * A ** -1
        return {"nodes": nodes, "poly": P, "c": c, "A": [[A[i, j] for j in range(s)] for i in range(s)],
                "b": [b[0, j] for j in range(s)], "d": [d[0, j] for j in range(s)]}


def _f64(x) -> sp.Float:
    """``x`` rounded to float64, as a SymPy Float that prints as that double."""
    return sp.Float(float(x), 17)


def stage_symbol(i: int, s: sp.Symbol) -> sp.Symbol:
    return sp.Symbol(f"_z{i + 1}_{s.name}", real=True)


def build(system: Hamiltonian, stages: int = DEFAULT_STAGES) -> Scheme:
    co = coefficients(stages)
    n = 2 * system.dim
    h = STEP
    f = vector_field(system)
    y0 = list(system.y)
    Z = [[stage_symbol(i, v) for v in y0] for i in range(stages)]
    F = [f.xreplace({v: v + z for v, z in zip(y0, Z[i])}) for i in range(stages)]
    A = [[_f64(a) for a in row] for row in co["A"]]
    d = [_f64(x) for x in co["d"]]
    residual = sp.Matrix([Z[i][k] - h * sp.Add(*[A[i][j] * F[j][k] for j in range(stages)])
                          for i in range(stages) for k in range(n)])
    increment = sp.Matrix([sp.Add(*[d[i] * Z[i][k] for i in range(stages)]) for k in range(n)])
    guess = sp.Matrix([_f64(co["c"][i]) * h * f[k] for i in range(stages) for k in range(n)])
    preserved = quadratic_invariants(system)
    notes = (f"{stages}-stage Gauss–Legendre collocation; coefficients from the exact "
             "nodes (roots of the shifted Legendre polynomial), rounded to float64",)
    if n >= 12:
        # said where Gauss is offered for a large system: its stage Newton is dense
        notes += (f"each Newton iteration solves a dense linear system of s·2d = {stages * n} unknowns "
                  f"(an LU of O({stages * n}³) a step): for N-body problems Störmer–Verlet composed to "
                  "order 8 or 10 (explicit, symplectic) or a Wisdom–Holman splitting (a dominant mass) "
                  "costs far less for the same accuracy",)
    if "H" in preserved:
        # stated where H is claimed: the float64 module drifts (measured, see the docs: "The method library")
        notes += ("H (quadratic) exact in exact arithmetic; in float64 it drifts linearly: "
                  "−4.2e-19 per step measured for s = 2, 1.4e-18 for s = 3 (p²/2 + q²/2, h = 0.1, mean over 64 "
                  "phases; s = 1 does not drift: its A = 1/2 and d = 2 are exact)",)
    traits = Traits(order=2 * stages, symmetric=True, symplectic=True,
                    energy_preserving="H" in preserved, preserved=preserved, solve="newton",
                    notes=notes)
    return Scheme(system=system, method=NAME, traits=traits,
                  unknowns=tuple(z for row in Z for z in row), residual=residual, guess=guess,
                  increment=increment, invariants=invariants(system),
                  description=(f"Gauss–Legendre collocation, s = {stages}: Z_i = h Σ a_ij f(y0 + Z_j), "
                               "y1 = y0 + Σ d_i Z_i (d = bᵀA⁻¹)"),
                  # No Jacobian-based h·ω guard: J − I = −h A⊗f' has the row sums of A in its
                  # norm (≈ 2.4× the midpoint rule's h‖f'‖/2 for s = 3), so the midpoint
                  # rule's reading would refuse resolved steps.  The local error estimate
                  # (E = Δy minus the trapezoidal rule on the chord) guards every step.
                  resolution=None, fixed_point=True,
                  options=(() if stages == DEFAULT_STAGES else (("stages", stages),)),
                  structure={"kind": "collocation", "nodes": "gauss", "stages": stages},
                  # the module's stage loops: u_k = y0 + Z_k, R_i = Z_i − h Σ_j a_ij f(u_j)
                  stage_system=StageSystem(field=tuple(f), state=tuple(y0), stages=stages,
                                           weights=tuple(tuple(float(a) for a in row) for row in A),
                                           points=None, scale=(1.0,) * stages))
