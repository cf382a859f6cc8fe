"""Claims about a symmetric composition ``Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}`` of a base step Φ_h.

A composed scheme (``discretize(system, method, order=K)``) keeps the base
step's equations, in the symbolic step h, and adds the coefficients γ
(:class:`methodgen.symbolic.compositions.Composition`).  The other claim groups of
:func:`methodgen.symbolic.verify.verify` certify the base step Φ_h; this module
certifies what the composition adds, and what it inherits:

1. **Order of the coefficients** (:func:`order_certificate`).  Triple jump and
   Suzuki are recursive: level k turns a symmetric method of order 2k into one of
   order 2k + 2 with palindromic coefficients satisfying ``Σγ = 1`` and
   ``Σγ^{2k+1} = 0`` [HLW06, §II.4].  Each level's conditions are reduced to
   exactly 0 (no floating point), and the product of the levels is rebuilt and
   compared exactly with the composition's γ.  Published decimal constants
   (Kahan–Li, Sofroniou–Spaletta) satisfy their conditions only to the printed
   digits: their certificate is numerical (free-algebra order conditions at 60
   digits, :func:`methodgen.symbolic.compositions.order_defects`).
2. **The float64 coefficients the generated module runs**
   (:func:`float_coefficients_certificate`): their order defects, from their
   exact binary values (numerical: round-off size, never a proof).
3. **Symmetry** (:func:`symmetry_certificate`): proved when the γ are exactly
   palindromic and the base step's symmetry is proved for every real h.
4. **Inherited properties** (:func:`inherited_certificates`): every invariant,
   constraint and symplecticity the composed traits claim.  Each stage is the base
   map at the real step ``γ_i h`` (some γ_i are negative), so a base proof carries
   over only if it holds for every real h, negative ones included: the proof must
   be an exact identity in the step symbol :data:`~methodgen.symbolic.schemes.base.STEP`,
   which is ``real=True`` with no sign assumption (checked, with the route of the
   base proof: :func:`holds_for_every_real_h`).  The derived status is never
   stronger than the base one.

Where a base certificate is not a sign-free proof, the composed map itself is
run in 60-digit arithmetic (:class:`ComposedStepper`, the base equations solved
by Newton at each stage step ``γ_i h``, h = 1/10, negative stage steps included):
a violation far above the evaluation error (> 1e-15) is a refutation at that start
point (an exact rational state, or a point on T*Q projected to 55 digits);
otherwise the certificate is numerical.

Not inherited, hence not claimed: Kahan's modified energy and volume form and the
trapezoidal rule's conjugacy to the midpoint rule depend on h, and the stages use
different steps; their certificates concern the base step only.  On a quadratic
1-DOF H the re-timing theorem *does* carry over, with a different re-timing: the
stage maps are all functions of the same matrix A and commute, so
``Ψ_h = exp(Σ_i τ(γ_i h) A)``.

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §II.3 (adjoint and symmetric methods), §II.4 (composition methods),
   §V.3 (order conditions of compositions).
"""

from __future__ import annotations

import math
import random
import time
from decimal import Decimal
from fractions import Fraction
from functools import lru_cache
from typing import Callable, NamedTuple

import mpmath as mp
import sympy as sp

from ..compositions import Composition, order_defects, triple_jump_exact
from ..derive import constraint_jacobian, separable_split
from ..schemes.base import STEP
from .exact import ZERO_AS_BUILT, guarded, reduce_to_zero
from .maps import NUM_TOL, symplectic_matrix
from .numeric import DPS, Stepper, param_point, random_state
from .report import NUMERICAL, PROVED, REFUTED, UNDECIDED, Certificate

__all__ = ["BaseResults", "ComposedStepper", "order_certificate", "float_coefficients_certificate",
           "symmetry_certificate", "inherited_certificates", "holds_for_every_real_h",
           "recursion_levels", "compose_levels", "exactly_palindromic", "BASE_PREFIX", "REF_HLW"]

REF_HLW = "Hairer, Lubich, Wanner, Geometric Numerical Integration (2006), §II.4, §V.3"
#: Prefix of the base step's certificates in a composed scheme's report.
BASE_PREFIX = "base step Φ_h: "
#: Stages per recursion level of the exact families.
PARTS = {"triple-jump": 3, "suzuki": 5}
#: The step of the 60-digit checks of the composed map (stage steps γ_i h).
H_CHECK = sp.Rational(1, 10)
#: A 60-digit check above this is a violation, not evaluation error (that is < 1e-35).
REFUTE_ABOVE = 1e-15
#: Unit round-off of float64.
UNIT_ROUNDOFF = 2.0 ** -53
#: Float coefficients whose order defects exceed this are wrong coefficients, not rounded
#: ones (rounding gives <= 1e-10 for every family here, triple jump of order 10 worst).
FLOAT_REFUTE = 1e-8
FLOAT_TOL = 1e-10

_X = sp.Symbol("x")
_RANK = {REFUTED: 0, UNDECIDED: 1, NUMERICAL: 2, PROVED: 3}


# --- what the base step's claim groups produced -------------------------------------------

