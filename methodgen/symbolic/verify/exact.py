"""The reduction engine: prove an identity exactly, refute it, or check it numerically.

:func:`certify` takes a claim and an expression (or a list/matrix of
expressions) that must vanish identically and returns a
:class:`~methodgen.symbolic.verify.report.Certificate`:

1. If the expression contains no floating-point number, the cheapest exact
   reductions are tried in order — ``cancel`` (rational functions), ``expand``,
   radical elimination followed by polynomial reduction (``sqrt`` of a
   polynomial replaced by a symbol ``t`` with ``t² = base``), a trigonometric
   reduction (half angles, ``expand_trig``, ``sin² + cos² = 1``) and, last and
   only for small expressions, ``simplify``.  The first that reaches exactly 0
   names the certificate's ``method``; the status is ``"proved"``.
2. Otherwise exact rational points are tried (preferring points where every
   square root is rational, e.g. Pythagorean quadruples for Kepler) and the
   first where the expression is nonzero is the counterexample; the status is
   ``"refuted"``.
3. Otherwise — and always when the expression carries floating-point
   coefficients (Gauss–Legendre nodes) — the expression is evaluated with
   50-digit arithmetic at random rational points; the status is
   ``"numerical"`` with the tolerance, the points and whether they passed.
"""

from __future__ import annotations

import random
import time
from fractions import Fraction
from math import gcd, isqrt

import sympy as sp

from ..derive import term_groups
from ...problem.special import DividedDifference, _RemovableFunction, datan_dd, dexp_dd, dsinc_dd, to_elementary

_QUOTIENT_FUNCTIONS = (DividedDifference, datan_dd, dexp_dd, dsinc_dd)

try:  # guarded quotient n/d (0 where d = 0), used by newer Gonzalez forms
    from ...problem.special import safe_div
except ImportError:  # pragma: no cover - older special.py
    safe_div = None
from .report import METHOD, NUMERICAL, PROVED, REFUTED, Certificate

__all__ = ["certify", "reduce_to_zero", "find_counterexample", "numerical_check", "Domain",
           "fmt_point"]

#: Expressions larger than this (count_ops) are never handed to ``simplify``.
SIMPLIFY_LIMIT = 400
#: Digits of the high-precision evaluations.
DIGITS = 50


class Domain:
    """Where sample points are drawn: which symbols are positive, small, or near another.

    Parameters
    ----------
    positive : iterable of Symbol
        Sampled in [1/2, 2] (masses, lengths, the step size...).
    near : dict Symbol -> Symbol
        ``y1 -> y0``: sampled as ``y0 + δ`` with a small rational δ (numerical
        checks of schemes whose formulas are only accurate for small steps).
    small : iterable of Symbol
        Sampled in [1/20, 1/4] (the step size h).
    """

    def __init__(self, positive=(), near=None, small=()):
        self.positive = set(positive)
        self.near = dict(near or {})
        self.small = set(small)

    def sample(self, symbols, rng: random.Random, integer: bool = False, spread: int = 6) -> dict:
        point = {}
        ordered = sorted(symbols, key=lambda s: (s in self.near, s.name))
        for s in ordered:
            if s in self.small:
                point[s] = sp.Rational(rng.randint(1, 5), 20)
            elif s in self.positive:
                point[s] = sp.Rational(rng.randint(2, 8), 4)
            elif s in self.near and self.near[s] in point:
                point[s] = point[self.near[s]] + sp.Rational(rng.randint(-10, 10), 100)
            elif integer:
                point[s] = sp.Integer(rng.randint(-spread, spread))
            else:
                point[s] = sp.Rational(rng.randint(-4 * spread, 4 * spread), rng.choice((2, 3, 4, 5)))
        return point


def fmt_point(point: dict) -> dict:
    """A JSON-friendly ``{name: "p/q"}`` form of a sample point."""
    return {str(k): str(v) for k, v in sorted(point.items(), key=lambda kv: str(kv[0]))}


def _flatten(expr) -> list[sp.Expr]:
    if isinstance(expr, (sp.MatrixBase, list, tuple)):
        return [sp.sympify(e) for e in (expr if not isinstance(expr, sp.MatrixBase) else list(expr))]
    return [sp.sympify(expr)]


