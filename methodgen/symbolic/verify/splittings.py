"""What is certified about a splitting of H = T + U (:mod:`methodgen.symbolic.splittings`).

1. Order of the coefficients for every splitting: ``log Ψ`` in the free associative algebra on
   {A, B} against ``A + B`` up to degree K.  Exact coefficients (McLachlan's √19): every
   coefficient of degree ≤ K is reduced to 0 by SymPy (``proved``); the published 15-digit
   constants: 60-digit evaluation (``numerical``: the conditions hold to the printed digits).
   An RKN family's order (T quadratic, M constant) is decided modulo the Lie ideal of
   [B, [B, [B, A]]] (:func:`methodgen.symbolic.splittings.rkn_order`), numerically at 60 digits.
2. The float64 stage fractions a generated module uses satisfy the same conditions up to
   rounding (60-digit evaluation of the rounded values).
3. Symmetry: kicks and drifts are palindromes (exact comparison), and each factor is an
   exact flow (e^{-cX} e^{cX} = id), so Ψ_{-h} ∘ Ψ_h = id.
4. Symplecticity: every factor is a kick ``p -= c h ∇U(q)`` or a drift ``q += c h ∇T(p)``, a
   shear with a symmetric Hessian block for every real step; the base step's structural proof
   (the same shears at h/2, h) holds for every real step, so it covers each factor.
5. Invariants: I is kept by every kick and every drift iff {I, U} = 0 and {I, T} = 0 (each
   factor is the exact flow of U or T); both brackets reduced to 0 exactly.
"""

from __future__ import annotations

import time

import mpmath as mp
import sympy as sp

from ..derive import separable_split
from ..splittings import DPS, Splitting, general_order, rkn_defects, splitting_defects
from .compositions import _derive, _digits, _fmt_defects, _missing
from .exact import certify
from .report import NUMERICAL, PROVED, REFUTED, Certificate

__all__ = ["splitting_order_certificate", "splitting_float_certificate", "splitting_symmetry_certificate",
           "splitting_inherited_certificates", "exact_defects"]

REF_SPLIT = "Blanes & Moan, J. Comput. Appl. Math. 142 (2002); HLW06 §III.5, §V.3"


def _exact_log(sp_: Splitting, wmax: int) -> dict:
    """log Ψ up to degree ``wmax`` with SymPy numbers (exact coefficients only)."""
    def mul(x, y):
        out: dict = {}
        for u, a in x.items():
            for v, b in y.items():
                if len(u) + len(v) <= wmax:
                    out[u + v] = sp.expand(out.get(u + v, 0) + a * b)
        return out

    P = {(): sp.Integer(1)}
    seq = []
    for i, a in enumerate(sp_.drifts):
        seq += [("B", sp_.kicks[i]), ("A", a)]
    seq.append(("B", sp_.kicks[-1]))
    for letter, c in seq:
        e = {(): sp.Integer(1)}
        for n in range(1, wmax + 1):
            e[(letter,) * n] = sp.expand(sp.sympify(c) ** n / sp.factorial(n))
        P = mul(e, P)
    Z = {k: v for k, v in P.items() if k != ()}
    out: dict = {}
    power = {(): sp.Integer(1)}
    for n in range(1, wmax + 1):
        power = mul(power, Z)
        for k, v in power.items():
            out[k] = sp.expand(out.get(k, 0) + (v if n % 2 else -v) / n)
    return out


def exact_defects(sp_: Splitting, upto: int) -> list:
    """The coefficients of ``log Ψ - (A + B)`` of degree 1..upto, exact (SymPy)."""
    L = _exact_log(sp_, upto)
    return [sp.radsimp(v - (1 if k in (("A",), ("B",)) else 0)) for k, v in L.items() if 1 <= len(k) <= upto]


