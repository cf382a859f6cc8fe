"""Discrete-gradient methods ``y1 = y0 + h J ∇̄H(y0, y1)``: AVF, Gonzalez, Itoh–Abe.

A discrete gradient satisfies ``(y1 - y0)ᵀ ∇̄H = H(y1) - H(y0)`` and
``∇̄H(y, y) = ∇H(y)``; the method then preserves H exactly [1].  Every form here
avoids the removable 0/0 of its quotient:

* **AVF** ``∫₀¹ ∇H((1-σ)y0 + σy1) dσ``, term by term — integrated symbolically for
  polynomial terms (no quotient at all), as the exact cancelled divided difference
  ``G[L(y0), L(y1)] ∇L`` for terms ``G(L(y))`` of one affine form L (``cos(q)``,
  ``exp(q1 - q2)``, ``1/(x - y)**2``), and by Gauss–Legendre quadrature otherwise
  (exact for polynomials of degree < 2N; energy error O(|Δy|^(2N)) per step — the
  traits say which was used and label H as kept only approximately).
* **Gonzalez** ``∇H(ȳ) + [H(y1) - H(y0) - ∇H(ȳ)ᵀΔ] / |Δ|² Δ`` — the numerator is
  O(|Δ|³) and would cancel catastrophically; for polynomial H it is expanded
  symbolically in (ȳ, Δ) so the O(1) terms cancel exactly; otherwise
  ``H(y1) - H(y0)`` is written as the Itoh–Abe sum ``Σ ∇̄H_i Δ_i`` of cancelled
  divided differences, so the numerator is a sum of O(|Δ|) terms.  At Δ = 0 exactly the (continuous) limit 0
  of the correction is taken.
* **Itoh–Abe** coordinate increments — each component is a divided difference
  in one coordinate, cancelled by :func:`methodgen.symbolic.divdiff.divided_difference`.

References
----------
.. [1] R. I. McLachlan, G. R. W. Quispel, N. Robidoux, Phil. Trans. R. Soc. A 357
   (1999) 1021-1045.
.. [2] O. Gonzalez, J. Nonlinear Sci. 6 (1996) 449-467.
.. [3] T. Itoh, K. Abe, J. Comput. Phys. 76 (1988) 85-102.
"""

from __future__ import annotations

from dataclasses import replace

import sympy as sp

from ..derive import _partials, gradient, plain_terms, potential_families, separable_split
from ..divdiff import divided_difference
from ...problem.special import safe_div
from ...problem.problem import Hamiltonian
from .base import Scheme, Traits, gradient_scheme, loop_family, next_symbol
from .quadrature import gauss_legendre_f64

GAUSS_NODES = 8


def _not_constrained(system: Hamiltonian, name: str) -> str | None:
    if system.constraints:
        return f"{name} does not enforce constraints; use rattle or shake"
    return None


def _is_polynomial(expr: sp.Expr, syms) -> bool:
    """``expr`` is a polynomial in ``syms`` with coefficients free of them: read off plain
    terms (:func:`methodgen.symbolic.derive.plain_terms`), else a ``Poly`` in the symbols it uses (a
    ``Poly`` over all 2d symbols cost ~20 ms per term of a 200-particle chain)."""
    if plain_terms(expr, syms) is not None:
        return True
    fs = expr.free_symbols
    gens = [s for s in syms if s in fs]
    if not gens:
        return True
    try:
        poly = sp.Poly(expr, *gens)
    except sp.PolynomialError:
        return False
    return not (poly.free_symbols_in_domain & set(syms))


def itoh_abe_components(H: sp.Expr, ys, y0, y1) -> list[sp.Expr]:
    """Itoh–Abe discrete-gradient components, each a cancelled divided difference.

    ``∇̄H_i = (H(y1_1..y1_i, y0_i+1..) - H(y1_1..y1_i-1, y0_i..)) / (y1_i - y0_i)``: H with the
    coordinates before i at y1, after i at y0, and coordinate i free, divided-differenced
    in that coordinate.  The components telescope: ``Σ ∇̄H_i (y1_i - y0_i) = H(y1) - H(y0)``.
    """
    out = []
    for i, s in enumerate(ys):
        fixed = {ys[j]: (y1[j] if j < i else y0[j]) for j in range(len(ys)) if j != i}
        out.append(divided_difference(H.xreplace(fixed), s, y0[i], y1[i]))
    return out