#: Cases of a guarded quotient split at most this many guards deep (2**k cases).
MAX_GUARDS = 3

#: What ``reduce_to_zero`` reports when SymPy's construction already gives 0.
ZERO_AS_BUILT = "0 as constructed: SymPy cancels the terms while building the expression"


def _zero_set(d: sp.Expr) -> dict | None:
    """A substitution describing the real solutions of ``d = 0`` for a sum of squares, or None.

    ``d = Σ c_k e_k²`` with numbers ``c_k > 0`` vanishes over the reals exactly when
    every ``e_k = 0``; each ``e_k`` linear in some symbol is solved for it (e.g.
    ``|Δ|² = 0`` gives ``y1 = y0``).
    """
    sub: dict = {}
    for t in sp.Add.make_args(d):
        c, rest = t.as_coeff_Mul()
        if not (c.is_number and c.is_positive and rest.is_Pow and rest.exp == 2):
            return None
        e = rest.base.xreplace(sub)
        if e == 0:
            continue
        for x in sorted(e.free_symbols, key=lambda s: s.name, reverse=True):
            coeff = sp.diff(e, x)
            if coeff.is_number and coeff != 0 and x not in sp.diff(e, x).free_symbols \
                    and sp.expand(e - coeff * x).free_symbols.isdisjoint({x}):
                val = sp.expand(x - e / coeff)
                sub = {k: v.xreplace({x: val}) for k, v in sub.items()}
                sub[x] = val
                break
        else:
            return None
    return sub


def guard_cases(e: sp.Expr):
    """``[(label, expression)]`` of :func:`guard_cases_with_zero_sets` (None if it cannot split)."""
    full = guard_cases_with_zero_sets(e)
    return None if full is None else [(label, expr) for label, expr, _ in full]


def guard_cases_with_zero_sets(e: sp.Expr):
    """Split ``e`` at its guarded quotients ``safe_div(n, d)`` into exhaustive cases.

    Returns a list of ``(label, expression)``: for each guard denominator ``d``
    the case ``d != 0`` (the guard is ``n/d``) and the case ``d = 0`` (the guard is
    0 and the zero set of d is substituted).  The identity holds everywhere iff it
    reduces to 0 in every case.  ``None`` when a zero set cannot be described.
    """
    if safe_div is None or not e.has(safe_div):
        return [("", e, {})]
    # Group guards by their expanded denominator: (p - p1)**2 and (p1 - p)**2 are one guard.
    rep: dict = {}
    for g in sorted(e.atoms(safe_div), key=sp.default_sort_key):
        rep.setdefault(sp.expand(g.args[1]), g.args[1])
    dens = sorted(rep, key=sp.default_sort_key)
    if len(dens) > MAX_GUARDS:
        return None
    zero_sets = []
    for d in dens:
        z = _zero_set(rep[d])
        if z is None:
            return None
        zero_sets.append(z)
    cases = []
    for mask in range(2 ** len(dens)):
        expr, labels, sub = e, [], {}
        for k, d in enumerate(dens):
            if mask >> k & 1:
                labels.append(f"case {rep[d]} = 0")
                sub.update(zero_sets[k])
                expr = expr.replace(lambda x, d=d: isinstance(x, safe_div) and sp.expand(x.args[1]) == d,
                                    lambda x: sp.S.Zero)
            else:
                labels.append(f"case {rep[d]} ≠ 0")
                expr = expr.replace(lambda x, d=d: isinstance(x, safe_div) and sp.expand(x.args[1]) == d,
                                    lambda x: x.args[0] / x.args[1])
        if sub:
            expr = expr.xreplace(sub)
            if expr.has(safe_div):   # a guard whose denominator vanished with the others
                expr = expr.replace(lambda x: isinstance(x, safe_div),
                                    lambda x: sp.S.Zero if sp.expand(x.args[1]) == 0 else x.args[0] / x.args[1])
        cases.append((", ".join(labels), expr, sub))
    return cases


