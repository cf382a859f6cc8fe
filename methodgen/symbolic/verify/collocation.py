"""Exact certificates for Gauss–Legendre collocation (``methodgen.symbolic.schemes.gauss``).

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

    The scheme is ``Z_j = (h/b_j) J I_j`` with ``I_j = Σ_k w_k ℓ_j(x_k) ∇H(u(x_k))``, an m-node
    Gauss–Legendre rule applied to ``∫_0^1 ℓ_j ∇H(u) dσ``, ``u(σ) = y0 + Σ_k Λ_k(σ) Z_k`` and
    ``y1 = y0 + Σ_j b_j Z_j``.  Decided here, exactly:

    * the basis: ``Λ_j' = ℓ_j``, ``Λ_j(0) = 0``, ``Λ_j(1) = b_j`` (so u is the step's
      polynomial: ``u(0) = y0``, ``u(1) = y1``, ``u' = Σ ℓ_j Z_j``);
    * the rule is exact for the integrand: the m nodes are the roots of the shifted Legendre
      polynomial P_m, whose moments give B(2m) in rational arithmetic (:func:`moments`), and
      the integrand's degree in σ, ``deg ℓ_j + deg f · deg u = (s − 1) + D·s``, is ≤ 2m − 1
      (D the total degree of f = J∇H in y, from its polynomial form).

    Then ``I_j = ∫_0^1 ℓ_j ∇H(u) dσ`` and, by the chain rule along u,
    ``H(y1) − H(y0) = ∫_0^1 ∇H(u)ᵀ u' dσ = Σ_j Z_jᵀ I_j = Σ_j (b_j/h) Z_jᵀ J⁻¹ Z_j = 0``
    (J⁻¹ = −J is skew).  The claim is the method's (exact nodes and weights); the module
    runs them rounded to float64, and the claim is proved only if those floats are certified
    (:func:`emitted_coefficient_certificates`, returned after it) -- a rule wrong in its
    weights must not carry a proof.
    """
    from ..schemes.base import _field_degree
    from ..schemes.gauss import legendre

    st = scheme.structure
    if not st.get("exact"):
        return []
    t0 = time.perf_counter()
    sig = st["sigma"]
    ell, Lam, b = st["ell"], st["Lam"], st["b"]
    s, m = len(ell), st["nodes"]
    ok_basis = all(sp.expand(sp.diff(L, sig) - l) == 0 and L.subs(sig, 0) == 0
                   and sp.expand(L.subs(sig, 1) - bj) == 0 for L, l, bj in zip(Lam, ell, b))
    D = _field_degree(scheme.system)
    deg_u = max(sp.Poly(L, sig).degree() for L in Lam)
    deg_l = max(sp.Poly(l, sig).degree() if l.has(sig) else 0 for l in ell)
    integrand = deg_l + D * deg_u if D != float("inf") else None
    mu = moments(legendre(m))
    rule_exact = all(mu[k] == sp.Rational(1, k + 1) for k in range(2 * m))
    ok_degree = integrand is not None and integrand <= 2 * m - 1
    ok = ok_basis and rule_exact and ok_degree
    details = {"basis": ok_basis, "nodes": m, "rule_exact_to_degree": 2 * m - 1 if rule_exact else None,
               "integrand_degree": integrand, "field_degree": None if integrand is None else int(D)}
    seconds = time.perf_counter() - t0
    # The claim rests on the quadrature, so it is only as good as the rule the module runs:
    # the float64 tables are certified against their exact definition (numerical).
    emitted = emitted_coefficient_certificates(scheme)
    floats_ok = all(c.status != REFUTED for c in emitted)
    details["module_coefficients_certified"] = floats_ok
    from ..schemes.energy_collocation import drift_note

    details["float64"] = drift_note(s)
    claim = (f"energy-collocation (s = {s}) keeps H exactly: H(y1) − H(y0) = −Σ_j (b_j/h) Z_jᵀ J Z_j = 0 "
             "(exact coefficients; the module's float64 ones are certified separately; "
             f"{drift_note(s)})")
    return [Certificate(claim, PROVED if ok and floats_ok else REFUTED,
                        f"Λ_j' = ℓ_j, Λ_j(1) = b_j; {m}-node rule exact to degree {2 * m - 1} ≥ {integrand}",
                        "", "exact lemmas (basis, B(2m) of the rule, degree count) + chain rule along u, J skew"
                        + ("" if floats_ok else "; REFUTED: the module's float64 coefficients are not the rule's"),
                        seconds, REF_ENERGY, details)] + emitted


