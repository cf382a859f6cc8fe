"""Certificates for modules that loop over sums of like terms (:mod:`methodgen.lower_loops`).

A looped module evaluates ``Σ_f Σ_k σ_k(∇̄U_f)`` — each family's template discrete
gradient, renamed to each instance and added into the coordinates of its slots — where
the scheme states ``∇̄U``.  The other claims are proved on the scheme's ``∇̄U``, so the
link is certified here, exactly:

1. the instances are the potential: ``Σ_f Σ_k σ_k(U_f) - U ≡ 0`` (each renaming gives
   its term back; the sum is U's own terms);
2. the template is a discrete gradient of its term, proved once per family:
   ``∇̄U_f(u, u + v)ᵀ v - (U_f(u + v) - U_f(u)) ≡ 0`` — every instance then is one, the
   renaming being a substitution of symbols;
3. the looped sums are the scheme's discrete gradient: ``Σ_f Σ_k scatter(σ_k(∇̄U_f)) - ∇̄U ≡ 0``
   componentwise, with ``v = q1 - q0``.
"""

from __future__ import annotations

import sympy as sp

from ..derive import separable_split
from .exact import certify
from .report import Certificate

REF_LOOPS = "methodgen.lower_loops; LaBudde & Greenspan, J. Comput. Phys. 15 (1974)"


def loop_identities(scheme) -> list[tuple[str, object]]:
    """``[(claim, expression that must be identically 0)]`` of the three certificates."""
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
    for f, lf in enumerate(plan.families):
        fam = lf.family
        end = {u: u + v for u, v in zip(fam.slots, lf.vslots)}
        ident = sp.Add(*[g * v for g, v in zip(lf.dg, lf.vslots)]) - (fam.template.xreplace(end) - fam.template)
        out.append((f"family {f} ({fam.size} instances of {fam.template}): its template's ∇̄ is a "
                    "discrete gradient of the term (proved once for all instances)", ident))
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
    """The three certificates (module docstring), each reduced exactly by :func:`certify`."""
    return [certify(claim, expr, ref=REF_LOOPS) for claim, expr in loop_identities(scheme)]