# --- AVF ------------------------------------------------------------------------

def additive_terms(e: sp.Expr) -> list[sp.Expr]:
    """The additive terms of ``e`` with products distributed over sums, nothing else expanded.

    ``g**2*(1/(q1 - q2)**2 + 1/(q1 - q3)**2)`` gives the two pair terms; unlike
    ``expand`` it leaves ``(q1 - q2)**-2`` alone, so each term keeps its affine argument.
    """
    if isinstance(e, sp.Add):
        return [t for a in e.args for t in additive_terms(a)]
    if isinstance(e, sp.Mul):
        for k, f in enumerate(e.args):
            if isinstance(f, sp.Add):
                rest = sp.Mul(*(e.args[:k] + e.args[k + 1:]))
                return [rest * t for a in f.args for t in additive_terms(a)]
    return [e]


def linear_form_term(t: sp.Expr, ys) -> tuple[sp.Expr, sp.Symbol, sp.Expr] | None:
    """Write a term as ``G(L(y))`` with L affine in y, or None.

    Returns ``(L, u, G)`` with ``G`` an expression in the fresh symbol ``u`` only
    (besides parameters) such that ``t = G(L)``.  Candidates for L are the
    subexpressions of t that are polynomials of degree 1 in y (``q1 - q2`` in
    ``exp(q1 - q2)``, ``cos(q1 - q2)``, ``1/(q1 - q2)**2``); a candidate is accepted
    when eliminating one of its variables in favour of u leaves no y in t.
    The AVF integral of such a term is exact: ``∫₀¹ ∇t(y0 + σΔ) dσ = G[L(y0), L(y1)] ∇L``.
    """
    yset = set(ys)
    vars_ = t.free_symbols & yset
    if not vars_:
        return None
    u = sp.Dummy("u", real=True)
    cands = []
    for e in sp.preorder_traversal(t):
        if not isinstance(e, sp.Expr) or not (e.free_symbols & yset) or e in cands:
            continue
        try:
            poly = sp.Poly(e, *sorted(vars_, key=str))
        except sp.PolynomialError:
            continue
        if poly.total_degree() == 1 and not (poly.free_symbols_in_domain & yset) \
                and e.free_symbols & yset == vars_:
            cands.append(e)
    for L in sorted(cands, key=sp.count_ops, reverse=True):
        v = sorted(L.free_symbols & yset, key=str)[0]
        a = sp.diff(L, v)
        G = t.xreplace({v: (u - (L - a * v)) / a})
        if not (G.free_symbols & yset):
            return L, u, G
    return None


def linear_form_gradient(lf: tuple[sp.Expr, sp.Symbol, sp.Expr], ys, y0, y1) -> list[sp.Expr]:
    """The exact discrete gradient ``G[L(y0), L(y1)] ∇L`` of a term ``G(L(y))``, L affine.

    ``lf = (L, u, G)`` as returned by :func:`linear_form_term`; one component per symbol
    of ``ys``.  ``G[·, ·]`` is the cancelled divided difference of
    :func:`methodgen.symbolic.divdiff.divided_difference`, and since ``L(y1) - L(y0) = ∇Lᵀ(y1 - y0)``
    (L affine) the identity ``(y1 - y0)ᵀ G[L0, L1] ∇L = G(L1) - G(L0)`` holds exactly.  It
    is both the AVF integral of the term and its energy-momentum discrete gradient.
    """
    L, u, G = lf
    L0, L1 = L.xreplace(dict(zip(ys, y0))), L.xreplace(dict(zip(ys, y1)))
    dd = divided_difference(G, u, L0, L1)
    used = L.free_symbols      # ∂L/∂s = 0 for the others: no diff of L per symbol of ys
    return [sp.diff(L, s) * dd if s in used else sp.S.Zero for s in ys]


