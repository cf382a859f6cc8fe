"""Certificates of a symmetrically projected method (:mod:`methodgen.symbolic.projection`).

The base step Φ_h is verified as it is (every claim of :func:`methodgen.symbolic.verify.verify`,
named "base step Φ_h of …"); on top of it, what the projection keeps:

* the projected invariants: ``g(y1) = g(y0)`` is one of the projected step's defining
  equations; nothing reduces it to 0 symbolically (the step is defined through a solve),
  so it is not ``proved``: it is ``numerical``, the projected step run in 60-digit
  arithmetic (:func:`projected_step`: the base step's own equations, λ by Newton) at
  rational start points with h = 1/10, the change of g measured (``refuted`` above 1e-15).
  The generated float64 solve meets it to round-off: measured by the tests, not here;
* symmetry: derived from the base step's symmetry certificate (the reverse step from y1
  is solved by -λ and ends at y0 [Hairer 2000]): the status of that certificate (proved
  only if the base step's symmetry was proved exactly); the same 60-digit run measures
  ``|Φ^proj_(-h)(Φ^proj_h(y0)) - y0|`` (a defect above 1e-15 refutes it; ``undecided``
  when no certificate of the step's symmetry is found);
* symplecticity: NOT claimed (no certificate; ``TRAITS["symplectic"]`` is False).

The standard projection (``project="energy-standard"``: Φ_h from y0 itself) has the
invariants certificate, measured on its own equations, and no symmetry claim (it is not
symmetric: its measured defect ``|Φ^proj_(-h)(Φ^proj_h(y0)) - y0|`` is O(h^{p+1}), in the
certificate's details).
"""

from __future__ import annotations

import time

import mpmath as mp
import sympy as sp

from .compositions import H_CHECK, REFUTE_ABOVE, ComposedStepper, _start_points
from .exact import guarded
from .numeric import DPS, Stepper, param_point
from .report import NUMERICAL, REFUTED, UNDECIDED, Certificate

REF = "symmetric projection [Hairer 2000, BIT 40; HLW06 §V.4.1]"


def projection_certificates(scheme, base_certs, seconds: float = 60.0) -> list[Certificate]:
    """The projection's certificates, from the base step's ``base_certs``; the 60-digit
    measurement within a budget of ``seconds`` (beyond it: ``undecided``)."""
    from .budget import BudgetExceeded, budget

    t0 = time.perf_counter()
    names = ", ".join(scheme.projection)
    claim = f"projected invariants kept: {names} at the run's initial level ({scheme.key})"
    b = budget(seconds)
    try:
        with b:
            meas = measure(scheme, symmetric=getattr(scheme, "projection_symmetric", True))
    except BudgetExceeded as exc:
        if exc.budget is not b:
            raise
        meas, why = None, f"time budget of {seconds:g} s exceeded"
    except Exception as exc:   # a start point the 60-digit step cannot take: unchecked, not proved
        meas, why = None, f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
    if meas is None:
        out = [Certificate(claim=claim, status=UNDECIDED, expression="g(y1) - g(y0)",
                           method=f"the 60-digit projected step failed: {why}",
                           seconds=time.perf_counter() - t0, ref=REF,
                           details={"projected": list(scheme.projection)})]
    else:
        det = {"projected": list(scheme.projection), **meas}
        bad = meas["invariant_change"] > REFUTE_ABOVE
        out = [Certificate(
            claim=claim, status=REFUTED if bad else NUMERICAL,
            expression="g(y1) - g(y0) with g = (" + names + ")",
            latex=r"g(y_1) - g(y_0)",
            method=(f"numerical, not a proof (g(y1) = g(y0) is an equation the step solves; nothing "
                    f"reduces it to 0): the projected step in {DPS}-digit arithmetic at rational "
                    f"points, h = {H_CHECK}: max |g(y1) - g(y0)| = {meas['invariant_change']:.1e}"),
            seconds=time.perf_counter() - t0, ref=REF, details=det)]
    if not getattr(scheme, "projection_symmetric", True):
        # the standard projection claims no symmetry (TRAITS["symmetric"] is False); the
        # measured defect is in the invariants certificate's details
        return out
    # the map projected is the whole (composed or split) step: its symmetry certificate (a
    # splitting's is worded "the splitting is symmetric", a composition's "the composition is
    # symmetric", the plain base step's names neither)
    comp = getattr(scheme, "composition", None)
    word = None if comp is None else ("splitting" if getattr(comp, "kind", None) == "splitting"
                                      else "composition")
    sym = [c for c in base_certs if "symmetric" in c.claim
           and (word in c.claim if word else not ("composition" in c.claim or "splitting" in c.claim))]
    if not sym:
        # the traits say symmetric: without the step's certificate that is unchecked, not omitted
        out.append(Certificate(
            claim=f"the projected step is symmetric ({scheme.key})", status=UNDECIDED,
            expression="Φ^proj_(-h)(Φ^proj_h(y0)) = y0",
            latex=r"\Phi^{\mathrm{proj}}_{-h}\circ\Phi^{\mathrm{proj}}_{h} = \mathrm{id}",
            method="no symmetry certificate of the projected (composed) step was found among the "
                   "base step's claims: the symmetry the projection inherits is unchecked",
            seconds=time.perf_counter() - t0, ref=REF))
    else:
        src = sym[-1]
        status, measured = src.status, ""
        if meas is not None:
            measured = (f"; measured at {DPS} digits, h = {H_CHECK}: max |Φ^proj_(-h)(Φ^proj_h(y0)) - y0| "
                        f"= {meas['symmetry_defect']:.1e}")
            if meas["symmetry_defect"] > REFUTE_ABOVE:
                status = REFUTED
        out.append(Certificate(
            claim=f"the projected step is symmetric ({scheme.key})", status=status,
            expression="Φ^proj_(-h)(Φ^proj_h(y0)) = y0",
            latex=r"\Phi^{\mathrm{proj}}_{-h}\circ\Phi^{\mathrm{proj}}_{h} = \mathrm{id}",
            method=f"from the base step's symmetry ({src.status}: {src.claim}): the reverse step from "
                   "y1 is solved by -λ and ends at y0" + measured,
            seconds=time.perf_counter() - t0, ref=REF,
            details={"from": src.claim, **({} if meas is None else meas)}))
    return out


