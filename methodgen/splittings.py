"""Splitting methods for ``H = T(p) + U(q)`` and their order conditions.

A symmetric splitting of ``H = T + U`` with kicks at both ends is

    Ψ_h = e^{b_{m+1} h B} e^{a_m h A} e^{b_m h B} … e^{b_2 h B} e^{a_1 h A} e^{b_1 h B},

``e^{a h A}`` the drift (flow of T for time a h), ``e^{b h B}`` the kick (flow of U),
with ``b_i = b_{m+2-i}``, ``a_i = a_{m+1-i}``, ``Σ a = Σ b = 1``.  A generated module runs
it as m *stages* of the first-same-as-last kernel (:mod:`methodgen.fsal`), each

    kick by KICK_A[k]·h (the carried force), drift by DRIFT[k]·h, new force, kick by KICK_B[k]·h,

stage 0 = (b_1, a_1, b_2) and stage k ≥ 1 = (0, a_{k+1}, b_{k+2}): one force evaluation
per stage.  (A symmetric composition of Störmer–Verlet with coefficients γ_k is the stages
(γ_k/2, γ_k, γ_k/2): :func:`composition_stages`.)

Families (the published constants, cross-checked against their order conditions here):

``"blanes-moan"`` (Blanes & Moan 2002, Table 2, S6 and S10)
    order 4 (6 stages = force evaluations) and order 6 (10 stages) for every splitting.
``"blanes-moan-rkn"`` (Blanes & Moan 2002, Table 3, SRKN_6^b and SRKN_11^b)
    order 4 (6 stages) and order 6 (11 stages) for Runge–Kutta–Nyström problems
    (T quadratic in p with a constant mass matrix, so [B,[B,[B,A]]] = 0); only order 2 for a
    general splitting (see below).
``"mclachlan"`` (McLachlan 1995, S5; [HLW06, (V.3.6)])
    order 4, 5 stages, exact algebraic coefficients (√19): the 5-fold composition of
    symplectic Euler with its adjoint, written with the kicks at both ends (6 kicks, 5
    drifts: 5 force evaluations).

Order conditions are decided, not assumed: the product of exponentials is expanded in the
free associative algebra on the two generators A and B, truncated at degree K + 1, and its
logarithm is compared with ``A + B``; order K means every word of degree 2…K has coefficient 0
(60-digit arithmetic; the defects are reported, tolerance 1e-40 for exact coefficients and
1e-13 for the 15-digit published constants).  This is the order *for every splitting*.
The RKN order rests on the reduced conditions of a quadratic T, which are not checked
symbolically here: it is stated as **measured** (error ratio under halving h on
Hénon–Heiles, tests/test_splittings.py) and labelled so.

References
----------
.. [BM02] S. Blanes, P. C. Moan, J. Comput. Appl. Math. 142 (2002) 313–330.
.. [McL95] R. I. McLachlan, SIAM J. Sci. Comput. 16 (1995) 151–168.
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §III.5, §V.3.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import mpmath as mp
import sympy as sp

__all__ = ["Splitting", "SPLITTING_FAMILIES", "RKN_FAMILIES", "splitting", "is_splitting",
           "log_splitting", "splitting_defects", "general_order", "splitting_error_constant",
           "composition_stages"]

DPS = 60

#: family → orders (the order claimed: for every splitting, or RKN for RKN_FAMILIES).
SPLITTING_FAMILIES = {"blanes-moan": (4, 6), "blanes-moan-rkn": (4, 6), "mclachlan": (4,)}
#: Families whose order holds only for RKN problems (T = ½ pᵀ M⁻¹ p, M constant).
RKN_FAMILIES = ("blanes-moan-rkn",)

# Published constants: (kicks b_1 … up to the middle, drifts a_1 … up to the middle); the
# middle coefficient of the longer list is fixed by Σ = 1 (below), as the papers do.
_BM_S6 = (["0.0792036964311957", "0.353172906049774", "-0.0420650803577195"],
          ["0.209515106613362", "-0.143851773179818"])
_BM_S10 = (["0.0502627644003922", "0.413514300428344", "0.0450798897943977", "-0.188054853819569",
            "0.541960678450780"],
           ["0.148816447901042", "-0.132385865767784", "0.067307604692185", "0.432666402578175"])
_BM_SRKN6 = (["0.0829844064174052", "0.396309801498368", "-0.0390563049223486"],
             ["0.245298957184271", "0.604872665711080"])
_BM_SRKN11 = (["0.0414649985182624", "0.198128671918067", "-0.0400061921041533",
               "0.0752539843015807", "-0.0115113874206879"],
              ["0.123229775946271", "0.290553797799558", "-0.127049212625417",
               "-0.246331761062075", "0.357208872795928"])


@dataclass(frozen=True)
class Splitting:
    """A symmetric kick-drift-kick splitting: ``kicks`` b_1 … b_{m+1}, ``drifts`` a_1 … a_m.

    The coefficients are exact SymPy numbers (``exact``) or decimal strings.  ``order`` is
    the claimed order (for RKN problems only when ``rkn``); ``stages`` = m = force
    evaluations per step.
    """

    family: str
    order: int
    kicks: tuple
    drifts: tuple
    exact: bool
    source: str
    rkn: bool = False

    kind = "splitting"

    @property
    def stages(self) -> int:
        return len(self.drifts)

    @property
    def gammas(self) -> tuple:
        """The drift coefficients (the stage "steps" a message names)."""
        return self.drifts

    def _f(self, x) -> float:
        return float(sp.N(x, 30)) if self.exact else float(mp.mpf(x))

    def floats(self) -> tuple[float, ...]:
        """The drift coefficients rounded to float64."""
        return tuple(self._f(a) for a in self.drifts)

    def stage_fractions(self) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """(KICK_A, DRIFT, KICK_B) per stage, float64: stage 0 = (b_1, a_1, b_2), stage k ≥ 1 =
        (0, a_{k+1}, b_{k+2})."""
        b = [self._f(x) for x in self.kicks]
        a = [self._f(x) for x in self.drifts]
        return (tuple([b[0]] + [0.0] * (len(a) - 1)), tuple(a), tuple(b[1:]))

    def mp(self) -> tuple[list, list]:
        with mp.workdps(DPS):
            conv = (lambda g: mp.mpf(str(sp.N(g, DPS + 10)))) if self.exact else mp.mpf
            return [conv(x) for x in self.kicks], [conv(x) for x in self.drifts]


def is_splitting(comp) -> bool:
    return getattr(comp, "kind", None) == "splitting"


def composition_stages(gammas) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
    """(KICK_A, DRIFT, KICK_B) of the symmetric composition of Störmer–Verlet with the float64
    coefficients ``gammas``: stage k = (γ_k/2, γ_k, γ_k/2) (halving is exact in binary, so
    ``h * (γ/2)`` is bitwise ``(h * γ) / 2``)."""
    g = tuple(float(x) for x in gammas)
    half = tuple(x / 2 for x in g)
    return half, g, half


def _decimal_symmetric(kicks_half: list, drifts_half: list, exact=False):
    """Mirror the published halves; the middle coefficient of the longer list closes Σ = 1."""
    with mp.workdps(DPS):
        b = [mp.mpf(x) for x in kicks_half]
        a = [mp.mpf(x) for x in drifts_half]
        if len(b) == len(a) + 1:      # odd number of kicks: a middle kick, an even number of drifts
            bm = 1 - 2 * mp.fsum(b)
            am = mp.mpf("0.5") - mp.fsum(a)
            kicks = b + [bm] + b[::-1]
            drifts = a + [am, am] + a[::-1]
        else:                          # equal halves: a middle drift, an even number of kicks
            bm = mp.mpf("0.5") - mp.fsum(b)
            am = 1 - 2 * mp.fsum(a)
            kicks = b + [bm, bm] + b[::-1]
            drifts = a + [am] + a[::-1]
        return (tuple(mp.nstr(x, DPS) for x in kicks), tuple(mp.nstr(x, DPS) for x in drifts))


def _mclachlan():
    """[HLW06, (V.3.6)]: Ψ_h = Φ_{α_5 h} ∘ Φ*_{β_5 h} ∘ … ∘ Φ_{α_1 h} ∘ Φ*_{β_1 h}, with Φ
    symplectic Euler (drift then kick) and Φ* its adjoint (kick then drift), as one splitting:
    adjacent kicks merge, so the drifts are 2/5, -1/10, 2/5, -1/10, 2/5 and the 6 kicks the
    sums of α and β (the order conditions do not depend on which flow is called A)."""
    r = sp.sqrt(19)
    alpha = [(146 + 5 * r) / 540, (-2 + 10 * r) / 135, sp.Rational(1, 5), (-23 - 20 * r) / 270,
             (14 - r) / 108]
    beta = alpha[::-1]
    # rightmost first: Φ*_{β_1 h} = kick(β_1 h) ∘ drift(β_1 h) (drift first), then
    # Φ_{α_1 h} = drift(α_1 h) ∘ kick(α_1 h) (kick first), ...
    seq = []   # (letter, coefficient), first applied first
    for al, be in zip(alpha, beta):
        seq += [("B", be), ("A", be), ("A", al), ("B", al)]
    return _merge(seq)


def _merge(seq):
    """Merge adjacent like flows of ``seq`` (first applied first) into kicks/drifts."""
    out: list = []
    for letter, c in seq:
        if out and out[-1][0] == letter:
            out[-1] = (letter, sp.nsimplify(sp.radsimp(out[-1][1] + c)))
        else:
            out.append((letter, c))
    if out[0][0] == "A":
        out.insert(0, ("B", sp.Integer(0)))
    if out[-1][0] == "A":
        out.append(("B", sp.Integer(0)))
    kicks = tuple(sp.radsimp(c) for L, c in out if L == "B")
    drifts = tuple(sp.radsimp(c) for L, c in out if L == "A")
    return kicks, drifts


@lru_cache(maxsize=None)
def splitting(order: int, family: str) -> Splitting:
    """The splitting of ``family`` with ``order`` (see :data:`SPLITTING_FAMILIES`)."""
    if family not in SPLITTING_FAMILIES:
        raise ValueError(f"unknown splitting family {family!r}; valid: {sorted(SPLITTING_FAMILIES)}")
    if order not in SPLITTING_FAMILIES[family]:
        raise ValueError(f"the {family} family has orders {SPLITTING_FAMILIES[family]}, not {order}")
    if family == "blanes-moan":
        k, d = _decimal_symmetric(*(_BM_S6 if order == 4 else _BM_S10))
        return Splitting(family, order, k, d, False,
                         f"Blanes & Moan 2002, {'S6' if order == 4 else 'S10'} (15 digits)")
    if family == "blanes-moan-rkn":
        src = _BM_SRKN6 if order == 4 else _BM_SRKN11
        k, d = _decimal_symmetric(*src)
        name = "SRKN_6^b" if order == 4 else "SRKN_11^b"
        return Splitting(family, order, k, d, False, f"Blanes & Moan 2002, {name} (15 digits; RKN order)",
                         rkn=True)
    k, d = _mclachlan()
    return Splitting(family, 4, k, d, True, "McLachlan 1995, S5 (exact, √19)")


# --- order conditions in the free associative algebra on {A, B} -------------------------

def _mul(x: dict, y: dict, wmax: int) -> dict:
    out: dict = {}
    for u, a in x.items():
        for v, b in y.items():
            if len(u) + len(v) <= wmax:
                w = u + v
                out[w] = out.get(w, 0) + a * b
    return out


def _exp_letter(letter: str, c, wmax: int) -> dict:
    out = {(): mp.mpf(1)}
    term = mp.mpf(1)
    for n in range(1, wmax + 1):
        term = term * c / n
        out[(letter,) * n] = term
    return out


def _log(P: dict, wmax: int) -> dict:
    Z = {k: v for k, v in P.items() if k != ()}
    out: dict = {}
    power = {(): mp.mpf(1)}
    for n in range(1, wmax + 1):
        power = _mul(power, Z, wmax)
        if not power:
            break
        for k, v in power.items():
            out[k] = out.get(k, 0) + (v if n % 2 else -v) / n
    return out


def log_splitting(kicks, drifts, wmax: int) -> dict:
    """``log Ψ`` (h = 1) up to degree ``wmax`` as {word over "A", "B": coefficient}, for
    Ψ = e^{b_{m+1} B} … e^{a_1 A} e^{b_1 B}.  The operator product applies its rightmost
    factor first; words are written in that product order, so the first flow applied is
    the word's last letter."""
    with mp.workdps(DPS):
        P = {(): mp.mpf(1)}
        seq = []
        for i, a in enumerate(drifts):
            seq += [("B", kicks[i]), ("A", a)]
        seq.append(("B", kicks[len(drifts)]))
        for letter, c in seq:   # later flows multiply from the left
            P = _mul(_exp_letter(letter, mp.mpf(c), wmax), P, wmax)
        return _log(P, wmax)


