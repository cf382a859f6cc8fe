"""Implicit midpoint rule: ``y1 = y0 + h f((y0 + y1)/2)``.

Symmetric, symplectic, order 2; preserves every quadratic first integral (so
angular momentum, and H itself when H is quadratic) [HLW06, §IV.2].

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration,
   2nd ed., Springer 2006.
"""

from __future__ import annotations

import sympy as sp

from ..derive import potential_families, separable_split
from ...problem.problem import Hamiltonian
from .base import (Scheme, Traits, gradient_scheme, loop_family, midpoint_gradient, next_symbol,
                   quadratic_invariants)

NAME = "midpoint"
SUMMARY = "implicit midpoint rule (symplectic, symmetric, order 2)"


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "the midpoint rule does not enforce constraints; use rattle or shake"
    return None


def _loops(system: Hamiltonian) -> tuple:
    """U's families of like terms with each template's gradient at the slots' midpoint
    (``∇U`` is linear in U, so ``∇U(q̄) = Σ_t ∇U_t(q̄)``): the module loops over them.
    Empty unless the momenta can be eliminated (separable H, quadratic kinetic energy)."""
    fams = potential_families(system)
    if fams is None or system.constraints or separable_split(system).Minv is None:
        return ()
    out = []
    for fam in fams:
        mid = {u: (u + next_symbol(u)) / 2 for u in fam.slots}
        out.append(loop_family(fam, [sp.diff(fam.template, u).xreplace(mid) for u in fam.slots]))
    return tuple(out)


def build(system: Hamiltonian) -> Scheme:
    preserved = quadratic_invariants(system)
    traits = Traits(order=2, symmetric=True, symplectic=True, energy_preserving="H" in preserved,
                    preserved=preserved, solve="newton")
    return gradient_scheme(system, NAME, midpoint_gradient(system), traits,
                           "y1 = y0 + h J ∇H((y0 + y1)/2)", loops=_loops(system))
