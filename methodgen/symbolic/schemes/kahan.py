"""Kahan's method: ``y1 = y0 + 2h f((y0+y1)/2) - h/2 (f(y0) + f(y1))``.

For quadratic vector fields (cubic H) the one-step RK form is *linear* in the
increment and equals the Jacobian form

    y1 = y0 + h (I - h/2 f'(y0))⁻¹ f(y0),

which is what is generated: one linear solve per step, no Newton.  For other
vector fields the RK form is solved with Newton.  Symmetric, order 2; for
cubic H it preserves a modified energy and a modified volume form [1].

References
----------
.. [1] E. Celledoni, R. I. McLachlan, B. Owren, G. R. W. Quispel, "Geometric
   properties of Kahan's method", J. Phys. A 46 (2013) 025201.
"""

from __future__ import annotations

import sympy as sp

from ..derive import gradient, invariants, vector_field
from ...problem.poisson import is_poisson
from ...problem.problem import Hamiltonian
from .base import (STEP, Scheme, Traits, gradient_scheme, increment_symbol, is_linear_field,
                   is_quadratic_field, linear_invariants, quadratic_invariants)

NAME = "kahan"
SUMMARY = "Kahan's method (linearly implicit for quadratic f: one linear solve per step)"


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "Kahan's method does not enforce constraints; use rattle or shake"
    return None


def jacobian_form(system: Hamiltonian):
    """``(A, b)`` with ``A = I - h/2 f'(y0)`` and ``b = h f(y0)``; the step solves ``A Δy = b``."""
    f = vector_field(system)
    fprime = f.jacobian(sp.Matrix(system.y))
    n = len(system.y)
    return sp.eye(n) - STEP / 2 * fprime, STEP * f


def build(system: Hamiltonian, form: str | None = None) -> Scheme:
    quadratic = is_quadratic_field(system)
    if form is None:
        form = "jacobian" if quadratic else "rk"
    if form not in ("jacobian", "rk"):
        raise ValueError(f"Kahan form must be 'jacobian' or 'rk', got {form!r}")
    if form == "jacobian" and not quadratic:
        from ...errors import MethodNotApplicable
        raise MethodNotApplicable("Kahan's Jacobian form needs a quadratic vector field (cubic H); "
                                  "use form='rk' (Newton on the one-step form)")
    if form == "rk" and is_poisson(system):
        from ...errors import MethodNotApplicable
        raise MethodNotApplicable("Kahan's one-step form is not generated for Poisson systems; the "
                                  "Jacobian form (quadratic f = S∇H) is")
    linear = is_linear_field(system)
    # linear first integrals cᵀy: cᵀf ≡ 0 (so cᵀf' ≡ 0) and both forms give cᵀΔy = 0
    preserved = quadratic_invariants(system) if linear else linear_invariants(system)
    # symplectic for a linear Hamiltonian field (it is the midpoint rule then); a Poisson
    # structure is never claimed (not certified)
    base = dict(order=2, symmetric=True, symplectic=linear and not is_poisson(system),
                energy_preserving="H" in preserved,
                preserved=preserved)
    if form == "jacobian":
        A, b = jacobian_form(system)
        z = tuple(increment_symbol(s) for s in system.y)
        residual = A * sp.Matrix(z) - b
        traits = Traits(**base, solve="linear",
                        notes=("quadratic vector field: Jacobian form y1 = y0 + h (I - h/2 f'(y0))^-1 f(y0), "
                               "one linear solve per step",))
        return Scheme(system=system, method=NAME, traits=traits, unknowns=z, residual=residual,
                      guess=b, increment=sp.Matrix(z), invariants=invariants(system),
                      description="y1 = y0 + h (I - h/2 f'(y0))^-1 f(y0)",
                      resolution=None if linear else "full")
    grad = gradient(system)

    def dg(y0, y1):
        mid = grad.xreplace({a: (a + c) / 2 for a, c in zip(y0, y1)})
        return 2 * mid - (grad + grad.xreplace(dict(zip(y0, y1)))) / 2

    traits = Traits(**base, solve="newton", notes=("one-step (RK) form solved with Newton",))
    return gradient_scheme(system, NAME, dg, traits,
                           "y1 = y0 + 2h f((y0+y1)/2) - h/2 (f(y0) + f(y1))")
