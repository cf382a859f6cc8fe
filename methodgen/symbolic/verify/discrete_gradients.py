"""Claims 2, 4 and 9 for discrete gradients: identity, consistency, symmetry, κ.

A discrete gradient ``∇̄H(y0, y1)`` satisfies [McLachlan, Quispel, Robidoux 1999]

    (y1 - y0)ᵀ ∇̄H(y0, y1) = H(y1) - H(y0)      and      ∇̄H(y, y) = ∇H(y).

Both are checked on the scheme's own ∇̄H (``scheme.discrete_gradient``, in the
symbols ``y0 = system.y`` and ``y1 = _n_<name>``).  The consistency limit is a
plain substitution ``y1 = y0``: the cancelled forms have no 0/0 left
(:mod:`methodgen.problem.special` evaluates ``sinc_u(0) = 1`` exactly).
"""

from __future__ import annotations

import sympy as sp

from ..derive import gradient, separable_split
from .common import REF_NOTES, at, system_domain, y1_symbols
from .exact import certify
from .helpers import helper_certificates
from .structural import gonzalez_symmetry_structural, identity_structural

__all__ = ["dg_identity", "dg_consistency", "dg_symmetry", "kappa_midpoint_gradient",
           "kappa_form", "kappa_applies", "dg_certificates", "dg_items"]


def dg_identity(system, dg: sp.Matrix, label: str, ref: str = "", scheme=None) -> "Certificate":
    """``(y1 - y0)ᵀ ∇̄H - (H(y1) - H(y0))`` reduced to 0 (or refuted).

    With ``scheme`` given, the structural proof of :mod:`.structural` (coordinate
    lemmas, the Gonzalez form) is tried first; the whole expression is reduced only
    when the scheme has no such structure or a lemma does not reduce.
    """
    y0, y1 = system.y, y1_symbols(system)
    # one Add: a Python sum re-flattens the growing Add once per term (quadratic in 2d)
    expr = sp.Add(*[(b - a) * g for a, b, g in zip(y0, y1, dg)]) - (at(system.H, y0, y1) - system.H)
    if scheme is not None and "H" in getattr(scheme.traits, "approximate", ()):
        # ∇̄H by quadrature: the identity holds only to the quadrature error, so the check is
        # what is claimed -- not H(y1) = H(y0).
        claim = (f"{label}: (y1 - y0)ᵀ ∇̄H(y0, y1) = H(y1) - H(y0) up to the quadrature error "
                 "(∇̄H by Gauss–Legendre quadrature: H is kept approximately, not exactly)")
    else:
        claim = (f"{label}: (y1 - y0)ᵀ ∇̄H(y0, y1) = H(y1) - H(y0) (discrete-gradient identity, "
                 "hence H(y1) = H(y0))")
    ref = ref or f"{REF_NOTES}, Ex. 1.1.2"
    if scheme is not None:
        cert = identity_structural(scheme, claim, ref, expr)
        if cert is not None:
            return cert
    return certify(claim, expr, system_domain(system), ref)


def dg_consistency(system, dg: sp.Matrix, label: str, ref: str = "") -> "Certificate":
    """``∇̄H(y, y) - ∇H(y)`` (substitution ``y1 = y0``) reduced to 0."""
    y0, y1 = system.y, y1_symbols(system)
    expr = at(dg, y1, y0) - gradient(system)
    return certify(f"{label}: ∇̄H(y, y) = ∇H(y) (consistency, by substitution y1 = y0)",
                   expr, system_domain(system), ref or f"{REF_NOTES}, Ex. 1.1.2")


def dg_symmetry(system, dg: sp.Matrix, label: str, scheme=None) -> "Certificate":
    """``∇̄H(y0, y1) - ∇̄H(y1, y0)``: a symmetric ∇̄H makes ``y1 = y0 + hJ∇̄H`` self-adjoint."""
    y0, y1 = system.y, y1_symbols(system)
    swap = {**dict(zip(y0, y1)), **dict(zip(y1, y0))}
    claim = (f"{label}: ∇̄H(y0, y1) = ∇̄H(y1, y0), so y1 = y0 + hJ∇̄H is symmetric "
             "(its adjoint, y0 = y1 - hJ∇̄H(y1, y0), is the same equation)")
    if scheme is not None:
        cert = gonzalez_symmetry_structural(scheme, claim, "symmetry (claim 9)")
        if cert is not None:
            return cert
    expr = dg - dg.xreplace(swap)
    return certify(claim, expr, system_domain(system), "symmetry (claim 9)")