#: Largest accepted deviation of a module coefficient from its exact value, in units of
#: 2^-52·max(1, |value|) (a correctly rounded float64 is within 1/2).
ULPS = 1.0


def emitted_coefficient_certificates(scheme) -> list[Certificate]:
    """The float64 numbers of an energy-collocation module, checked against their definition.

    Two numerical certificates: the m-node rule (:func:`methodgen.symbolic.verify.quadrature.rule_certificate`:
    sums to 1, integrates degree < 2m to round-off), and every table entry of the
    equations -- ``Λ_i(x_k)``, ``w_k ℓ_j(x_k)``, ``1/b_j``, ``b_j`` -- within :data:`ULPS` of its
    value computed at 60 digits from the exact nodes, weights and basis.
    """
    import mpmath as mp

    from ..schemes.energy_collocation import _at, quadrature
    from .quadrature import rule_certificate

    st = scheme.structure
    tab = st.get("tables")
    if tab is None:     # nothing to certify against: the claim cannot rest on it
        return [Certificate("the module's float64 coefficients are their exact values rounded", REFUTED,
                            "", "", "no float64 tables recorded in the scheme", 0.0, REF_ENERGY,
                            {"passed": False})]
    ell, Lam, b = st["ell"], st["Lam"], st["b"]
    m = st["nodes"]
    if len(tab["nodes"]) != m or any(len(r) != m for r in tab["quad"]) or len(tab["path"]) != m:
        return [Certificate(f"the module's float64 tables are those of the {m}-node rule", REFUTED, "", "",
                            f"the tables have {len(tab['nodes'])} nodes", 0.0, REF_ENERGY, {"passed": False})]
    out = [rule_certificate(tab["nodes"], tab["weights"], "energy-collocation quadrature")]
    t0 = time.perf_counter()
    rule = quadrature(m)
    worst, where = 0.0, None
    with mp.workdps(60):
        pairs = ([(tab["path"][k][i], _at(Lam[i], x), f"Λ_{i + 1}(x_{k + 1})")
                  for k, (x, _) in enumerate(rule) for i in range(len(Lam))]
                 + [(tab["quad"][j][k], w * _at(ell[j], x), f"w_{k + 1} ℓ_{j + 1}(x_{k + 1})")
                    for j in range(len(ell)) for k, (x, w) in enumerate(rule)]
                 + [(tab["inv_b"][j], 1 / mp.mpf(str(sp.N(bj, 70))), f"1/b_{j + 1}") for j, bj in enumerate(b)]
                 + [(tab["b"][j], mp.mpf(str(sp.N(bj, 70))), f"b_{j + 1}") for j, bj in enumerate(b)])
        for got, want, name in pairs:
            dev = float(abs(mp.mpf(got) - want) / (mp.mpf(2) ** -52 * max(1, abs(want))))
            if dev > worst:
                worst, where = dev, name
    ok = worst <= ULPS
    out.append(Certificate(
        "the module's float64 coefficients Λ_i(x_k), w_k ℓ_j(x_k), 1/b_j, b_j are their exact values "
        f"rounded (error ≤ {ULPS:g}·2^-52·max(1, |value|))", NUMERICAL if ok else REFUTED, "", "",
        "60-digit values from the exact nodes, weights and basis", time.perf_counter() - t0, REF_ENERGY,
        {"worst_ulps": worst, "worst_entry": where, "tolerance_ulps": ULPS, "entries": len(pairs), "passed": ok}))
    return out


#: Tolerance of the 60-digit checks of the generated step (its coefficients are float64:
#: Φ_(-h)∘Φ_h = id holds to their rounding, ~1e-17, not to the 60-digit evaluation error).
STEP_TOL = 1e-14


def _step_points(scheme, seed: int, points: int = 2):
    import random

    from .numeric import random_state

    rng = random.Random(seed)
    return [random_state(scheme.system, rng) for _ in range(points)]


