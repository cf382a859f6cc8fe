"""Structural proofs of the discrete-gradient identity: small lemmas instead of one huge expression.

Reducing ``(y1 - y0)ᵀ∇̄H - (H(y1) - H(y0))`` for the whole system at once costs
minutes on a 3-body or a 3-site Toda system.  The methods' constructions give the
identity as an exact sum of small pieces, so it is proved piece by piece:

* **Itoh–Abe** (and the Itoh–Abe numerator of Gonzalez): with
  ``z_i = (y1_1, …, y1_i, y0_{i+1}, …)``,

      Σ_i Δ_i c_i - (H(y1) - H(y0)) = Σ_i [Δ_i c_i - (H(z_i) - H(z_{i-1}))]

  is an identity of the symbols (a telescoping sum), so it suffices that each
  *coordinate lemma* ``Δ_i c_i = H(z_i) - H(z_{i-1})`` — one coordinate changes,
  the terms of H without it cancel as built — reduces to 0.  The lemmas are
  statements about the scheme's own components: no trust in how they were built.
* **Gonzalez**: ``∇̄H_i = G_i + safe_div(N, |Δ|²) Δ_i`` with ``G = ∇H(ȳ)``.  First
  the instance is checked (the scheme's ∇̄H *is* this form with the recorded G, N,
  |Δ|² — structural equality); then, in the case ``|Δ|² ≠ 0``, ``Δᵀ∇̄H - (H1 - H0)
  = ΔᵀG + N - (H1 - H0)`` exactly, which is the lemma ``N = H1 - H0 - ΔᵀG``
  (expanded for polynomial H; from the coordinate lemmas of its Itoh–Abe form
  ``N = Σ (c_i - G_i) Δ_i`` otherwise); the case ``|Δ|² = 0`` is ``y1 = y0``, where
  the identity is reduced after substitution.  Symmetry follows from the same
  lemma: ``G`` and ``|Δ|²`` are invariant under ``y0 ↔ y1`` (checked) and N is odd.

* **Term-wise discrete gradients** (energy-momentum, AVF without quadrature): ``∇̄H = Σ_t ∇̄_t`` over additive
  terms ``H_t`` of H (the kinetic energy one of them), recorded by the scheme.  Checked:
  ``∇̄H`` *is* that sum and ``H - Σ_t H_t`` is free of y (expanded); then

      Δᵀ∇̄H - (H1 - H0) = Σ_t [Δᵀ∇̄_t - (H_t(y1) - H_t(y0))]

  and each term lemma is proved.  A term ``H_t = V(F(y))`` of one form F (a coordinate,
  a quadratic form E, an affine form aᵀq + c) with ``∇̄_t = V[F0, F1] w`` is reduced to
  two small facts: ``wᵀΔ = F(y1) - F(y0)`` (expanded; ``w = ∇E(ȳ)`` for E quadratic,
  ``a`` for an affine form) and ``V[s0, s1](s1 - s0) = V(s1) - V(s0)`` in two fresh
  symbols — after checking ``V(F) = H_t`` and that ``∇̄_t`` is ``V[s0, s1] w`` at
  ``s0 = F0, s1 = F1`` (structurally).  So a 1D Lennard-Jones chain costs one
  one-variable lemma, not a rational function of degree 24 in all coordinates.  Other
  terms (polynomials: an AVF integral) are reduced whole.

Each function returns ``None`` when the scheme does not have the structure (or a
lemma does not reduce): the caller then reduces the whole expression as before.
"""

from __future__ import annotations

import time

import sympy as sp

from ..divdiff import divided_difference
from ...problem.special import safe_div
from .exact import expression_text, reduce_to_zero
from .report import PROVED, Certificate

__all__ = ["coordinate_lemmas", "identity_structural", "gonzalez_symmetry_structural"]


def coordinate_lemmas(H: sp.Expr, ys, y0, y1, comps) -> list[sp.Expr]:
    """``Δ_i c_i - (H(z_i) - H(z_{i-1}))`` for each coordinate i (they sum to the identity).

    When ``c_i`` is (structurally) the sum of the divided differences of the additive
    terms of ``H(z)`` in ``y_i``, the lemma is split further into one lemma per term —
    ``t[a, b]·Δ_i = t(b) - t(a)`` — which sum to it exactly; otherwise it is kept whole.
    """
    n = len(ys)
    out = []
    for i in range(n):
        zi = {ys[j]: (y1[j] if j <= i else y0[j]) for j in range(n)}
        zp = {ys[j]: (y1[j] if j < i else y0[j]) for j in range(n)}
        fixed = {ys[j]: (y1[j] if j < i else y0[j]) for j in range(n) if j != i}
        terms = [t for t in sp.Add.make_args(H.xreplace(fixed)) if ys[i] in t.free_symbols]
        dds = [divided_difference(t, ys[i], y0[i], y1[i]) for t in terms]
        if terms and sp.Add(*dds) == comps[i]:
            out += [d * (y1[i] - y0[i]) - (t.xreplace({ys[i]: y1[i]}) - t.xreplace({ys[i]: y0[i]}))
                    for t, d in zip(terms, dds)]
        else:
            out.append(comps[i] * (y1[i] - y0[i]) - (H.xreplace(zi) - H.xreplace(zp)))
    return out


