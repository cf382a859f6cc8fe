"""Claims 1 and 3: angular momentum is a first integral, and the schemes keep it.

* Claim 1 (Ex. 1.1.1): ``{L_ij, H} = 0`` for ``H = pᵀp/(2m) + V(|q|)`` with an
  *undefined* function V (any radial potential), and for the user's own H.
* Claim 3 (Ex. 1.1.3) and every other quadratic invariant a gradient-form
  scheme claims to keep: for quadratic Q, ``Q(y1) - Q(y0) = ∇Q(ȳ)ᵀ(y1 - y0)``
  exactly (checked), and the scheme's equation ``y1 - y0 = h J ∇̄H(y0, y1)`` is
  substituted, leaving ``h ∇Q(ȳ)ᵀ J ∇̄H(y0, y1)`` to reduce.  For explicit or
  linearly implicit steps ``Q(y0 + Δy) - Q(y0)`` is reduced directly.
"""

from __future__ import annotations

import time

import sympy as sp

from ..derive import (_partials, angular_momenta, constraint_monitors, declared, detected_momenta,
                      poisson_bracket)
from ...problem.problem import Hamiltonian
from .common import REF_NOTES, at, system_domain, y1_symbols
from .exact import Domain, certify, fmt_point, guarded
from .report import FLOW, Certificate

__all__ = ["angular_momentum_generic", "angular_momentum_user", "invariant_preserved",
           "invariant_certificates", "invariant_items", "first_integral_certificates",
           "splitting_invariant"]

REF_FIRST_INTEGRALS = "HLW06 §IV.1 (first integrals: {I, H} = 0)"


def angular_momentum_generic(dim: int) -> list[Certificate]:
    """``{q_i p_j - q_j p_i, H} = 0`` for ``H = pᵀp/(2m) + V(|q|)``, V an undefined function."""
    q = sp.symbols(f"q1:{dim + 1}", real=True)
    p = sp.symbols(f"p1:{dim + 1}", real=True)
    m = sp.Symbol("m", positive=True)
    V = sp.Function("V")
    H = sum(v**2 for v in p) / (2 * m) + V(sp.sqrt(sum(v**2 for v in q)))
    out = []
    for i in range(dim):
        for j in range(i + 1, dim):
            L = q[i] * p[j] - q[j] * p[i]
            br = sum(sp.diff(L, a) * sp.diff(H, b) - sp.diff(L, b) * sp.diff(H, a) for a, b in zip(q, p))
            out.append(certify(f"for every radial potential V (undefined function), "
                               f"L = {L} is a first integral: {{L, H}} = 0 ({dim}D)", br,
                               Domain(positive={m}), f"{REF_NOTES}, Ex. 1.1.1"))
    return _about_flow(out)


def _about_flow(certs: list[Certificate]) -> list[Certificate]:
    """``certs`` marked as facts of the exact flow (reports list them apart from the method's)."""
    for c in certs:
        c.subject = FLOW
    return certs


def angular_momentum_user(system: Hamiltonian) -> list[Certificate]:
    """``{L, H} = 0`` for each angular-momentum component of the user's H."""
    return _about_flow([certify(f"{inv.name} = {inv.expr} is a first integral of this H: {{{inv.name}, H}} = 0",
                                poisson_bracket(system, inv.expr, system.H), system_domain(system),
                                f"{REF_NOTES}, Ex. 1.1.1")
                        for inv in angular_momenta(system)])