def splitting_order_certificate(sp_: Splitting) -> Certificate:
    """Order of the coefficients for every splitting (see the module docstring, 1)."""
    t0 = time.perf_counter()
    if sp_.rkn:
        return _rkn_order_certificate(sp_, t0)
    K = sp_.order
    claim = (f"splitting coefficients ({sp_.family}, {sp_.stages} stages): Ψ_h = e^(b_(m+1) hB) … "
             f"e^(a_1 hA) e^(b_1 hB) has order {K} for every splitting H = T + U")
    det: dict = {"source": sp_.source, "how": "log Ψ in the free associative algebra on {A, B}, truncated "
                 "at degree K + 1: order K iff every coefficient of degree 2…K vanishes and those of "
                 "A and B are 1"}
    if sp_.exact:
        cert = certify(claim, exact_defects(sp_, K), ref=REF_SPLIT, details=det)
        cert.seconds = time.perf_counter() - t0
        return cert
    d = splitting_defects(sp_, K + 1)
    worst = max(d[w] for w in range(1, K + 1))
    det.update(defects_by_degree=_fmt_defects(d), max_defect_up_to_K=f"{worst:.1e}",
               conditions_hold_to_digits=_digits(worst), digits=DPS, tolerance=1e-13,
               why_numerical="published 15-digit constants: the conditions hold only to the printed digits")
    status = NUMERICAL if worst < 1e-13 else REFUTED
    if status == REFUTED:
        det["counterexample"] = f"degree ≤ {K}: defect {worst:.3e}"
    else:
        det["passed"] = True
        det["leading_defect"] = f"{d[K + 1]:.3e}"
    return Certificate(claim, status, "log Ψ_h - (A + B) up to degree K", "", "60-digit free-algebra order "
                       "conditions", time.perf_counter() - t0, REF_SPLIT, det)


def _rkn_order_certificate(sp_: Splitting, t0: float) -> Certificate:
    """RKN order: the defects modulo the ideal of [B, [B, [B, A]]] (60 digits)."""
    K = sp_.order
    claim = (f"splitting coefficients ({sp_.family}, {sp_.stages} stages): order {K} for every "
             "Runge–Kutta–Nyström problem, T = pᵀM⁻¹p/2 (M constant), U = U(q)")
    d = rkn_defects(sp_, K + 1)
    worst = max(d[w] for w in range(1, K + 1))
    det = {"source": sp_.source, "defects_modulo_ideal_by_degree": _fmt_defects(d),
           "general_order": general_order(sp_), "max_defect_up_to_K": f"{worst:.1e}",
           "conditions_hold_to_digits": _digits(worst), "digits": DPS, "tolerance": 1e-13,
           "how": ("log Ψ in the free associative algebra on {A, B}; each degree's part of log Ψ - (A + B) "
                   "projected off the span of ad_Y1 … ad_Yk [B,[B,[B,A]]] (least squares, 60 digits): "
                   "that ideal vanishes for T quadratic in p, since {U,{U,{U,T}}} = 0"),
           "why_numerical": "published 15-digit constants: the conditions hold only to the printed digits"}
    status = NUMERICAL if worst < 1e-13 else REFUTED
    if status == REFUTED:
        det["counterexample"] = f"degree ≤ {K}: defect modulo the ideal {worst:.3e}"
    else:
        det["passed"] = True
        det["leading_defect"] = f"{d[K + 1]:.3e}"
    return Certificate(claim, status, "log Ψ_h - (A + B) modulo the ideal of [B,[B,[B,A]]]", "",
                       "60-digit free-algebra order conditions modulo the RKN ideal", time.perf_counter() - t0,
                       REF_SPLIT, det)


def _rounded(sp_: Splitting) -> Splitting:
    ka, dr, kb = sp_.stage_fractions()
    kicks = (ka[0],) + tuple(kb)
    return Splitting(sp_.family, sp_.order, tuple(repr(x) for x in kicks), tuple(repr(x) for x in dr), False,
                     "float64", sp_.rkn)


