"""One-step methods for lattices of symbolic size, derived once per site term.

For ``H = Σ_t Σ_{i ∈ R_t} h_t(Z_t(i))`` (:class:`methodgen.problem.lattice.Lattice`; ``Z_t(i)`` the
template's slots at site i) every method here has a discrete gradient of the same form:

    ∇̄H(y0, y1)_{f, j} = Σ_t Σ_{s = (f, o) ∈ slots(t), j - o ∈ R_t} A_{t,s}(Z_t(j - o)|y0, Z_t(j - o)|y1)

with one *piece* ``A_{t,s}`` per term and slot, an expression in the template's slots at the
step's start and end.  The step is ``y1 = y0 + h J ∇̄H(y0, y1)`` (J canonical); its Newton
matrix ``I - h J ∂∇̄H/∂y1`` is banded in the sites (2 × 2 blocks, coupling sites as far apart as
the widest term's slots), cyclic when a term wraps.  The pieces and their derivatives ``∂A_{t,s}/∂Z1_{s'}`` are all a module needs:
they are derived here once, whatever N.

Methods:

* ``avf`` -- the average vector field: ``A_{t,s} = ∫₀¹ ∂h_t/∂s(Z0 + σ(Z1 - Z0)) dσ``, taken
  per additive piece of ``h_t`` by the rule of :class:`methodgen.symbolic.schemes.discrete_gradients.AVF`
  (polynomial: symbolic; ``G(L)`` with L affine: an exact divided difference; otherwise
  Gauss–Legendre quadrature, not exact).  Energy-preserving: for each term,
  ``Σ_s A_{t,s}(Z1_s - Z0_s) = h_t(Z1) - h_t(Z0)`` (the *term lemma*, proved exactly per
  template by :func:`certificates`); summing it over the range and re-indexing the sites
  (``j = i + o``, a bijection of the range onto its shift -- this is how the module assembles
  ∇̄H) gives ``(y1 - y0)ᵀ ∇̄H = H(y1) - H(y0)``, and ``(y1 - y0)ᵀ∇̄H = h ∇̄Hᵀ Jᵀ ∇̄H = 0``.
* ``midpoint`` -- the implicit midpoint rule: ``A_{t,s} = ∂h_t/∂s((Z0 + Z1)/2)``; symplectic,
  keeps quadratic invariants, not H.

A *skew* lattice (one field u, ``u' = S ∇H`` with S a constant skew stencil,
:class:`methodgen.problem.lattice.Lattice`) takes the same pieces: its step is
``u1 - u0 = h S ∇̄H(u0, u1)``.  With the term lemma, ``H(u1) - H(u0) = ∇̄Hᵀ(u1 - u0) =
h ∇̄Hᵀ S ∇̄H``, and that vanishes for every N because S is skew -- proved per stencil by
re-indexing, never expanding N terms (:func:`skew_certificates`).  Its Newton matrix
``I - h S ∂∇̄H/∂u1`` is banded and cyclic, of half-bandwidth the stencil's plus ∂∇̄H's (5 diagonals
for the centred difference and nearest neighbours): the canonical lattices' solver applies
(:mod:`methodgen.runtime.lattice_stepper`: w sites grouped into a block make any band block
tridiagonal).

A *2-D periodic* lattice (:class:`methodgen.problem.lattice.Lattice2D`) takes the same pieces per
template (its slots are 2-D offsets) and the same certificates: the module adds each piece at
the site of its slot, (i + a, j + b) on the torus, a bijection, so the term lemma summed over
the sites is energy at every N × M.  Its Newton matrix is not block tridiagonal; the module
iterates simplified Newton with the constant part, ``I - (h/2) J K`` for K the Hessian of H's
quadratic part (:func:`linear_stencil`), a periodic stencil the 2-D FFT diagonalises.

References
----------
.. [1] G. R. W. Quispel, D. I. McLaren, "A new class of energy-preserving numerical
   integration methods", J. Phys. A 41 (2008) 045206.
.. [2] E. Celledoni et al., J. Comput. Phys. 231 (2012) 6770-6789.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp

from ..errors import InputError
from ..problem.lattice import Lattice, SiteTerm, slot_symbol
from .compositions import stage_composition

__all__ = ["TermPieces", "LatticeScheme", "LATTICE_METHODS", "LATTICE_ORDERS", "discretize_lattice",
           "certificates",
           "skew_certificates", "proved_invariants", "linear_stencil"]

#: the methods a lattice of symbolic size can be discretised with, and what they claim
LATTICE_METHODS = {
    "avf": "average vector field (energy-preserving, symmetric, order 2)",
    "midpoint": "implicit midpoint rule (symplectic, symmetric, order 2; keeps quadratic invariants)",
}

#: the orders a lattice method is run at: its order-2 step, composed symmetrically to 4, 6, 8
LATTICE_ORDERS = (2, 4, 6, 8)

QUADRATURE_NODES = 8


def end_symbol(s: sp.Symbol) -> sp.Symbol:
    """The slot ``s`` at the step's end (``q_p1`` → ``q_p1_new``)."""
    return sp.Symbol(s.name + "_new", real=True)