class BaseResults:
    """The base step's certificates, by property, for the composition's derived claims.

    Properties: ``"invariant:<name>"``, ``"constraint:position"``,
    ``"constraint:velocity"``, ``"symplectic"``, ``"symmetry"``, ``"retiming"``,
    ``"helper"`` and others nobody derives from.  A claim group that raised or ran
    out of time is remembered in :attr:`failed` (label → reason), so a derived claim
    can say why its evidence is missing.
    """

    def __init__(self):
        self.items: list[tuple[str, Certificate]] = []
        self.failed: dict[str, str] = {}

    def recorder(self, label: str, items_fn: Callable[[], object], prefix: str = BASE_PREFIX):
        """A claim thunk: run ``items_fn`` (→ ``[(property, certificate)]`` or None), record the
        items with each claim prefixed by ``prefix``, return the certificates."""
        def run():
            try:
                items = _pairs(items_fn())
            except BaseException as exc:        # BudgetExceeded is a BaseException
                self.failed[label] = f"{type(exc).__name__}: {str(exc).strip()[:200]}"
                raise
            items = [(p, _relabelled(c, prefix)) for p, c in items]
            self.items += items
            return [c for _, c in items]
        return run

    def get(self, prop: str) -> list[Certificate]:
        """The recorded certificates about ``prop`` (empty if none, or if their group failed)."""
        return [c for p, c in self.items if p == prop]


def _pairs(out) -> list[tuple[str, Certificate]]:
    if out is None:
        return []
    return [(p, c) for p, c in out if c is not None]


def _relabelled(cert: Certificate, prefix: str) -> Certificate:
    if not prefix or cert.claim.startswith(prefix):
        return cert
    from dataclasses import replace
    return replace(cert, claim=prefix + cert.claim, details=dict(cert.details))


# --- exact arithmetic on the coefficients ---------------------------------------------------

def _exact_zero(e) -> str | None:
    """The exact route that reduces the constant ``e`` to 0, or None (never with floats)."""
    e = sp.sympify(e)
    if e.has(sp.Float) or e.free_symbols:
        return None
    if e == 0:
        return ZERO_AS_BUILT
    route = reduce_to_zero(e, allow_simplify=False)
    if route is not None:
        return route
    if sp.radsimp(e) == 0:
        return "radsimp"
    if sp.count_ops(e) <= 200:
        try:
            if sp.minimal_polynomial(e, _X) == _X:
                return "minimal polynomial = x"
        except Exception:       # not algebraic / not supported: no proof from this route
            pass
    return None


def _exact_nonzero(e) -> str | None:
    """A proof that the algebraic constant ``e`` is not 0 (its minimal polynomial is not x), or None."""
    e = sp.sympify(e)
    if e.has(sp.Float) or e.free_symbols or sp.count_ops(e) > 200:
        return None
    try:
        poly = sp.minimal_polynomial(e, _X)
    except Exception:
        return None
    return None if poly == _X else f"minimal polynomial {poly} ≠ x"


def _decide(e) -> tuple[str, str]:
    """``("zero" | "nonzero" | "unknown", how)`` for the constant ``e``, exactly."""
    route = _exact_zero(e)
    if route is not None:
        return "zero", route
    why = _exact_nonzero(e)
    if why is not None:
        return "nonzero", why
    return "unknown", "neither reduced to 0 nor proved nonzero"


def _exact_number(g, exact: bool) -> sp.Expr:
    """A coefficient as an exact SymPy number: radicals as they are, decimals as rationals."""
    if exact:
        return sp.sympify(g)
    return sp.Rational(Fraction(str(g)))


