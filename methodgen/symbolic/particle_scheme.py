"""Methods for particle families of symbolic size N, derived once per template.

For ``H = Σ_a [T(p_a) + W(q_a)] + Σ_{a<b} V(q_a, q_b)`` (:class:`methodgen.problem.particles.Particles`)
every quantity a step needs is a sum of *one-body* and *pair* contributions, each an
expression in one template's slots: the generated module evaluates them over the particles
and the pairs of the N of its input, so nothing here depends on N.

Methods:

* ``stormer-verlet`` -- kick, drift, kick: ``p += (h/2) F(q)``, ``q += h ∇T(p)``,
  ``p += (h/2) F(q)`` with ``F = -∇(Σ W + Σ V)`` assembled from the pair forces
  ``-∂V/∂q_a``, ``-∂V/∂q_b``; composed symmetrically to order 4, 6, 8
  (:func:`methodgen.symbolic.compositions.composition`), adjacent half kicks merged.  Each
  kick is the exact flow of the potential (free of the momenta), each drift the exact flow of
  T (free of the positions, ∇T linear in p): a composition of exact Hamiltonian flows, so
  symplectic; total linear and angular momentum are kept when V is translation and rotation
  invariant (and W = 0, resp. W rotation invariant) and T isotropic.
* ``energy-momentum`` -- the radial discrete gradient of LaBudde & Greenspan [1]_: for a pair
  term ``V = V_s(s)``, ``s = |q_a - q_b|²`` (checked exactly), each pair contributes
  ``c_ab = g_ab (r0 + r1)``, ``g_ab = V_s[s0, s1]`` (the divided difference of V_s, in a
  cancellation-free form: :func:`methodgen.symbolic.divdiff.divided_difference`) to
  ``A_a`` and ``-c_ab`` to ``A_b``; an external potential W adds a discrete gradient ``G_a`` of
  W per particle to ``A_a`` (:func:`external_discrete_gradient`); the step is
  ``q1 = q0 + h ∇T(p̄)``, ``p1 = p0 - h A``, ``p̄ = (p0 + p1)/2`` (momenta eliminated:
  ``Δq = h ∇T(p0 - (h/2) A(q0, q0 + Δq))``).  With ``(r0 + r1)·(Δq_a - Δq_b) = s1 - s0`` and
  ``g (s1 - s0) = V_s(s1) - V_s(s0)`` per pair, ``G_a·Δq_a = W(q1_a) - W(q0_a)`` per particle
  and the midpoint identity ``∇T(p̄)·(p1 - p0) = T(p1) - T(p0)`` per particle,
  ``H(y1) - H(y0) = 0`` for every N (the step is a sum of these contributions:
  :func:`certificates`).  The step is symmetric (``g``, ``G`` symmetric in the step's two ends),
  so the symmetric compositions of Störmer–Verlet (stages of size ``γ_k h``, negative ``γ_k``
  included) raise it to order 4, 6, 8 [2]_; each stage keeps H, P and L exactly, so their
  composition does.

The external potential's discrete gradient (:func:`external_discrete_gradient`):

* W a function of ``σ = |q_a|²`` alone (a central field about the origin: a fixed star, an
  isotropic trap; checked exactly): ``G_a = W_σ[σ0, σ1] (q0_a + q1_a)``, the pair term's chord
  identity with ``q_b = 0`` -- along the midpoint ``q̄_a``, so it keeps L as well as H;
* otherwise the symmetrised Itoh–Abe discrete gradient [3]_ [4]_: component k is the divided
  difference of W in the coordinate k with the other coordinates at their start or end values,
  averaged over the d! orders in which the coordinates can be moved from q0 to q1 (for d ≤ 3:
  at most 2^(d-1) = 4 distinct quotients per component, weights ``|S|! (d-1-|S|)! / d!`` for the
  set S of coordinates already moved).  Each ordering telescopes to ``W(q1) - W(q0)``, so the
  average does; the ordering set is closed under reversal, so G is symmetric in (q0, q1).
  Chosen over Gonzalez's midpoint discrete gradient [5]_ because every piece is a divided
  difference in one variable, which :func:`methodgen.symbolic.divdiff.divided_difference`
  writes without the removable singularity at ``q1 = q0`` (no 0/0, no cancellation as
  ``Δq → 0``: the form the pair term's ``V_s[s0, s1]`` is printed in), while Gonzalez's
  correction ``(W(q1) - W(q0) - ∇W(q̄)·Δq) Δq / |Δq|²`` divides an O(|Δq|³) difference of
  O(1) values by ``|Δq|²`` -- its rounding error grows as ``ε |W| / |Δq|`` as ``Δq → 0``, and
  no exact rewriting removes the division for a general W.  The price: Itoh–Abe's G is not
  along ``q̄_a``, so it keeps H but not L, even for a rotation invariant W (such a W is central
  in d ≤ 3 and takes the first branch).

References
----------
.. [1] R. A. LaBudde, D. Greenspan, "Energy and momentum conserving methods of arbitrary order
   for the numerical integration of equations of motion", Numer. Math. 25 (1976) 323-346;
   J. Comput. Phys. 15 (1974) 134-167.
.. [2] E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed. (2006),
   I.1.4 (Störmer–Verlet), II.4 and V.3 (symmetric compositions), IV.1 (invariants).
.. [3] T. Itoh, K. Abe, "Hamiltonian-conserving discrete canonical equations based on
   variational difference quotients", J. Comput. Phys. 76 (1988) 85-102.
.. [4] R. I. McLachlan, G. R. W. Quispel, N. Robidoux, "Geometric integration using discrete
   gradients", Phil. Trans. R. Soc. A 357 (1999) 1021-1045 (the coordinate-increment discrete
   gradient and its symmetrisation).
.. [5] O. Gonzalez, "Time integration and discrete Hamiltonian systems", J. Nonlinear Sci. 6
   (1996) 449-467.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations
from math import factorial

import sympy as sp

from ..errors import InputError, MethodNotApplicable
from ..problem.particles import Particles, particle_symbol

__all__ = ["PARTICLE_METHODS", "ParticleScheme", "discretize_particles", "radial_profile", "certificates",
           "proved_invariants", "invariant_names", "verify_particles", "dg_identity", "kinetic_midpoint_identity",
           "translation_defect", "rotation_defects", "central_profile", "external_discrete_gradient",
           "external_dg_identity", "ORDERS", "SV_ORDERS"]

#: the methods of a particle family, and what they claim
PARTICLE_METHODS = {
    "stormer-verlet": "Störmer–Verlet (kick-drift-kick; symplectic, symmetric; order 2, composed to 4, 6, 8)",
    "energy-momentum": ("energy-momentum (LaBudde–Greenspan radial discrete gradient, a discrete gradient of the "
                        "external potential per particle; keeps H, and P and L where proved; symmetric; order 2, "
                        "composed to 4, 6, 8)"),
}
#: the orders both methods are composed to (symmetric compositions of the order-2 step)
ORDERS = (2, 4, 6, 8)
#: (the name of :data:`ORDERS` from when only Störmer–Verlet was composed)
SV_ORDERS = ORDERS


@dataclass(frozen=True)
class ParticleScheme:
    """A particle method: the templates' pieces, and the composition's coefficients.

    Attributes
    ----------
    family : Particles
    method : str
    order : int
    velocity : tuple of sympy.Expr
        ``∇_p T`` at the particle a (d expressions in ``p_a``, ``m_a``, the parameters).
    pair_force : tuple of two tuples of sympy.Expr
        ``-∂V/∂q_a`` and ``-∂V/∂q_b`` (Störmer–Verlet; d expressions each).
    external_force : tuple of sympy.Expr
        ``-∂W/∂q_a`` (zeros where there is no W).
    s, s0, s1 : sympy.Symbol
        The squared distance and its values at the step's start and end (energy-momentum).
    profile : sympy.Expr or None
        ``V_s(s)`` (energy-momentum).
    g : sympy.Expr or None
        ``V_s[s0, s1]`` in a cancellation-free form (energy-momentum).
    kicks, drifts : tuple of float
        The composition's kick and drift coefficients (Störmer–Verlet): ``s + 1`` kicks around
        ``s`` drifts, adjacent half kicks merged.
    composition : str
    gammas : tuple of float
        The composition's stage coefficients ``γ_1 … γ_s`` (``Σ γ = 1``, symmetric; ``(1.0,)`` at
        order 2): Störmer–Verlet's drifts, energy-momentum's stage sizes ``γ_k h``.
    external_kind : {"none", "central", "itoh-abe"}
        How the external potential's discrete gradient is formed (energy-momentum;
        :func:`external_discrete_gradient`); "none" where W does not depend on the positions.
    external_dg : tuple of sympy.Expr
        ``G_a`` (d expressions in the start slots ``q_a``, the end slots ``q1_a``
        (:attr:`q1_slots`), ``m_a``, the parameters), cancellation-free; () where there is none.
    q1_slots : tuple of sympy.Symbol
        The end positions ``x_a1, y_a1, …`` of the particle a in ``external_dg``.
    sigma, sigma0, sigma1, external_profile, w : sympy.Expr or None
        The central branch: ``σ``, its values at the ends, ``W_σ(σ)`` and ``w = W_σ[σ0, σ1]``.
    """

    family: Particles
    method: str
    order: int
    velocity: tuple
    pair_force: tuple
    external_force: tuple
    s: sp.Symbol | None = None
    s0: sp.Symbol | None = None
    s1: sp.Symbol | None = None
    profile: sp.Expr | None = None
    g: sp.Expr | None = None
    kicks: tuple = ()
    drifts: tuple = ()
    composition: str = "base"
    notes: tuple = field(default=())
    gammas: tuple = (1.0,)
    external_kind: str = "none"
    external_dg: tuple = ()
    q1_slots: tuple = ()
    sigma: sp.Symbol | None = None
    sigma0: sp.Symbol | None = None
    sigma1: sp.Symbol | None = None
    external_profile: sp.Expr | None = None
    w: sp.Expr | None = None

    @property
    def traits(self) -> dict:
        em = self.method == "energy-momentum"
        out = {"order": self.order, "symmetric": True, "symplectic": not em, "energy_preserving": em,
               "composition": self.composition, "stages": max(1, len(self.gammas)),
               "solve": "fixed-point iteration from the Störmer–Verlet predictor" if em else "explicit"}
        if em:
            out["external_discrete_gradient"] = self.external_kind
        return out


def _grad(expr, syms):
    return tuple(sp.diff(expr, s) for s in syms)


def radial_profile(fam: Particles):
    """``(s, V_s)`` with ``V(q_a, q_b) = V_s(|q_a - q_b|²)`` identically, or None.

    V_s is V on a line, ``q_a = (√s, 0, …)``, ``q_b = 0``; it is accepted only when
    ``V - V_s(|q_a - q_b|²)`` simplifies to 0 exactly (no floating point)."""
    qa, qb = fam.q_slots
    s = sp.Symbol("_s", positive=True)
    line = {v: sp.S.Zero for v in qa + qb}
    line[qa[0]] = sp.sqrt(s)
    Vs = fam.pair.xreplace(line)
    if Vs.has(sp.zoo, sp.nan, sp.oo) or Vs.free_symbols & set(qa + qb):
        return None
    diff = fam.pair - Vs.xreplace({s: _s_of(fam)})
    if diff != 0 and sp.simplify(diff) != 0:
        return None
    return s, Vs


def _s_of(fam: Particles) -> sp.Expr:
    qa, qb = fam.q_slots
    return sp.Add(*[(a - b) ** 2 for a, b in zip(qa, qb)])


def central_profile(fam: Particles):
    """``(σ, W_σ)`` with ``W(q_a) = W_σ(|q_a|²)`` identically (a central field about the origin), or None.

    W_σ is W on a ray, ``q_a = (√σ, 0, …)``; accepted only when ``W - W_σ(|q_a|²)`` simplifies to 0
    exactly (no floating point), as :func:`radial_profile` does for the pair term."""
    qa = fam.q_slots[0]
    sig = sp.Symbol("_sigma", positive=True)
    ray = {v: sp.S.Zero for v in qa}
    ray[qa[0]] = sp.sqrt(sig)
    Ws = fam.external.xreplace(ray)
    if Ws.has(sp.zoo, sp.nan, sp.oo) or Ws.free_symbols & set(qa):
        return None
    diff = fam.external - Ws.xreplace({sig: sp.Add(*[v ** 2 for v in qa])})
    if diff != 0 and sp.simplify(diff) != 0:
        return None
    return sig, Ws


def _end_slots(fam: Particles) -> tuple:
    """The end positions of the particle a in a one-body discrete gradient: ``x_a1, y_a1, …``
    (never a parameter's name: those may not start with a field's name and ``_``)."""
    return tuple(particle_symbol(f, "a1") for f in fam.q_names)


def _itoh_abe_parts(W: sp.Expr, q0, q1) -> list:
    """The pieces of the symmetrised Itoh–Abe discrete gradient of ``W(q0)``: per component k, the
    list of ``(weight, S, D)`` with S the set of the other coordinates already at their end values
    and ``D = W[…]_k`` the cancellation-free divided difference in the coordinate k from ``q0_k`` to
    ``q1_k`` (the others at ``q1`` in S, at ``q0`` outside it); ``weight = |S|! (d-1-|S|)! / d!``, the
    share of the d! orderings of the coordinates that move S before k."""
    from .divdiff import divided_difference

    d = len(q0)
    xi = sp.Symbol("_xi", real=True)
    out = []
    for k in range(d):
        others = [l for l in range(d) if l != k]
        parts = []
        for r in range(d):
            for S in combinations(others, r):
                at = {q0[l]: q1[l] for l in S}
                at[q0[k]] = xi
                weight = sp.Rational(factorial(r) * factorial(d - 1 - r), factorial(d))
                parts.append((weight, S, divided_difference(W.xreplace(at), xi, q0[k], q1[k])))
        out.append(parts)
    return out


def external_discrete_gradient(fam: Particles) -> dict:
    """The discrete gradient ``G_a(q0_a, q1_a)`` of the external potential W of one particle.

    ``G·(q1 - q0) = W(q1) - W(q0)`` for any two points, ``G(q0, q1) = G(q1, q0)``, and every quotient
    in it cancellation-free (no 0/0 at ``q1 = q0``, where ``G = ∇W(q0)``).  Central W (a function of
    ``|q_a|²`` alone, :func:`central_profile`): ``G = W_σ[σ0, σ1] (q0 + q1)`` (the LaBudde–Greenspan
    chord form with ``q_b = 0``; along ``q̄``, so L is kept too).  Otherwise the symmetrised
    Itoh–Abe discrete gradient (module docstring: why not Gonzalez's).  O(1) per particle: at most
    ``d 2^(d-1)`` (= 12 at d = 3) one-variable quotients.

    Parameters
    ----------
    fam : Particles
        With W = ``fam.external`` in the slots ``q_a`` (and ``m_a``, the parameters).

    Returns
    -------
    dict
        ``kind`` ("none", "central" or "itoh-abe"), ``G`` (d expressions in ``q_a``, ``q1``, ``m_a``,
        the parameters; () for "none"), ``q1`` (the end slots); central: ``sigma``, ``sigma0``,
        ``sigma1``, ``profile`` (W_σ), ``w`` (W_σ[σ0, σ1]); Itoh–Abe: ``parts``
        (:func:`_itoh_abe_parts`).

    References
    ----------
    Itoh & Abe (1988); McLachlan, Quispel & Robidoux (1999); LaBudde & Greenspan (1974).
    """
    from .divdiff import divided_difference

    qa = fam.q_slots[0]
    q1 = _end_slots(fam)
    W = fam.external
    if not W.free_symbols & set(qa):
        return {"kind": "none", "G": (), "q1": q1}
    prof = central_profile(fam)
    if prof is not None:
        sig, Ws = prof
        s0, s1 = sp.Symbol("sigma0", positive=True), sp.Symbol("sigma1", positive=True)
        w = divided_difference(Ws, sig, s0, s1)
        at = {s0: sp.Add(*[v ** 2 for v in qa]), s1: sp.Add(*[v ** 2 for v in q1])}
        wq = w.xreplace(at)
        return {"kind": "central", "G": tuple(wq * (a + b) for a, b in zip(qa, q1)), "q1": q1, "sigma": sig,
                "sigma0": s0, "sigma1": s1, "profile": Ws, "w": w}
    parts = _itoh_abe_parts(W, qa, q1)
    G = tuple(sp.Add(*[wt * D for wt, _, D in comp]) for comp in parts)
    return {"kind": "itoh-abe", "G": G, "q1": q1, "parts": parts}


def discretize_particles(fam: Particles, method: str, order: int = 2, composition: str | None = None) -> ParticleScheme:
    """Derive ``method``'s pieces for the family's templates (independent of N).

    Parameters
    ----------
    fam : Particles
    method : {"stormer-verlet", "energy-momentum"}
    order : {2, 4, 6, 8}
        Either method composed symmetrically to this order
        (:data:`methodgen.symbolic.compositions.DEFAULT_FAMILY` unless ``composition`` names one):
        Störmer–Verlet's kick-drift-kick stages, energy-momentum's steps of size ``γ_k h``.
    composition : str, optional
        The composition family for order > 2.

    Raises
    ------
    InputError
        An unknown method or order (the message names the valid ones).
    MethodNotApplicable
        energy-momentum for a pair term that is not a function of ``|q_a - q_b|²`` alone.
    """
    from .compositions import stage_composition

    if method not in PARTICLE_METHODS:
        raise InputError(f"method {method!r} is not available for particles of symbolic size; available: "
                         f"{', '.join(PARTICLE_METHODS)}")
    comp = stage_composition(order, composition, offered=ORDERS, what=f"{method} for particles")
    qa, qb = fam.q_slots
    pa = fam.p_slots[0]
    velocity = _grad(fam.kinetic, pa)
    ext = tuple(-x for x in _grad(fam.external, qa))
    import mpmath as mp

    with mp.workdps(40):
        g = comp.mp()
        kicks = [g[0] / 2] + [(g[k] + g[k + 1]) / 2 for k in range(len(g) - 1)] + [g[-1] / 2]
        kicks = tuple(float(x) for x in kicks)
        gammas = tuple(float(x) for x in g)
    if method == "energy-momentum":
        prof = radial_profile(fam)       # (s, 0) where there is no pair term
        if prof is None:
            raise MethodNotApplicable(
                f"energy-momentum needs a pair term that is a function of s = |q_i - q_j|² alone; "
                f"{fam.pair} is not (checked exactly); stormer-verlet takes any pair term")
        from .divdiff import divided_difference

        s0, s1 = sp.Symbol("s0", positive=True), sp.Symbol("s1", positive=True)
        s, Vs = prof
        gpair = divided_difference(Vs, s, s0, s1)
        xd = external_discrete_gradient(fam)
        return ParticleScheme(fam, method, order, velocity, ((), ()), ext, s, s0, s1, Vs, gpair,
                              composition=comp.family, gammas=gammas, external_kind=xd["kind"],
                              external_dg=tuple(xd["G"]), q1_slots=xd["q1"], sigma=xd.get("sigma"),
                              sigma0=xd.get("sigma0"), sigma1=xd.get("sigma1"),
                              external_profile=xd.get("profile"), w=xd.get("w"))
    fa = tuple(-x for x in _grad(fam.pair, qa))
    fb = tuple(-x for x in _grad(fam.pair, qb))
    return ParticleScheme(fam, method, order, velocity, (fa, fb), ext, kicks=kicks, drifts=gammas,
                          composition=comp.family, gammas=gammas)


# --- certificates: each about one template, so about every N ----------------------------------

def translation_defect(expr: sp.Expr, slots) -> sp.Expr:
    """``expr(q + c) - expr(q)`` for a symbolic shift ``c`` of every role's position slots."""
    c = [sp.Symbol(f"_c{k}", real=True) for k in range(len(slots[0]))]
    return expr.xreplace({v: v + ck for role in slots for v, ck in zip(role, c)}) - expr


def rotation_defects(expr: sp.Expr, slots) -> list:
    """The infinitesimal rotations of ``expr`` in each coordinate plane (k, l):
    ``Σ_roles (v_k ∂/∂v_l - v_l ∂/∂v_k) expr`` -- zero iff expr is rotation invariant (the
    Poisson bracket of the angular momentum's (k, l) component with the term)."""
    d = len(slots[0])
    out = []
    for k in range(d):
        for l in range(k + 1, d):
            out.append(sp.Add(*[role[k] * sp.diff(expr, role[l]) - role[l] * sp.diff(expr, role[k])
                                for role in slots]))
    return out


def dg_identity(Vs: sp.Expr, s: sp.Symbol, g: sp.Expr, s0: sp.Symbol, s1: sp.Symbol) -> sp.Expr:
    """``g (s1 - s0) - (V_s(s1) - V_s(s0))``: zero iff g is a discrete gradient of V_s in s."""
    return g * (s1 - s0) - (Vs.xreplace({s: s1}) - Vs.xreplace({s: s0}))


def kinetic_midpoint_identity(T: sp.Expr, p) -> sp.Expr:
    """``∇T(p̄)·(p1 - p0) - (T(p1) - T(p0))`` with ``p̄ = (p0 + p1)/2`` (zero for quadratic T)."""
    p0 = [sp.Symbol(f"{v.name}_0", real=True) for v in p]
    p1 = [sp.Symbol(f"{v.name}_1", real=True) for v in p]
    mid = {v: (a + b) / 2 for v, a, b in zip(p, p0, p1)}
    grad = [sp.diff(T, v).xreplace(mid) for v in p]
    return (sp.Add(*[gk * (b - a) for gk, a, b in zip(grad, p0, p1)])
            - (T.xreplace(dict(zip(p, p1))) - T.xreplace(dict(zip(p, p0)))))


def _chord_identity(d: int) -> sp.Expr:
    """``(r0 + r1)·(Δq_a - Δq_b) - (s1 - s0)`` with ``r1 = r0 + Δq_a - Δq_b``: a polynomial identity."""
    qa = [sp.Symbol(f"_qa{k}", real=True) for k in range(d)]
    qb = [sp.Symbol(f"_qb{k}", real=True) for k in range(d)]
    da = [sp.Symbol(f"_da{k}", real=True) for k in range(d)]
    db = [sp.Symbol(f"_db{k}", real=True) for k in range(d)]
    r0 = [a - b for a, b in zip(qa, qb)]
    r1 = [r + x - y for r, x, y in zip(r0, da, db)]
    s0, s1 = sp.Add(*[x ** 2 for x in r0]), sp.Add(*[x ** 2 for x in r1])
    return sp.expand(sp.Add(*[(x + y) * (u - v) for x, y, u, v in zip(r0, r1, da, db)]) - (s1 - s0))


def _pair_angular_identity(d: int) -> list:
    """The angular momentum a pair's contributions ``±c``, ``c = G (r0 + r1)`` (G any scalar) add
    at the midpoint positions: ``q̄_a ∧ c - q̄_b ∧ c`` per plane, with ``r0 + r1 = 2 (q̄_a - q̄_b)``."""
    qa = [sp.Symbol(f"_ma{k}", real=True) for k in range(d)]
    qb = [sp.Symbol(f"_mb{k}", real=True) for k in range(d)]
    G = sp.Symbol("_G", real=True)
    c = [2 * G * (a - b) for a, b in zip(qa, qb)]
    out = []
    for k in range(d):
        for l in range(k + 1, d):
            out.append(sp.expand((qa[k] - qb[k]) * c[l] - (qa[l] - qb[l]) * c[k]))
    return out


def external_dg_identity(W: sp.Expr, q0, q1, G) -> sp.Expr:
    """``Σ_k G_k (q1_k - q0_k) - (W(q1) - W(q0))``: zero iff ``G`` is a discrete gradient of ``W``
    (``W`` in the symbols ``q0``; ``q1`` the end point's symbols)."""
    return (sp.Add(*[gk * (b - a) for gk, a, b in zip(G, q0, q1)])
            - (W.xreplace(dict(zip(q0, q1))) - W))


def _one_body_chord_identity(d: int) -> sp.Expr:
    """``(q0 + q1)·(q1 - q0) - (σ1 - σ0)``, ``σ = |q|²``: the chord identity with ``q_b = 0``."""
    q0 = [sp.Symbol(f"_q0{k}", real=True) for k in range(d)]
    q1 = [sp.Symbol(f"_q1{k}", real=True) for k in range(d)]
    return sp.expand(sp.Add(*[(a + b) * (b - a) for a, b in zip(q0, q1)])
                     - (sp.Add(*[b ** 2 for b in q1]) - sp.Add(*[a ** 2 for a in q0])))


def _one_body_angular_identity(d: int) -> list:
    """The angular momentum a particle's ``G = w (q0 + q1)`` (w any scalar) adds at its midpoint
    ``q̄ = (q0 + q1)/2``: ``q̄_k G_l - q̄_l G_k`` per plane."""
    q0 = [sp.Symbol(f"_q0{k}", real=True) for k in range(d)]
    q1 = [sp.Symbol(f"_q1{k}", real=True) for k in range(d)]
    w = sp.Symbol("_w", real=True)
    mid = [(a + b) / 2 for a, b in zip(q0, q1)]
    G = [w * (a + b) for a, b in zip(q0, q1)]
    return [sp.expand(mid[k] * G[l] - mid[l] * G[k]) for k in range(d) for l in range(k + 1, d)]


def _external_certificates(scheme: ParticleScheme, certify) -> list:
    """The energy-momentum certificates of the external potential's discrete gradient ``G`` as
    emitted (``scheme.external_dg``): ``G·(q1 - q0) = W(q1) - W(q0)`` for any two points, proved
    in pieces that are each exact (module docstring; :func:`external_discrete_gradient`)."""
    fam = scheme.family
    qa = fam.q_slots[0]
    q1 = scheme.q1_slots
    G = list(scheme.external_dg)
    W = fam.external
    out = []
    swap = {**dict(zip(qa, q1)), **dict(zip(q1, qa))}
    if scheme.external_kind == "central":
        ref = "LaBudde & Greenspan (1974): the chord identity with q_b = 0"
        sig, Ws, w, s0, s1 = scheme.sigma, scheme.external_profile, scheme.w, scheme.sigma0, scheme.sigma1
        out.append(certify("the external potential is a function of σ = |q_a|² alone: W - W_σ(σ) = 0",
                           W - Ws.xreplace({sig: sp.Add(*[v ** 2 for v in qa])}), ref=ref,
                           details={"keeps": "H"}))
        out.append(certify("one-body chord identity: (q0 + q1)·(q1 - q0) = σ1 - σ0",
                           _one_body_chord_identity(fam.dim), ref=ref, details={"keeps": "H"}))
        out.append(certify("discrete gradient of W: w (σ1 - σ0) = W_σ(σ1) - W_σ(σ0), w = W_σ[σ0, σ1]",
                           dg_identity(Ws, sig, w, s0, s1), ref=ref, details={"keeps": "H"}))
        at = {s0: sp.Add(*[v ** 2 for v in qa]), s1: sp.Add(*[v ** 2 for v in q1])}
        out.append(certify("the emitted discrete gradient of W is G = w(σ0, σ1) (q0 + q1), so G·(q1 - q0) = "
                           "W(q1) - W(q0) per particle",
                           sp.Matrix([gk - w.xreplace(at) * (a + b) for gk, a, b in zip(G, qa, q1)]), ref=ref,
                           details={"keeps": ("H", "L") if fam.dim >= 2 else "H"}))
        if fam.dim >= 2:
            out.append(certify("a particle's G = w (q0 + q1) adds no angular momentum at its midpoint: q̄ ∧ G = 0",
                               sp.Matrix(_one_body_angular_identity(fam.dim)), ref=ref, details={"keeps": "L"}))
        out.append(certify("symmetric: w(σ0, σ1) = w(σ1, σ0)", w - w.xreplace({s0: s1, s1: s0}), ref=ref))
        return out
    # Itoh–Abe: G_k = Σ_S w_S D_kS; D_kS Δ_k = W(q^(S ∪ k)) - W(q^S) (each a one-variable divided
    # difference); Σ_k Σ_S w_S (W(q^(S ∪ k)) - W(q^S)) = W(q1) - W(q0) (each ordering telescopes).
    # So G·Δq - (W(q1) - W(q0)) = Σ w_S (the pieces' identities) + (the telescoping sum's): 0.
    ref = "Itoh & Abe (1988); McLachlan, Quispel & Robidoux (1999), the coordinate-increment discrete gradient"
    parts = _itoh_abe_parts(W, qa, q1)

    def at(S):
        return W.xreplace({qa[l]: q1[l] for l in S})

    pieces, tele, form = [], [], []
    for k, comp in enumerate(parts):
        for wt, S, D in comp:
            pieces.append(D * (q1[k] - qa[k]) - (at((*S, k)) - at(S)))
            tele.append(wt * (at((*S, k)) - at(S)))
        form.append(G[k] - sp.Add(*[wt * D for wt, _, D in comp]))
    n = len(pieces)
    out.append(certify(f"each of the {n} one-variable quotients D of the symmetrised Itoh–Abe discrete gradient "
                       "is a divided difference: D (q1_k - q0_k) = W(…) - W(…), coordinate k moved",
                       sp.Matrix(pieces), ref=ref, details={"keeps": "H"}))
    out.append(certify("the orderings telescope: Σ_k Σ_S w_S (W(q^(S ∪ k)) - W(q^S)) = W(q1) - W(q0), "
                       "w_S = |S|! (d-1-|S|)!/d!", sp.Add(*tele) - (at(tuple(range(fam.dim))) - W), ref=ref,
                       details={"keeps": "H"}))
    out.append(certify("the emitted discrete gradient of W is G_k = Σ_S w_S D_kS, so G·(q1 - q0) = W(q1) - W(q0) "
                       "per particle", sp.Matrix(form), ref=ref, details={"keeps": "H"}))
    out.append(certify("symmetric: G(q0, q1) = G(q1, q0)", sp.Matrix([gk - gk.xreplace(swap) for gk in G]), ref=ref))
    return out


def certificates(scheme: ParticleScheme) -> list:
    """The method's claims as exact certificates, each about one template (so for every N).

    Both methods: the pair term is translation invariant (with W = 0: total linear momentum
    P kept) and rotation invariant, T and W rotation invariant (angular momentum L kept; d ≥ 2).
    Störmer–Verlet: the kick is the exact flow of the potential (free of the momenta), the
    drift the exact flow of T (free of the positions, ∇T linear in p): a composition of exact
    flows, symplectic.  Energy-momentum: ``V = V_s(|q_a - q_b|²)``; ``(r0 + r1)·(Δq_a - Δq_b) =
    s1 - s0`` and ``g (s1 - s0) = V_s(s1) - V_s(s0)`` (so ``g (r0 + r1)·(Δq_a - Δq_b) = V(s1) -
    V(s0)`` per pair, any increments); the kinetic midpoint identity per particle; with
    ``Δq_a = h ∇T(p̄_a)``, ``Δp_a = -h Σ_b ±c_ab`` these sum to ``H(y1) - H(y0) = 0`` at every N;
    the pair's ``±c`` add no momentum and, c being along ``q̄_a - q̄_b``, no angular momentum; g
    symmetric in (s0, s1) (the step is symmetric).  An external potential W: its discrete
    gradient ``G`` as emitted satisfies ``G·(q1 - q0) = W(q1) - W(q0)`` per particle
    (:func:`_external_certificates`: central W, ``W = W_σ(|q|²)``, the one-body chord identity
    and ``w = W_σ[σ0, σ1]``, and ``G = w (q0 + q1)`` along ``q̄``, so no angular momentum;
    otherwise Itoh–Abe's pieces, each a one-variable divided difference, and their telescoping).
    Every identity holds for any increments, so for a stage of any size ``γ_k h`` (negative
    included): a composition of stages each keeping H (P, L) keeps them.

    Each certificate's ``details["keeps"]`` names what it is part of a proof for ("H", "P",
    "L", "symplectic"), or a tuple of them.
    """
    from .verify.exact import certify

    fam = scheme.family
    qa, qb = fam.q_slots
    pa = fam.p_slots[0]
    ref_inv = "Hairer, Lubich & Wanner, GNI (2006) IV.1 (Noether: translation and rotation invariance)"
    out = []
    if fam.pair != 0:
        out.append(certify("the pair term depends on q_a - q_b only: V(q_a + c, q_b + c) = V(q_a, q_b)",
                           translation_defect(fam.pair, (qa, qb)), ref=ref_inv, details={"keeps": "P"}))
    if fam.dim >= 2:
        if fam.pair != 0:
            out.append(certify("the pair term is rotation invariant: Σ (q_k ∂/∂q_l - q_l ∂/∂q_k) V = 0 per plane",
                               sp.Matrix(rotation_defects(fam.pair, (qa, qb))), ref=ref_inv, details={"keeps": "L"}))
        out.append(certify("the kinetic energy is isotropic: Σ (p_k ∂/∂p_l - p_l ∂/∂p_k) T = 0 per plane",
                           sp.Matrix(rotation_defects(fam.kinetic, (pa,))), ref=ref_inv, details={"keeps": "L"}))
        if fam.external != 0:
            out.append(certify("the external potential is rotation invariant about the origin",
                               sp.Matrix(rotation_defects(fam.external, (qa,))), ref=ref_inv,
                               details={"keeps": "L"}))
    if scheme.method == "stormer-verlet":
        ref = "Hairer, Lubich & Wanner, GNI (2006) VI.3 (Störmer–Verlet as a composition of exact flows), V.3"
        U_p = [sp.diff(fam.pair, v) for v in pa] + [sp.diff(fam.external, v) for v in pa]
        out.append(certify("the kick is the exact flow of the potential: W and V are free of the momenta",
                           sp.Matrix(U_p), ref=ref, details={"keeps": "symplectic"}))
        hess = [sp.diff(fam.kinetic, u, v, w) for u in pa for v in pa for w in pa]
        out.append(certify("the drift is the exact flow of T: T is free of the positions and ∇T is linear in p",
                           sp.Matrix([sp.diff(fam.kinetic, v) for v in qa] + hess), ref=ref,
                           details={"keeps": "symplectic"}))
        return out
    ref = "LaBudde & Greenspan (1974, 1976); Simo, Tarnow & Wong (1992)"
    S = _s_of(fam)
    if fam.pair != 0:
        out.append(certify("the pair term is a function of s = |q_a - q_b|² alone: V - V_s(s) = 0",
                           fam.pair - scheme.profile.xreplace({scheme.s: S}), ref=ref, details={"keeps": "H"}))
        out.append(certify("chord identity: (r0 + r1)·(Δq_a - Δq_b) = s1 - s0 for any increments",
                           _chord_identity(fam.dim), ref=ref, details={"keeps": "H"}))
        out.append(certify("discrete gradient: g (s1 - s0) = V_s(s1) - V_s(s0), so g (r0 + r1)·(Δq_a - Δq_b) = "
                           "V(s1) - V(s0) per pair",
                           dg_identity(scheme.profile, scheme.s, scheme.g, scheme.s0, scheme.s1),
                           ref=ref, details={"keeps": "H"}))
    if scheme.external_kind != "none":
        out += _external_certificates(scheme, certify)
    out.append(certify("kinetic midpoint identity: ∇T(p̄)·(p1 - p0) = T(p1) - T(p0) per particle",
                       kinetic_midpoint_identity(fam.kinetic, pa), ref=ref, details={"keeps": "H"}))
    if fam.dim >= 2 and fam.pair != 0:
        out.append(certify("a pair's contributions ±g (r0 + r1) add no angular momentum at the midpoint positions",
                           sp.Matrix(_pair_angular_identity(fam.dim)), ref=ref, details={"keeps": "L"}))
    if fam.pair != 0:
        swap = {scheme.s0: scheme.s1, scheme.s1: scheme.s0}
        out.append(certify("symmetric: g(s0, s1) = g(s1, s0)", scheme.g - scheme.g.xreplace(swap), ref=ref))
    return out


def invariant_names(fam: Particles) -> tuple[str, ...]:
    """The monitored quantities: H, the total momentum per axis, the angular momentum per plane."""
    q = fam.q_names
    P = tuple(f"P{f}" for f in q)
    planes = [(k, l) for k in range(fam.dim) for l in range(k + 1, fam.dim)]
    if fam.dim == 2:
        L = ("L",)
    else:
        L = tuple(f"L{q[k]}{q[l]}" for k, l in planes)
    return ("H", *P, *L)


def proved_invariants(scheme: ParticleScheme, certs) -> list[str]:
    """What the certificates prove kept at every N, in the order first tagged: "H"
    (energy-momentum), "P", "L" (d ≥ 2) and "symplectic" (Störmer–Verlet), each where every
    certificate tagged for it is proved -- and never "P" with an external potential that depends
    on the positions (an external force moves the centre of mass), never "L" with the Itoh–Abe
    discrete gradient of W (it is not along ``q̄_a``: it keeps H, not L, even were W rotation
    invariant; a rotation-invariant W in d ≤ 3 is central and takes the chord form)."""
    keeps: dict[str, bool] = {}
    for c in certs:
        k = (c.details or {}).get("keeps")
        for name in ((k,) if isinstance(k, str) else tuple(k or ())):
            keeps[name] = keeps.get(name, True) and c.status == "proved"
    fam = scheme.family
    if fam.external.free_symbols & set(fam.q_slots[0]):
        keeps.pop("P", None)
    if scheme.method == "energy-momentum" and scheme.external_kind == "itoh-abe":
        keeps.pop("L", None)
    return [k for k, ok in keeps.items() if ok]


def verify_particles(fam: Particles, method: str = "energy-momentum", order: int = 2,
                     composition: str | None = None) -> list:
    """The certificates of ``method`` on the family ``fam`` (:func:`certificates`): exact, each about
    one template, so they hold at every N."""
    return certificates(discretize_particles(fam, method, order, composition))