@dataclass(frozen=True)
class TermPieces:
    """A term's discrete-gradient pieces and their derivatives in the step's end values.

    Attributes
    ----------
    term : SiteTerm
    z0, z1 : tuple of sympy.Symbol
        The slots at the step's start and end (same order as ``term.slots``).
    pieces : tuple of sympy.Expr
        ``A_s`` per slot.
    jac : tuple of tuple of sympy.Expr
        ``jac[a][b] = ∂A_a/∂z1_b``.
    rules : tuple of str
        How each additive part of the template was integrated ("symbolic", "divided
        difference", "quadrature", "midpoint").
    """

    term: SiteTerm
    z0: tuple
    z1: tuple
    pieces: tuple
    jac: tuple
    rules: tuple


@dataclass(frozen=True)
class LatticeScheme:
    """A lattice method: the pieces of every term, and what the method claims."""

    lattice: Lattice
    method: str
    terms: tuple[TermPieces, ...]
    exact_energy: bool
    notes: tuple[str, ...] = field(default=())
    #: the order of the step: 2, or 4, 6, 8 by a symmetric composition of the order-2 step
    order: int = 2
    #: the composition family (:mod:`methodgen.symbolic.compositions`; "base" at order 2)
    composition: str = "base"
    #: the stage sizes γ_1 … γ_s as float64 (Σ γ = 1, symmetric, negative ones included; (1.0,)
    #: at order 2): the step is the order-2 step taken s times, of sizes γ_k h
    gammas: tuple = (1.0,)

    @property
    def traits(self) -> dict:
        avf = self.method == "avf"
        skew = self.lattice.structure == "skew"
        return {"order": self.order, "stages": len(self.gammas), "composition": self.composition,
                "symmetric": True, "symplectic": not avf and not skew,
                "energy_preserving": avf and self.exact_energy,
                "preserved": ("H",) if avf and self.exact_energy else (),
                "structure": self.lattice.structure,
                "solve": ("simplified newton (the constant linear part, a periodic 2-D stencil, solved by the 2-D FFT)"
                          if getattr(self.lattice, "dims", 1) == 2 else
                          "newton (block tridiagonal, cyclic)" if self.lattice.half_width <= 1 else
                          f"newton (banded, half-width {self.lattice.half_width} sites, cyclic: block tridiagonal "
                          f"over groups of {self.lattice.half_width} sites)")}


def _avf_pieces(h: sp.Expr, z0, z1) -> tuple[list, list]:
    from .schemes.discrete_gradients import (_is_polynomial, additive_terms, linear_form_gradient,
                                             linear_form_term)
    from .schemes.quadrature import gauss_legendre_f64

    sigma = sp.Symbol("_sigma", real=True)
    out = [sp.S.Zero] * len(z0)
    rules = []
    poly = []
    for part in additive_terms(h):
        if not part.free_symbols & set(z0):
            continue
        if _is_polynomial(part, z0):
            poly.append(part)
            continue
        lf = linear_form_term(part, z0)
        if lf is not None:
            out = [o + g for o, g in zip(out, linear_form_gradient(lf, z0, z0, z1))]
            rules.append("divided difference")
            continue
        x64, w64 = gauss_legendre_f64(QUADRATURE_NODES)
        for k, s in enumerate(z0):
            g = sp.diff(part, s)
            out[k] += sp.Add(*[sp.Float(repr(w), 17) * g.xreplace({a: a + sp.Float(repr(x), 17) * (b - a)
                                                                   for a, b in zip(z0, z1)})
                               for x, w in zip(x64, w64)])
        rules.append("quadrature")
    if poly:
        P = sp.Add(*poly)
        path = {a: a + sigma * (b - a) for a, b in zip(z0, z1)}
        out = [o + sp.integrate(sp.expand(sp.diff(P, s).xreplace(path)), (sigma, 0, 1))
               for o, s in zip(out, z0)]
        rules.append("symbolic")
    return out, rules


