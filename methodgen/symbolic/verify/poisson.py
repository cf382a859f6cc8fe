"""Certificates for Poisson systems ``y' = S(y)∇H(y)`` (:class:`methodgen.PoissonSystem`).

System-level claims:

* ``S + Sᵀ ≡ 0`` (checked at construction; re-proved here so the report carries it);
* the **Jacobi identity** of S — proved, or refuted with the failing index triple and a
  rational point.  A refutation does not stop anything: H and the Casimirs need only
  skew-symmetry (``Ḣ = ∇HᵀS∇H = 0``, ``Ċ = ∇CᵀS∇H = -(S∇C)ᵀ∇H = 0``); what is lost is that S
  defines a Poisson bracket, so the exact flow is not a Poisson map and there is no
  foliation into symplectic leaves (the certificate says so in ``details["lost"]``);
* each **Casimir** found (``S∇C ≡ 0``).

Step-level claims (the scheme's own equations ``y1 = y0 + h S̄ ∇̄H``, ``S̄ = S((y0+y1)/2)``):

* a first integral I of degree ≤ 2 (H, a Casimir) is kept: ``I(y1) - I(y0) = ∇I(ȳ)ᵀ(y1 - y0)``
  (exact for quadratic I, checked) ``= h ∇I(ȳ)ᵀ S̄ ∇̄H`` is reduced to 0 — for a Casimir this
  is ``-(S(ȳ)∇C(ȳ))ᵀ ∇̄H`` and vanishes by the Casimir identity, for H with a discrete gradient
  the discrete-gradient identity covers it (:mod:`.discrete_gradients`);
* symmetry: ``∇̄H(y0, y1) = ∇̄H(y1, y0)`` and ``S̄(y0, y1) = S̄(y1, y0)``.

Kahan's method (Jacobian form) on ``f = S∇H``: the modified energy
``H̃ = H + h/3 ∇Hᵀ(I - h/2 f')⁻¹ f`` and the measure ``dy/det(I - h/2 f')`` of
Celledoni–McLachlan–Owren–Quispel (2013) are claimed only where their conditions hold —
S constant (and, for the measure, invertible) and f quadratic — and then proved by the
structural lemmas of :mod:`.kahan` with J replaced by S.  For a state-dependent S (the rigid
body) the 2013 H̃ is *not* preserved; no claim is made (``tests/test_poisson.py`` refutes it
as a negative control).
"""

from __future__ import annotations

import itertools

import sympy as sp

from ..derive import casimir_invariants, gradient, structure_matrix
from .common import at, system_domain, y1_symbols
from .exact import certify
from .report import FLOW, PROVED, REFUTED, Certificate

__all__ = ["skew_certificate", "jacobi_certificate", "casimir_certificate", "casimir_certificates",
           "structure_symmetry", "kahan_conditions", "REF_POISSON", "LOST_WITHOUT_JACOBI"]

REF_POISSON = "HLW06 §VII.2 (Poisson systems, Casimirs); MQR99 (discrete gradients for y' = S∇H)"
#: What a skew S that fails the Jacobi identity loses (the report's ``details["lost"]``).
LOST_WITHOUT_JACOBI = ("S is only almost-Poisson: its bracket {F, G} = ∇FᵀS∇G is not a Lie bracket, so the "
                       "exact flow is not a Poisson map and has no symplectic leaves; H and the Casimirs "
                       "(which need only skew-symmetry) are still first integrals and are still kept by the "
                       "methods")


def skew_certificate(system, S: sp.Matrix | None = None) -> Certificate:
    """``S + Sᵀ ≡ 0`` (``S`` defaults to the system's; pass another for a negative control)."""
    S = structure_matrix(system) if S is None else sp.Matrix(S)
    return certify(f"the structure matrix is skew-symmetric: S + Sᵀ = 0 (S = {S.tolist()})", S + S.T,
                   system_domain(system), REF_POISSON, subject=FLOW)


