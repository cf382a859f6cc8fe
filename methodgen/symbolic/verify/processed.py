"""Claims about a processed composition ``π ∘ K_h^n ∘ π⁻¹`` (:mod:`methodgen.symbolic.processing`).

What is certified, and how (both **numerical**: the published coefficients have 15–19 digits,
so nothing here reduces to an exact 0):

1. **Effective order** (:func:`effective_order_certificate`): ``log`` of the whole sequence
   pre-processor, kernel, post-processor in the free associative algebra of the base step
   ``Φ_h = exp(hX1 + h³X3 + …)`` (60 digits) is ``h X1 + O(h^{K+1})``: every defect of weight
   ≤ K below :data:`TOL`; the kernel's own order (4) is reported beside it, so the
   certificate shows what the processing adds.
2. **The float64 coefficients the three modules run** (:func:`float64_certificate`): the
   same conditions on the exact binary values of the rounded coefficients.

Everything else is the kernel's: :func:`verify_processed` runs :func:`methodgen.symbolic.verify.verify`
on the kernel (a symmetric composition of the base step: its coefficients, symmetry, and the
base step's invariants, constraints and symplecticity carried to every real stage step,
negative ones included).  The processors are compositions of the same base step at real
steps, so what the kernel inherits from the base step (a proof that holds for every real h)
holds for them too; the processed map is conjugate to the kernel and so keeps those
invariants at every returned row.  Not claimed: symmetry of the processed map.
"""

from __future__ import annotations

import time
from decimal import Decimal

from ..compositions import order_of_defects
from ..processing import Processed, order_defects
from .report import NUMERICAL, REFUTED, Certificate

REF_BCM = ("Blanes, Casas & Murua, SIAM J. Sci. Comput. 27 (2006) 1817-1843; Hairer, Lubich, Wanner, "
           "Geometric Numerical Integration (2006), §V.3.3")
#: Largest defect at weights ≤ K accepted for the published coefficients (they have 15-19 digits).
TOL = 1e-14
#: A defect above this is a wrong coefficient, not a rounded one.
REFUTE = 1e-10

__all__ = ["effective_order_certificate", "float64_certificate", "verify_processed", "TOL", "REFUTE"]


def _fmt(d):
    return {str(w): f"{v:.1e}" for w, v in sorted(d.items())}


def _check(claim, d, K, details, how) -> Certificate:
    worst = max(d[w] for w in range(1, K + 1))
    details = {**details, "defects_by_weight": _fmt(d), "max_defect_up_to_K": f"{worst:.1e}",
               "tolerance": TOL, "how": how}
    if worst > REFUTE:
        w = min(w for w in range(1, K + 1) if d[w] > REFUTE)
        details["counterexample"] = f"weight {w}: defect {d[w]:.3e}, far above the evaluation error"
        return Certificate(claim, REFUTED, "log(post ∘ K_h ∘ pre) - h X1 up to weight K", "",
                           "60-digit free-algebra order conditions", 0.0, REF_BCM, details)
    details["passed"] = worst <= TOL
    return Certificate(claim, NUMERICAL, "log(post ∘ K_h ∘ pre) - h X1 up to weight K", "",
                       "60-digit free-algebra order conditions", 0.0, REF_BCM, details)


_HOW = ("the base step is exp(hX1 + h³X3 + …) with free generators; log of the sequence pre-processor, "
        "kernel, post-processor (the order of application) truncated at weight K + 1, 60-digit arithmetic: "
        "effective order K iff every weight 2…K coefficient vanishes")


def effective_order_certificate(proc: Processed) -> Certificate:
    """Effective order ``proc.order`` of the published coefficients (numerical, 60 digits)."""
    t0 = time.perf_counter()
    K = proc.order
    d = order_defects(proc.pre + proc.kernel + proc.post, K + 1)
    dk = order_defects(proc.kernel, K + 1)
    kernel_order = order_of_defects(dk, TOL)
    claim = (f"processed composition ({proc.family}, {proc.stages}-stage kernel, {proc.processor_stages}-"
             f"stage processor): π ∘ K_h ∘ π⁻¹ has order {K} for every symmetric base step Φ_h of order 2 "
             f"(the kernel alone: order {kernel_order})")
    cert = _check(claim, d, K, {"kernel_order": kernel_order, "kernel_defects_by_weight": _fmt(dk),
                                "source": proc.source,
                                "why_numerical": "published decimal constants (15-19 digits)"}, _HOW)
    cert.seconds = time.perf_counter() - t0
    return cert


def float64_certificate(proc: Processed) -> Certificate:
    """The same conditions on the float64 coefficients the generated modules run."""
    t0 = time.perf_counter()
    K = proc.order
    seq = [str(Decimal(float(g))) for g in proc.pre + proc.kernel + proc.post]
    d = order_defects(seq, K + 1)
    claim = (f"float64 coefficients of the {proc.family} order-{K} modules (pre-processor, kernel, "
             f"post-processor): the rounded values satisfy the effective-order-{K} conditions up to rounding")
    cert = _check(claim, d, K, {"stages": len(seq)}, _HOW + " (on the exact binary values of the doubles)")
    cert.seconds = time.perf_counter() - t0
    return cert


def verify_processed(base_scheme, proc: Processed, **kw):
    """The report of the processed composition of ``base_scheme`` (order 2, symmetric).

    ``kw`` goes to :func:`methodgen.symbolic.verify.verify` (run on the kernel's composed scheme).
    """
    from . import verify

    kernel = base_scheme.compose(proc.composition("kernel"))
    rep = verify(kernel, **kw)
    rep.certificates[:0] = [effective_order_certificate(proc), float64_certificate(proc)]
    rep.title = f"{base_scheme.method}, processed composition of order {proc.order} ({proc.family}): " + rep.title
    return rep