def _midpoint_pieces(h: sp.Expr, z0, z1) -> tuple[list, list]:
    mid = {a: (a + b) / 2 for a, b in zip(z0, z1)}
    return [sp.diff(h, s).xreplace(mid) for s in z0], ["midpoint"]


def discretize_lattice(lattice: Lattice, method: str, order: int = 2, composition: str | None = None) -> LatticeScheme:
    """Derive ``method``'s pieces for every site term of ``lattice`` (independent of N).

    Parameters
    ----------
    lattice : Lattice
    method : {"avf", "midpoint"}
    order : {2, 4, 6, 8}
        Above 2, the order-2 step Φ_h (symmetric: its pieces are, :func:`certificates`) is composed
        symmetrically, ``Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}`` with ``Σ γ = 1``, ``γ_k = γ_{s+1-k}``
        (negative γ included), of order ``order`` [Yos90]_, [Suz90]_, [HLW06]_ §II.4, §V.3.  The
        pieces -- and so every certificate -- are those of Φ, a stage of any size: a composition
        of maps each keeping an invariant keeps it, so what is proved kept is unchanged.  The
        order of Ψ rests on the order conditions of the coefficients
        (:mod:`methodgen.symbolic.compositions`), not on a certificate of the lattice method.
    composition : str, optional
        The family (:data:`methodgen.symbolic.compositions.FAMILIES`; default
        :data:`~methodgen.symbolic.compositions.DEFAULT_FAMILY` of the order).

    Raises
    ------
    InputError
        ``method`` is not one of :data:`LATTICE_METHODS`; an order not 2, 4, 6 or 8; an unknown
        family or one without the order.

    References
    ----------
    .. [Yos90] H. Yoshida, "Construction of higher order symplectic integrators", Phys. Lett. A
       150 (1990) 262-268.
    .. [Suz90] M. Suzuki, "Fractal decomposition of exponential operators with applications to
       many-body theories and Monte Carlo simulations", Phys. Lett. A 146 (1990) 319-323.
    .. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
       Springer 2006, §II.4, §V.3.
    """
    if method not in LATTICE_METHODS:
        raise InputError(f"method {method!r} is not available for a lattice of symbolic size; "
                         f"available: {', '.join(LATTICE_METHODS)}")
    comp = stage_composition(order, composition, offered=LATTICE_ORDERS, what=f"{method} for a lattice")
    make = _avf_pieces if method == "avf" else _midpoint_pieces
    terms, exact = [], True
    for t in lattice.terms:
        z0 = t.symbols()
        z1 = tuple(end_symbol(s) for s in z0)
        pieces, rules = make(t.template, z0, z1)
        exact &= "quadrature" not in rules
        jac = tuple(tuple(sp.diff(a, b) for b in z1) for a in pieces)
        terms.append(TermPieces(t, z0, z1, tuple(pieces), jac, tuple(rules)))
    notes = ()
    if method == "avf" and not exact:
        notes = (f"H kept only up to the error of {QUADRATURE_NODES}-point Gauss-Legendre quadrature in "
                 "the terms that are neither polynomial nor a function of one affine form",)
    return LatticeScheme(lattice, method, tuple(terms), exact, notes, order=order, composition=comp.family,
                         gammas=comp.floats())


