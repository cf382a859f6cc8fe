"""Störmer–Verlet (velocity Verlet) for separable ``H = T(p) + U(q)``: explicit.

    p½ = p0 - h/2 ∇U(q0),   q1 = q0 + h ∇T(p½),   p1 = p½ - h/2 ∇U(q1)

Symmetric, symplectic, order 2; preserves first integrals of the form
``qᵀ D p`` (angular momentum) exactly [HLW06, Thm IV.2.4], and linear ones ``cᵀp``
whose c annihilates ∇U (total momentum) — see
:func:`methodgen.symbolic.schemes.base.splitting_invariants`.  The reference
point for cost: no solve at all.
"""

from __future__ import annotations

import sympy as sp

from ..derive import invariants, separable_gradients, separable_split
from ...problem.problem import Hamiltonian
from .base import STEP, Scheme, Traits, splitting_invariants

NAME = "stormer-verlet"
SUMMARY = "explicit Störmer–Verlet for separable H (symplectic, symmetric, order 2, no solve)"


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "Störmer–Verlet does not enforce constraints; use rattle or shake"
    if separable_split(system) is None:
        return "Störmer–Verlet needs a separable H = T(p) + U(q)"
    return None


def build(system: Hamiltonian) -> Scheme:
    h = STEP
    q0, p0 = list(system.q), list(system.p)
    gT, gU = separable_gradients(system)     # per family of like terms where U has them
    gradU, gradT = sp.Matrix(gU), sp.Matrix(gT)
    phalf = sp.Matrix(p0) - h / 2 * gradU
    dq = h * gradT.xreplace(dict(zip(p0, phalf)))
    q1 = sp.Matrix(q0) + dq
    dp = -h / 2 * gradU - h / 2 * gradU.xreplace(dict(zip(q0, q1)))
    preserved = splitting_invariants(system)
    traits = Traits(order=2, symmetric=True, symplectic=True, energy_preserving=False,
                    preserved=preserved, solve="explicit")
    return Scheme(system=system, method=NAME, traits=traits, unknowns=(), residual=sp.zeros(0, 1),
                  guess=sp.zeros(0, 1), increment=sp.Matrix(list(dq) + list(dp)),
                  invariants=invariants(system),
                  description="p½ = p0 - h/2 ∇U(q0), q1 = q0 + h ∇T(p½), p1 = p½ - h/2 ∇U(q1)",
                  # the stages, for the structural symplecticity proof (verify/maps.py)
                  structure={"kind": "splitting",
                             "stages": (("kick", h / 2), ("drift", h), ("kick", h / 2))})