def guarded(e: sp.Expr) -> sp.Expr:
    """``safe_div(n, d)`` as ``Piecewise((n/d, d != 0), (0, True))`` (for numerical evaluation)."""
    if safe_div is None or not e.has(safe_div):
        return e
    return e.replace(lambda x: isinstance(x, safe_div),
                     lambda x: sp.Piecewise((x.args[0] / x.args[1], sp.Ne(x.args[1], 0)), (0, True)))


def _radical_reduce(e: sp.Expr) -> bool:
    """Prove ``e == 0`` by replacing ``base**(1/q)`` with ``t`` and reducing mod ``t**q - base``."""
    pows = [p for p in e.atoms(sp.Pow) if p.exp.is_Rational and not p.exp.is_Integer]
    if not pows:
        return False
    den: dict[sp.Expr, int] = {}
    for p in pows:
        q = int(p.exp.q)
        den[p.base] = q * den.get(p.base, 1) // gcd(q, den.get(p.base, 1))
    ts = {b: sp.Dummy("t") for b in den}
    repl = {p: ts[p.base] ** int(p.exp * den[p.base]) for p in pows}
    e2 = e.xreplace(repl)
    if any(p.exp.is_Rational and not p.exp.is_Integer for p in e2.atoms(sp.Pow)):
        return False  # nested radicals: not handled here
    num = sp.expand(sp.numer(sp.together(e2)))
    for b, t in ts.items():
        if num == 0:
            return True
        if not num.has(t):
            continue
        rel = sp.Poly(t ** den[b] - b, t)
        num = sp.Poly(num, t).rem(rel).as_expr()
        num = sp.expand(num)
    return num == 0


def _trig_reduce(e: sp.Expr) -> bool:
    """Prove ``e == 0`` for polynomials in sin/cos of linear combinations of symbols."""
    e = e.rewrite(sp.sin, sp.cos, sp.tan) if e.has(sp.tan) else e
    e = e.replace(lambda x: isinstance(x, sp.tan), lambda x: sp.sin(x.args[0]) / sp.cos(x.args[0]))
    trig = [a for a in e.atoms(sp.sin, sp.cos)]
    if not trig:
        return False
    syms = set().union(*(a.args[0].free_symbols for a in trig))
    scale = 1
    for a in trig:
        try:
            poly = sp.Poly(a.args[0], *syms)
        except sp.PolynomialError:
            return False
        if poly.total_degree() > 1:
            return False
        for c in poly.coeffs():
            if not c.is_Rational:
                return False
            scale = scale * int(c.q) // gcd(scale, int(c.q))
    half = {x: sp.Dummy(x.name) for x in syms}
    e2 = sp.expand_trig(e.xreplace({x: scale * half[x] for x in syms}))
    S = {x: sp.Dummy("S") for x in syms}
    C = {x: sp.Dummy("C") for x in syms}
    e3 = e2.xreplace({sp.sin(half[x]): S[x] for x in syms}).xreplace({sp.cos(half[x]): C[x] for x in syms})
    if e3.atoms(sp.sin, sp.cos):
        return False
    num = sp.expand(sp.numer(sp.together(e3)))
    for x in syms:
        if num == 0:
            break
        if num.has(C[x]):
            num = sp.expand(sp.Poly(num, C[x]).rem(sp.Poly(C[x] ** 2 + S[x] ** 2 - 1, C[x])).as_expr())
    return num == 0


def reduce_to_zero(e: sp.Expr, allow_simplify: bool = True, cheap: bool = True) -> str | None:
    """Try to reduce ``e`` to exactly 0; return the name of the reduction that did, or None.

    Soundness rules (what makes ``proved`` mean proved for the generated code):

    * a ``Piecewise`` is never reduced on one branch: an expression with one is not
      proved here (methodgen's schemes emit none; the parser refuses them);
    * a guarded quotient ``safe_div(n, d)`` is split into its exhaustive cases
      ``d ≠ 0`` (``n/d``) and ``d = 0`` (0, with the zero set of d substituted),
      and every case must reduce to 0 (:func:`guard_cases`);
    * the removable-singularity functions and divided differences of
      :mod:`methodgen.problem.special` are replaced by their defining quotients; they are
      analytic, so an identity proved away from their removable points holds there
      too by continuity.  That the generated helpers evaluate exactly these
      functions is proved separately (:mod:`methodgen.symbolic.verify.helpers`).

    The cheap reductions come first; ``simplify`` (slow, and unpredictable on
    large expressions) only when ``allow_simplify`` and the expression is small;
    ``cheap=False`` skips straight to ``simplify``.
    """
    if e == 0:
        return ZERO_AS_BUILT
    if e.has(sp.Piecewise):
        return None
    cases = guard_cases(e)
    if cases is None:
        return None
    names = []
    for label, ce in cases:
        m = _reduce_case(ce, allow_simplify, cheap)
        if m is None:
            return None
        names.append(f"{label}: {m}" if label else m)
    return "; ".join(names)


