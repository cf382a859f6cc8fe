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
  ``A_a`` and ``-c_ab`` to ``A_b``; the step is ``q1 = q0 + h ∇T(p̄)``, ``p1 = p0 - h A``,
  ``p̄ = (p0 + p1)/2`` (momenta eliminated: ``Δq = h ∇T(p0 - (h/2) A(q0, q0 + Δq))``).  With
  ``(r0 + r1)·(Δq_a - Δq_b) = s1 - s0`` and ``g (s1 - s0) = V_s(s1) - V_s(s0)`` per pair and the
  midpoint identity ``∇T(p̄)·(p1 - p0) = T(p1) - T(p0)`` per particle, ``H(y1) - H(y0) = 0`` for
  every N (the step is a sum of these contributions: :func:`certificates`).  An external
  potential W has no discrete gradient here: refused.

References
----------
.. [1] R. A. LaBudde, D. Greenspan, "Energy and momentum conserving methods of arbitrary order
   for the numerical integration of equations of motion", Numer. Math. 25 (1976) 323-346;
   J. Comput. Phys. 15 (1974) 134-167.
.. [2] E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed. (2006),
   I.1.4 (Störmer–Verlet), II.4 and V.3 (symmetric compositions), IV.1 (invariants).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp

from ..errors import InputError, MethodNotApplicable
from ..problem.particles import Particles

__all__ = ["PARTICLE_METHODS", "ParticleScheme", "discretize_particles", "radial_profile", "certificates",
           "proved_invariants", "invariant_names", "verify_particles", "dg_identity", "kinetic_midpoint_identity",
           "translation_defect", "rotation_defects"]

#: the methods of a particle family, and what they claim
PARTICLE_METHODS = {
    "stormer-verlet": "Störmer–Verlet (kick-drift-kick; symplectic, symmetric; order 2, composed to 4, 6, 8)",
    "energy-momentum": "energy-momentum (LaBudde–Greenspan radial discrete gradient; keeps H, P and L; order 2)",
}
#: the orders Störmer–Verlet is composed to
SV_ORDERS = (2, 4, 6, 8)


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

    @property
    def traits(self) -> dict:
        em = self.method == "energy-momentum"
        return {"order": self.order, "symmetric": True, "symplectic": not em, "energy_preserving": em,
                "composition": self.composition, "stages": max(1, len(self.drifts)),
                "solve": "fixed-point iteration from the Störmer–Verlet predictor" if em else "explicit"}


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