def energy_collocation_claims(scheme) -> list[Certificate]:
    """Everything energy collocation claims except H (that is the invariants group's).

    * the basis lemmas ``Λ_j' = ℓ_j``, ``Λ_j(0) = 0``, ``Λ_j(1) = b_j`` (exact);
    * the s collocation nodes are distinct Gauss nodes: B(2s) of the node polynomial (exact,
      rational), and both node sets (collocation, quadrature) symmetric about 1/2 (exact);
    * order 2s: from those lemmas by [Hai10, Thm 1] when the integrals are exact
      (polynomial H); otherwise measured (numerical) from 60-digit steps;
    * symmetric: ``Φ_(−h)(Φ_h(y0)) = y0`` of the scheme's own equations (numerical);
    * the module's float64 quadrature rule and tables (numerical,
      :func:`emitted_coefficient_certificates`);
    * for non-polynomial H, what is *not* claimed: H is kept only to the quadrature error,
      with the change measured at sample points (numerical).
    """
    from ..schemes.gauss import legendre

    st = scheme.structure
    sig, ell, Lam, b = st["sigma"], st["ell"], st["Lam"], st["b"]
    s, m, exact = len(ell), st["nodes"], st["exact"]
    out = []
    t0 = time.perf_counter()
    ok_basis = all(sp.expand(sp.diff(L, sig) - l) == 0 and L.subs(sig, 0) == 0
                   and sp.expand(L.subs(sig, 1) - bj) == 0 for L, l, bj in zip(Lam, ell, b))
    out.append(Certificate(f"energy-collocation basis (s = {s}): Λ_j' = ℓ_j, Λ_j(0) = 0, Λ_j(1) = b_j, so "
                           "u(0) = y0, u(1) = y1 and u' = Σ ℓ_j Z_j", PROVED if ok_basis else REFUTED,
                           "Λ_j' − ℓ_j, Λ_j(0), Λ_j(1) − b_j", "", "expand (exact radicals / rationals)",
                           time.perf_counter() - t0, REF_ENERGY, {}))
    P = legendre(s)
    gc = gauss_certificates(s, P)
    nodes_ok = all(c.status == PROVED for c in gc[:2])
    out += [gc[0], gc[1]]
    t0 = time.perf_counter()
    sym_nodes = all(sp.expand(Q.as_expr().subs(_X, 1 - _X) - (-1) ** Q.degree() * Q.as_expr()) == 0
                    for Q in (P, legendre(m)))
    out.append(_cert(f"the {s} collocation nodes and the {m} quadrature nodes are symmetric about 1/2: "
                     "P(1 − x) = (−1)^deg P(x) for both node polynomials", sym_nodes,
                     "P(1 − x) − (−1)^deg P(x)", "expand", t0, {}))
    if exact:
        t0 = time.perf_counter()
        out.append(Certificate(f"order {2 * s}: Gauss nodes (B({2 * s}) above) and exact integrals "
                               f"(the {m}-node rule is exact for this polynomial field) [Hai10, Thm 1]",
                               PROVED if nodes_ok else REFUTED, "", "",
                               "from the certificates above and the degree count of the H certificate",
                               time.perf_counter() - t0, REF_ENERGY, {}))
    else:
        out.append(_measured_order(scheme, 2 * s))
    out.append(_measured_symmetry(scheme))
    out += emitted_coefficient_certificates(scheme)
    if not exact:
        out.append(_measured_energy(scheme, m))
    return out


#: ``_measured_order``: the coarsest step sizes, and the finest the ladder may halve down to
#: at a sample point where the coarse steps are not yet in the asymptotic regime.
_ORDER_HS = (sp.Rational(1, 8), sp.Rational(1, 16), sp.Rational(1, 32))
_ORDER_H_MIN = sp.Rational(1, 1024)