def _reduce_groups(e: sp.Expr, allow_simplify: bool) -> str | None:
    """Reduce a large sum group by group (:func:`methodgen.symbolic.derive.term_groups`: terms grouped
    by their symbols), each group to 0 on its own.  Sound — the groups partition the sum —
    but not complete: None then, and the whole is reduced."""
    parts = term_groups(e)
    if parts is None:
        return None
    hows = []
    for part in parts:
        # expand first: a group is typically one term's pieces sharing a factor (a pair's
        # divided difference), which expand cancels where together/cancel would combine
        # the radicals first
        if part == 0 or sp.expand(part) == 0:
            m = "expand" if part != 0 else ZERO_AS_BUILT
        else:
            m = _reduce_case(part, allow_simplify, True, grouped=False)
        if m is None:
            return None
        if m not in hows:
            hows.append(m)
    return f"{len(parts)} groups of terms by their symbols, each: " + ", ".join(hows)


def _reduce_case(e: sp.Expr, allow_simplify: bool, cheap: bool, grouped: bool = True) -> str | None:
    if e == 0:
        return "0 by substitution"
    pre = ""
    if any(isinstance(f, (_RemovableFunction,) + _QUOTIENT_FUNCTIONS) for f in e.atoms(sp.Function)):
        e = to_elementary(e)
        pre = "special functions → their defining quotients + "
    if cheap and grouped:
        try:
            m = _reduce_groups(e, allow_simplify)
        except Exception:   # a group SymPy cannot reduce (PolynomialError...): reduce the whole
            m = None
        if m is not None:
            return pre + m
    if cheap:
        if sp.cancel(sp.together(e)) == 0:
            return pre + "cancel"
        ex = sp.expand(e)
        if ex == 0:
            return pre + "expand"
        if _radical_reduce(e):
            return pre + "radical elimination + polynomial reduction"
        if _trig_reduce(e):
            return pre + "half-angle expand_trig + reduction mod sin²+cos²=1"
        if e.has(sp.exp, sp.sinh, sp.cosh, sp.tanh, sp.atanh, sp.log):
            r = sp.cancel(sp.expand(e.rewrite(sp.exp)))
            if r == 0:
                return pre + "rewrite(exp) + cancel"
    if allow_simplify and sp.count_ops(e) <= SIMPLIFY_LIMIT and sp.simplify(e) == 0:
        return pre + "simplify"
    return None


def _value(e: sp.Expr, point: dict):
    """Exact value at a rational point (None if undefined), and whether it is rational."""
    try:
        v = guarded(e).xreplace(point)
        v = to_elementary(v)
        v = sp.nsimplify(v) if v.has(sp.Float) else v
    except (ZeroDivisionError, TypeError):
        return None, False
    if v.has(sp.zoo, sp.nan, sp.oo, -sp.oo) or v.free_symbols:
        return None, False
    return v, v.is_Rational


def _radicands(exprs) -> list[sp.Expr]:
    out = set()
    for e in exprs:
        for p in e.atoms(sp.Pow):
            if p.exp.is_Rational and p.exp.q == 2:
                out.add(p.base)
    return list(out)


def _is_square(v) -> bool:
    if not v.is_Rational or v < 0:
        return False
    n, d = int(v.p), int(v.q)
    return isqrt(n) ** 2 == n and isqrt(d) ** 2 == d