def discretize_particles(fam: Particles, method: str, order: int = 2, composition: str | None = None) -> ParticleScheme:
    """Derive ``method``'s pieces for the family's templates (independent of N).

    Parameters
    ----------
    fam : Particles
    method : {"stormer-verlet", "energy-momentum"}
    order : int
        2, 4, 6 or 8 for Störmer–Verlet (a symmetric composition,
        :data:`methodgen.symbolic.compositions.DEFAULT_FAMILY` unless ``composition`` names one);
        2 for energy-momentum.

    Raises
    ------
    InputError
        An unknown method or order.
    MethodNotApplicable
        energy-momentum for a pair term that is not a function of ``|q_a - q_b|²`` alone, or
        with an external potential.
    """
    from .compositions import composition as _composition

    if method not in PARTICLE_METHODS:
        raise InputError(f"method {method!r} is not available for particles of symbolic size; available: "
                         f"{', '.join(PARTICLE_METHODS)}")
    qa, qb = fam.q_slots
    pa = fam.p_slots[0]
    velocity = _grad(fam.kinetic, pa)
    ext = tuple(-x for x in _grad(fam.external, qa))
    if method == "energy-momentum":
        if order != 2:
            raise InputError(f"energy-momentum for particles is of order 2 (got order {order}); for higher order "
                             "use stormer-verlet --order 4/6/8")
        if fam.external != 0:
            raise MethodNotApplicable(
                f"energy-momentum for particles has no discrete gradient of the external potential "
                f"W = {fam.external}; it takes a kinetic energy and a pair term only (stormer-verlet takes W)")
        prof = radial_profile(fam)
        if prof is None:
            raise MethodNotApplicable(
                f"energy-momentum needs a pair term that is a function of s = |q_i - q_j|² alone; "
                f"{fam.pair} is not (checked exactly); stormer-verlet takes any pair term")
        from .divdiff import divided_difference

        s, Vs = prof
        s0, s1 = sp.Symbol("s0", positive=True), sp.Symbol("s1", positive=True)
        g = divided_difference(Vs, s, s0, s1)
        return ParticleScheme(fam, method, 2, velocity, ((), ()), ext, s, s0, s1, Vs, g)
    if order not in SV_ORDERS:
        raise InputError(f"stormer-verlet for particles is composed to order {', '.join(map(str, SV_ORDERS))}; "
                         f"got {order!r}")
    comp = _composition(order, composition) if order > 2 else _composition(2)
    import mpmath as mp

    with mp.workdps(40):
        g = comp.mp()
        kicks = [g[0] / 2] + [(g[k] + g[k + 1]) / 2 for k in range(len(g) - 1)] + [g[-1] / 2]
        kicks = tuple(float(x) for x in kicks)
        drifts = tuple(float(x) for x in g)
    fa = tuple(-x for x in _grad(fam.pair, qa))
    fb = tuple(-x for x in _grad(fam.pair, qb))
    return ParticleScheme(fam, method, order, velocity, (fa, fb), ext, kicks=kicks, drifts=drifts,
                          composition=comp.family)


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
    symmetric in (s0, s1) (the step is symmetric).

    Each certificate's ``details["keeps"]`` names what it is part of a proof for ("H", "P",
    "L", "symplectic").
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
    out.append(certify("the pair term is a function of s = |q_a - q_b|² alone: V - V_s(s) = 0",
                       fam.pair - scheme.profile.xreplace({scheme.s: S}), ref=ref, details={"keeps": "H"}))
    out.append(certify("chord identity: (r0 + r1)·(Δq_a - Δq_b) = s1 - s0 for any increments",
                       _chord_identity(fam.dim), ref=ref, details={"keeps": "H"}))
    out.append(certify("discrete gradient: g (s1 - s0) = V_s(s1) - V_s(s0), so g (r0 + r1)·(Δq_a - Δq_b) = "
                       "V(s1) - V(s0) per pair", dg_identity(scheme.profile, scheme.s, scheme.g, scheme.s0, scheme.s1),
                       ref=ref, details={"keeps": "H"}))
    out.append(certify("kinetic midpoint identity: ∇T(p̄)·(p1 - p0) = T(p1) - T(p0) per particle",
                       kinetic_midpoint_identity(fam.kinetic, pa), ref=ref, details={"keeps": "H"}))
    if fam.dim >= 2:
        out.append(certify("a pair's contributions ±g (r0 + r1) add no angular momentum at the midpoint positions",
                           sp.Matrix(_pair_angular_identity(fam.dim)), ref=ref, details={"keeps": "L"}))
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
    """What the certificates prove kept at every N: "H" (energy-momentum), "P" (no external
    potential), "L" (d ≥ 2), and "symplectic" (Störmer–Verlet), where every certificate tagged
    for it is proved."""
    keeps: dict[str, bool] = {}
    for c in certs:
        k = (c.details or {}).get("keeps")
        if k is not None:
            keeps[k] = keeps.get(k, True) and c.status == "proved"
    if scheme.family.external != 0:
        keeps.pop("P", None)      # an external force moves the centre of mass
    return [k for k, ok in keeps.items() if ok]


def verify_particles(fam: Particles, method: str = "energy-momentum", order: int = 2,
                     composition: str | None = None) -> list:
    """The certificates of ``method`` on the family ``fam`` (:func:`certificates`): exact, each about
    one template, so they hold at every N."""
    return certificates(discretize_particles(fam, method, order, composition))
