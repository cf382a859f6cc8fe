"""The energy–momentum method of Exercise 1.1 (Simo, Tarnow & Wong 1992).

For ``H = ½ pᵀM⁻¹p + U(q)`` the midpoint rule with the potential gradient
scaled by

    κ = (U(q1) - U(q0)) / ((q1 - q0)ᵀ ∇U(q̄)),   q̄ = (q0 + q1)/2,

is a discrete-gradient method: it preserves H exactly, and for ``U = V(|q|)``
with isotropic M every component of ``q × p``.

The quotient κ is 0/0 as ``q1 → q0`` and wherever ``(q1-q0) ⟂ ∇U(q̄)``.  For a
radial potential ``U(q) = V(s)``, ``s = |q|²``, we have ``∇U = 2V'(s) q`` and
``(q1-q0)ᵀ(q0+q1) = s1 - s0``, so

    κ ∇U(q̄) = V[s0, s1] (q0 + q1)

where ``V[s0, s1]`` is the divided difference of V, computed in cancelled form
by :func:`methodgen.divdiff.divided_difference` (for Kepler
``k / (r0 r1 (r0 + r1))``: no difference quotient left at all).  In one degree
of freedom ``κ U'(q̄) = U[q0, q1]`` for any U.  Other potentials have a genuine
(not removable) singularity of κ, and the method is refused for them.

References
----------
.. [1] J. C. Simo, N. Tarnow, K. K. Wong, Comput. Methods Appl. Mech. Eng. 100
   (1992) 63-116.
.. [2] E. Celledoni, lecture notes (shared/seed), Exercise 1.1.
"""

from __future__ import annotations

import sympy as sp

from ..derive import angular_momenta, radial_profile, separable_split
from ..divdiff import divided_difference
from ..problem import Hamiltonian
from .base import Scheme, Traits, gradient_scheme

NAME = "energy-momentum"
SUMMARY = "Exercise 1.1 discrete gradient: preserves H and, for U = V(|q|), q × p"


def applies(system: Hamiltonian) -> str | None:
    if system.constraints:
        return "energy-momentum does not enforce constraints; use rattle or shake"
    sep = separable_split(system)
    if sep is None:
        return "energy-momentum needs a separable H = T(p) + U(q)"
    if not sep.quadratic_kinetic:
        return "energy-momentum needs a quadratic kinetic energy T = ½ pᵀ M⁻¹ p with constant M"
    if system.dim > 1 and radial_profile(system) is None:
        return ("energy-momentum needs U(q) = V(|q|) (or one degree of freedom): for other "
                "potentials κ has non-removable singularities")
    return None


def build(system: Hamiltonian) -> Scheme:
    sep = separable_split(system)
    d = system.dim
    radial = radial_profile(system)

    def dg(y0, y1):
        q0, q1 = sp.Matrix(y0[:d]), sp.Matrix(y1[:d])
        p0, p1 = sp.Matrix(y0[d:]), sp.Matrix(y1[d:])
        if radial is not None:
            s, V = radial
            s0 = sum(v**2 for v in q0)
            s1 = sum(v**2 for v in q1)
            Vdd = divided_difference(V, s, s0, s1)
            Gq = Vdd * (q0 + q1)
        else:
            Gq = sp.Matrix([divided_difference(sep.U, y0[0], q0[0], q1[0])])
        Gp = sep.Minv * (p0 + p1) / 2
        return sp.Matrix(list(Gq) + list(Gp))

    momenta = tuple(inv.name for inv in angular_momenta(system)) if (radial and sep.isotropic) else ()
    form = ("κ∇U(q̄) = V[s0, s1](q0 + q1), V[·,·] the cancelled divided difference of V in s = |q|²"
            if radial is not None else "κU'(q̄) = U[q0, q1], the cancelled divided difference of U")
    traits = Traits(order=2, symmetric=True, symplectic=False, energy_preserving=True,
                    preserved=("H",) + momenta, solve="newton", discrete_gradient=True,
                    notes=(form,))
    return gradient_scheme(system, NAME, dg, traits,
                           "y1 = y0 + h J [κ∇U(q̄); M⁻¹(p0 + p1)/2]")