# --- the projected step in 60-digit arithmetic --------------------------------------------

class _SplitStepper:
    """A kick-drift-kick splitting ``e^(b_(m+1) hB) e^(a_m hA) … e^(a_1 hA) e^(b_1 hB)`` of
    ``H = T(p) + U(q)`` in 60-digit arithmetic (kick: p -= b h ∇U(q), drift: q += a h ∇T(p))."""

    def __init__(self, system, h, comp):
        from ..derive import separable_split

        sep = separable_split(system)
        pv = param_point(system)
        q, p = list(system.q), list(system.p)
        self.d = len(q)
        self.dU = sp.lambdify([q], [guarded(sp.diff(sep.U, s).xreplace(pv)) for s in q], modules="mpmath")
        self.dT = sp.lambdify([p], [guarded(sp.diff(sep.T, s).xreplace(pv)) for s in p], modules="mpmath")
        self.kicks, self.drifts = comp.mp()
        self.h = h

    def __call__(self, y0):
        with mp.workdps(DPS):
            h = mp.mpf(self.h.p) / self.h.q
            q, p = [mp.mpf(v) for v in y0[:self.d]], [mp.mpf(v) for v in y0[self.d:]]
            for k, b in enumerate(self.kicks):
                if k:
                    a = mp.mpf(self.drifts[k - 1])
                    q = [x + a * h * f for x, f in zip(q, self.dT(p))]
                p = [x - mp.mpf(b) * h * f for x, f in zip(p, self.dU(q))]
            return q + p


def base_stepper(scheme, h):
    """Φ_h of the projected ``scheme``'s base step (composed or split) in 60-digit arithmetic."""
    base = scheme.projected_from
    comp = getattr(base, "composition", None)
    if comp is None:
        return Stepper(base, h)
    if getattr(comp, "kind", None) == "splitting":
        return _SplitStepper(base.system, h, comp)
    return ComposedStepper(base, h, comp.mp())