def first_integral_certificates(system: Hamiltonian) -> list[Certificate]:
    """``{I, H} = 0`` (and ``{I, g_i} = 0`` for each constraint) for every detected total
    momentum and every declared invariant: proved, or refuted with a counterexample point.

    A declared invariant that is refuted here is still monitored, but no method claims it
    (it is not ``exact`` in :func:`methodgen.symbolic.derive.invariants`).
    """
    out = []
    cons = list(system.constraints)
    for kind, invs in (("detected", detected_momenta(system)), ("declared", declared(system))):
        for inv in invs:
            brackets = [poisson_bracket(system, inv.expr, system.H)]
            what = f"{{{inv.name}, H}} = 0"
            if cons:
                brackets += [poisson_bracket(system, inv.expr, g) for g in cons]
                what += " and " + ", ".join(f"{{{inv.name}, g{i + 1}}} = 0" for i in range(len(cons)))
            cert = certify(f"{kind} invariant {inv.name} = {inv.expr} is a first integral of this H: {what}",
                           brackets if len(brackets) > 1 else brackets[0], system_domain(system),
                           REF_FIRST_INTEGRALS)
            cert.details.setdefault("invariant", inv.name)
            cert.details.setdefault("kind", kind)
            out.append(cert)
    return _about_flow(out)


def splitting_invariant(scheme, name: str, expr: sp.Expr) -> Certificate | None:
    """An exact route for a kick–drift splitting (Störmer–Verlet) and ``I`` affine in q and in p.

    The stages recorded in ``scheme.structure`` are recomposed from ``H = T(p) + U(q)`` and
    checked to *be* the scheme's increment.  A drift ``q += τ∇T(p)`` changes such an I by
    exactly ``τ ∂I/∂q(p)·∇T(p)`` and a kick ``p -= τ∇U(q)`` by ``-τ ∂I/∂p(q)·∇U(q)``, so
    I is kept when both expressions vanish identically — proved by :func:`certify` (or
    refuted).  None when the route does not apply.
    """
    if (scheme.structure or {}).get("kind") != "splitting":
        return None
    system = scheme.system
    d = system.dim
    try:
        poly = sp.Poly(expr, *system.y)
    except sp.PolynomialError:
        return None
    if poly.free_symbols_in_domain & set(system.y) or \
            not all(sum(m[:d]) <= 1 and sum(m[d:]) <= 1 for m in poly.monoms()):
        return None
    from .maps import recompose_splitting
    t0 = time.perf_counter()
    rec = recompose_splitting(scheme)
    if rec is None:
        return None
    qs, ps, gradU, gradT = rec.q, rec.p, rec.gradU, rec.gradT
    drift = sp.Add(*[sp.diff(expr, s) * g for s, g in zip(qs, gradT)])
    kick = sp.Add(*[sp.diff(expr, s) * g for s, g in zip(ps, gradU)])
    cert = certify(f"{scheme.method}: {name}(y1) = {name}(y0), {name} = {expr} (kick–drift splitting: "
                   f"∂{name}/∂q·∇T = 0 and ∂{name}/∂p·∇U = 0)", [drift, kick], system_domain(system),
                   "HLW06 Thm IV.2.4 (partitioned RK) / splitting stages")
    if cert.status == "proved":
        cert.method = ("structural: stages recomposed and checked equal to the increment; each stage changes "
                       f"{name} by τ·(∂{name}/∂q·∇T) or −τ·(∂{name}/∂p·∇U) exactly ({name} affine in q and "
                       "in p) + " + cert.method)
    cert.seconds = time.perf_counter() - t0
    return cert


def _is_quadratic(expr, syms) -> bool:
    from ..schemes.base import _degree_at_most   # plain terms read off, else a Poly in the symbols used

    return _degree_at_most(expr, syms, 2)


