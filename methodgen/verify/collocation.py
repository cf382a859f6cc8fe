"""Exact certificates for Gauss–Legendre collocation (``methodgen.schemes.gauss``).

Everything follows from one fact about the nodes: the c_i are the s distinct
roots of the shifted Legendre polynomial ``P(x) = P_s(2x − 1)`` (integer
coefficients).  The method's A and b are *defined* by C(s) and B(s):

    Σ_j a_ij c_j^(l−1) = c_i^l / l,     Σ_i b_i c_i^(l−1) = 1/l      (l = 1..s).

Write ``μ_m = Σ_i b_i c_i^m``.  Because ``c_i^m ≡ Σ_l R_ml c_i^l (mod P)`` with
the *same* rational R for every root, ``μ_m = Σ_l R_ml μ_l = Σ_l R_ml /(l+1)``:
the quadrature moments of every degree are rational numbers computed from P
alone.  Then, with V the (invertible: distinct nodes) Vandermonde matrix,

* B(2s): ``μ_m = 1/(m+1)`` for m < 2s — decided from the reduction matrix R;
* D(s): ``Σ_i b_i c_i^(k−1) a_ij = b_j (1 − c_j^k)/k``.  Multiplying by
  ``c_j^(l−1)`` and summing over j (that is, by V) turns it into
  ``μ_(k+l−1)/l = (μ_(l−1) − μ_(k+l−1))/k`` for k, l ≤ s, a rational identity;
* symplecticity ``M = BA + AᵀB − bbᵀ = 0``: ``(VᵀMV)_kl = μ_(k+l−1)/l +
  μ_(k+l−1)/k − μ_(k−1) μ_(l−1) = 0`` for k, l ≤ s;
* symmetry: ``P(1 − x) = (−1)^s P(x)`` (the nodes are symmetric about 1/2, and
  collocation at symmetric nodes is symmetric [HLW06, Thm V.2.3]);
* order 2s from B(2s), C(s), D(s) [HLW06, Thm II.1.11].

All of it is rational arithmetic — no floats, no radicals, any s.  The module
runs the coefficients rounded to float64; a numerical certificate states how
well those satisfy the same conditions (≈ 1e-16: below round-off per step).

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §II.1.3, §IV.2, §V.2.
"""

from __future__ import annotations

import time

import sympy as sp

from .report import NUMERICAL, PROVED, REFUTED, Certificate

REF = "HLW06 §II.1.3 (Thm II.1.11), §IV.2 (Thm IV.2.2), §V.2"
_X = sp.Symbol("x")


def moments(P: sp.Poly) -> list[sp.Rational]:
    """``μ_m = Σ b_i c_i^m`` for m = 0..2s−1, exact, from P alone (see the module docstring)."""
    s = P.degree()
    out = []
    for m in range(2 * s):
        r = sp.Poly(_X**m, _X).rem(P)              # x^m mod P, degree < s, rational coefficients
        coeffs = r.all_coeffs()[::-1]              # R_m0, R_m1, ...
        out.append(sp.Add(*[sp.Rational(cf) / (l + 1) for l, cf in enumerate(coeffs)]))
    return out


def _cert(claim, ok, expr, how, t0, details, exact=True):
    status = (PROVED if exact else NUMERICAL) if ok else REFUTED
    return Certificate(claim, status, expr, "", how, time.perf_counter() - t0, REF, details)


