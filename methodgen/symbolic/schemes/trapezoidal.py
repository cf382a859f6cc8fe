"""Trapezoidal rule: ``y1 = y0 + h/2 (f(y0) + f(y1))``.

Symmetric, order 2, not symplectic but conjugate to the midpoint rule by half
an explicit Euler step (Exercise 2.1 of the notes), so it behaves like a
symplectic method.  For linear f it coincides with the midpoint rule.
"""

from __future__ import annotations

from ..derive import gradient
from ...problem.problem import Hamiltonian
from .base import Scheme, Traits, gradient_scheme, is_linear_field, linear_invariants, quadratic_invariants

NAME = "trapezoidal"
SUMMARY = "trapezoidal rule (symmetric, order 2, conjugate to the midpoint rule)"


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "the trapezoidal rule does not enforce constraints; use rattle or shake"
    return None


def build(system: Hamiltonian) -> Scheme:
    grad = gradient(system)

    def dg(y0, y1):
        return (grad + grad.xreplace(dict(zip(y0, y1)))) / 2

    linear = is_linear_field(system)
    # linear first integrals cᵀy: cᵀf ≡ 0, so cᵀ(y1 - y0) = h/2 cᵀ(f(y0) + f(y1)) = 0
    preserved = quadratic_invariants(system) if linear else linear_invariants(system)
    traits = Traits(order=2, symmetric=True, symplectic=linear, energy_preserving="H" in preserved,
                    preserved=preserved, solve="newton",
                    notes=("linear vector field: identical to the midpoint rule",) if linear else ())
    return gradient_scheme(system, NAME, dg, traits, "y1 = y0 + h/2 (f(y0) + f(y1))")