def invariant_preserved(scheme, name: str, expr: sp.Expr, dg: sp.Matrix | None = None) -> Certificate | None:
    """Certificate that the step keeps ``expr`` (None if no exact route applies).

    Parameters
    ----------
    dg : Matrix, optional
        A (discrete) gradient to use instead of the scheme's (negative controls).
    """
    system = scheme.system
    y0, y1 = system.y, y1_symbols(system)
    d = len(y0) // 2
    ref = f"{REF_NOTES}, Ex. 1.1.3" if name.startswith("L") and scheme.method == "energy-momentum" \
        else "preserved invariants (scheme traits)"
    claim = f"{scheme.method}: {name}(y1) = {name}(y0), {name} = {expr}"
    dg = scheme.discrete_gradient if dg is None else dg
    if dg is not None and _is_quadratic(expr, y0):
        mid = [(a + b) / 2 for a, b in zip(y0, y1)]
        # ∂Q by one pass over Q's terms; sums as one Add (a Python sum re-flattens a growing
        # Add per term: quadratic in the number of terms)
        gQ = at(sp.Matrix(_partials(expr, y0)), y0, mid)
        # Q quadratic: Q(y1) - Q(y0) = ∇Q(ȳ)ᵀ(y1 - y0) exactly (checked, never assumed).
        if sp.expand(at(expr, y0, y1) - expr
                     - sp.Add(*[g * (b - a) for g, a, b in zip(gQ, y0, y1) if g != 0])) != 0:
            return None
        if getattr(scheme, "structure_matrix", None) is not None:
            # a Poisson system: y1 - y0 = h S̄ ∇̄H with S̄ = S((y0 + y1)/2) (methodgen.symbolic.verify.poisson)
            Jdg, how = scheme.structure_matrix * dg, "h S̄ ∇̄H(y0, y1), S̄ = S((y0 + y1)/2)"
        else:
            Jdg, how = sp.Matrix(list(dg[d:]) + [-v for v in dg[:d]]), "h J ∇̄H(y0, y1)"
        e = scheme.h * sp.Add(*[g * v for g, v in zip(gQ, Jdg) if g != 0])
        cert = certify(claim + f" (from the scheme's equations y1 - y0 = {how})", e,
                       system_domain(system), ref)
        cert.method = "substitution of the scheme's equations + " + cert.method
        return cert
    if not scheme.unknowns:
        y1e = [a + b for a, b in zip(y0, scheme.increment)]
        return certify(claim + " (explicit step)", at(expr, y0, y1e) - expr, system_domain(system), ref)
    if scheme.traits.solve == "linear" and len(scheme.unknowns) <= 4:
        z = sp.Matrix(scheme.unknowns)
        A = scheme.residual.jacobian(z)
        b = -scheme.residual.xreplace({s: 0 for s in scheme.unknowns})
        sol = A.LUsolve(b)
        inc = scheme.increment.xreplace(dict(zip(scheme.unknowns, sol)))
        y1e = [a + c for a, c in zip(y0, inc)]
        cert = certify(claim + " (linear solve done symbolically)", at(expr, y0, y1e) - expr,
                       system_domain(system), ref)
        return cert
    return None


def invariant_numerical(scheme, name: str, expr: sp.Expr, points: int = 3, seed: int = 17) -> Certificate:
    """A claimed invariant without an exact route: ``I(Φ_h(y0)) - I(y0)`` in 60 digits.

    The scheme's own equations are solved by 60-digit Newton at exact rational
    start points with h = 1/10.  A change above 1e-15 (far above the ~1e-38
    evaluation error) is a refutation at that exact point; below NUM_TOL it is a
    numerical check — never a proof.
    """
    import random
    import time

    import mpmath as mp

    from .maps import NUM_TOL
    from .numeric import DPS, Stepper, param_point, random_state
    from .report import NUMERICAL, REFUTED
    t0 = time.perf_counter()
    system = scheme.system
    h = sp.Rational(1, 10)
    claim = f"{scheme.method}: {name}(y1) = {name}(y0), {name} = {expr}"
    pv = param_point(system)
    I = sp.lambdify([list(system.y)], guarded(expr.xreplace(pv)), modules="mpmath")
    step = Stepper(scheme, h)
    rng = random.Random(seed)
    worst, pts = mp.mpf(0), []
    with mp.workdps(DPS):
        for _ in range(points):
            y0 = random_state(system, rng)
            y1 = step(y0)
            change = abs(I(y1) - I([mp.mpf(v) for v in y0]))
            pts.append({"y0": fmt_point(dict(zip(system.y, y0))), "change": mp.nstr(change, 5)})
            worst = max(worst, change)
    det = {"h": str(h), "params": fmt_point(pv), "sample_points": pts, "tolerance": NUM_TOL,
           "digits": DPS, "how": "the scheme's equations solved by 60-digit Newton at rational points"}
    if worst > 1e-15:
        det["counterexample"] = max(pts, key=lambda p: float(mp.mpf(p["change"])))
        det["evaluation"] = ("exact rational (y0, h); y1 in 60-digit arithmetic: the change is > 1e-15, "
                             "far above the evaluation error (< 1e-35)")
        return Certificate(claim, REFUTED, f"{name}(y1) - {name}(y0)", "", "60-digit evaluation at rational "
                           "points", time.perf_counter() - t0, "preserved invariants (scheme traits)", det)
    det["passed"] = bool(worst <= NUM_TOL)
    return Certificate(claim, NUMERICAL, f"{name}(y1) - {name}(y0)", "", "60-digit evaluation at rational points "
                       "(no exact route for this invariant and scheme)", time.perf_counter() - t0,
                       "preserved invariants (scheme traits)", det)