def gauss_certificates(s: int, P: sp.Poly | None = None, A=None, b=None) -> list[Certificate]:
    """Exact certificates of the s-stage Gauss method; numerical ones for float ``A``, ``b``.

    Parameters
    ----------
    s : int
    P : sympy.Poly, optional
        The node polynomial (default: the shifted Legendre polynomial); passing
        another polynomial is the negative control.
    A, b : sequences of floats, optional
        The coefficients the generated module uses (rounded), checked numerically
        against C(s), B(2s), D(s) and the symplecticity condition.
    """
    from ..schemes.gauss import legendre

    P = legendre(s) if P is None else P
    out = []
    t0 = time.perf_counter()
    distinct = sp.gcd(P, P.diff(_X)).degree() == 0 and P.count_roots(0, 1) == s
    out.append(_cert(f"the {s} nodes are distinct and in (0, 1) (gcd(P, P') = 1, Sturm count)",
                     distinct, str(P.as_expr()), "exact polynomial gcd and Sturm sequence", t0,
                     {"polynomial": str(P.as_expr())}))
    mu = moments(P)
    t0 = time.perf_counter()
    bad = [m for m in range(2 * s) if mu[m] != sp.Rational(1, m + 1)]
    out.append(_cert(f"B({2 * s}): Σ b_i c_i^(m) = 1/(m+1) for m < {2 * s} (quadrature order {2 * s})",
                     not bad and distinct, "μ_m − 1/(m+1)", "rational reduction of x^m modulo P", t0,
                     {"moments": [str(v) for v in mu], "failing_m": bad}))
    t0 = time.perf_counter()
    dbad = [(k, l) for k in range(1, s + 1) for l in range(1, s + 1)
            if mu[k + l - 1] / l - (mu[l - 1] - mu[k + l - 1]) / k != 0]
    out.append(_cert(f"D({s}): Σ_i b_i c_i^(k−1) a_ij = b_j (1 − c_j^k)/k (times V: μ_(k+l−1)/l = "
                     "(μ_(l−1) − μ_(k+l−1))/k)", not dbad and distinct, "μ_(k+l−1)/l − (μ_(l−1) − μ_(k+l−1))/k",
                     "rational arithmetic on the moments; V invertible (distinct nodes)", t0,
                     {"failing_kl": dbad}))
    t0 = time.perf_counter()
    sbad = [(k, l) for k in range(1, s + 1) for l in range(1, s + 1)
            if mu[k + l - 1] / l + mu[k + l - 1] / k - mu[k - 1] * mu[l - 1] != 0]
    out.append(_cert("symplectic: b_i a_ij + b_j a_ji − b_i b_j = 0 (as VᵀMV = 0)", not sbad and distinct,
                     "μ_(k+l−1)/l + μ_(k+l−1)/k − μ_(k−1) μ_(l−1)", "rational arithmetic on the moments", t0,
                     {"failing_kl": sbad}))
    t0 = time.perf_counter()
    sym = sp.expand(P.as_expr().subs(_X, 1 - _X) - (-1) ** s * P.as_expr()) == 0
    out.append(_cert("symmetric: P(1 − x) = (−1)^s P(x), so c_i + c_(s+1−i) = 1 and the collocation "
                     "method is symmetric", sym, "P(1 − x) − (−1)^s P(x)", "expand", t0, {}))
    t0 = time.perf_counter()
    order = not bad and not dbad and distinct
    out.append(_cert(f"order {2 * s}: B({2 * s}), C({s}) (the definition of A), D({s}) [Thm II.1.11]",
                     order, "", "from the certificates above", t0, {}))
    out.append(_cert("every quadratic first integral is preserved (symplectic RK, Thm IV.2.2)",
                     order and not sbad, "", "from the symplecticity certificate", t0, {}))
    if A is not None and b is not None:
        out.append(_rounded(s, A, b))
    return out


def _rounded(s: int, A, b) -> Certificate:
    """How well the float64 coefficients satisfy B(2s), C(s), D(s) and symplecticity (numerical)."""
    import mpmath as mp

    from ..schemes.gauss import coefficients

    t0 = time.perf_counter()
    c = coefficients(s)["c"]
    with mp.workdps(40):
        A = [[mp.mpf(float(x)) for x in row] for row in A]
        b = [mp.mpf(float(x)) for x in b]
        dev = {
            "B": max(abs(sum(b[i] * c[i] ** m for i in range(s)) - mp.mpf(1) / (m + 1)) for m in range(2 * s)),
            "C": max(abs(sum(A[i][j] * c[j] ** (l - 1) for j in range(s)) - c[i] ** l / l)
                     for i in range(s) for l in range(1, s + 1)),
            "D": max(abs(sum(b[i] * c[i] ** (k - 1) * A[i][j] for i in range(s)) - b[j] * (1 - c[j] ** k) / k)
                     for j in range(s) for k in range(1, s + 1)),
            "symplectic": max(abs(b[i] * A[i][j] + b[j] * A[j][i] - b[i] * b[j])
                              for i in range(s) for j in range(s)),
        }
    worst = float(max(dev.values()))
    return Certificate("the float64 coefficients of the module satisfy B(2s), C(s), D(s) and the "
                       "symplecticity condition to round-off", NUMERICAL if worst < 1e-14 else REFUTED,
                       "", "", "40-digit evaluation at the exact nodes", time.perf_counter() - t0, REF,
                       {k: float(v) for k, v in dev.items()} | {"tolerance": 1e-14})