class AVF:
    NAME = "avf"
    SUMMARY = "average vector field discrete gradient (energy-preserving, symmetric, order 2)"

    @staticmethod
    def applies(system):
        return _not_constrained(system, "AVF")

    @staticmethod
    def build(system: Hamiltonian, nodes: int = GAUSS_NODES) -> Scheme:
        grad = gradient(system)
        ys = system.y
        sigma = sp.Symbol("_sigma", real=True)
        # Nodes and weights on [0, 1], computed at 60 digits and rounded to float64 once
        # (numpy's leggauss is a few ulp off: 2e-15 in the moments at 64 nodes), as 17-digit
        # Floats; the rule is certified by verify (methodgen.symbolic.verify.quadrature).
        x64, w64 = gauss_legendre_f64(nodes)
        cs = [sp.Float(repr(x), 17) for x in x64]
        ws = [sp.Float(repr(w), 17) for w in w64]
        # Each additive term of H is integrated on its own, by the first rule that is exact:
        # polynomial → symbolic integral; a function of one affine form L(y) (one
        # coordinate, q1 - q2, ...) → the divided difference G[L(y0), L(y1)] ∇L; otherwise
        # Gauss–Legendre quadrature of its gradient (the only inexact case).
        terms = [t for t in additive_terms(system.H) if t.free_symbols & set(ys)]
        plan = []
        for t in terms:
            if _is_polynomial(t, ys):
                plan.append(("symbolic", t, None))
            else:
                lf = linear_form_term(t, ys)
                plan.append(("divided-difference", t, lf) if lf is not None else ("quadrature", t, None))
        kinds = [k for k, _, _ in plan]
        parts = []   # term-wise pieces for the structural proof (methodgen.symbolic.verify.structural)

        def dg(y0, y1):
            path = {a: a + sigma * (b - a) for a, b in zip(y0, y1)}
            poly = sp.Add(*[t for k, t, _ in plan if k == "symbolic"])
            # ∂poly/∂s by one pass over its terms (_partials), and no integral of a zero
            out = [sp.integrate(sp.expand(g.xreplace(path)), (sigma, 0, 1)) if g != 0 else sp.S.Zero
                   for g in _partials(poly, ys)]
            parts.clear()
            parts.append({"expr": poly, "dg": list(out), "profile": None})
            for kind, t, lf in plan:
                if kind == "divided-difference":
                    g_t = linear_form_gradient(lf, ys, y0, y1)
                    out = [o + g for o, g in zip(out, g_t)]
                    L, u, G = lf
                    parts.append({"expr": t, "dg": g_t, "profile": (G, u, L, [sp.diff(L, s) if s in L.free_symbols
                                                                              else sp.S.Zero for s in ys])})
                elif kind == "quadrature":
                    gt = [sp.diff(t, s) for s in ys]
                    out = [o + sp.Add(*[wk * g.xreplace({a: a + ck * (b - a) for a, b in zip(y0, y1)})
                                        for ck, wk in zip(cs, ws)]) for o, g in zip(out, gt)]
            return sp.Matrix(out)

        used = sorted(set(kinds))
        notes = []
        if "symbolic" in used:
            notes.append("AVF integral computed symbolically for the polynomial components")
        if "divided-difference" in used:
            notes.append("AVF integral as exact cancelled divided differences G[L(y0), L(y1)] ∇L for the "
                         "terms G(L(y)) of H with L affine (one coordinate, a difference, ...)")
        if "quadrature" in used:
            notes.append(f"AVF integral by {nodes}-point Gauss-Legendre quadrature for the other "
                         f"terms (exact for polynomials of degree < {2 * nodes})")
        exact = "quadrature" not in used
        # With quadrature, H is kept only up to the quadrature error: not claimed as exact.
        traits = Traits(order=2, symmetric=True, symplectic=False, energy_preserving=exact,
                        preserved=("H",) if exact else (), solve="newton", discrete_gradient=True,
                        approximate=() if exact else ("H",),
                        notes=tuple(notes) + (() if exact else (
                            "H kept only up to the quadrature error O(|Δy|^%d) per step (not exactly; "
                            "its certificates are numerical)" % (2 * nodes),)))
        scheme = gradient_scheme(system, AVF.NAME, dg, traits,
                                 "y1 = y0 + h J ∫₀¹ ∇H((1-σ) y0 + σ y1) dσ", loops=AVF._loops(system, cs, ws))
        if not exact:
            return replace(scheme, structure={"kind": "avf-quadrature", "rule": (x64, w64)})
        # ∇̄H = (AVF integral of the polynomial terms) + Σ G[L0, L1] ∇L, in the scheme's y0/y1
        # symbols: the identity is proved term by term from these pieces.
        return replace(scheme, structure={"kind": "term-wise", "terms": tuple(parts)})


    @staticmethod
    def _loops(system: Hamiltonian, cs, ws) -> tuple:
        """U's families of like terms, each template's AVF integral taken once by the rule
        :meth:`build` applies to a term (the integral is linear in U, so the sum of the
        instances' integrals is the scheme's): the module loops over them.  Empty unless
        the momenta can be eliminated (separable H, quadratic kinetic energy)."""
        # the families are H's own terms (not those of an expanded H), so the pieces
        # below are exactly the terms build() integrates, each by the same rule
        fams = potential_families(system)
        if fams is None or system.constraints or separable_split(system).Minv is None:
            return ()
        sigma = sp.Symbol("_sigma", real=True)
        out = []
        for fam in fams:
            u = list(fam.slots)
            u1 = [next_symbol(s) for s in u]
            dg = [sp.S.Zero] * len(u)
            # a template k*(cos(u0 - u1) + cos(u2 - u3)) is two of build()'s terms: each
            # piece by its own rule (two exact divided differences, not one quadrature)
            for t in additive_terms(fam.template):
                if not t.free_symbols & set(u):
                    continue
                if _is_polynomial(t, u):
                    path = {a: a + sigma * (b - a) for a, b in zip(u, u1)}
                    piece = [sp.integrate(sp.expand(sp.diff(t, s).xreplace(path)), (sigma, 0, 1)) for s in u]
                else:
                    lf = linear_form_term(t, u)
                    if lf is not None:
                        piece = linear_form_gradient(lf, u, u, u1)
                    else:
                        piece = [sp.Add(*[wk * sp.diff(t, s).xreplace({a: a + ck * (b - a) for a, b in zip(u, u1)})
                                          for ck, wk in zip(cs, ws)]) for s in u]
                dg = [a + b for a, b in zip(dg, piece)]
            out.append(loop_family(fam, dg))
        return tuple(out)