def find_counterexample(exprs, domain: Domain, seed: int = 1, tries: int = 60):
    """An exact rational point where some expression is nonzero, or None.

    Returns
    -------
    (point, index, value, exact) or None
        ``exact`` is True when the value is a rational number; otherwise its
        nonzero-ness was certified by a 50-digit evaluation.
    """
    exprs = _flatten(exprs)
    syms = set().union(*(e.free_symbols for e in exprs))
    rng = random.Random(seed)
    rad = _radicands(exprs)
    points = []
    if rad:
        # Prefer points where every square root is rational, so evaluation stays exact.
        exact_domain = Domain(domain.positive, None, domain.small)
        for _ in range(1500):
            pt = exact_domain.sample(syms, rng, integer=True)
            if all(_is_square(r.xreplace(pt)) for r in rad):
                points.append(pt)
                if len(points) >= tries // 2:
                    break
    # Counterexamples need no small steps: ignore "near" so values are not tiny.
    wide = Domain(domain.positive, None, domain.small)
    points += [wide.sample(syms, rng) for _ in range(tries - len(points))]
    for pt in points:
        for i, e in enumerate(exprs):
            v, exact = _value(e, pt)
            if v is None:
                continue
            if exact:
                if v != 0:
                    return pt, i, v, True
            else:
                num = sp.N(v, DIGITS)
                if num.is_number and abs(num) > sp.Float(10) ** (-(DIGITS - 10)):
                    return pt, i, num, False
    return None


def numerical_check(exprs, domain: Domain, tol: float, n: int = 5, seed: int = 7):
    """Evaluate at ``n`` random rational points with 50-digit arithmetic.

    Returns
    -------
    (passed, max_abs, points)
    """
    exprs = _flatten(exprs)
    syms = set().union(*(e.free_symbols for e in exprs))
    rng = random.Random(seed)
    worst, pts, got = 0.0, [], 0
    for _ in range(20 * n):
        if got >= n:
            break
        # Moderate states (|y| <= 2) and steps |y1 - y0| <= 0.1: where the
        # formulas with floating-point nodes are meant to be accurate.
        pt = domain.sample(syms, rng, spread=1)
        vals = []
        for e in exprs:
            v = guarded(e).xreplace(pt)
            v = to_elementary(v)
            v = sp.N(v, DIGITS)
            if not v.is_number or v.has(sp.zoo, sp.nan):
                vals = None
                break
            vals.append(abs(complex(v)))
        if vals is None:
            continue
        got += 1
        pts.append(fmt_point(pt))
        worst = max([worst] + vals)
    return (got > 0 and worst <= tol), worst, pts


def _case_counterexample(exprs, domain: Domain):
    """:func:`find_counterexample`, also inside each guard case (e.g. on ``y1 = y0``, which
    random points never hit); the point reports the substituted symbols too."""
    ce = find_counterexample(exprs, domain)
    if ce is not None:
        return ce
    for i, e in enumerate(exprs):
        cases = guard_cases_with_zero_sets(e) or []
        for label, ce_expr, sub in cases:
            if not sub:
                continue
            found = find_counterexample([ce_expr], domain)
            if found is not None:
                pt, _, v, exact = found
                full = dict(pt)
                free = set().union(*(val.free_symbols for val in sub.values())) - set(full) - set(sub)
                full.update(domain.sample(free, random.Random(3)) if free else {})
                for x, val in sub.items():
                    full[x] = val.xreplace(full)
                return full, i, v, exact
    return None


#: Above this many terms an expression is printed in SymPy's internal term order (which is
#: deterministic) instead of the sorted one: sorting the terms of a sum over N instances
#: costs seconds at N = 400 (printing took a quarter of ``verify``), for a text nobody reads
#: term by term.  Smaller expressions keep the familiar sorted text.
_SORTED_TERMS = 64
_UNSORTED = sp.printing.str.StrPrinter({"order": "none"})


def expression_text(e) -> str:
    """``str(e)``, or for a large expression the same text in internal term order (fast)."""
    if isinstance(e, sp.Add) and len(e.args) > _SORTED_TERMS:
        return _UNSORTED.doprint(e)
    return str(e)


def _show(exprs) -> tuple[str, str]:
    if len(exprs) == 1:
        e = exprs[0]
        return expression_text(e), sp.latex(e)
    return str(list(exprs)), sp.latex(sp.Matrix(exprs))


