"""First-same-as-last Störmer–Verlet: one evaluation of ∇U per stage.

A Störmer–Verlet step (stage of a composition) is

    p½ = p0 - (h/2) ∇U(q0),   q1 = q0 + h ∇T(p½),   p1 = p½ - (h/2) ∇U(q1),

and the force at its end, ∇U(q1), is the force at the start of the next stage and of the
next step.  Written with the start force as an input ``G0`` (symbols ``_g0``, ``_g1``, ...),
the step needs ∇U once: at q1, which it returns as the next stage's ``G0``.  The step is
written with three step symbols, kick ``ha`` - drift ``hd`` - kick ``hb`` ((h/2, h, h/2) for
Störmer–Verlet), so that the same kernel runs every stage of a splitting
(:mod:`methodgen.symbolic.splittings`).  The
generated runtimes carry it from stage to stage, from step to step and, through
``info["force"]``, from chunk to chunk.

The carried force is the one the step itself used for its final half kick, evaluated with
the compensated stage sums at ``q0 + (Δq + c)`` -- the exact numerical state at the stage's
end.  The step without first-same-as-last evaluated it afresh at ``q1 + c1`` (the stored
state plus its new compensation): the same point in exact arithmetic, rounded differently.
So the two agree to round-off, not to the bit.

A composed step runs its stages with merged kicks where it can (:func:`merged_stage`): the
stage is then written at y + D, D the composed step's increment so far, for a short chain of
dependent operations from one force to the next.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .derive import separable_gradients, separable_split
from .schemes.base import STEP

__all__ = ["FsalPlan", "fsal_plan", "merged_stage", "STAGE_STEPS"]

#: The three step symbols of a stage (the post kernel's arguments ``_ha, _hd, _hb``).
STAGE_STEPS = (sp.Symbol("_ha", real=True), sp.Symbol("_hd", real=True), sp.Symbol("_hb", real=True))


@dataclass(frozen=True)
class FsalPlan:
    """The first-same-as-last form of a Störmer–Verlet step (:func:`fsal_plan`).

    Attributes
    ----------
    symbols : tuple of sympy.Symbol
        ``G0``: ∇U at the step's start, an input of the step.
    steps : tuple of sympy.Symbol
        ``(ha, hd, hb)``: the first kick's, the drift's and the last kick's step.
    increment : list of sympy.Expr
        Δy = (Δq, Δp) in the start state, ``G0`` and the three steps.
    end_force : list of sympy.Expr
        ∇U(q0 + Δq): the next step's ``G0`` (shares its code with Δp).
    start_force : list of sympy.Expr
        ∇U(q0), for the first step of a run.
    """

    symbols: tuple
    #: The stage's step fractions times h: ``(ha, hd, hb)``, symbols ``_ha, _hd, _hb`` —
    #: kick by ha with G0, drift by hd, kick by hb with the end force.  Störmer–Verlet is
    #: (h/2, h, h/2); a splitting's stages are its (a_k h, d_k h, b_k h)
    #: (:mod:`methodgen.symbolic.splittings`).
    steps: tuple
    increment: list
    end_force: list
    start_force: list


def fsal_applies(scheme) -> bool:
    """Whether :func:`fsal_plan` can apply: Störmer–Verlet (or a composition or projection of
    it) on an unconstrained separable H (cheap; the plan itself is checked when built)."""
    system = scheme.system
    # (a projected method runs its base step: Störmer–Verlet under another name)
    if (getattr(scheme, "projected_from", None) or scheme).method != "stormer-verlet" or system.constraints:
        return False
    return separable_split(system) is not None


def fsal_plan(scheme, full: bool = True) -> FsalPlan | None:
    """The first-same-as-last form of ``scheme`` if it is Störmer–Verlet (or a composition of
    it), else None.

    The plan is checked against the scheme: with ``G0 = ∇U(q0)`` its increment must be the
    scheme's increment expression for expression (structural equality, no floating
    point); otherwise None (the module is then generated without first-same-as-last).

    ``full=False``: Δq only (``increment`` has the d entries of Δq, checked against the
    scheme's; ``end_force`` is empty) -- what a module whose end force and Δp are loops over
    U's families (:func:`methodgen.codegen.lower_loops.force_plan`) uses; the unrolled end force
    ∇U(q0 + Δq) is then never built (a Toda ring of 200: seconds of SymPy).
    """
    if not fsal_applies(scheme):
        return None
    system = scheme.system
    h = STEP
    q0, p0 = list(system.q), list(system.p)
    gT, gU = separable_gradients(system)     # per family of like terms where U has them
    gradU, gradT = sp.Matrix(gU), sp.Matrix(gT)
    G0 = sp.Matrix([sp.Symbol(f"_g{i}", real=True) for i in range(len(q0))])
    ha, hd, hb = STAGE_STEPS
    phalf = sp.Matrix(p0) - ha * G0
    dq = hd * gradT.xreplace(dict(zip(p0, phalf)))
    if not full:
        sv = {ha: h / 2, hd: h, hb: h / 2, **dict(zip(G0, gradU))}
        if dq.xreplace(sv) != sp.Matrix(scheme.increment[:len(q0)]):
            return None
        return FsalPlan(symbols=tuple(G0), steps=STAGE_STEPS, increment=list(dq), end_force=[],
                        start_force=list(gradU))
    g1 = gradU.xreplace(dict(zip(q0, sp.Matrix(q0) + dq)))
    dp = -ha * G0 - hb * g1
    inc = sp.Matrix(list(dq) + list(dp))
    sv = {ha: h / 2, hd: h, hb: h / 2, **dict(zip(G0, gradU))}
    if inc.xreplace(sv) != sp.Matrix(scheme.increment):
        return None
    return FsalPlan(symbols=tuple(G0), steps=STAGE_STEPS, increment=list(inc), end_force=list(g1),
                    start_force=list(gradU))


def merged_stage(plan: FsalPlan, system, comp) -> list:
    """A stage's Δy and end force for a composed step run with merged kicks: the post kernel's
    first expressions where :attr:`methodgen.codegen.lower.ModuleIR.merged_kicks` holds.

    There the kernel is called at ``(q0, p0) + D``, D the composed step's increment so far
    (the compensation symbols ``comp`` stand for it: O(h), not below ulp(y), so ``p0 + D_p`` is
    an ordinary sum), with ``ha`` the merged kick and ``hb`` 0.  Written so that few operations
    depend on the carried force G0 (the stage is latency-bound): with K = ha·G0 (the runtime's
    own kick of D_p, the same product) and T quadratic (∇T(p) = M⁻¹p),

        X  = q0 + ((D_q + hd M⁻¹(p0 + D_p)) - hd M⁻¹K)      (the stage's end, rounded)
        Δq = hd M⁻¹(p0 + D_p) - hd M⁻¹K,   Δp = -K - hb ∇U(X),   end force ∇U(X),

    the same as the plan's increment and end force at y + D in exact arithmetic.  The force
    is evaluated at the rounded point X, its linear part included: every rounding here is of
    a sum of O(h) terms (Brouwer's law measured kept, ``benchmarks/brouwer_slope.py``)."""
    from .compensate import grouped
    from .derive import separable_split

    Minv = separable_split(system).Minv
    q0, p0 = list(system.q), list(system.p)
    ha, hd, hb = plan.steps
    K = sp.Matrix([grouped(ha * g) for g in plan.symbols])   # (the runtime's product)
    P = Minv * sp.Matrix([p + comp[p] for p in p0])
    MK = Minv * K
    drift = [hd * grouped(P[i]) for i in range(len(q0))]
    X = [grouped(q + grouped(grouped(comp[q] + drift[i]) - hd * MK[i])) for i, q in enumerate(q0)]
    _, gU = separable_gradients(system)
    g1 = [sp.sympify(e).xreplace(dict(zip(q0, X))) for e in gU]
    dq = [drift[i] - hd * MK[i] for i in range(len(q0))]
    dp = [-K[i] - hb * g1[i] for i in range(len(q0))]
    return dq + dp + g1
