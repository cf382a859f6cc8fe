"""RATTLE and SHAKE for ``H = ½ pᵀM⁻¹p + U(q)`` with holonomic constraints ``g(q) = 0``.

RATTLE (seed §1.3, Andersen 1983)::

    p½ = p0 - h/2 (∇U(q0) + G(q0)ᵀ λ)
    q1 = q0 + h M⁻¹ p½,                     g(q1) = 0
    p1 = p½ - h/2 (∇U(q1) + G(q1)ᵀ μ),       G(q1) M⁻¹ p1 = 0

Position stage: q1 is explicit in λ, so Newton runs on the m multipliers only,
in the scaled form ``ν = h²λ/2``:

    R(ν) = g(q0 + h M⁻¹ p0 - h²/2 M⁻¹∇U(q0) - M⁻¹ G(q0)ᵀ ν) = 0,

whose Jacobian ``-G(q1) M⁻¹ G(q0)ᵀ`` is O(1) for every h (λ itself would be
determined only to eps/h²).  Velocity stage: linear in μ, solved in closed form
as the projection ``p1 = w - G1ᵀ (G1 M⁻¹ G1ᵀ)⁻¹ G1 M⁻¹ w`` with
``w = p½ - h/2 ∇U(q1)``, derived symbolically.

SHAKE (Ryckaert, Ciccotti & Berendsen 1977) in one-step form: the same
position stage, and ``p1 = p½ - h/2 (∇U(q1) + G(q1)ᵀ λ)`` with the
position-stage multiplier — the velocities are not projected onto the
cotangent space, so ``G M⁻¹ p`` is only O(h²) small.  Its positions coincide with
RATTLE's.

References
----------
.. [1] H. C. Andersen, J. Comput. Phys. 52 (1983) 24-34.
.. [2] J.-P. Ryckaert, G. Ciccotti, H. J. C. Berendsen, J. Comput. Phys. 23 (1977) 327-341.
.. [3] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, §VII.1.
"""

from __future__ import annotations

import sympy as sp

from ..derive import constraint_jacobian, constraint_monitors, invariants, separable_split
from ...problem.problem import Hamiltonian
from .base import STEP, Scheme, Traits


def _applies(system: Hamiltonian, name: str) -> str | None:
    if not system.constraints:
        return f"{name} needs holonomic constraints g(q) = 0 (the system has none)"
    sep = separable_split(system)
    if sep is None or sep.Minv is None:
        return f"{name} needs H = ½ pᵀ M⁻¹ p + U(q) with a constant mass matrix"
    if _generically_dependent(system):
        return (f"the constraints of this system are dependent (G(q) = ∂g/∂q has rank < "
                f"{len(system.constraints)} at generic points); remove the redundant ones")
    return None


def _generically_dependent(system: Hamiltonian) -> bool:
    """Rank of G at a few fixed rational points (exact arithmetic) below m at all of them."""
    G = constraint_jacobian(system)
    m = len(system.constraints)
    pts = [[sp.Rational(2 * i + 3, 7 + k) for i in range(system.dim)] for k in range(3)]
    par = {s: sp.Rational(5 + i, 4) for i, s in enumerate(system.params)}
    for pt in pts:
        Gp = G.xreplace({**dict(zip(system.q, pt)), **par})
        if Gp.rank() == m:
            return False
    return True


def _build(system: Hamiltonian, name: str, project: bool) -> Scheme:
    sep = separable_split(system)
    h = STEP
    m = len(system.constraints)
    q0 = sp.Matrix(system.q)
    p0 = sp.Matrix(system.p)
    Minv = sep.Minv
    g = sp.Matrix(list(system.constraints))
    G = constraint_jacobian(system)
    gradU = sp.Matrix([sp.diff(sep.U, s) for s in system.q])
    nu = tuple(sp.Symbol(f"_nu_{i + 1}", real=True) for i in range(m))
    nuv = sp.Matrix(nu)
    G0 = G
    pred = q0 + h * Minv * p0 - h**2 / 2 * Minv * gradU          # unconstrained prediction
    dq = pred - q0 - Minv * G0.T * nuv                             # Δq(ν)
    q1 = q0 + dq
    at1 = dict(zip(system.q, q1))
    residual = g.xreplace(at1)
    # Newton start: one linearised step, ν ≈ (G(q̃) M⁻¹ G0ᵀ)⁻¹ g(q̃).
    at_pred = dict(zip(system.q, pred))
    A0 = G.xreplace(at_pred) * Minv * G0.T
    guess = A0.LUsolve(g.xreplace(at_pred)) if m <= 3 else sp.zeros(m, 1)
    # λ = 2ν/h²; p½ = p0 - h/2 ∇U(q0) - (1/h) G0ᵀ ν   (since h/2 · 2ν/h² = ν/h)
    phalf = p0 - h / 2 * gradU - G0.T * nuv / h
    gradU1 = gradU.xreplace(at1)
    G1 = G.xreplace(at1)
    w = phalf - h / 2 * gradU1
    structure = None
    if project:
        A1 = G1 * Minv * G1.T
        b1 = G1 * Minv * w
        c = A1.LUsolve(b1)
        p1 = w - G1.T * c
        # The pieces of the velocity stage, so that verify can prove G(q1)M⁻¹p1 = 0
        # from a lemma about LUsolve instead of cancelling p1(ν) (see verify/constrained.py).
        structure = {"kind": "rattle", "q1": q1, "w": w, "G1": G1, "A1": A1, "b": b1, "c": c}
    else:
        p1 = w - G1.T * nuv / h
    dp = p1 - p0
    scale = sp.Max(*[sp.Abs(s) for s in system.q]) if len(system.q) > 1 else sp.Abs(system.q[0])
    traits = Traits(
        order=2, symmetric=project, symplectic=project, energy_preserving=False,
        preserved=tuple(inv.name for inv in constraint_monitors(system)
                        if project or not inv.name.endswith("_v")),
        solve="newton",
        notes=(("Newton on the scaled multipliers ν = h²λ/2 only (q1 is explicit in λ); "
                "velocity multipliers μ by a symbolic projection") if project else
               "Newton on the scaled multipliers ν = h²λ/2; velocities not projected",))
    return Scheme(system=system, method=name, traits=traits, unknowns=nu, residual=residual,
                  guess=guess, increment=sp.Matrix(list(dq) + list(dp)),
                  invariants=invariants(system), unknown_scale=scale, structure=structure,
                  description=("RATTLE: position stage with multipliers λ (g(q1) = 0), velocity "
                               "stage projected so that G(q1) M⁻¹ p1 = 0") if project else
                  "SHAKE: RATTLE's position stage, velocities updated with the same multipliers")


class Rattle:
    NAME = "rattle"
    SUMMARY = "RATTLE for holonomic constraints (symplectic on T*Q, symmetric, order 2)"

    @staticmethod
    def applies(system):
        return _applies(system, "RATTLE")

    @staticmethod
    def build(system):
        return _build(system, Rattle.NAME, project=True)


class Shake:
    NAME = "shake"
    SUMMARY = "SHAKE (position constraints only; velocities not projected), for comparison"

    @staticmethod
    def applies(system):
        return _applies(system, "SHAKE")

    @staticmethod
    def build(system):
        return _build(system, Shake.NAME, project=False)
