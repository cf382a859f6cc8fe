"""Symmetric composition coefficients and their order conditions.

A symmetric one-step method Φ_h of order 2 composed as

    Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h},      γ_i = γ_{s+1-i},  Σ γ_i = 1,

is symmetric again and has order K when the coefficients satisfy the order
conditions of [HLW06, §V.3].  The families here:

``"triple-jump"`` (Creutz–Gocksch 1989, Yoshida 1990)
    recursive: from order 2k to 2k + 2 with (γ1, γ2, γ1), γ1 = 1/(2 − 2^{1/(2k+1)}),
    γ2 = 1 − 2γ1; 3^{K/2 − 1} stages; exact algebraic numbers.
``"suzuki"`` (Suzuki 1990)
    recursive with five stages (γ1, γ1, γ2, γ1, γ1), γ1 = 1/(4 − 4^{1/(2k+1)}),
    γ2 = 1 − 4γ1; 5^{K/2 − 1} stages; exact; much smaller error constants than the
    triple jump at the same order (its substeps stay short).
``"kahan-li"`` (Kahan & Li 1997)
    optimised: s9odr6a (order 6, 9 stages), s17odr8a (order 8, 17 stages); the
    published 26-digit constants.
``"sofroniou-spaletta"`` (Sofroniou & Spaletta 2005)
    s35odr10 (order 10, 35 stages), 26-digit constants.

Order conditions are decided here, not assumed: the base method is written as
``Φ_h = exp(h X1 + h³ X3 + h⁵ X5 + …)`` with *free* generators X_k (a symmetric
method has only odd powers), the composition's logarithm is computed in the free
associative algebra truncated at weight K + 1 (BCH without a Lie basis), and
order K means ``log Ψ_h = h X1 + O(h^{K+1})``: every word of weight 2…K has
coefficient 0.  For the exact families the two conditions of each recursion
level are also proved exactly (``triple_jump_exact``); for published decimal
constants the check is numerical at 60 digits and reports how many digits the
conditions hold to.  The weight-(K+1) coefficients give the error constant
(their 2-norm in the word basis, :func:`error_constant`).

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §II.4, §V.3.
.. [KL97] W. Kahan, R.-C. Li, Math. Comp. 66 (1997) 1089–1099.
.. [SS05] M. Sofroniou, G. Spaletta, Optim. Methods Softw. 20 (2005) 597–613.
.. [Suz90] M. Suzuki, Phys. Lett. A 146 (1990) 319–323.
.. [Yos90] H. Yoshida, Phys. Lett. A 150 (1990) 262–268.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import mpmath as mp
import sympy as sp

from .series import exp as _exp
from .series import log as _log
from .series import mul as _mul

__all__ = ["Composition", "FAMILIES", "ALL_FAMILIES", "ORDERS", "DEFAULT_FAMILY", "composition", "stage_composition", "order_defects",
           "sequence_defects",
           "achieved_order", "error_constant", "efficiency", "triple_jump_exact"]

ORDERS = (2, 4, 6, 8, 10)
#: The family used for each order when none is given (smallest error constant per
#: stage among those available here; see the docs, "High order").
DEFAULT_FAMILY = {2: "base", 4: "suzuki", 6: "kahan-li", 8: "kahan-li", 10: "sofroniou-spaletta"}
DPS = 60

# Published constants (first half incl. the middle one; the sequence is symmetric).
_KAHAN_LI = {
    6: ["0.39216144400731413927925056", "0.33259913678935943859974864",
        "-0.70624617255763935980996482", "0.08221359629355080023149045",
        "0.79854399093482996339895035"],
    8: ["0.13020248308889008087881763", "0.56116298177510838456196441",
        "-0.38947496264484728640807860", "0.15884190655515560089621075",
        "-0.39590389413323757733623154", "0.18453964097831570709183254",
        "0.25837438768632204729397911", "0.29501172360931029887096624",
        "-0.60550853383003451169892108"],
}
_SOFSPA = {
    10: ["0.07879572252168641926390768", "0.31309610341510852776481247",
         "0.02791838323507806610952027", "-0.22959284159390709415121340",
         "0.13096206107716486317465686", "-0.26973340565451071434460973",
         "0.07497334315589143566613711", "0.11199342399981020488957508",
         "0.36613344954622675119314812", "-0.39910563013603589787862981",
         "0.10308739852747107731580277", "0.41143087395589023782070412",
         "-0.00486636058313526176219566", "-0.39203335370863990644808194",
         "0.05194250296244964703718290", "0.05066509075992449633587434",
         "0.04967437063972987905456880", "0.04931773575959453791768001"],
}
FAMILIES = {"triple-jump": (4, 6, 8, 10), "suzuki": (4, 6, 8, 10), "kahan-li": (6, 8),
            "sofroniou-spaletta": (10,)}
# Splitting families of H = T + U (methodgen.symbolic.splittings): Störmer–Verlet only, run as
# kick/drift/kick stages rather than as compositions of the base step.
from .splittings import SPLITTING_FAMILIES as _SPLIT  # noqa: E402

# Processed compositions (methodgen.symbolic.processing): a kernel between two processors, three modules.
PROCESSED_FAMILIES = {"blanes-casas-murua": (6, 8)}

#: Every family ``composition=`` accepts: the compositions above, the splittings, then the
#: processed families (built by :func:`methodgen.build` as three modules, not as one scheme).
ALL_FAMILIES = {**FAMILIES, **_SPLIT, **PROCESSED_FAMILIES}


@dataclass(frozen=True)
class Composition:
    """A symmetric composition: ``gammas`` (exact SymPy numbers or decimal strings), family, order."""

    family: str
    order: int
    gammas: tuple
    exact: bool
    source: str
    #: "method" (a composition that is the method), or a piece of a processed composition
    #: (:mod:`methodgen.symbolic.processing`): "kernel", "pre-processor", "post-processor".
    role: str = "method"
    #: Largest order defect that counts as satisfied for decimal constants: their printed
    #: digits (26 for Kahan–Li and Sofroniou–Spaletta: 1e-22; 15–19 for the processed
    #: families: 1e-14).  Exact coefficients: 1e-40 at 60 digits.
    digits_tol: float = 1e-22

    @property
    def tolerance(self) -> float:
        """The defect tolerance of the order conditions (see :attr:`digits_tol`)."""
        return 1e-40 if self.exact else self.digits_tol

    @property
    def stages(self) -> int:
        return len(self.gammas)

    def floats(self) -> tuple[float, ...]:
        """The coefficients rounded to float64 (what a generated module uses)."""
        return tuple(float(sp.N(g, 30)) if self.exact else float(mp.mpf(g)) for g in self.gammas)

    def mp(self) -> list:
        with mp.workdps(DPS):
            return [mp.mpf(str(sp.N(g, DPS + 10))) if self.exact else mp.mpf(g) for g in self.gammas]


def _mirror(half: list) -> tuple:
    return tuple(half) + tuple(reversed(half[:-1]))


def _recursive(order: int, parts: int) -> tuple:
    gam = (sp.Integer(1),)
    for k in range(1, order // 2):
        r = sp.Integer(parts - 1) ** sp.Rational(1, 2 * k + 1)
        g1 = 1 / (parts - 1 - r)
        g2 = -r * g1                      # = 1 - (parts - 1) γ1
        outer = [g1] * ((parts - 1) // 2)
        level = outer + [g2] + outer
        gam = tuple(a * b for a in level for b in gam)
    return gam


@lru_cache(maxsize=None)
def composition(order: int, family: str | None = None) -> Composition:
    """The composition of ``family`` for ``order`` (default: :data:`DEFAULT_FAMILY`)."""
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
    if order == 2:
        return Composition("base", 2, (sp.Integer(1),), True, "the base method itself")
    family = family or DEFAULT_FAMILY[order]
    if family not in ALL_FAMILIES:
        raise ValueError(f"unknown composition family {family!r}; valid: {sorted(ALL_FAMILIES)}")
    if order not in ALL_FAMILIES[family]:
        raise ValueError(f"the {family} family has orders {ALL_FAMILIES[family]}, not {order}")
    if family in _SPLIT:
        from .splittings import splitting
        return splitting(order, family)
    if family in PROCESSED_FAMILIES:
        raise ValueError(f"the {family} family is a processed composition: a kernel between two "
                         "processors, three modules built by methodgen.build (methodgen.symbolic.processing), "
                         "not one composed scheme")
    if family == "triple-jump":
        return Composition(family, order, _recursive(order, 3), True, "Creutz–Gocksch 1989, Yoshida 1990")
    if family == "suzuki":
        return Composition(family, order, _recursive(order, 5), True, "Suzuki 1990")
    if family == "kahan-li":
        return Composition(family, order, _mirror(_KAHAN_LI[order]), False,
                           f"Kahan & Li 1997, s{len(_mirror(_KAHAN_LI[order]))}odr{order}a (26 digits)")
    return Composition(family, order, _mirror(_SOFSPA[order]), False,
                       "Sofroniou & Spaletta 2005, s35odr10 (26 digits)")


# --- order conditions in the truncated free associative algebra ----------------------

def log_composition(gammas, wmax: int) -> dict:
    """``log Ψ`` up to weight ``wmax``, as {word (tuple of odd generator weights): coefficient}."""
    with mp.workdps(DPS):
        P = {(): mp.mpf(1)}
        gens = range(1, wmax + 1, 2)
        for g in gammas:
            g = mp.mpf(g)
            P = _mul(P, _exp({(k,): g**k for k in gens}, wmax), wmax)
        return _log(P, wmax)


def order_defects(comp: Composition, upto: int | None = None) -> dict[int, float]:
    """Largest |coefficient| of log Ψ - h X1 at each weight 1..upto (60-digit arithmetic)."""
    return sequence_defects(comp.mp(), upto or comp.order + 1)


def sequence_defects(gammas, upto: int) -> dict[int, float]:
    """:func:`order_defects` of any sequence of steps ``gammas`` (decimal strings or mpf, in the
    order of application; a processed composition's pre-processor, kernel and post-processor)."""
    L = log_composition(gammas, upto)
    out = {}
    with mp.workdps(DPS):
        for w in range(1, upto + 1):
            vals = [abs(v - (1 if k == (1,) else 0)) for k, v in L.items() if sum(k) == w]
            out[w] = float(max(vals)) if vals else 0.0
    return out


def achieved_order(comp: Composition, tol: float | None = None, upto: int = 11) -> int:
    """The largest K such that every defect of weight ≤ K is below ``tol``.

    ``tol``: 1e-40 for exact coefficients (evaluated at 60 digits), 1e-22 for
    the published 26-digit constants.
    """
    tol = tol if tol is not None else getattr(comp, "tolerance", 1e-40 if comp.exact else 1e-22)
    return order_of_defects(order_defects(comp, upto), tol)


def order_of_defects(d: dict[int, float], tol: float) -> int:
    """The largest K such that every defect ``d[w]`` of weight w ≤ K is at most ``tol``."""
    K = 0
    for w in sorted(d):
        if d[w] > tol:
            break
        K = w
    return K


def error_constant(comp: Composition) -> float:
    """2-norm of the weight-(K+1) coefficients of log Ψ (the leading local error, word basis)."""
    L = log_composition(comp.mp(), comp.order + 1)
    with mp.workdps(DPS):
        return float(mp.sqrt(sum(v**2 for k, v in L.items() if sum(k) == comp.order + 1)))


def efficiency(comp: Composition) -> float:
    """``s · C^(1/K)``: stages times the K-th root of the error constant — the cost of a
    given accuracy, up to a common factor (smaller is better; [KL97], [HLW06, §V.3.2])."""
    return comp.stages * error_constant(comp) ** (1.0 / comp.order)


def triple_jump_exact(order: int, parts: int = 3) -> list[sp.Expr]:
    """The recursion's conditions at each level, which must be exactly 0.

    Level k (order 2k → 2k + 2): ``Σ γ = 1`` and ``Σ γ^{2k+1} = 0`` for the level's
    coefficients (``parts`` = 3 triple jump, 5 Suzuki).  Returned as expressions
    (radicals) for :func:`methodgen.symbolic.verify.exact.certify`.
    """
    out = []
    for k in range(1, order // 2):
        r = sp.Integer(parts - 1) ** sp.Rational(1, 2 * k + 1)
        g1 = 1 / (parts - 1 - r)
        g2 = -r * g1
        out.append((parts - 1) * g1 + g2 - 1)
        out.append((parts - 1) * g1 ** (2 * k + 1) + g2 ** (2 * k + 1))
    return out


def stage_composition(order, family: str | None = None, *, offered=(2, 4, 6, 8), what: str = "the method"):
    """The symmetric composition (:func:`composition`) that raises a symmetric order-2 step to
    ``order``, checked as user input (the lattice and particle families' one check): the
    :class:`Composition` whose stages the caller runs as steps of size ``γ_k h``.

    Parameters
    ----------
    order : int
        One of ``offered`` (a bool is refused: ``True`` is not an order).
    family : str, optional
        A family of :data:`methodgen.symbolic.compositions.FAMILIES` offering ``order`` (default
        :data:`~methodgen.symbolic.compositions.DEFAULT_FAMILY`); ignored
        at order 2 (the base step itself, one stage γ = 1).
    offered : tuple of int
        The orders the caller runs.
    what : str
        The method's name, for the messages.

    Raises
    ------
    InputError
        An order not offered (the message names them), an unknown family or one without the order.
    """
    from ..errors import InputError

    names = ", ".join(map(str, offered))
    if isinstance(order, bool) or not isinstance(order, int) or order not in offered:
        raise InputError(f"{what} is a symmetric method of order 2, composed symmetrically to a higher order: "
                         f"the orders are {names}; got {order!r}")
    if order == 2:
        return composition(2)
    if family is not None and family not in FAMILIES:
        # (splittings are kick/drift stages of H = T + U, processed compositions three modules:
        # neither is a composition of one symmetric step)
        raise InputError(f"composition {family!r} is not a composition family of a symmetric step; the families "
                         f"are {', '.join(sorted(FAMILIES))}")
    try:
        return composition(order, family)
    except ValueError as exc:
        raise InputError(str(exc)) from None
