"""Claim 7 (section 1.2): on a quadratic H the midpoint map is the exact flow, re-timed.

For ``H = ½ yᵀSy`` in one degree of freedom, ``A = JS`` has ``A² = -ω² I`` with
``ω² = det S``, so ``exp(tA) = cos(ωt) I + sin(ωt)/ω A``.  The midpoint map is
the Cayley transform ``Φ = (I - hA/2)⁻¹(I + hA/2)``; with ``x = hω/2`` and
``θ = 2 arctan x`` (``cos θ = (1-x²)/(1+x²)``, ``sin θ = 2x/(1+x²)``)

    Φ = ((1 - x²) I + h A) / (1 + x²) = exp(τ A),   τ = θ/ω,

a rational identity in (h, S) proved with ``cancel``: the numerical solution is
the exact one at times ``n τ``, i.e. with frequency ``ω_h = (2/h) arctan(hω/2)``.
"""

from __future__ import annotations

import sympy as sp

from ..derive import gradient
from .common import REF_NOTES, system_domain
from .exact import certify
from .maps import step_jacobian, symplectic_matrix
from .report import Certificate

__all__ = ["retiming_certificate"]


def retiming_certificate(scheme) -> Certificate | None:
    """Φ' = ((1 - x²) I + hA)/(1 + x²), x² = h² det S / 4 (1 DOF, quadratic H); None otherwise."""
    system = scheme.system
    if system.dim != 1:
        return None
    P = step_jacobian(scheme)
    if P is None:
        return None
    S = sp.hessian(system.H, system.y)
    if S.free_symbols & set(system.y):
        return None
    h = scheme.h
    A = symplectic_matrix(2) * S
    w2 = sp.factor(S.det())
    x2 = h**2 * w2 / 4
    expr = P - ((1 - x2) * sp.eye(2) + h * A) / (1 + x2)
    w = sp.sqrt(w2)
    wh = 2 / h * sp.atan(h * w / 2)
    cert = certify(f"{scheme.method}: on this quadratic H the step is the exact flow at time τ = θ/ω, "
                   f"with ω = sqrt({w2}) and numerical frequency ω_h = (2/h) arctan(hω/2)",
                   expr, system_domain(system), f"{REF_NOTES}, section 1.2 (Theorem 1.1)",
                   details={"omega": sp.sstr(w), "omega_h": sp.sstr(wh), "omega_h_latex": sp.latex(wh),
                            "note": "for det S < 0 read arctan as i·artanh (hyperbolic case)"})
    return cert