# --- Gonzalez -------------------------------------------------------------------------

class Gonzalez:
    NAME = "gonzalez"
    SUMMARY = "Gonzalez midpoint discrete gradient (energy-preserving, symmetric, order 2)"

    @staticmethod
    def applies(system):
        return _not_constrained(system, "Gonzalez' method")

    @staticmethod
    def build(system: Hamiltonian) -> Scheme:
        ys = system.y
        n = len(ys)
        H = system.H
        grad = gradient(system)
        mids = [sp.Symbol(f"_m_{s.name}", real=True) for s in ys]
        dels = [sp.Symbol(f"_D_{s.name}", real=True) for s in ys]
        t = sp.Symbol("_t", real=True)
        to_md = lambda sign: {s: m + sign * dl / 2 for s, m, dl in zip(ys, mids, dels)}
        grad_m = grad.xreplace(dict(zip(ys, mids)))
        polynomial = _is_polynomial(H, ys)
        if polynomial:
            N = sp.expand(H.xreplace(to_md(1)) - H.xreplace(to_md(-1))
                          - sum(g * dl for g, dl in zip(grad_m, dels)))
            how = "numerator expanded symbolically in (ȳ, Δ): its O(1) terms cancel exactly"
        else:
            # H(y1) - H(y0) = Σ_i ∇̄H_IA,i Δ_i exactly, with the Itoh–Abe components as
            # cancelled divided differences: the numerator is then a sum of O(|Δ|)
            # terms, accurate to eps·|∇H|·|Δ| instead of eps·|H| (no catastrophic
            # cancellation; the correction N/|Δ|² · Δ is accurate to round-off).
            y0s = [m - dl / 2 for m, dl in zip(mids, dels)]
            y1s = [m + dl / 2 for m, dl in zip(mids, dels)]
            ia = itoh_abe_components(H, ys, y0s, y1s)
            N = sum((ia[i] - grad_m[i]) * dels[i] for i in range(n))
            how = ("numerator as Σ (∇̄H_Itoh-Abe - ∇H(ȳ))_i Δ_i with cancelled divided differences: "
                   "no catastrophic cancellation")
        D2 = sum(dl**2 for dl in dels)
        corr = safe_div(N, D2)
        dg_md = sp.Matrix([grad_m[i] + corr * dels[i] for i in range(n)])

        def dg(y0, y1):
            sub = {}
            for m, dl, a, b in zip(mids, dels, y0, y1):
                sub[m] = (a + b) / 2
                sub[dl] = b - a
            return dg_md.xreplace(sub)

        traits = Traits(order=2, symmetric=True, symplectic=False, energy_preserving=True,
                        preserved=("H",), solve="newton", discrete_gradient=True, notes=(how,))
        scheme = gradient_scheme(system, Gonzalez.NAME, dg, traits,
                                 "y1 = y0 + h J [∇H(ȳ) + (H(y1) - H(y0) - ∇H(ȳ)ᵀΔ)/|Δ|² Δ]")
        # The parts, in y0/y1 symbols, for the structural proofs of methodgen.symbolic.verify.structural.
        y1 = scheme.y1
        sub = {}
        for m, dl, a, b in zip(mids, dels, ys, y1):
            sub[m] = (a + b) / 2
            sub[dl] = b - a
        parts = {"kind": "gonzalez", "G": [g.xreplace(sub) for g in grad_m], "N": N.xreplace(sub),
                 "D2": D2.xreplace(sub), "ia": None if polynomial else [c.xreplace(sub) for c in ia]}
        return replace(scheme, structure=parts)