def splitting_float_certificate(sp_: Splitting, key: str = "") -> Certificate:
    """The float64 stage fractions keep the order conditions up to rounding (module docstring, 2)."""
    t0 = time.perf_counter()
    K = sp_.order
    rounded = _rounded(sp_)
    d = rkn_defects(rounded, K) if sp_.rkn else splitting_defects(rounded, K)
    worst = max(d.values())
    claim = (f"float64 stage fractions of {key or sp_.family}: KICK_A, DRIFT, KICK_B satisfy the order-{K} "
             f"{'RKN ' if sp_.rkn else ''}conditions up to rounding")
    det = {"defects_by_degree": _fmt_defects(d), "threshold": 1e-10,
           "why_numerical": "float64 values: the conditions hold to rounding, not exactly"}
    status = NUMERICAL if worst < 1e-10 else REFUTED
    det["passed"] = status == NUMERICAL
    return Certificate(claim, status, "", "", "60-digit free-algebra order conditions of the float64 values",
                       time.perf_counter() - t0, REF_SPLIT, det)


def _palindrome(xs, exact: bool) -> bool:
    if exact:
        return all(sp.simplify(sp.sympify(a) - sp.sympify(b)) == 0 for a, b in zip(xs, reversed(xs)))
    with mp.workdps(DPS):
        return all(mp.mpf(a) == mp.mpf(b) for a, b in zip(xs, reversed(xs)))


def splitting_symmetry_certificate(sp_: Splitting, key: str = "") -> Certificate:
    """Ψ_{-h} ∘ Ψ_h = id (module docstring, 3)."""
    t0 = time.perf_counter()
    claim = f"{key or sp_.family}: the splitting is symmetric, Ψ_(-h) ∘ Ψ_h = id"
    ok = _palindrome(sp_.kicks, sp_.exact) and _palindrome(sp_.drifts, sp_.exact)
    fl = sp_.stage_fractions()
    kicks_f = (fl[0][0],) + fl[2]
    ok_f = list(kicks_f) == list(kicks_f)[::-1] and list(fl[1]) == list(fl[1])[::-1]
    det = {"palindromic_coefficients": ok, "palindromic_float64": ok_f}
    if ok and ok_f:
        return Certificate(claim, PROVED, "", "", "structural: the kicks b and drifts a are palindromes "
                           "(compared exactly) and each factor is an exact flow, e^(-chX) e^(chX) = id, so "
                           "Ψ_(-h) = Ψ_h^(-1)", time.perf_counter() - t0, REF_SPLIT, det)
    det["counterexample"] = "the coefficients are not palindromic"
    return Certificate(claim, REFUTED, "", "", "structural", time.perf_counter() - t0, REF_SPLIT, det)


def splitting_inherited_certificates(scheme, base) -> list[Certificate]:
    """Symplecticity from the base step's structural proof, and the invariants kept by every
    kick and every drift (module docstring, 4 and 5)."""
    key, t, system = scheme.key, scheme.traits, scheme.system
    out = []
    if t.symplectic:
        out.append(_derive(f"{key}: the splitting is symplectic (a composition of symplectic shears)", REF_SPLIT,
                           scheme, base.get("symplectic"), None,
                           "derived: every factor is a kick p -= c h∇U(q) or a drift q += c h∇T(p) with a "
                           "real c (some negative), the shears of the base step's structural proof, which "
                           "holds for every real step; (Ψ')ᵀJΨ' = J by the chain rule", missing=_missing(base)))
    sep = separable_split(system)
    invs = {inv.name: inv.expr for inv in scheme.invariants}
    q, p = list(system.q), list(system.p)

    def bracket(f, g):
        return sp.Add(*[sp.diff(f, a) * sp.diff(g, b) - sp.diff(f, b) * sp.diff(g, a) for a, b in zip(q, p)])

    for name in t.preserved:
        expr = invs.get(name)
        if expr is None or name == "H":
            continue
        out.append(certify(f"{key}: every kick and every drift keeps {name} = {expr} ({{I, U}} = {{I, T}} = 0)",
                           [bracket(expr, sep.U), bracket(expr, sep.T)], ref=REF_SPLIT,
                           details={"why": "each factor is the exact flow of U or of T for a real time; "
                                    "I is constant along the flow of F iff {I, F} = 0"}))
    return out
