"""Implicit midpoint rule: ``y1 = y0 + h f((y0 + y1)/2)``.

Symmetric, symplectic, order 2; preserves every quadratic first integral (so
angular momentum, and H itself when H is quadratic) [HLW06, §IV.2].

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration,
   2nd ed., Springer 2006.
"""

from __future__ import annotations

from ..problem import Hamiltonian
from .base import Scheme, Traits, gradient_scheme, midpoint_gradient, quadratic_invariants

NAME = "midpoint"
SUMMARY = "implicit midpoint rule (symplectic, symmetric, order 2)"


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "the midpoint rule does not enforce constraints; use rattle or shake"
    return None


def build(system: Hamiltonian) -> Scheme:
    preserved = quadratic_invariants(system)
    traits = Traits(order=2, symmetric=True, symplectic=True, energy_preserving="H" in preserved,
                    preserved=preserved, solve="newton")
    return gradient_scheme(system, NAME, midpoint_gradient(system), traits,
                           "y1 = y0 + h J ∇H((y0 + y1)/2)")