def certificates(scheme: LatticeScheme) -> list:
    """The method's claims as certificates, each about one template (so independent of N).

    * ``avf``: per term, the term lemma ``Σ_s A_s (Z1_s - Z0_s) - (h(Z1) - h(Z0)) = 0`` reduced
      exactly (:func:`methodgen.symbolic.verify.exact.certify`); with the re-indexing of the module
      docstring it is energy preservation at every N.
    * both methods: symmetry, ``A_s(Z0, Z1) = A_s(Z1, Z0)`` per term and slot (the step's adjoint
      is itself: y1 = y0 + h J ∇̄H(y0, y1) read backwards is the same equation).
    * a skew lattice: :func:`skew_certificates` (the stencil's skewness, which with the term
      lemma is AVF's energy at every N; linear invariants kept by both methods).

    Each certificate's ``details["keeps"]`` names the quantity it is part of a proof for (``"H"``,
    an invariant's name), where it is one (:func:`proved_invariants`).
    """
    from .verify.exact import certify

    ref = "Quispel & McLaren (2008); Celledoni et al. (2012)"
    out = []
    for tp in scheme.terms:
        t = tp.term
        if not t.slots:
            continue              # a constant: no pieces, nothing to claim
        if scheme.method == "avf":
            h0, h1 = t.template, t.template.xreplace(dict(zip(tp.z0, tp.z1)))
            expr = sp.Add(*[a * (b - c) for a, b, c in zip(tp.pieces, tp.z1, tp.z0)]) - (h1 - h0)
            out.append(certify(f"term lemma: Σ_s A_s ΔZ_s = h(Z1) - h(Z0) for {t.source}", expr, ref=ref,
                               details={"keeps": "H"}))
        swap = {**dict(zip(tp.z0, tp.z1)), **dict(zip(tp.z1, tp.z0))}
        expr = sp.Matrix([a - a.xreplace(swap) for a in tp.pieces])
        out.append(certify(f"symmetric: A_s(Z0, Z1) = A_s(Z1, Z0) for {t.source}", expr, ref=ref))
    if scheme.lattice.structure == "skew":
        out += skew_certificates(scheme.lattice, scheme.method)
    elif scheme.method == "midpoint":
        out += quadratic_invariant_certificates(scheme.lattice)
    return out


def skew_certificates(lattice: Lattice, method: str = "avf") -> list:
    """A skew lattice's structure claims, per stencil (so for every N), proved exactly.

    * ``avf`` -- ``gᵀ S g = 0`` for every g and every N: the site density ``E(i) = g_i Σ_k c_k g_{i+k}``
      summed over the periodic sites, re-indexed part by part (``i → i - k`` in the k-th part, a
      bijection of the sites mod N), is ``Σ_i E'(i)`` with ``E'(i) = Σ_k c_k g_{i-k} g_i``; so
      ``2 Σ_i E(i) = Σ_i (E + E')(i)``, and ``E + E' = Σ_k (c_k + c_{-k}) g_i g_{i+k}`` reduces to 0
      exactly (the pairs c_k, c_{-k} cancel, c_0 = 0).  With the term lemma:
      ``H(u1) - H(u0) = ∇̄Hᵀ(u1 - u0) = h ∇̄Hᵀ S ∇̄H = 0``.
    * both methods, each monitored invariant ``Q = Σ_i Σ_o a_o u_{i+o}`` that is linear with
      constant coefficients (a mass): ``Q(u1) - Q(u0) = h Σ_j (Σ_o a_o) (S v)_j = h (Σ_o a_o)
      (Σ_k c_k) Σ_i v_i`` for the step's ``v`` (any: ∇̄H or ∇H at the midpoint), so Q is kept
      when ``(Σ_o a_o)(Σ_k c_k)`` reduces to 0 (re-indexing ``j = i + k`` again).  Other
      invariants are not decided (nothing is claimed).

    Returns
    -------
    list of Certificate
        Empty for a canonical lattice.
    """
    from .verify.exact import certify

    if lattice.structure != "skew":
        return []
    g = "g"
    c = lattice.stencil
    ref = "re-indexing the periodic sum (McLachlan, Quispel & Robidoux 1999, discrete gradients for y' = S ∇H)"
    out = []
    if method == "avf":
        E = sp.Add(*[ck * slot_symbol(g, 0) * slot_symbol(g, k) for k, ck in c.items()])
        # the k-th part re-indexed i → i - k: every slot moved by -k
        E_re = sp.Add(*[_shift(ck * slot_symbol(g, 0) * slot_symbol(g, k), -k, (g,)) for k, ck in c.items()])
        out.append(certify("skew stencil: gᵀ S g = Σ_i g_i Σ_k c_k g_(i+k) = 0 for every N (the density plus its "
                           "re-indexed form, Σ_k (c_k + c_(-k)) g_i g_(i+k), reduces to 0); with the term lemmas, "
                           "AVF keeps H at every N", sp.expand(E + E_re), ref=ref, details={"keeps": "H"}))
    csum = sp.Add(*c.values())
    for name, terms in lattice.invariants.items():
        a = sp.S.Zero
        linear = True
        for t in terms:
            syms = t.symbols()
            if not syms:
                continue
            coeffs = [sp.diff(t.template, s) for s in syms]
            if any(x.free_symbols & set(syms) for x in coeffs):
                linear = False
                break
            a += sp.Add(*coeffs)
        if not linear:
            continue
        out.append(certify(f"the linear invariant {name} = Σ_i a·{lattice.q_name}_i is kept: Σ_j (S v)_j = (Σ_k c_k) "
                           f"Σ_i v_i by re-indexing, and a·Σ_k c_k reduces to 0", sp.cancel(a * csum),
                           ref="Hairer, Lubich & Wanner, GNI (2006) IV.1 (linear invariants)",
                           details={"keeps": name}))
    return out