def _measured_order(scheme, order: int) -> Certificate:
    """Local error slope: ``|Φ_h(y) − Φ_(h/2)(Φ_(h/2)(y))| ~ C h^(p+1)`` at 60 digits (numerical).

    At each sample point the slope is read from the two finest pairs of the ladder h = 1/8,
    1/16, 1/32, which is halved further (down to 1/1024) while that slope is short of the
    claim: a random point may sit close to a singularity of the field (a Calogero pair
    potential 1/(q_i − q_j)²), where h = 1/8 is not small and the coarse slopes say nothing
    about the order.  A method of lower order stays short at every h and is refuted.
    """
    import mpmath as mp

    from .numeric import DPS, Stepper

    t0 = time.perf_counter()
    slopes, finest = [], []
    steppers = {}

    def step_pair(h):
        if h not in steppers:
            steppers[h] = (Stepper(scheme, h), Stepper(scheme, h / 2))
        return steppers[h]

    with mp.workdps(DPS):
        for y0 in _step_points(scheme, seed=23):
            hs, d = list(_ORDER_HS), []
            for h in hs:
                big, half = step_pair(h)
                d.append(max(abs(a - b) for a, b in zip(big(y0), half(half(y0)))))
            while True:
                slope = min(float(mp.log(d[i] / d[i + 1], 2)) for i in (len(d) - 3, len(d) - 2))
                if slope >= order + 1 - 0.5 or hs[-1] / 2 < _ORDER_H_MIN:
                    break
                h = hs[-1] / 2
                big, half = step_pair(h)
                hs.append(h)
                d.append(max(abs(a - b) for a, b in zip(big(y0), half(half(y0)))))
            slopes.append(slope)
            finest.append(hs[-1])
    ok = min(slopes) >= order + 1 - 0.5
    ladder = ", ".join(f"h ≥ {h}" for h in finest)
    return Certificate(f"order {order}: local error O(h^{order + 1}) measured, slopes "
                       f"{', '.join(f'{v:.2f}' for v in slopes)} (the integrals are by quadrature, H not a "
                       "polynomial)", NUMERICAL if ok else REFUTED,
                       f"log2 of |Φ_h(y) − Φ_(h/2)∘Φ_(h/2)(y)| ratios, the two finest pairs of h = 1/8, 1/16, "
                       f"1/32, … ({ladder})", "",
                       "60-digit steps of the scheme's equations at rational points", time.perf_counter() - t0,
                       REF_ENERGY, {"slopes": [round(v, 2) for v in slopes], "expected": order + 1,
                                    "finest_h": [str(h) for h in finest], "passed": ok})


def _measured_symmetry(scheme) -> Certificate:
    """``Φ_(−h)(Φ_h(y0)) = y0`` for the scheme's equations, 60 digits (numerical)."""
    import mpmath as mp

    from .numeric import DPS, Stepper

    t0 = time.perf_counter()
    h = sp.Rational(1, 10)
    fwd, bwd = Stepper(scheme, h), Stepper(scheme, -h)
    worst = mp.mpf(0)
    with mp.workdps(DPS):
        for y0 in _step_points(scheme, seed=5):
            worst = max(worst, max(abs(a - b) for a, b in zip(bwd(fwd(y0)), y0)))
    ok = worst <= STEP_TOL
    return Certificate(f"{scheme.method}: the step is symmetric, Φ_(−h)(Φ_h(y0)) = y0 (symmetric nodes, "
                       "[Hai10]; checked on the equations with their float64 coefficients)",
                       NUMERICAL if ok else REFUTED, "max |Φ_(−h)(Φ_h(y0)) − y0|", "",
                       "60-digit steps at rational points, h = 1/10", time.perf_counter() - t0, REF_ENERGY,
                       {"worst": mp.nstr(worst, 5), "tolerance": STEP_TOL, "passed": ok})


def _measured_energy(scheme, m: int) -> Certificate:
    """What is not claimed for non-polynomial H: H is kept only to the quadrature error."""
    import mpmath as mp

    from .numeric import DPS, Stepper, param_point
    from .exact import guarded

    t0 = time.perf_counter()
    system = scheme.system
    H = sp.lambdify([list(system.y)], guarded(system.H.xreplace(param_point(system))), modules="mpmath")
    h = sp.Rational(1, 10)
    step = Stepper(scheme, h)
    worst = mp.mpf(0)
    with mp.workdps(DPS):
        for y0 in _step_points(scheme, seed=17):
            worst = max(worst, abs(H(step(y0)) - H([mp.mpf(v) for v in y0])))
    return Certificate(f"H is NOT kept exactly (H not a polynomial: the integrals use the {m}-node rule); "
                       f"only to the quadrature error: max |H(y1) − H(y0)| = {mp.nstr(worst, 3)} measured at h = 1/10",
                       NUMERICAL,
                       "max |H(y1) − H(y0)|", "", "60-digit steps at rational points", time.perf_counter() - t0,
                       REF_ENERGY, {"max_change": mp.nstr(worst, 5), "h": "1/10", "claimed": "approximate"})