def splitting_defects(sp_: Splitting, upto: int | None = None) -> dict[int, float]:
    """Largest |coefficient| of ``log Ψ - (A + B)`` at each degree 1..upto (60 digits)."""
    upto = upto or sp_.order + 1
    b, a = sp_.mp()
    L = log_splitting(b, a, upto)
    out = {}
    with mp.workdps(DPS):
        for w in range(1, upto + 1):
            vals = [abs(v - (1 if k in (("A",), ("B",)) else 0)) for k, v in L.items() if len(k) == w]
            out[w] = float(max(vals)) if vals else 0.0
    return out


def general_order(sp_: Splitting, tol: float | None = None, upto: int = 7) -> int:
    """The largest K with every defect of degree ≤ K below ``tol`` — the order for every
    splitting (1e-40 for exact coefficients, 1e-13 for the 15-digit published constants)."""
    tol = tol if tol is not None else (1e-40 if sp_.exact else 1e-13)
    d = splitting_defects(sp_, upto)
    K = 0
    for w in range(1, upto + 1):
        if d[w] > tol:
            break
        K = w
    return K


def splitting_error_constant(sp_: Splitting, degree: int | None = None) -> float:
    """2-norm of the degree-``degree`` coefficients of log Ψ (default K + 1, K the general
    order): the leading local error in the word basis."""
    K = general_order(sp_)
    degree = degree or K + 1
    b, a = sp_.mp()
    L = log_splitting(b, a, degree)
    with mp.workdps(DPS):
        return float(mp.sqrt(sum(v**2 for k, v in L.items() if len(k) == degree)))