def _structural(scheme, name: str, expr) -> Certificate | None:
    """An exact route for collocation methods, where the equations carry float64 coefficients.

    * Gauss collocation and a quadratic first integral I: the coefficients satisfy the
      symplecticity condition b_i a_ij + b_j a_ji = b_i b_j (proved exactly in rational
      arithmetic, :mod:`.collocation`), so every quadratic first integral is preserved
      [HLW06, Thm IV.2.2].
    * energy-preserving collocation on a polynomial H: the structural energy identity of
      :func:`.collocation.energy_collocation_certificates`.

    The claim is about the method (exact coefficients); the generated module runs them
    rounded to float64 (they satisfy the conditions to ~1e-17, below round-off).
    """
    st = scheme.structure or {}
    if st.get("kind") == "collocation":
        from ..schemes.base import _is_quadratic
        from .collocation import gauss_certificates

        inv = next((i for i in scheme.invariants if i.name == name), None)
        if inv is None or not inv.exact or not _is_quadratic(expr, scheme.system.y):
            return None
        t0 = time.perf_counter()
        symp = next(c for c in gauss_certificates(st["stages"]) if c.claim.startswith("symplectic"))
        return Certificate(f"{scheme.method}: {name}(y1) = {name}(y0), {name} = {expr} (quadratic first integral)",
                           symp.status, str(expr), "",
                           "symplecticity condition of the coefficients (exact, rational) + HLW06 Thm IV.2.2",
                           time.perf_counter() - t0, "HLW06 Thm IV.2.2",
                           {"first_integral": inv.why, "coefficients": "float64 in the module (conditions "
                            "hold to ~1e-17)"})
    if st.get("kind") == "energy-collocation" and name == "H":
        from .collocation import energy_collocation_certificates

        out = energy_collocation_certificates(scheme)
        return out[0] if out else None
    return None


def invariant_items(scheme) -> list[tuple[str, Certificate]]:
    """``(f"invariant:{name}", certificate)`` per invariant in ``traits.preserved``.

    H for discrete-gradient schemes is covered by the discrete-gradient identity,
    constraint monitors by :mod:`methodgen.symbolic.verify.constrained`.  The property
    names let a composition's derived claims find the base certificate of each
    invariant (:mod:`methodgen.symbolic.verify.compositions`).
    """
    out = []
    invs = {inv.name: inv.expr for inv in scheme.invariants}
    cons = {inv.name for inv in constraint_monitors(scheme.system)}
    for name in scheme.traits.preserved:
        if name in cons or name not in invs:
            continue
        if name == "H" and scheme.traits.discrete_gradient:
            continue
        cert = _structural(scheme, name, invs[name])
        if cert is None:
            cert = splitting_invariant(scheme, name, invs[name])
        if cert is None:
            cert = invariant_preserved(scheme, name, invs[name])
        # A claimed invariant is never left unchecked: without an exact route it is
        # checked numerically (and refuted where it visibly fails).
        out.append((f"invariant:{name}",
                    cert if cert is not None else invariant_numerical(scheme, name, invs[name])))
    return out


def invariant_certificates(scheme) -> list[Certificate]:
    """One certificate per invariant in ``traits.preserved`` (see :func:`invariant_items`)."""
    return [cert for _, cert in invariant_items(scheme)]