def projected_step(scheme, flow, y0, symmetric=True):
    """One projected step from ``y0`` in 60-digit arithmetic: ``(y1, max |g(y1) - g(y0)|)``.

    ``ỹ0 = y0 + D(y0)λ, ŷ1 = Φ_h(ỹ0), y1 = ŷ1 + D(y1)λ, g(y1) = g(y0)`` (D = diag(w) Gᵀ):
    y1 by Newton for given λ, λ by Newton, both with central-difference Jacobians.
    ``symmetric=False`` is the standard projection (``ỹ0 = y0``): a negative control.
    """
    from ..projection import gradients

    system = scheme.system
    pv = param_point(system)
    y = list(system.y)
    n = len(y)
    g, G, w = gradients(scheme)
    m = len(g)
    gf = sp.lambdify([y], [guarded(e.xreplace(pv)) for e in g], modules="mpmath")
    Gf = sp.lambdify([y], [guarded(e.xreplace(pv)) for e in G], modules="mpmath")
    wv = [mp.mpf(sp.Rational(e.xreplace(pv)).p) / sp.Rational(e.xreplace(pv)).q for e in w]
    tiny = mp.mpf(10) ** (-(DPS - 8))
    with mp.workdps(DPS):
        y0 = [mp.mpf(v.p) / v.q if isinstance(v, sp.Rational) else mp.mpf(v) for v in y0]
        tgt = gf(y0)

        def corr(x, lam):   # D(x) λ
            Gx = Gf(x)
            return [sum(wv[i] * Gx[a * n + i] * lam[a] for a in range(m)) for i in range(n)]

        def end(lam):
            # y1 = ŷ1 + D(y1)λ by Newton (a plain fixed-point iteration diverges where |∂(Dλ)/∂y|
            # exceeds 1: large λ at a strong force, as for 1/r² pairs near each other), with
            # the Jacobian I − ∂(D(y)λ)/∂y by central differences at 60 digits
            yh = flow([a + b for a, b in zip(y0, corr(y0, lam))] if symmetric else y0)
            y1 = list(yh)
            d = mp.mpf(10) ** (-(DPS // 2))
            for _ in range(60):
                R = [a - b - c for a, b, c in zip(y1, yh, corr(y1, lam))]
                if max(map(abs, R)) <= tiny * (1 + max(map(abs, y1))):
                    return y1
                J = mp.eye(n)
                for j in range(n):
                    up = corr([x + (d if k == j else 0) for k, x in enumerate(y1)], lam)
                    dn = corr([x - (d if k == j else 0) for k, x in enumerate(y1)], lam)
                    for i in range(n):
                        J[i, j] -= (up[i] - dn[i]) / (2 * d)
                dy = mp.lu_solve(J, mp.matrix(R))
                y1 = [x - dy[k] for k, x in enumerate(y1)]
            raise ArithmeticError("the 60-digit Newton solve of y1 = ŷ1 + D(y1)λ did not converge")

        def F(lam):
            return [a - b for a, b in zip(gf(end(lam)), tgt)]

        lam = [mp.mpf(0)] * m
        eps = mp.mpf("1e-20")
        for _ in range(40):
            r = F(lam)
            if max(map(abs, r)) <= tiny:
                break
            J = mp.matrix(m, m)
            for b in range(m):
                up = F([x + (eps if k == b else 0) for k, x in enumerate(lam)])
                dn = F([x - (eps if k == b else 0) for k, x in enumerate(lam)])
                for a in range(m):
                    J[a, b] = (up[a] - dn[a]) / (2 * eps)
            dl = mp.lu_solve(J, mp.matrix(r))
            lam = [x - dl[k] for k, x in enumerate(lam)]
        else:
            raise ArithmeticError("the 60-digit Newton solve for λ did not converge")
        y1 = end(lam)
        return y1, max(abs(a - b) for a, b in zip(gf(y1), tgt))


def measure(scheme, points=2, seed=7, symmetric=True) -> dict:
    """The projected step in 60-digit arithmetic at ``points`` rational start points, h = 1/10:
    the largest change of the projected invariants and the largest symmetry defect."""
    fwd, bwd = base_stepper(scheme, H_CHECK), base_stepper(scheme, -H_CHECK)
    worst_g, worst_s = mp.mpf(0), mp.mpf(0)
    with mp.workdps(DPS):
        for y0 in _start_points(scheme.system, points, seed):
            y1, dg = projected_step(scheme, fwd, y0, symmetric)
            back, _ = projected_step(scheme, bwd, y1, symmetric)
            worst_g = max(worst_g, dg)
            worst_s = max(worst_s, max(abs(a - mp.mpf(b.p) / b.q) for a, b in zip(back, y0)))
    return {"invariant_change": float(worst_g), "symmetry_defect": float(worst_s), "digits": DPS,
            "h": str(H_CHECK), "points": points}
