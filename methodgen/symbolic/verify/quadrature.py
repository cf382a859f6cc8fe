"""Certificates of the Gauss–Legendre rules that generated modules actually use.

A rule (nodes ``x_k``, weights ``w_k`` on [0, 1]) with m nodes is *Gauss* iff it
integrates every polynomial of degree < 2m exactly.  In the module the rule is made
of float64 numbers, so "exactly" becomes "to round-off": :func:`rule_deviation`
evaluates, in :data:`DPS`-digit arithmetic on the exact binary values of the floats,

    e_p = Σ_k w_k P̃_p(x_k) − ∫_0^1 P̃_p,      p = 0 … 2m − 1,

with ``P̃_p(x) = P_p(2x − 1)`` the shifted Legendre polynomials (|P̃_p| ≤ 1 on [0, 1]:
a well-conditioned basis, unlike the monomials, whose coefficients reach 2^p).
``e_0`` is the weights' sum minus 1.  A correctly rounded rule gives |e_p| of a few
units of 2^-53; :data:`TOLERANCE` is 1e-15.  A rule that is wrong by 1e-12 in one weight
fails (the negative control in the tests).  This is a numerical certificate of the
floats; the exactness of the ideal rule is the rational B(2m) of
:func:`methodgen.symbolic.verify.collocation.moments`.
"""

from __future__ import annotations

import time

import mpmath as mp

from .report import NUMERICAL, REFUTED, Certificate

__all__ = ["DPS", "TOLERANCE", "rule_deviation", "rule_certificate"]

DPS = 60
#: Largest |e_p| accepted for a float64 rule (a correctly rounded rule: ≲ 4e-16, measured for m ≤ 128).
TOLERANCE = 1e-15
REF = "Gauss–Legendre quadrature: exact for polynomials of degree < 2m"


def rule_deviation(nodes, weights) -> dict:
    """``{"sum": e_0, "worst": max_p |e_p|, "worst_degree": p}`` of a rule on [0, 1] (floats).

    Computed at :data:`DPS` digits from the exact values of the given numbers (a float64
    converts to mpmath without rounding), so the result is the rule's own error, not ours.
    """
    m = len(nodes)
    if m != len(weights) or m == 0:
        raise ValueError(f"a rule needs as many weights as nodes (≥ 1), got {len(nodes)} and {len(weights)}")
    with mp.workdps(DPS):
        xs = [2 * mp.mpf(x) - 1 for x in nodes]
        ws = [mp.mpf(w) for w in weights]
        # Σ_k w_k P_p(t_k) for p = 0..2m-1 by the recurrence, all nodes at once
        prev = [mp.mpf(0)] * m
        cur = [mp.mpf(1)] * m
        errs = []
        for p in range(2 * m):
            total = mp.fsum(w * v for w, v in zip(ws, cur))
            errs.append(total - (1 if p == 0 else 0))
            cur, prev = [((2 * p + 1) * t * c - p * q) / (p + 1) for t, c, q in zip(xs, cur, prev)], cur
        worst = max(range(2 * m), key=lambda p: abs(errs[p]))
        return {"sum": float(errs[0]), "worst": float(abs(errs[worst])), "worst_degree": worst}


def rule_certificate(nodes, weights, what: str, tolerance: float = TOLERANCE) -> Certificate:
    """Numerical certificate that the float rule integrates degree < 2m to ``tolerance``.

    Parameters
    ----------
    nodes, weights : sequences of float
        The rule as the module uses it, on [0, 1].
    what : str
        What the rule is used for (goes into the claim).
    tolerance : float
        Largest accepted |e_p| (default :data:`TOLERANCE`).
    """
    t0 = time.perf_counter()
    m = len(nodes)
    dev = rule_deviation(nodes, weights)
    ok = dev["worst"] <= tolerance
    return Certificate(
        f"the float64 {m}-node Gauss–Legendre rule of the module ({what}) sums to 1 and integrates "
        f"every polynomial of degree ≤ {2 * m - 1} to round-off",
        NUMERICAL if ok else REFUTED, "Σ_k w_k P_p(2x_k − 1) − δ_p0, p < 2m", "",
        f"{DPS}-digit evaluation on the float64 nodes and weights (shifted Legendre basis)",
        time.perf_counter() - t0, REF,
        {"nodes": m, "weights_sum_minus_1": dev["sum"], "worst_deviation": dev["worst"],
         "worst_degree": dev["worst_degree"], "tolerance": tolerance, "passed": ok})