def kappa_midpoint_gradient(system, kappa=None) -> sp.Matrix:
    """The notes' ∇̄H = [κ ∇U(q̄); M⁻¹ p̄] with κ given (in y0, y1 symbols) or the notes' choice.

    ``kappa=None`` uses κ = (U(q1) - U(q0)) / ((q1 - q0)ᵀ ∇U(q̄)); ``kappa=1`` is the
    plain midpoint gradient (a negative control: it is not a discrete gradient).
    """
    sep = separable_split(system)
    if sep is None or sep.Minv is None:
        raise ValueError("the κ-scaled midpoint gradient needs H = ½ pᵀM⁻¹p + U(q)")
    d = system.dim
    y0, y1 = system.y, y1_symbols(system)
    q0, q1 = sp.Matrix(y0[:d]), sp.Matrix(y1[:d])
    p0, p1 = sp.Matrix(y0[d:]), sp.Matrix(y1[d:])
    gradU = sp.Matrix([sp.diff(sep.U, s) for s in system.q])
    gbar = at(gradU, system.q, (q0 + q1) / 2)
    if kappa is None:
        kappa = (at(sep.U, system.q, q1) - sep.U) / ((q1 - q0).T * gbar)[0, 0]
    return sp.Matrix(list(kappa * gbar) + list(sep.Minv * (p0 + p1) / 2))


def kappa_form(scheme) -> "Certificate":
    """The scheme's cancelled q-part equals the notes' κ∇U(q̄) (Ex. 1.1.2's κ)."""
    system = scheme.system
    d = system.dim
    notes = kappa_midpoint_gradient(system)
    expr = sp.Matrix(scheme.discrete_gradient[:d]) - sp.Matrix(notes[:d])
    return certify("energy-momentum: the generated (cancelled) κ∇U(q̄) equals the notes' "
                   "κ∇U(q̄) with κ = (U(q1) - U(q0)) / ((q1 - q0)ᵀ∇U(q̄))",
                   expr, system_domain(system), f"{REF_NOTES}, Ex. 1.1.2")


def kappa_applies(scheme) -> bool:
    """Is the scheme's q-part the notes' single κ∇U(q̄) (Ex. 1.1.2) for this system?

    Yes in one degree of freedom, and when every term of U is a function of the same
    quadratic form E (a radial U: E = |q|²): then Σ V_t[E0, E1] ∇E(q̄) = κ∇U(q̄) exactly.
    For a term-wise discrete gradient (Hénon–Heiles, N-body sums) the method is not the
    notes' κ-scaled midpoint gradient, so the claim is not this method's and is not checked.
    """
    from ..schemes.energy_momentum import decompose

    system = scheme.system
    if system.dim == 1:
        return True
    terms = decompose(system)
    if not terms or any(t.kind != "quadratic-form" for t in terms):
        return False
    forms = {sp.expand(t.E) for t in terms}
    return len(forms) == 1


def dg_items(scheme) -> list[tuple[str, "Certificate"]]:
    """:func:`dg_certificates` with what each certificate is about.

    ``"invariant:H"`` (the identity: the step keeps H), ``"consistency"``,
    ``"kappa"`` and ``"helper"`` (the generated helpers evaluate the functions the
    identity's proof uses).
    """
    system, dg, label = scheme.system, scheme.discrete_gradient, scheme.method
    ref = f"{REF_NOTES}, Ex. 1.1.2" if scheme.method == "energy-momentum" else \
        "discrete gradients (claim 4; McLachlan-Quispel-Robidoux 1999)"
    out = [("invariant:H", dg_identity(system, dg, label, ref, scheme=scheme)),
           ("consistency", dg_consistency(system, dg, label, ref))]
    if scheme.method == "energy-momentum" and kappa_applies(scheme):
        out.append(("kappa", kappa_form(scheme)))
    out += [("helper", c) for c in helper_certificates(list(dg))]
    if (scheme.structure or {}).get("kind") == "avf-quadrature":
        from .quadrature import rule_certificate

        out.append(("quadrature", rule_certificate(*scheme.structure["rule"], "AVF integral")))
    return out


def dg_certificates(scheme) -> list:
    """Identity and consistency for a discrete-gradient scheme; κ for energy-momentum where it is
    the notes' κ; one certificate per generated helper the discrete gradient evaluates."""
    return [cert for _, cert in dg_items(scheme)]