# --- Itoh–Abe ---------------------------------------------------------------------

class ItohAbe:
    NAME = "itoh-abe"
    SUMMARY = "Itoh-Abe coordinate-increment discrete gradient (energy-preserving, order 1)"

    @staticmethod
    def applies(system):
        return _not_constrained(system, "Itoh-Abe")

    @staticmethod
    def build(system: Hamiltonian) -> Scheme:
        ys = system.y
        H = system.H

        def dg(y0, y1):
            return sp.Matrix(itoh_abe_components(H, ys, y0, y1))

        grad = gradient(system)
        # When every ∂H/∂y_i depends on y_i only, each component is the divided
        # difference of its own one-variable term: symmetric (it equals AVF), order 2.
        decoupled = all(g.free_symbols & set(ys) <= {ys[i]} for i, g in enumerate(grad))
        notes = ("coordinate-wise divided differences, cancelled symbolically",)
        if decoupled:
            notes += ("H is a sum of one-coordinate terms: the method is symmetric (equal to AVF), order 2",)
        traits = Traits(order=2 if decoupled else 1, symmetric=decoupled, symplectic=False,
                        energy_preserving=True, preserved=("H",), solve="newton",
                        discrete_gradient=True, notes=notes)
        return gradient_scheme(system, ItohAbe.NAME, dg, traits,
                               "y1 = y0 + h J ∇̄H, ∇̄H_i = (H(y1_1..i, y0_i+1..) - H(y1_1..i-1, y0_i..))/(y1_i - y0_i)")