def _reduce_all(lemmas) -> list[str] | None:
    methods = []
    for e in lemmas:
        m = reduce_to_zero(e, allow_simplify=True)
        if m is None:
            return None
        if m not in methods:
            methods.append(m)
    return methods


_LEMMAS: dict = {}


def _gonzalez_parts(scheme):
    """The checked Gonzalez form ``(G, N, D2, ia)``, or None if the scheme is not that form."""
    st = scheme.structure or {}
    if st.get("kind") != "gonzalez":
        return None
    y0, y1 = scheme.system.y, scheme.y1
    G, N, D2, ia = st["G"], st["N"], st["D2"], st["ia"]
    dels = [b - a for a, b in zip(y0, y1)]
    if D2 != sp.Add(*[d**2 for d in dels]):
        return None
    corr = safe_div(N, D2)
    if any(not _same(g, Gi + corr * dl) for g, Gi, dl in zip(scheme.discrete_gradient, G, dels)):
        return None
    if ia is not None and not _same(N, sp.Add(*[(c - g) * dl for c, g, dl in zip(ia, G, dels)])):
        return None
    return G, N, D2, ia


def _same(a: sp.Expr, b: sp.Expr) -> bool:
    """Structurally equal, or equal after the common parts cancel and a small rest expands to 0."""
    if a == b:
        return True
    rest = a - b
    return sp.count_ops(rest) < 300 and sp.expand(rest) == 0


def _gonzalez_lemma(scheme) -> tuple[bool, str]:
    """``N = H(y1) - H(y0) - ∇H(ȳ)ᵀΔ`` (cached per scheme): (proved, how)."""
    key = id(scheme)
    if key in _LEMMAS and _LEMMAS[key][0] is scheme:
        return _LEMMAS[key][1]
    system = scheme.system
    y0, y1 = system.y, scheme.y1
    G, N, D2, ia = _gonzalez_parts(scheme)
    H = system.H
    if ia is not None:
        ms = _reduce_all(coordinate_lemmas(H, y0, y0, y1, ia))
        how = (f"N = Σ (c_i - ∇H(ȳ)_i) Δ_i with Itoh–Abe components c_i; {len(ia)} coordinate lemmas "
               f"Δ_i c_i = H(z_i) - H(z_i-1) ({', '.join(ms)})" if ms else "")
    else:
        H1 = H.xreplace(dict(zip(y0, y1)))
        lemma = N + sp.Add(*[(b - a) * g for a, b, g in zip(y0, y1, G)]) - (H1 - H)
        m = reduce_to_zero(lemma, allow_simplify=False)
        ms = [m] if m else None
        how = f"N = H(y1) - H(y0) - ∇H(ȳ)ᵀΔ ({m})" if m else ""
    out = (ms is not None, how)
    _LEMMAS.clear()
    _LEMMAS[key] = (scheme, out)
    return out


def _profile_lemma(V: sp.Expr, s: sp.Symbol, cache: dict) -> tuple[sp.Expr, sp.Symbol, sp.Symbol, str] | None:
    """``(V[s0, s1], s0, s1, how)`` with ``V[s0, s1](s1 - s0) = V(s1) - V(s0)`` reduced to 0
    (fresh s0, s1 with the assumptions of s), or None if it does not reduce.  Cached per V."""
    # One canonical variable (internal name: users' names cannot start with "_"), so equal
    # profiles V of different terms share one lemma.
    canon = sp.Symbol("_dd_var", **s.assumptions0)
    Vc = V.xreplace({s: canon})
    if Vc not in cache:
        s0, s1 = sp.Symbol("_dd_s0", **s.assumptions0), sp.Symbol("_dd_s1", **s.assumptions0)
        D = divided_difference(Vc, canon, s0, s1)
        m = reduce_to_zero(D * (s1 - s0) - (Vc.xreplace({canon: s1}) - Vc.xreplace({canon: s0})),
                           allow_simplify=True)
        cache[Vc] = None if m is None else (D, s0, s1, m)
    return cache[Vc]


