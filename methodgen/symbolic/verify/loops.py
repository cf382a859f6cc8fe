"""Certificates for modules that loop over sums of like terms (:mod:`methodgen.codegen.lower_loops`).

A looped module evaluates ``Σ_f Σ_k σ_k(∇̄U_f)`` — each family's template discrete
gradient, renamed to each instance and added into the coordinates of its slots — where
the scheme states ``∇̄U``.  The other claims are proved on the scheme's ``∇̄U``, so the
link is certified here, exactly:

1. the instances are the potential: ``Σ_f Σ_k σ_k(U_f) - U ≡ 0`` (each renaming gives
   its term back; the sum is U's own terms);
2. the looped sums are the scheme's discrete gradient: ``Σ_f Σ_k scatter(σ_k(∇̄U_f)) - ∇̄U ≡ 0``
   componentwise, with ``v = q1 - q0``.

That each term's ∇̄ is a discrete gradient of the term is the scheme's own claim, proved
term-wise by :mod:`methodgen.symbolic.verify.structural` (one lemma per distinct profile V, so like
terms share it).  A whole-template reduction was tried here and is too slow under a budget
(a Lennard-Jones template: 7 s alone, over 60 s on a loaded machine).
"""

from __future__ import annotations

import sympy as sp

from ..derive import separable_split
from .exact import certify
from .report import Certificate

REF_LOOPS = "methodgen.codegen.lower_loops; LaBudde & Greenspan, J. Comput. Phys. 15 (1974)"


def loop_identities(scheme) -> list[tuple[str, object]]:
    """``[(claim, expression that must be identically 0)]`` of the two certificates."""
    plan = scheme.loops
    if plan is None:
        return []
    system = scheme.system
    q, params = list(system.q), list(system.params)
    d = system.dim
    U = separable_split(system).U
    out = []
    q_free = sp.Add(*[t for t in sp.Add.make_args(U) if not (t.free_symbols & set(q))])
    total = sp.Add(*[lf.family.instance(lf.family.template, k, q, params)
                     for lf in plan.families for k in range(lf.family.size)])
    sizes = ", ".join(str(lf.family.size) for lf in plan.families)
    out.append((f"the looped families (instances {sizes}) sum to U exactly", total + q_free - U))
    q1 = list(scheme.y1[:d])
    acc = [sp.S.Zero] * d
    for lf in plan.families:
        fam = lf.family
        for k in range(fam.size):
            idx = fam.index[k]
            ren = fam.renaming(k, q, params)
            ren.update({v: q1[i] - q[i] for v, i in zip(lf.vslots, idx)})
            for j, i in enumerate(idx):
                acc[i] += lf.dg[j].xreplace(ren)
    out.append(("the module's loops over the families evaluate the scheme's ∇̄U (every component)",
                [a - g for a, g in zip(acc, scheme.discrete_gradient[:d])]))
    return out


def loop_certificates(scheme) -> list[Certificate]:
    """The two certificates (module docstring), each reduced exactly by :func:`certify`."""
    return [certify(claim, expr, ref=REF_LOOPS) for claim, expr in loop_identities(scheme)]