def recursion_levels(order: int, parts: int) -> list[tuple]:
    """The exact coefficients of each recursion level (order 2k → 2k + 2), k = 1 … K/2 - 1.

    ``(γ1, …, γ1, γ2, γ1, …, γ1)`` with ``parts`` entries, ``γ1 = 1/(parts - 1 - r)``,
    ``γ2 = -r γ1``, ``r = (parts - 1)^{1/(2k+1)}`` [Yos90, Suz90].
    """
    out = []
    for k in range(1, order // 2):
        r = sp.Integer(parts - 1) ** sp.Rational(1, 2 * k + 1)
        g1 = 1 / (parts - 1 - r)
        outer = [g1] * ((parts - 1) // 2)
        out.append(tuple(outer + [-r * g1] + outer))
    return out


def compose_levels(levels) -> tuple:
    """The stage coefficients of the nested composition: level k runs the level-(k-1) method
    with steps ``a h`` for each of its coefficients a, in order."""
    gam = (sp.Integer(1),)
    for level in levels:
        gam = tuple(a * b for a in level for b in gam)
    return gam


def _level_conditions(k: int, level: tuple) -> dict[str, sp.Expr]:
    n = len(level)
    out = {"Σγ - 1": sp.Add(*level) - 1, f"Σγ^{2 * k + 1}": sp.Add(*[g ** (2 * k + 1) for g in level])}
    for i in range(n // 2):
        out[f"γ{i + 1} - γ{n - i}"] = level[i] - level[n - 1 - i]
    return out


def _same_gammas(built: tuple, gammas: tuple) -> tuple[bool, str]:
    """Are the rebuilt coefficients exactly the composition's?  (ok, how / where not)."""
    if len(built) != len(gammas):
        return False, f"{len(gammas)} coefficients, the recursion gives {len(built)}"
    routes = set()
    for i, (a, b) in enumerate(zip(built, gammas)):
        b = sp.sympify(b)
        if a == b:                          # same canonical SymPy expression
            routes.add("structural equality")
            continue
        verdict, how = _decide(a - b)
        if verdict == "zero":
            routes.add(how)
            continue
        with mp.workdps(DPS):
            diff = mp.mpf(str(sp.N(a - b, DPS + 10)))
        why = how if verdict == "nonzero" else f"60-digit value {mp.nstr(diff, 5)}"
        return False, f"γ_{i + 1} differs from the recursion's product ({why})"
    return True, ", ".join(sorted(routes))


@lru_cache(maxsize=64)
def _defects(comp: Composition, upto: int) -> dict[int, float]:
    return order_defects(comp, upto)


def _fmt_defects(d: dict[int, float]) -> dict[str, str]:
    return {str(w): f"{v:.1e}" for w, v in sorted(d.items())}


def _digits(worst: float) -> int:
    """Digits to which conditions with largest defect ``worst`` hold (at most the 60 computed)."""
    return DPS if worst <= 10.0 ** -DPS else min(DPS, int(math.floor(-math.log10(worst))))


# --- 1. order of the coefficients ----------------------------------------------------------

def order_certificate(comp: Composition, levels=None) -> Certificate:
    """Order K of the composition coefficients, for every symmetric base step of order 2.

    Parameters
    ----------
    comp : Composition
    levels : list of tuple, optional
        The recursion levels claimed to produce ``comp.gammas`` (exact families;
        default :func:`recursion_levels`).  Given explicitly by negative controls.

    Returns
    -------
    Certificate
        Exact families: ``proved`` when every level condition reduces to exactly 0
        and the levels' product is exactly ``comp.gammas``.  Decimal constants (or
        coefficients that are not the recursion's): ``numerical`` from the 60-digit
        free-algebra order conditions.  ``refuted`` when the order is lost
        (``achieved_order < K``), with an exactly failing level condition if there is one.
    """
    t0 = time.perf_counter()
    K = comp.order
    claim = (f"composition coefficients ({comp.family}, {comp.stages} stages): Ψ_h = Φ_(γ_s h) ∘ … ∘ "
             f"Φ_(γ_1 h) has order {K} for every symmetric base step Φ_h of order 2")
    if comp.exact and comp.family in PARTS:
        cert = _exact_order(comp, claim, levels)
    else:
        cert = _numerical_order(comp, claim, "published decimal constants: the order conditions hold "
                                "only to the printed digits" if not comp.exact else
                                "not a recursive family: no exact level conditions")
    cert.seconds = time.perf_counter() - t0
    return cert


def _free_algebra(comp: Composition) -> tuple[dict[int, float], int]:
    """Defects up to weight K + 1 and the achieved order, by the rule of
    :func:`methodgen.symbolic.compositions.achieved_order` (its default tolerances: 1e-40 for exact
    coefficients, 1e-22 for 26-digit constants) applied to the cached defects."""
    d = _defects(comp, comp.order + 1)
    tol = getattr(comp, "tolerance", 1e-40 if comp.exact else 1e-22)
    got = 0
    for w in sorted(d):
        if d[w] > tol:
            break
        got = w
    return d, got


def _numerical_order(comp: Composition, claim: str, why: str) -> Certificate:
    K = comp.order
    d, got = _free_algebra(comp)
    worst = max(d[w] for w in range(1, K + 1))
    det = {"defects_by_weight": _fmt_defects(d), "max_defect_up_to_K": f"{worst:.1e}",
           "conditions_hold_to_digits": _digits(worst), "achieved_order": got,
           "tolerance": getattr(comp, "tolerance", 1e-40 if comp.exact else 1e-22), "digits": DPS,
           "why_numerical": why,
           "how": ("log Ψ in the free associative algebra of Φ_h = exp(hX1 + h³X3 + …), truncated at "
                   "weight K + 1, 60-digit arithmetic: order K iff every weight 2…K coefficient vanishes"),
           "source": comp.source}
    if got < K:
        det["counterexample"] = f"weight {got + 1}: defect {d[got + 1]:.3e}, far above the 60-digit " \
                                "evaluation error"
        return Certificate(claim, REFUTED, "log Ψ_h - h X1 up to weight K", "", "60-digit free-algebra "
                           "order conditions", 0.0, REF_HLW, det)
    det["passed"] = True
    det["error_constant_weight"] = K + 1
    det["leading_defect"] = f"{d[K + 1]:.3e}"
    det["note"] = (f"the conditions hold to {_digits(worst)} digits; the residual defects δ_w perturb "
                   "the method by δ_w h^w per step, far below float64 round-off")
    return Certificate(claim, NUMERICAL, "log Ψ_h - h X1 up to weight K", "",
                       "60-digit free-algebra order conditions", 0.0, REF_HLW, det)


def _exact_order(comp: Composition, claim: str, levels) -> Certificate:
    K, parts = comp.order, PARTS[comp.family]
    standard = levels is None
    levels = recursion_levels(K, parts) if standard else list(levels)
    rows, failing, unknown = [], [], []
    for k, level in enumerate(levels, 1):
        row = {"level": k, "order": f"{2 * k} → {2 * k + 2}", "coefficients": [str(g) for g in level]}
        for name, e in _level_conditions(k, level).items():
            verdict, how = _decide(e)
            row[name] = how if verdict == "zero" else f"{verdict.upper()}: {e} ({how})"
            if verdict == "nonzero":
                failing.append(f"level {k}: {name} = {e} ({how})")
            elif verdict == "unknown":
                unknown.append(f"level {k}: {name} = {e} ({how})")
        rows.append(row)
    library = []
    if standard:
        for i, e in enumerate(triple_jump_exact(K, parts)):
            verdict, how = _decide(e)
            library.append(f"{e} → {how if verdict == 'zero' else verdict}")
            if verdict != "zero":
                where = failing if verdict == "nonzero" else unknown
                where.append(f"compositions.triple_jump_exact condition {i + 1}: {e} ({how})")
    same, how_same = _same_gammas(compose_levels(levels), tuple(comp.gammas))
    d, got = _free_algebra(comp)
    det = {"theorem": ("[HLW06, §II.4] if Φ_h is symmetric of order 2k and the palindromic coefficients "
                       "(γ1, …, γm) satisfy Σγ = 1 and Σγ^{2k+1} = 0, then Φ_{γm h} ∘ … ∘ Φ_{γ1 h} is "
                       "symmetric of order 2k + 2 (order ≥ 2k + 1, and a symmetric method has even "
                       "order, §II.3); applied per level, k = 1 … K/2 - 1, starting from the base step "
                       "(order 2)"),
           "premise": ("the base step is symmetric (see the composition's symmetry certificate, derived "
                       "from the base step's) and consistent, hence of order 2 (base_traits.order)"),
           "levels": rows, "gammas_are_the_recursion": how_same if same else f"NO: {how_same}",
           "cross_check_free_algebra": {"achieved_order": got, "defects_by_weight": _fmt_defects(d)},
           "source": comp.source}
    if library:
        det["compositions.triple_jump_exact"] = library
    if failing:
        det["failing_conditions"] = failing
        if got < K:
            det["counterexample"] = failing[0]
            return Certificate(claim, REFUTED, "level conditions Σγ - 1, Σγ^{2k+1}", "",
                               "exact: minimal polynomial of a level condition ≠ x; 60-digit free "
                               f"algebra: order {got}", 0.0, REF_HLW, det)
        det["passed"] = False
        det["inconsistent"] = "a level condition fails exactly, yet the free algebra gives order K"
        return Certificate(claim, NUMERICAL, "level conditions", "", "exact level conditions vs "
                           "60-digit free algebra (inconsistent)", 0.0, REF_HLW, det)
    if not same:
        cert = _numerical_order(comp, claim, "the coefficients are not the recursion's product, so the "
                                "level proof does not apply")
        cert.details.update({"levels": rows, "gammas_are_the_recursion": f"NO: {how_same}"})
        return cert
    if unknown:
        cert = _numerical_order(comp, claim, "some level condition neither reduced to 0 nor was proved "
                                "nonzero")
        cert.details["undecided_conditions"] = unknown
        return cert
    if got < K:   # a proof and the 60-digit computation disagree: trust neither
        det["passed"] = False
        det["inconsistent"] = "every level condition is exactly 0, yet the free algebra gives order < K"
        return Certificate(claim, NUMERICAL, "level conditions", "", "exact level conditions vs "
                           "60-digit free algebra (inconsistent)", 0.0, REF_HLW, det)
    routes = sorted({r[name] for r in rows for name in r if name not in ("level", "order", "coefficients")})
    method = (f"exact: every level's Σγ - 1, Σγ^(2k+1) and palindrome condition reduced to 0 "
              f"({'; '.join(routes)}); the levels' product is exactly the composition's γ ({how_same}); "
              "theorem applied per level")
    return Certificate(claim, PROVED, "; ".join(f"level {r['level']}: Σγ - 1, Σγ^{2 * r['level'] + 1}"
                                                for r in rows), "", method, 0.0, REF_HLW, det)


# --- 2. the float64 coefficients ------------------------------------------------------------

def float_coefficients_certificate(comp: Composition, floats=None, key: str = "") -> Certificate:
    """The float64 coefficients a generated module runs: order defects of their exact binary values.

    Parameters
    ----------
    comp : Composition
    floats : sequence of float, optional
        The coefficients used (default ``comp.floats()``, which ``methodgen.codegen.lower``
        emits as ``repr(float)``, an exact round trip).
    key : str
        The composed method's name, for the claim.

    Returns
    -------
    Certificate
        ``numerical`` (passed: every float is the nearest double to its 60-digit γ and
        the defects at weights ≤ K are at most :data:`FLOAT_TOL`); ``refuted`` when a
        defect exceeds :data:`FLOAT_REFUTE` (a wrong coefficient, not a rounded one).
    """
    t0 = time.perf_counter()
    K = comp.order
    floats = tuple(comp.floats() if floats is None else floats)
    claim = (f"float64 coefficients of {key or comp.family}: the rounded γ̃_i = fl(γ_i) the generated "
             f"module uses satisfy the order-{K} conditions up to rounding")
    exact = comp.mp()
    with mp.workdps(DPS):
        nearest = len(floats) == len(exact) and all(
            abs(mp.mpf(x) - g) <= mp.mpf(math.ulp(x)) / 2 for x, g in zip(floats, exact))
    # Decimal(x) is the exact binary value of x (repr(x) is only the shortest round-trip string).
    rounded = Composition(comp.family, K, tuple(str(Decimal(x)) for x in floats), False, "float64")
    d = _defects(rounded, K + 1)
    worst = max(d[w] for w in range(1, K + 1))
    h_star = min([1.0] + [(UNIT_ROUNDOFF / d[w]) ** (1.0 / (w - 1))
                          for w in range(2, K + 1) if d[w] > UNIT_ROUNDOFF])
    det = {"stages": len(floats), "nearest_double": nearest, "defects_by_weight": _fmt_defects(d),
           "max_defect_up_to_K": f"{worst:.1e}", "tolerance": FLOAT_TOL,
           "palindromic": floats == floats[::-1],
           "time_rescaling": (f"|Σγ̃ - 1| = {d[1]:.1e}: each step advances time by (1 + δ)h, a relative "
                              "error of the size of rounding h itself"),
           "perturbation": (f"the rounded coefficients change the step by Σ_w δ_w h^w (δ_w: defect at "
                            f"weight w), at most O({max(worst, UNIT_ROUNDOFF):.0e}·|h|) per step for |h| ≤ 1 "
                            "(in the units of f), and below the float64 round-off 2^-53·|h| of one step "
                            "for |h| ≤ h_star"),
           "h_star": (f"{h_star:.2g} (the largest |h| ≤ 1 with δ_w |h|^w ≤ 2^-53·|h| at every weight "
                      "w ≥ 2)"),
           "emitted_as": "repr(float) of Composition.floats() (an exact round trip), methodgen/codegen/lower.py",
           "digits": DPS}
    if floats == floats[::-1]:
        det["even_weights"] = "exactly 0 up to evaluation error: the rounded sequence is still palindromic"
    if worst > FLOAT_REFUTE:
        w = next(w for w in range(1, K + 1) if d[w] > FLOAT_REFUTE)
        det["counterexample"] = f"weight {w}: defect {d[w]:.3e}, far above what rounding gives (< 1e-10)"
        return Certificate(claim, REFUTED, "log Ψ̃_h - h X1 up to weight K", "",
                           "60-digit free-algebra order conditions of the float64 values",
                           time.perf_counter() - t0, REF_HLW, det)
    det["passed"] = bool(nearest and worst <= FLOAT_TOL)
    return Certificate(claim, NUMERICAL, "log Ψ̃_h - h X1 up to weight K", "",
                       "60-digit free-algebra order conditions of the float64 values",
                       time.perf_counter() - t0, REF_HLW, det)


# --- the composed map in 60 digits ----------------------------------------------------------

class ComposedStepper:
    """``Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h}`` in 60-digit arithmetic.

    One :class:`~methodgen.symbolic.verify.numeric.Stepper` (the base equations solved by
    Newton) per distinct stage step ``γ_i h``, negative ones included.

    Parameters
    ----------
    scheme : Scheme
        The base scheme's equations are used.
    h : sympy.Rational
    gammas : sequence
        60-digit coefficients (``Composition.mp()``).
    """

    def __init__(self, scheme, h, gammas):
        self.h = h
        cache: dict[str, Stepper] = {}
        self.stages = []
        with mp.workdps(DPS):
            for g in gammas:
                step = sp.Float(str(mp.mpf(g) * mp.mpf(h.p) / h.q), DPS)
                key = str(step)
                if key not in cache:
                    cache[key] = Stepper(scheme, step)
                self.stages.append(cache[key])

    def __call__(self, y0):
        """Ψ_h(y0): the stages in order, each a 60-digit Newton solve of the base equations."""
        y = y0
        for stage in self.stages:
            y = stage(y)
        return y

    def derivative(self, y0, v):
        """Ψ'(y0) v by a 60-digit central difference (ε = 1e-22)."""
        eps = mp.mpf("1e-22")
        with mp.workdps(DPS):
            plus = self([mp.mpf(a) + eps * b for a, b in zip(y0, v)])
            minus = self([mp.mpf(a) - eps * b for a, b in zip(y0, v)])
            return [(a - b) / (2 * eps) for a, b in zip(plus, minus)]


class _Direct(NamedTuple):
    """A 60-digit check of the composed map: the largest defect and the sample points."""

    worst: object
    points: list
    what: str

    @property
    def violated(self) -> bool:
        return self.worst > REFUTE_ABOVE

    @property
    def passed(self) -> bool:
        return self.worst <= NUM_TOL

    def details(self) -> dict:
        return {"quantity": self.what, "max": mp.nstr(self.worst, 5), "sample_points": self.points,
                "h": str(H_CHECK), "tolerance": NUM_TOL, "digits": DPS,
                "how": ("the base equations solved by 60-digit Newton at each stage step γ_i h "
                        "(negative ones included); start points exact rationals, or on T*Q projected "
                        "in 60 digits for constrained systems")}


def _start_points(system, n: int, seed: int):
    rng = random.Random(seed)
    if system.constraints:
        from .constrained import manifold_point
        return [manifold_point(system, rng) for _ in range(n)]
    return [random_state(system, rng) for _ in range(n)]


def _point_text(system, y0) -> dict:
    return {str(s): (str(v) if isinstance(v, sp.Basic) else mp.nstr(v, 20)) for s, v in zip(system.y, y0)}


def _run(fn, system, points, what) -> _Direct:
    worst, pts = mp.mpf(0), []
    with mp.workdps(DPS):
        for y0 in points:
            val = fn(y0)
            pts.append({"y0": _point_text(system, y0), "defect": mp.nstr(val, 5)})
            worst = max(worst, val)
    return _Direct(worst, pts, what)


def _lambdified(system, exprs):
    pv = param_point(system)
    return sp.lambdify([list(system.y)], [guarded(sp.sympify(e).xreplace(pv)) for e in exprs],
                       modules="mpmath")


def _check_invariant(scheme, stepper, expr, name, points=3, seed=17) -> _Direct:
    system = scheme.system
    I = _lambdified(system, [expr])
    return _run(lambda y0: abs(I(stepper(y0))[0] - I([mp.mpf(v) for v in y0])[0]), system,
                _start_points(system, points, seed), f"|{name}(Ψ_h(y0)) - {name}(y0)|")


def _check_position(scheme, stepper, points=2, seed=5) -> _Direct:
    system = scheme.system
    g = _lambdified(system, system.constraints)
    return _run(lambda y0: max(abs(v) for v in g(stepper(y0))), system,
                _start_points(system, points, seed), "max |g(q1)| after Ψ_h")


def _check_velocity(scheme, stepper, points=2, seed=5) -> _Direct:
    system = scheme.system
    sep = separable_split(system)
    hidden = list(constraint_jacobian(system) * sep.Minv * sp.Matrix(system.p))
    gv = _lambdified(system, hidden)
    return _run(lambda y0: max(abs(v) for v in gv(stepper(y0))), system,
                _start_points(system, points, seed), "max |G(q1) M⁻¹ p1| after Ψ_h")


def _check_symplectic(scheme, stepper, points=2, seed=3) -> _Direct:
    system = scheme.system
    n = 2 * system.dim
    Jm = mp.matrix(symplectic_matrix(n).tolist())

    def defect(y0):
        if system.constraints:
            from .constrained import _tangent_basis
            basis = _tangent_basis(system, y0)
        else:
            basis = [[1 if i == j else 0 for i in range(n)] for j in range(n)]
        images = [stepper.derivative(y0, b) for b in basis]
        worst = mp.mpf(0)
        for i, (bi, pi) in enumerate(zip(basis, images)):
            for bj, pj in zip(basis[i + 1:], images[i + 1:]):
                before = (mp.matrix(bi).T * Jm * mp.matrix(bj))[0]
                after = (mp.matrix(pi).T * Jm * mp.matrix(pj))[0]
                worst = max(worst, abs(after - before))
        return worst

    where = " on a tangent basis of T*Q" if system.constraints else ""
    return _run(defect, system, _start_points(system, points, seed),
                f"max |ξᵀΨ'ᵀJΨ'η - ξᵀJη|{where} (Ψ' by central differences, ε = 1e-22)")


def _check_symmetry(scheme, comp, points=2, seed=5) -> _Direct:
    system = scheme.system
    g = comp.mp()
    fwd, bwd = ComposedStepper(scheme, H_CHECK, g), ComposedStepper(scheme, -H_CHECK, g)
    return _run(lambda y0: max(abs(a - mp.mpf(b)) for a, b in zip(bwd(fwd(y0)), y0)), system,
                _start_points(system, points, seed), "max |Ψ_(-h)(Ψ_h(y0)) - y0|")


# --- deriving a composition certificate from the base ones ---------------------------------

def _step_symbols_ok(scheme) -> tuple[bool, str]:
    """The scheme's equations use the one step symbol STEP, real with no sign assumption."""
    if not STEP.is_real or STEP.is_positive is not None or STEP.is_nonnegative is not None:
        return False, "the step symbol carries a sign assumption"
    exprs = [scheme.residual, scheme.increment, scheme.guess]
    if scheme.discrete_gradient is not None:
        exprs.append(scheme.discrete_gradient)
    syms = set().union(*(sp.Matrix(e).free_symbols for e in exprs))
    others = [s for s in syms if s.name == STEP.name and s != STEP]
    if others:
        return False, f"the equations contain another step symbol {others[0]!r} with other assumptions"
    return True, "h is the symbol _h, real=True with no sign assumption"


#: Names of the exact reductions and structural proofs of the verification layer: identities
#: in the symbols, which SymPy proves without any assumption on the sign of h.
_EXACT_ROUTES = ("cancel", "expand", "radical elimination", "half-angle", "rewrite(exp)", "simplify",
                 ZERO_AS_BUILT, "0 by substitution", "structural", "exact limit", "derivative argument",
                 "polynomial reduction", "QQ(")
_SAMPLED = ("evaluation", "numerical", "sample", "counterexample")


def holds_for_every_real_h(cert: Certificate, scheme=None) -> tuple[bool, str]:
    """Does ``cert``'s proof hold for every real step h, negative ones included?

    Yes when it is ``proved`` by an exact reduction or a structural lemma (the routes of
    :mod:`.exact` and :mod:`.structural`: identities in the symbols, no sampling), and h
    is :data:`~methodgen.symbolic.schemes.base.STEP`, a real symbol with no sign assumption — so
    SymPy could not have used h > 0.  Anything else is "no" with the reason (the caller
    then falls back to a numerical check).
    """
    if cert.status != PROVED:
        return False, f"the base certificate is {cert.status}"
    if scheme is not None:
        ok, why = _step_symbols_ok(scheme)
        if not ok:
            return False, why
    elif STEP.is_positive is not None or STEP.is_nonnegative is not None:
        return False, "the step symbol carries a sign assumption"
    if any(w in cert.method for w in _SAMPLED):
        return False, f"the base proof route ({cert.method}) samples points"
    if not any(r in cert.method for r in _EXACT_ROUTES):
        return False, f"the base proof route ({cert.method}) is not recognised as an identity in h"
    return True, "exact identity in the real symbol h (no sign assumption)"


def _summary(cert: Certificate) -> dict:
    out = {"claim": cert.claim, "status": cert.status, "method": cert.method}
    if cert.status == REFUTED and "counterexample" in cert.details:
        out["counterexample"] = cert.details["counterexample"]
    if cert.status == NUMERICAL:
        out["passed"] = cert.passed
    if cert.status == UNDECIDED:
        out["reason"] = cert.details.get("reason", "")
    return out


def _derive(claim: str, ref: str, scheme, base: list[Certificate], direct: Callable[[], _Direct] | None,
            proof: str, *, premise: tuple[bool, str] = (True, ""), missing: str = "",
            approximate: bool = False) -> Certificate:
    """The composition's certificate from the base step's ``base`` certificates.

    ``proved`` only if the premise holds (e.g. palindromic γ) and every base
    certificate is a proof valid for every real h; otherwise the composed map is
    checked in 60 digits (``direct``): ``refuted`` on a violation, else ``numerical``
    — with ``passed`` no better than the base evidence.  Never stronger than the base.
    """
    t0 = time.perf_counter()
    det: dict = {"base_certificates": [_summary(c) for c in base]}
    if missing:
        det["missing_base_evidence"] = missing
    premise_ok, premise_text = premise
    if premise_text:
        det["premise"] = premise_text
    weakest = min((_RANK[c.status] for c in base), default=None)
    sign = [holds_for_every_real_h(c, scheme) for c in base]
    if sign:
        det["every_real_h"] = "; ".join(sorted({why for _, why in sign}))
    if premise_ok and base and weakest == _RANK[PROVED] and all(ok for ok, _ in sign) and not approximate:
        return Certificate(claim, PROVED, "", "", proof, time.perf_counter() - t0, ref, det)

    def done(status, method, **more):
        det.update(more)
        return Certificate(claim, status, "", "", method, time.perf_counter() - t0, ref, det)

    base_passed = all(c.passed for c in base)
    if approximate:   # kept only up to each stage's approximation error: no exact statement to check
        if weakest is None or weakest <= _RANK[UNDECIDED]:
            status = REFUTED if weakest == _RANK[REFUTED] else UNDECIDED
            return done(status, "from the base step's certificate", reason="the base evidence is "
                        + ("refuted" if status == REFUTED else "missing or undecided"))
        return done(NUMERICAL, "from the base step's certificate (approximate invariant)",
                    passed=bool(base_passed), note="each stage keeps it up to its own approximation "
                    "error, so the composition up to the sum over its stages")
    check, why_not = None, ""
    if direct is not None:
        try:
            check = direct()
        except Exception as exc:     # the composed map could not be evaluated: say so, do not guess
            why_not = f"{type(exc).__name__}: {str(exc).strip()[:200]}"
    if check is not None:
        det["composed_map_check"] = check.details()
        if check.violated:
            return done(REFUTED, "60-digit evaluation of the composed map at sample points",
                        counterexample=max(check.points, key=lambda p: mp.mpf(p["defect"])),
                        evaluation="Ψ_h(y0) in 60-digit arithmetic at h = 1/10 (y0 exact rational, or "
                                   "on T*Q to 55 digits): the defect is > 1e-15, far above the "
                                   "evaluation error (< 1e-35)")
        if weakest == _RANK[REFUTED]:
            return done(NUMERICAL, "60-digit evaluation of the composed map at sample points",
                        passed=False, note="the base step's certificate is refuted; the composed map "
                        "did not show the violation at these points")
        return done(NUMERICAL, "60-digit evaluation of the composed map at sample points",
                    passed=bool(check.passed and base_passed and premise_ok),
                    why_numerical=_why_numerical(base, sign, premise))
    if why_not:
        det["composed_map_check"] = f"could not be evaluated: {why_not}"
    if weakest == _RANK[REFUTED]:
        return done(REFUTED, "refuted through its premise", note="the base step Φ_h does not have the "
                    "property (see its counterexample), and the composition's claim rests on every "
                    "stage having it; the composed map itself was not evaluated")
    if weakest == _RANK[NUMERICAL] and premise_ok:
        return done(NUMERICAL, "from the base step's numerical certificate", passed=bool(base_passed),
                    note="the base step was checked at h = 1/10 only; the negative stage steps were "
                         "not sampled")
    return done(UNDECIDED, "not decided", reason=_why_numerical(base, sign, premise) or
                "no base certificate and no check of the composed map")


def _why_numerical(base, sign, premise) -> str:
    if not premise[0]:
        return f"premise fails: {premise[1]}"
    if not base:
        return "the base step has no certificate for this property"
    weak = [c for c in base if c.status != PROVED]
    if weak:
        return f"the base certificate is {weak[0].status}: {weak[0].claim}"
    bad = [why for ok, why in sign if not ok]
    return f"the base proof may not hold for negative h: {bad[0]}" if bad else ""


def _missing(base: BaseResults) -> str:
    return "; ".join(f"claim group '{k}' did not finish ({v})" for k, v in base.failed.items())


# --- 3. symmetry --------------------------------------------------------------------------

def exactly_palindromic(comp: Composition) -> tuple[bool, str]:
    """γ_i = γ_{s+1-i} for all i, compared exactly (radicals reduced; decimals as rationals)."""
    g = [_exact_number(x, comp.exact) for x in comp.gammas]
    s = len(g)
    routes = set()
    for i in range(s // 2):
        a, b = g[i], g[s - 1 - i]
        if a == b:
            routes.add("structural equality" if comp.exact else "equal decimals")
            continue
        verdict, how = _decide(a - b)
        if verdict != "zero":
            return False, f"γ_{i + 1} ≠ γ_{s - i} ({how})"
        routes.add(how)
    return True, f"γ_i = γ_(s+1-i) for all i, exactly ({', '.join(sorted(routes)) or 'one stage'})"


def symmetry_certificate(scheme, base: BaseResults, comp: Composition | None = None) -> Certificate:
    """The composition is symmetric, ``Ψ_{-h} ∘ Ψ_h = id``.

    Proof: ``Ψ_h* = Φ*_{γ_1 h} ∘ … ∘ Φ*_{γ_s h} = Φ_{γ_1 h} ∘ … ∘ Φ_{γ_s h} = Ψ_h``
    when Φ is symmetric for every real step and the γ are palindromic [HLW06, §II.4].
    Palindromic is decided exactly, on the exact / decimal coefficients (and the
    float64 ones the module uses are compared too).  Not palindromic: the composed
    map is run forward and back in 60 digits (a refutation when it does not return).
    """
    comp = comp or scheme.composition
    pal, text = exactly_palindromic(comp)
    fl = tuple(comp.floats())
    fpal = fl == fl[::-1]
    premise = (pal and fpal, text + ("; the float64 coefficients are palindromic too" if fpal else
                                     "; but the float64 coefficients are NOT palindromic"))
    claim = (f"{scheme.key}: the composition is symmetric, Ψ_(-h) ∘ Ψ_h = id "
             f"({comp.family}, {comp.stages} stages)")
    proof = ("derived: Ψ_h* = Φ*_(γ_1 h) ∘ … ∘ Φ*_(γ_s h) = Φ_(γ_1 h) ∘ … ∘ Φ_(γ_s h) = Ψ_h, since the base "
             "step is symmetric for every real step (its proof is an identity in the real symbol h) and "
             "the γ are exactly palindromic")
    cert = _derive(claim, REF_HLW, scheme, base.get("symmetry"), lambda: _check_symmetry(scheme, comp),
                   proof, premise=premise, missing=_missing(base))
    if not pal:
        d = _defects(comp, 4)
        cert.details["free_algebra_even_weights"] = {"2": f"{d[2]:.1e}", "4": f"{d[4]:.1e}",
                                                     "note": "nonzero even-weight terms of log Ψ: not "
                                                             "symmetric for a generic symmetric base"}
    return cert


# --- 4. inherited invariants, constraints, symplecticity ------------------------------------

def _inherit_proof(what: str) -> str:
    return (f"derived: each stage Φ_(γ_i h) is the base map at the real step γ_i h (some negative); "
            f"the base proof of {what} is an identity in the real symbol h, so it holds at every "
            "stage, hence for the composition (induction over the stages)")


def inherited_certificates(scheme, base: BaseResults) -> list[Certificate]:
    """One certificate per property the composed traits claim from the base step.

    Invariants and constraint monitors in ``traits.preserved`` (and those in
    ``traits.approximate``, numerical at best), symplecticity, and on a quadratic
    1-DOF H the re-timed exact flow.  See :func:`_derive` for the statuses.
    """
    comp, t, system = scheme.composition, scheme.traits, scheme.system
    key, missing = scheme.key, _missing(base)
    invs = {inv.name: inv.expr for inv in scheme.invariants}
    ref = REF_HLW
    stepper_cache: list = []

    def stepper():
        if not stepper_cache:
            stepper_cache.append(ComposedStepper(scheme, H_CHECK, comp.mp()))
        return stepper_cache[0]

    out = []
    for name in tuple(t.preserved) + tuple(t.approximate):
        if name.startswith("g") and system.constraints:
            continue
        approx = name in t.approximate and name not in t.preserved
        certs = base.get(f"invariant:{name}")
        if name == "H" and t.discrete_gradient:
            certs = certs + base.get("helper")   # the identity's proof uses the generated helpers
        expr = invs.get(name)
        direct = None if expr is None else (lambda e=expr, n=name: _check_invariant(scheme, stepper(), e, n))
        what = f"{name}(y1) = {name}(y0)"
        claim = (f"{key}: the composition keeps {name}" + (f" = {expr}" if expr is not None else "")
                 + (" up to each stage's approximation error" if approx else "")
                 + " (every stage Φ_(γ_i h) keeps it)")
        out.append(_derive(claim, ref, scheme, certs, direct, _inherit_proof(what), missing=missing,
                           approximate=approx))
    if system.constraints:
        pos = [n for n in t.preserved if n.startswith("g") and not n.endswith("_v")]
        vel = [n for n in t.preserved if n.endswith("_v")]
        if pos:
            out.append(_derive(f"{key}: the composition stays on g(q) = 0 ({', '.join(pos)})", ref, scheme,
                               base.get("constraint:position"),
                               lambda: _check_position(scheme, stepper()),
                               _inherit_proof("g(q1) = 0"), missing=missing))
        if vel:
            out.append(_derive(f"{key}: the composition keeps the hidden constraints G(q)M⁻¹p = 0 "
                               f"({', '.join(vel)})", ref, scheme, base.get("constraint:velocity"),
                               lambda: _check_velocity(scheme, stepper()),
                               _inherit_proof("G(q1)M⁻¹p1 = 0"), missing=missing))
    if t.symplectic:
        on = " on T*Q" if system.constraints else ""
        out.append(_derive(f"{key}: the composition is symplectic{on} (a composition of symplectic maps)",
                           ref, scheme, base.get("symplectic"),
                           lambda: _check_symplectic(scheme, stepper()),
                           _inherit_proof("Φ'ᵀJΦ' = J") + "; (Ψ')ᵀJΨ' = J by the chain rule",
                           missing=missing))
    for cert in base.get("retiming"):
        out.append(_retiming(scheme, cert, missing))
    return out


def _retiming(scheme, base_cert: Certificate, missing: str) -> Certificate:
    """On a quadratic 1-DOF H: Ψ_h = exp(τ_Ψ A) with τ_Ψ = Σ_i τ(γ_i h)."""
    comp = scheme.composition
    omega = base_cert.details.get("omega", "ω")
    claim = (f"{scheme.key}: on this quadratic H the composed step is the exact flow at time "
             f"τ_Ψ(h) = Σ_i τ(γ_i h), τ(t) = (2/ω) arctan(tω/2), ω = {omega}; numerical frequency "
             "ω_Ψ = (2/h) Σ_i arctan(γ_i hω/2)")
    proof = ("derived: each stage's Φ' = ((1 - x_i²)I + γ_i hA)/(1 + x_i²), x_i = γ_i hω/2 (the base identity, "
             "in the real symbol h, at h → γ_i h) equals exp(τ(γ_i h) A) (τ odd: negative steps run the flow "
             "backwards); all are functions of the same matrix A, so they commute and their product is "
             "exp(Σ_i τ(γ_i h) A)")
    cert = _derive(claim, f"{REF_HLW}; Celledoni, lecture notes, section 1.2 (Theorem 1.1)", scheme,
                   [base_cert], None, proof, missing=missing)
    cert.details["note"] = "for det S < 0 read arctan as i·artanh (hyperbolic case)"
    cert.details["stages"] = comp.stages
    return cert