def _termwise_identity(scheme) -> str | None:
    """The identity from the recorded term-wise pieces (see the module docstring): how, or None."""
    st = scheme.structure or {}
    if st.get("kind") != "term-wise":
        return None
    system = scheme.system
    y0, y1 = system.y, scheme.y1
    ys = set(y0)
    terms = st["terms"]
    dels = [b - a for a, b in zip(y0, y1)]
    # ∇̄H is the sum of the pieces, and H the sum of the terms up to a constant.
    # (each piece's nonzero entries only: a chain of 200 has 201 pieces of 400 entries, 2 each)
    cols: list[list] = [[] for _ in scheme.discrete_gradient]
    for t in terms:
        for i, gi in enumerate(t["dg"]):
            if gi != 0:
                cols[i].append(gi)
    for g, col in zip(scheme.discrete_gradient, cols):
        if not _same(g, sp.Add(*col)):
            return None
    if sp.expand(system.H - sp.Add(*[t["expr"] for t in terms])).free_symbols & ys:
        return None
    cache: dict = {}
    hows, n_profile = [], 0
    for t in terms:
        expr, dg, prof = t["expr"], t["dg"], t["profile"]
        if prof is not None:
            V, s, F, w = prof
            F0, F1 = F, F.xreplace(dict(zip(y0, y1)))
            lemma = _profile_lemma(V, s, cache)
            if lemma is None:
                return None
            D, s0, s1, m = lemma
            Dt = D.xreplace({s0: F0, s1: F1})
            if (not _same(V.xreplace({s: F}), expr)
                    or sp.expand(sp.Add(*[wi * dl for wi, dl in zip(w, dels) if wi != 0]) - (F1 - F0)) != 0
                    or any(not _same(g, Dt * wi) for g, wi in zip(dg, w) if g != 0 or wi != 0)):
                return None
            n_profile += 1
        else:
            e = sp.Add(*[g * dl for g, dl in zip(dg, dels) if g != 0]) - (expr.xreplace(dict(zip(y0, y1))) - expr)
            m = reduce_to_zero(e, allow_simplify=False)
            if m is None:
                return None
        if m not in hows:
            hows.append(m)
    out = (f"structural: ∇̄H = Σ_t ∇̄_t over {len(terms)} additive terms H_t of H (checked, and H - Σ_t H_t "
           f"free of y); Δᵀ∇̄H - (H1 - H0) = Σ_t [Δᵀ∇̄_t - (H_t(y1) - H_t(y0))]; ")
    if n_profile:
        out += (f"{n_profile} term(s) V(F) with ∇̄_t = V[F0, F1] w: wᵀΔ = F1 - F0 (expand) and "
                f"V[s0, s1](s1 - s0) = V(s1) - V(s0) ({len(cache)} distinct V)")
    if n_profile < len(terms):
        out += ("; the others" if n_profile else "each term lemma") + " reduced whole"
    return out + f" ({', '.join(hows)})"


def identity_structural(scheme, claim: str, ref: str, shown) -> Certificate | None:
    """The discrete-gradient identity proved from lemmas, or None (not structured / not reduced)."""
    t0 = time.perf_counter()
    system = scheme.system
    y0, y1 = system.y, scheme.y1
    if scheme.method == "itoh-abe":
        ms = _reduce_all(coordinate_lemmas(system.H, y0, y0, y1, list(scheme.discrete_gradient)))
        if ms is None:
            return None
        method = (f"structural: telescoping sum of {len(y0)} coordinate lemmas "
                  f"Δ_i ∇̄H_i = H(z_i) - H(z_i-1), z_i = (y1_1..y1_i, y0_i+1..) ({', '.join(ms)})")
    elif (scheme.structure or {}).get("kind") == "term-wise":
        method = _termwise_identity(scheme)
        if method is None:
            return None
    elif _gonzalez_parts(scheme) is not None:
        ok, how = _gonzalez_lemma(scheme)
        if not ok:
            return None
        # The case |Δ|² = 0 is y1 = y0: substitute and reduce (the guard is 0 there).
        at_rest = shown.xreplace(dict(zip(y1, y0)))
        m0 = reduce_to_zero(at_rest, allow_simplify=False)
        if m0 is None:
            return None
        method = (f"structural: form ∇̄H = ∇H(ȳ) + safe_div(N, |Δ|²) Δ checked; case |Δ|² ≠ 0: "
                  f"Δᵀ∇̄H - (H1 - H0) = ΔᵀG + N - (H1 - H0), zero by the lemma {how}; "
                  f"case |Δ|² = 0 (y1 = y0): {m0}")
    else:
        return None
    small = not (isinstance(shown, sp.Add) and len(shown.args) > 400) and sp.count_ops(shown) < 400
    return Certificate(claim, PROVED, expression_text(shown), sp.latex(shown) if small else "",
                       method, time.perf_counter() - t0, ref, {"structural": True})


def gonzalez_symmetry_structural(scheme, claim: str, ref: str) -> Certificate | None:
    """∇̄H(y0, y1) = ∇̄H(y1, y0) for Gonzalez from the same lemma, or None."""
    t0 = time.perf_counter()
    parts = _gonzalez_parts(scheme)
    if parts is None:
        return None
    G, N, D2, ia = parts
    y0, y1 = scheme.system.y, scheme.y1
    swap = {**dict(zip(y0, y1)), **dict(zip(y1, y0))}
    if any(sp.expand(g.xreplace(swap) - g) != 0 for g in G) or sp.expand(D2.xreplace(swap) - D2) != 0:
        return None
    ok, how = _gonzalez_lemma(scheme)
    if not ok:
        return None
    method = ("structural: ∇̄H_i = G_i + N/|Δ|² Δ_i with G = ∇H(ȳ) and |Δ|² invariant under y0 ↔ y1 "
              f"(checked) and Δ odd; N = H(y1) - H(y0) - GᵀΔ is odd by the lemma {how}")
    return Certificate(claim, PROVED, "∇̄H(y0, y1) - ∇̄H(y1, y0)", "", method, time.perf_counter() - t0,
                       ref, {"structural": True})