def certify(claim: str, expr, domain: Domain | None = None, ref: str = "", *,
            shown=None, tol: float = 1e-12, details: dict | None = None,
            subject: str = METHOD) -> Certificate:
    """Decide whether ``expr`` vanishes identically (see :func:`_certify`); ``subject``: what the
    claim is about, the method (default) or the exact flow (:data:`~.report.FLOW`)."""
    cert = _certify(claim, expr, domain, ref, shown=shown, tol=tol, details=details)
    cert.subject = subject
    return cert


def _certify(claim: str, expr, domain: Domain | None = None, ref: str = "", *,
             shown=None, tol: float = 1e-12, details: dict | None = None) -> Certificate:
    """Decide whether ``expr`` (scalar, list or Matrix) vanishes identically.

    Parameters
    ----------
    claim : str
        The claim in words.
    expr : sympy.Expr or list or Matrix
        Must be identically 0 for the claim to hold.
    domain : Domain, optional
        How to draw sample points (counterexamples, numerical checks).
    ref : str
        Source of the claim (exercise, section, paper).
    shown : sympy.Expr, optional
        A more readable form of the expression for the certificate (defaults to ``expr``).
    tol : float
        Absolute tolerance of the numerical fallback when ``expr`` has floats.
    details : dict, optional
        Extra details recorded in the certificate.
    """
    t0 = time.perf_counter()
    domain = domain or Domain()
    exprs = _flatten(expr)
    text, tex = _show(_flatten(shown) if shown is not None else exprs)
    det = dict(details or {})
    if any(e.has(sp.Float) for e in exprs):
        # Floating-point coefficients (quadrature nodes): an identity cannot be proved.
        passed, worst, pts = numerical_check(exprs, domain, tol)
        det.update({"passed": passed, "tolerance": tol, "max_abs_value": worst,
                    "sample_points": pts, "digits": DIGITS,
                    "why_numerical": "the expression has floating-point coefficients"})
        return Certificate(claim, NUMERICAL, text, tex, "50-digit evaluation at rational points",
                           time.perf_counter() - t0, ref, det)
    methods = []
    failing = []
    for e in exprs:
        m = reduce_to_zero(e, allow_simplify=False)
        if m is None:
            failing.append(e)
        elif m not in methods:
            methods.append(m)
    # A false identity is refuted at a random point much faster than simplify
    # gives up, so look for a counterexample before the last-resort simplify.
    ce = _case_counterexample(failing, domain) if failing else None
    if ce is None and failing:
        still = []
        for e in failing:
            m = reduce_to_zero(e, allow_simplify=True, cheap=False)
            if m is None:
                still.append(e)
            elif m not in methods:
                methods.append(m)
        failing = still
    if not failing:
        return Certificate(claim, PROVED, text, tex, ", ".join(methods) or ZERO_AS_BUILT,
                           time.perf_counter() - t0, ref, det)
    if ce is not None:
        pt, i, v, exact = ce
        det.update({"counterexample": fmt_point(pt), "value": str(v),
                    "evaluation": "exact (rational)" if exact else
                    f"exact point; nonzero certified by {DIGITS}-digit evaluation"})
        return Certificate(claim, REFUTED, text, tex, "counterexample at a rational point",
                           time.perf_counter() - t0, ref, det)
    passed, worst, pts = numerical_check(failing, domain, 1e-40)
    det.update({"passed": passed, "tolerance": 1e-40, "max_abs_value": worst, "sample_points": pts,
                "digits": DIGITS, "inconclusive": "symbolic reduction did not reach 0 and no "
                "counterexample was found; checked numerically only"})
    return Certificate(claim, NUMERICAL, text, tex, "50-digit evaluation (symbolic inconclusive)",
                       time.perf_counter() - t0, ref, det)


def numerical_certificate(claim: str, ref: str, method: str, passed: bool, seconds: float,
                          expression: str = "", **details) -> Certificate:
    """A certificate for a property checked numerically (not an identity)."""
    details["passed"] = passed
    return Certificate(claim, NUMERICAL, expression, "", method, seconds, ref, details)