def jacobi_certificate(system, S: sp.Matrix | None = None) -> Certificate:
    """The Jacobi identity of S: every cyclic sum ``Σ_l (S_il ∂_l S_jk + S_jl ∂_l S_ki + S_kl ∂_l S_ij)``
    for ``i < j < k`` reduced to 0, or refuted (the failing triple in ``details``)."""
    S = structure_matrix(system) if S is None else sp.Matrix(S)
    y = list(system.y)
    n = len(y)
    triples = list(itertools.combinations(range(n), 3))
    sums = [sp.Add(*[S[i, l] * sp.diff(S[j, k], y[l]) + S[j, l] * sp.diff(S[k, i], y[l])
                     + S[k, l] * sp.diff(S[i, j], y[l]) for l in range(n)]) for i, j, k in triples]
    names = [s.name for s in y]
    claim = ("the structure matrix satisfies the Jacobi identity (S defines a Poisson bracket: the flow "
             "is a Poisson map)")
    if not triples:
        return Certificate(claim, PROVED, "0", "0", "n = 2: no triple of distinct indices (every skew 2×2 "
                           "matrix satisfies it)", 0.0, REF_POISSON, {"triples": 0}, subject=FLOW)
    cert = certify(claim, sums, system_domain(system), REF_POISSON, details={"triples": len(triples)},
                   subject=FLOW)
    if cert.status != PROVED:
        bad = next((t for t, e in zip(triples, sums) if sp.expand(e) != 0), None)
        if bad is not None:
            cert.details["failing_triple"] = [names[i] for i in bad]
            cert.details["cyclic_sum"] = str(sums[triples.index(bad)])
        cert.details["lost"] = LOST_WITHOUT_JACOBI
    return cert


def casimir_certificate(system, name: str, expr: sp.Expr) -> Certificate:
    """``S(y) ∇C(y) ≡ 0``: C is a Casimir (a first integral for every H)."""
    S = structure_matrix(system)
    g = sp.Matrix([sp.diff(expr, s) for s in system.y])
    return certify(f"{name} = {expr} is a Casimir of S: S∇{name} ≡ 0 (a first integral for every H)",
                   S * g, system_domain(system), REF_POISSON, details={"casimir": name}, subject=FLOW)


def casimir_certificates(system) -> list[Certificate]:
    """One :func:`casimir_certificate` per Casimir found (:meth:`PoissonSystem.casimirs`)."""
    return [casimir_certificate(system, inv.name, inv.expr) for inv in casimir_invariants(system)]


def structure_symmetry(scheme, S_bar: sp.Matrix | None = None) -> Certificate:
    """``S̄(y0, y1) = S̄(y1, y0)``: with a symmetric ∇̄H, ``y1 = y0 + hS̄∇̄H`` is its own adjoint.

    ``S_bar`` defaults to the scheme's (``S((y0 + y1)/2)``); pass ``S(y0)`` for a negative control.
    """
    system = scheme.system
    S_bar = scheme.structure_matrix if S_bar is None else sp.Matrix(S_bar)
    y0, y1 = system.y, y1_symbols(system)
    swap = {**dict(zip(y0, y1)), **dict(zip(y1, y0))}
    return certify(f"{scheme.method}: S̄(y0, y1) = S̄(y1, y0) for the structure matrix of the step "
                   "(with ∇̄H symmetric, the adjoint step y0 = y1 - hS̄(y1, y0)∇̄H(y1, y0) is the same "
                   "equation)", S_bar - S_bar.xreplace(swap), system_domain(system), "symmetry (claim 9)")


def structure_times(scheme, dg: sp.Matrix, S_bar: sp.Matrix | None = None) -> sp.Matrix:
    """``S̄ ∇̄H`` of a Poisson scheme (``S_bar`` overrides the scheme's: negative controls)."""
    S_bar = scheme.structure_matrix if S_bar is None else sp.Matrix(S_bar)
    return S_bar * dg


def kahan_conditions(system) -> dict:
    """Whether the CMOQ 2013 theorems apply to Kahan's method on ``y' = S∇H``: ``energy`` (S
    constant, f quadratic) and ``volume`` (also det S ≠ 0), with ``why`` when not."""
    from ..schemes.base import is_quadratic_field

    S = structure_matrix(system)
    const = not (S.free_symbols & set(system.y))
    quad = is_quadratic_field(system)
    out = {"energy": const and quad, "volume": False, "why": ""}
    if not quad:
        out["why"] = "f = S∇H is not quadratic"
    elif not const:
        out["why"] = ("S depends on the state: the modified energy and measure of CMOQ 2013 are "
                      "theorems for a constant structure matrix only")
    else:
        invertible = sp.simplify(S.det()) != 0
        out["volume"] = invertible
        if not invertible:
            out["why"] = "S is singular: the measure argument (det(I + hK) = det A via S) needs S invertible"
    return out


def kahan_poisson_certificates(system) -> list[Certificate]:
    """Modified energy (and measure) of Kahan's method on a constant-S Poisson system, by the
    structural lemmas of :mod:`.kahan` with J replaced by S; nothing when the conditions fail."""
    from .kahan import modified_energy, modified_energy_structural, modified_volume, \
        modified_volume_structural

    cond = kahan_conditions(system)
    out = []
    if cond["energy"]:
        cert = modified_energy_structural(system)
        out.append(cert if cert is not None else modified_energy(system))
    if cond["volume"]:
        cert = modified_volume_structural(system)
        out.append(cert if cert is not None else modified_volume(system))
    return out