def proved_invariants(scheme: LatticeScheme, certs) -> list[str]:
    """The quantities the certificates prove kept at every N: "H" where every certificate tagged
    for H is proved (and AVF's pieces are exact), and each invariant whose certificate is."""
    keeps: dict[str, bool] = {}
    for c in certs:
        k = (c.details or {}).get("keeps")
        if k is not None:
            keeps[k] = keeps.get(k, True) and c.status == "proved"
    if "H" in keeps and not scheme.exact_energy:
        keeps["H"] = False
    return [k for k, ok in keeps.items() if ok]


def _geometry(lattice):
    """``(parse, make, add)`` of the lattice's slots: a slot symbol's (field, offset) or None, the
    symbol of (field, offset), and the sum of two offsets (ints in 1-D, pairs in 2-D)."""
    from ..problem.lattice import _parse_slot, _parse_slot2, slot_symbol2

    if getattr(lattice, "dims", 1) == 2:
        return _parse_slot2, slot_symbol2, lambda a, b: (a[0] + b[0], a[1] + b[1])
    return _parse_slot, slot_symbol, lambda a, b: a + b


def _neg(o):
    return tuple(-x for x in o) if isinstance(o, tuple) else -o


def _shift(expr: sp.Expr, k, fields, geometry=None) -> sp.Expr:
    """``expr`` in slots relative to the site i, rewritten relative to the site i - k (every
    slot (f, o) becomes (f, o + k)); ``geometry`` from :func:`_geometry` (default 1-D)."""
    parse, make, add = geometry or _geometry(None)
    sub = {}
    for s in expr.free_symbols:
        got = parse(s)
        if got and got[0] in fields:
            sub[s] = make(got[0], add(got[1], k))
    return expr.xreplace(sub)


def _site_gradient(terms, field: str, fields, geometry=None) -> sp.Expr:
    """∂/∂field_j of Σ_t Σ_i t(i) as an expression in slots relative to j (full-range terms)."""
    parse, make, add = geometry or _geometry(None)
    out = sp.S.Zero
    for t in terms:
        for f, o in t.slots:
            if f == field:
                out += _shift(sp.diff(t.template, make(f, o)), _neg(o), fields, geometry)
    return out


def _full_periodic(t) -> bool:
    """The term is summed over every site of a periodic lattice (a 2-D term always is)."""
    return not hasattr(t, "lo") or (t.lo.from_end, t.lo.c, t.hi.from_end, t.hi.c) == (False, 1, True, 0)