# --- energy-preserving collocation ----------------------------------------------------

REF_ENERGY = "Hairer, JNAIAM 5 (2010) 73–84, Thm 1 (energy-preserving collocation)"


def energy_collocation_certificates(scheme) -> list[Certificate]:
    """Exact energy preservation of ``energy-collocation`` on a polynomial H, structurally.

    With ``u(σ) = y0 + Σ_k Λ_k(σ) Z_k`` and ``I_j = ∫_0^1 ℓ_j ∇H(u) dσ`` (exact: a
    polynomial in σ), three identities are reduced by ``expand``:

    * ``Λ_j' = ℓ_j`` and ``Λ_j(0) = 0``, ``Λ_j(1) = b_j`` — u is the step's polynomial;
    * the scheme's residual is ``Z_j − (h/b_j) J I_j`` — the equations are what they claim;
    * ``H(y0 + Σ_j b_j Z_j) − H(y0) − Σ_j Z_jᵀ I_j ≡ 0`` — the fundamental theorem of
      calculus along u, as a polynomial identity in (y0, Z).

    At a solution ``I_j = (b_j/h) J⁻¹ Z_j`` with ``J⁻¹ = −J`` skew, so
    ``H(y1) − H(y0) = −Σ_j (b_j/h) Z_jᵀ J Z_j = 0``.
    """
    from ..derive import gradient

    st = scheme.structure
    if not st.get("exact"):
        return []
    t0 = time.perf_counter()
    system, h, sig = scheme.system, scheme.h, st["sigma"]
    ell, Lam, b, Z = st["ell"], st["Lam"], st["b"], st["Z"]
    s, d = len(ell), system.dim
    ok_basis = all(sp.expand(sp.diff(L, sig) - l) == 0 and L.subs(sig, 0) == 0
                   and sp.expand(L.subs(sig, 1) - bj) == 0 for L, l, bj in zip(Lam, ell, b))
    u = {v: v + sp.Add(*[Lam[k] * Z[k][i] for k in range(s)]) for i, v in enumerate(system.y)}
    gH = [sp.expand(g.xreplace(u)) for g in gradient(system)]

    def integrate01(expr):
        poly = sp.Poly(sp.expand(expr), sig)
        return sp.Add(*[cf / (k + 1) for (k,), cf in poly.terms()])

    I = [[integrate01(ell[j] * g) for g in gH] for j in range(s)]
    res_diff = []
    for j in range(s):
        JI = [I[j][d + i] for i in range(d)] + [-I[j][i] for i in range(d)]
        for i in range(2 * d):
            res_diff.append(sp.expand(scheme.residual[j * 2 * d + i] - (Z[j][i] - h / b[j] * JI[i])))
    ok_res = all(e == 0 for e in res_diff)
    y1 = {v: v + sp.Add(*[b[j] * Z[j][i] for j in range(s)]) for i, v in enumerate(system.y)}
    ftc = sp.expand(system.H.xreplace(y1) - system.H
                    - sp.Add(*[Z[j][i] * I[j][i] for j in range(s) for i in range(2 * d)]))
    ok = ok_basis and ok_res and ftc == 0
    details = {"basis": ok_basis, "residual_matches": ok_res, "fundamental_theorem": ftc == 0}
    if not ok_res:
        details["residual_difference"] = str(next(e for e in res_diff if e != 0))[:200]
    return [Certificate(f"energy-collocation (s = {s}) keeps H exactly: H(y1) − H(y0) = −Σ_j (b_j/h) Z_jᵀ J Z_j = 0",
                        PROVED if ok else REFUTED, "H(y0 + Σ b_j Z_j) − H(y0) − Σ_j Z_jᵀ ∫ℓ_j ∇H(u)",
                        "", "expand (polynomial identities in y0, Z; J skew)", time.perf_counter() - t0,
                        REF_ENERGY, details)]
