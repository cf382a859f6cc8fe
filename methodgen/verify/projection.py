"""Certificates of a symmetrically projected method (:mod:`methodgen.projection`).

The base step Φ_h is verified as it is (every claim of :func:`methodgen.verify.verify`,
named "base step Φ_h of …"); on top of it, what the projection keeps:

* the projected invariants: ``g(y1) = g(y0)`` is one of the projected step's defining
  equations, so the *exact* projected map keeps them by construction — ``proved``, with
  the method saying "by construction" (nothing is reduced: it is the equation solved).
  The generated solve meets it to round-off; that part is numerical and is measured by
  the tests and the benchmarks, not claimed here;
* symmetry: derived from the base step's symmetry certificate (the reverse step from y1
  is solved by -λ and ends at y0 [Hairer 2000]): the status of that certificate (proved
  only if the base step's symmetry was proved exactly);
* symplecticity: NOT claimed (no certificate; ``TRAITS["symplectic"]`` is False).
"""

from __future__ import annotations

import time

from .report import PROVED, Certificate

REF = "symmetric projection [Hairer 2000, BIT 40; HLW06 §V.4.1]"


def projection_certificates(scheme, base_certs) -> list[Certificate]:
    """The projection's certificates, from the base step's ``base_certs``."""
    t0 = time.perf_counter()
    names = ", ".join(scheme.projection)
    out = [Certificate(
        claim=f"projected invariants kept: {names} at the run's initial level ({scheme.key})",
        status=PROVED,
        expression="g(y1) - g(y0) = 0 with g = (" + names + ")",
        latex=r"g(y_1) - g(y_0) = 0",
        method="by construction: it is one of the projected step's equations (no reduction); the "
               "generated solve meets it to round-off (numerical, not part of this certificate)",
        seconds=time.perf_counter() - t0, ref=REF,
        details={"projected": list(scheme.projection)})]
    # the map projected is the whole (composed) step: its symmetry certificate
    composed = getattr(scheme, "composition", None) is not None
    sym = [c for c in base_certs if "symmetric" in c.claim and ("composition" in c.claim) == composed]
    if sym:
        src = sym[-1]
        out.append(Certificate(
            claim=f"the projected step is symmetric ({scheme.key})", status=src.status,
            expression="Φ^proj_(-h)(Φ^proj_h(y0)) = y0",
            latex=r"\Phi^{\mathrm{proj}}_{-h}\circ\Phi^{\mathrm{proj}}_{h} = \mathrm{id}",
            method=f"from the base step's symmetry ({src.status}: {src.claim}): the reverse step from "
                   "y1 is solved by -λ and ends at y0",
            seconds=time.perf_counter() - t0, ref=REF, details={"from": src.claim}))
    return out