def quadratic_invariant_certificates(lattice: Lattice) -> list:
    """The midpoint rule keeps each monitored invariant Q that is quadratic and in involution
    with H, on a periodic lattice (1-D, or 2-D: the same with offsets in both directions) --
    decided per template, without expanding in N (or N × M).

    For quadratic Q, Q(y1) - Q(y0) = ∇Q(ȳ)ᵀ(y1 - y0) exactly, and the midpoint step is
    y1 - y0 = h J ∇H(ȳ), so the change is h {Q, H}(ȳ) = h Σ_j E(j) with the bracket's site
    density E (slots relative to j).  Σ_j E(j) vanishes for every state and every N iff E is a
    difference F(j + 1) - F(j) plus nothing: iff the discrete Euler operator
    ``Σ_o S^{-o} ∂E/∂f_o`` is 0 for each field f (the gradient of Σ_j E(j) at any site, whatever
    N) and E(0) = 0.  Both reduce exactly, N never enters.  Lattices whose terms are not summed
    over all sites (boundaries) are not decided here (no certificate: nothing is claimed).

    References
    ----------
    P. E. Hydon, E. L. Mansfield, "A variational complex for difference equations", Found.
    Comput. Math. 4 (2004) 187-217 (the kernel of the difference Euler operator).
    """
    from .verify.exact import certify

    if lattice.structure != "canonical":
        return []                 # the bracket below is the canonical one
    geometry = _geometry(lattice)
    parse, make, _ = geometry
    fields = lattice.fields
    q, p = fields
    allterms = list(lattice.terms) + [t for ts in lattice.invariants.values() for t in ts]
    if not all(_full_periodic(t) for t in allterms if t.slots):   # (constants have no bracket)
        return []
    out = []
    for name, terms in lattice.invariants.items():
        quadratic = True
        for t in terms:
            syms = t.symbols()
            try:
                poly = sp.Poly(t.template, *syms)
                quadratic &= poly.total_degree() <= 2 and not (poly.free_symbols_in_domain & set(syms))
            except sp.PolynomialError:
                quadratic = False
        if not quadratic:
            continue
        E = (_site_gradient(terms, q, fields, geometry) * _site_gradient(lattice.terms, p, fields, geometry)
             - _site_gradient(terms, p, fields, geometry) * _site_gradient(lattice.terms, q, fields, geometry))
        E = sp.expand(E)
        slots = sorted({k for k in map(parse, E.free_symbols) if k and k[0] in fields})
        euler = [sp.Add(*[_shift(sp.diff(E, make(f, o)), _neg(o), fields, geometry) for f2, o in slots if f2 == f])
                 for f in fields]
        at_zero = E.xreplace({make(f, o): 0 for f, o in slots})
        out.append(certify(f"midpoint keeps the quadratic invariant {name}: {{{name}, H}} sums to 0 on the "
                           f"periodic lattice (Euler operator of its site density and its value at 0)",
                           sp.Matrix(euler + [at_zero]),
                           ref="Hairer, Lubich & Wanner, GNI (2006) IV.2; Hydon & Mansfield (2004)",
                           details={"keeps": name}))
    return out


# --- 2-D periodic lattices: the step's constant linear part ----------------------------------

def _quadratic_part(template: sp.Expr, syms) -> sp.Expr:
    """The part of ``template`` that is a homogeneous quadratic form in the slots ``syms`` (its
    additive pieces that are polynomials in the slots, their degree-2 monomials); its Hessian is
    constant."""
    out = sp.S.Zero
    for part in sp.Add.make_args(template):
        if not part.free_symbols & set(syms):
            continue
        try:
            poly = sp.Poly(part, *syms)
        except sp.PolynomialError:
            continue
        if poly.free_symbols_in_domain & set(syms):
            continue
        for monom, coeff in poly.terms():
            if sum(monom) == 2:
                out += coeff * sp.Mul(*[s**e for s, e in zip(syms, monom)])
    return out


def linear_stencil(lattice) -> dict:
    """The constant part of a 2-D lattice step's Newton matrix, as a periodic stencil.

    Each template's quadratic part (:func:`_quadratic_part`) has a constant Hessian C_t; summing
    the templates over the sites gives the Hessian of H's quadratic part, a periodic stencil
    ``(K x)_{f, j} = Σ_{g, d} K[f, g, d] x_{g, j + d}`` with ``K[f, g, o' - o] += C_t[(f, o), (g, o')]``
    (the site j is the slot o of the template at j - o).  For both lattice methods the pieces of
    a quadratic part are its gradient at the midpoint, so their derivative in the step's end
    is ``K / 2``: the module's simplified-Newton matrix is ``I - (h/2) J K``, diagonalised by the
    2-D FFT (one 2 × 2 block per wavenumber).  The rest of the Newton matrix (the derivative of
    the pieces of the non-quadratic part, e.g. a site's ``q⁴`` or ``1 - cos q``) is left to the
    iteration.

    Returns
    -------
    dict
        ``(f, g, (a, b)) → coefficient`` (field indices f, g; a sympy expression in the parameters
        and the sizes), the nonzero entries.
    """
    fields = lattice.fields
    K: dict = {}
    for t in lattice.terms:
        syms = t.symbols()
        Q = _quadratic_part(t.template, syms)
        if Q == 0:
            continue
        for (f, o), s in zip(t.slots, syms):
            for (g, o2), s2 in zip(t.slots, syms):
                c = sp.diff(Q, s, s2)
                if c != 0:
                    key = (fields.index(f), fields.index(g), (o2[0] - o[0], o2[1] - o[1]))
                    K[key] = K.get(key, sp.S.Zero) + c
    return {k: v for k, v in ((k, sp.cancel(v)) for k, v in sorted(K.items())) if v != 0}

