"""Certificates for the generated helpers: each evaluates exactly the function the proofs use.

The identity certificates reduce expressions in which every removable-singularity
function and every divided difference ``g[a, b]`` of :mod:`methodgen.problem.special` is
replaced by its *defining relation* (``sinhc(x) = sinh(x)/x``,
``exp[a, b] = (exp(b) - exp(a))/(b - a)``).  The generated code evaluates other,
cancellation-free formulas.  This module proves, once per helper and for all
real arguments in its domain, that the two agree — so "proved" is a statement
about the code that runs:

* ``g(x)/x`` helpers (``_sinc``, ``_sinhc``, ``_atanhc``, ``_atanc``) evaluate the
  quotient for ``x ≠ 0`` and a constant at ``x = 0``: the constant is proved to
  be the exact limit (SymPy's series limit).
* divided-difference helpers evaluate a stable form ``S(a, b)``; proved is
  ``S(a, b)·(b - a) = g(b) - g(a)``, either as an algebraic identity (exp, sin,
  cos, sinh, cosh, tan, tanh: ``rewrite(exp)`` / half-angle reduction) or, for
  log and atan, by the derivative argument: ``F(b) = S(a, b)(b - a) - (g(b) - g(a))``
  has ``F(a) = 0`` and ``∂F/∂b ≡ 0`` (reduced exactly), on a set of b that is an
  interval containing a (``a, b > 0`` for log; ``1 + ab > 0`` for atan's first
  branch — its other branch *is* the quotient).

The helpers' floating-point accuracy near and at their removable points is a
numerical matter, tested against mpmath in ``tests/test_special_helpers.py``.
"""

from __future__ import annotations

import functools
import time
from dataclasses import replace

import sympy as sp

from ...problem.special import (SPECIAL_FUNCTIONS, DividedDifference, atan_dd, atanc, atanhc, log_dd, sinc_dd, sinc_u,
                                sinhc, to_elementary)
from .exact import Domain, certify, reduce_to_zero
from .report import NUMERICAL, PROVED, REFUTED, Certificate

__all__ = ["helper_certificates", "helper_certificate", "helpers_used"]

REF = "methodgen.problem.special / templates/_special.py.j2"

#: The g(x)/x helpers whose *values* enter residuals (their derivatives enter Jacobians only).
VALUE_HELPERS = (sinc_u, sinhc, atanhc, atanc)

_A = sp.Symbol("a", real=True)
_B = sp.Symbol("b", real=True)
_X = sp.Symbol("x", real=True)


def helpers_used(exprs) -> list[type]:
    """The special-function classes (values, not derivatives) occurring in ``exprs``."""
    used: set[type] = set()
    for e in exprs:
        for f in sp.sympify(e).atoms(sp.Function):
            t = type(f)
            if issubclass(t, DividedDifference) or t in VALUE_HELPERS:
                used.add(t)
    # A divided-difference helper calls a g(x)/x helper: certify that one too.
    for t in list(used):
        if issubclass(t, DividedDifference):
            form = t.stable_form(_A, _B) if t not in (atan_dd, sinc_dd) else t.branch_form(_A, _B)
            for f in form.atoms(sp.Function):
                if type(f) in VALUE_HELPERS:
                    used.add(type(f))
    return sorted(used, key=lambda t: t.__name__)


def _derivative_argument(F: sp.Expr, domain: str) -> tuple[str | None, dict]:
    """Prove ``F(b) ≡ 0`` for b in an interval containing a, from ``F(a) = 0`` and ``∂F/∂b ≡ 0``."""
    base = F.xreplace({_B: _A})
    base = sp.simplify(base) if base != 0 else base
    if base != 0:
        return None, {}
    dF = to_elementary(sp.diff(F, _B))
    m = reduce_to_zero(dF, allow_simplify=True)
    if m is None:
        return None, {}
    return (f"derivative argument: F(a) = 0 and ∂F/∂b = 0 ({m}) on {domain}",
            {"domain": domain, "F": str(F)})


@functools.lru_cache(maxsize=None)
def _certificate(cls: type) -> Certificate:
    t0 = time.perf_counter()
    helper = SPECIAL_FUNCTIONS[cls]
    details: dict = {"helper": helper}
    if cls in VALUE_HELPERS:
        q = cls(_X).as_quotient()
        limit = sp.limit(q, _X, 0)
        ok = sp.simplify(limit - cls._value_at_zero) == 0
        claim = (f"helper {helper}(x) evaluates {cls.__name__}(x) = {q}: the quotient for x ≠ 0, "
                 f"and {cls._value_at_zero} at x = 0, its exact limit")
        return Certificate(claim, PROVED if ok else REFUTED, f"lim_(x→0) {q} - {cls._value_at_zero}", "",
                           "exact limit (series)", time.perf_counter() - t0, REF,
                           {**details, "limit": str(limit)})
    if cls is sinc_dd:
        return _sinc_dd_certificate(helper, details, t0)
    g = cls.func_elementary
    quotient_rel = g(_B) - g(_A)
    if cls is atan_dd:
        form = cls.branch_form(_A, _B)
        F = to_elementary(form) * (_B - _A) - quotient_rel
        method, extra = _derivative_argument(F, "{b : 1 + ab > 0}, an interval containing a")
        claim = (f"helper {helper}(a, b) evaluates atan[a, b] = (atan b - atan a)/(b - a): "
                 "atanc((b-a)/(1+ab))/(1+ab) where 1 + ab > 0 (else the quotient itself, |b - a| >= 2)")
        details.update(extra)
    else:
        form = cls.stable_form(_A, _B)
        F = to_elementary(form) * (_B - _A) - quotient_rel
        claim = (f"helper {helper}(a, b) evaluates {g.__name__}[a, b] = ({g.__name__}(b) - {g.__name__}(a))/(b - a) "
                 f"as {form}")
        if cls is log_dd:
            method, extra = _derivative_argument(sp.expand(F), "a > 0 and b > 0 (log's real domain; the helper "
                                                 "returns NaN outside it)")
            details.update(extra)
        else:
            method = reduce_to_zero(F, allow_simplify=True)
        hform = getattr(cls, "helper_form", None)
        if method is not None and hform is not None:
            # The helper evaluates yet another form of the same function (overflow-safe): prove it too.
            F2 = sp.expand(hform(_A, _B) * (_B - _A)) - quotient_rel
            m2 = reduce_to_zero(F2, allow_simplify=True)
            claim += f", computed as {hform(_A, _B)} with its arguments ordered b > a (exp[a, b] = exp[b, a])"
            details["helper_form"] = str(hform(_A, _B))
            method = f"{method}; helper form: {m2}" if m2 is not None else None
            F = F2 if m2 is None else F
    if method is not None:
        return Certificate(claim, PROVED, str(F), "", method, time.perf_counter() - t0, REF, details)
    # Not proved: look for an exact counterexample in the helper's domain (a bug in a stable form).
    positive = {_A, _B} if cls is log_dd else set()
    cert = certify(claim, F, Domain(positive=positive), REF,
                   details=details)
    if cls is atan_dd and cert.status == REFUTED:
        pt = cert.details.get("counterexample", {})
        a, b = (sp.Rational(pt.get("a", "0")), sp.Rational(pt.get("b", "0")))
        if 1 + a * b <= 0:   # outside the branch: not a counterexample of this claim
            cert = replace(cert, status=NUMERICAL, details={**cert.details, "passed": False,
                                                            "reason": "not proved"})
    return cert


#: The tail of _sincdd's series: Σ_{k>12} k 4^(k-1)/(2k+1)! ≥ |c_k h_(k-1)(a², b²)| summed
#: over the omitted k, for |a|, |b| < 2 (h_(k-1) has k terms, each at most 4^(k-1)).
SINC_DD_TAIL = 2.1e-20


def _sinc_dd_certificate(helper: str, details: dict, t0: float) -> Certificate:
    """_sincdd: two branches proved exactly, the series branch numerical (a truncation)."""
    F = to_elementary(sinc_dd.branch_form(_A, _B)) * (_B - _A) - (sp.sin(_B) / _B - sp.sin(_A) / _A)
    method = reduce_to_zero(F, allow_simplify=True)
    claim = (f"helper {helper}(a, b) evaluates sinc[a, b] = (sin(b)/b - sin(a)/a)/(b - a): the quotient "
             "where |b - a| >= 1, (m cos m sinc δ - sin m cos δ)/(ab) where |a| or |b| >= 2 and "
             "|b - a| < 1 "
             "(an identity), the Taylor series (a + b) Σ_(k<=12) c_k h_(k-1)(a², b²) where |a|, |b| < 2 "
             f"(truncated: tail below {SINC_DD_TAIL:g} |a + b|)")
    details = {**details, "branch_form": str(sinc_dd.branch_form(_A, _B)), "series_tail": SINC_DD_TAIL,
               "reason": "the series branch is a truncation (numerical to round-off), the others are proved"}
    if method is None:
        cert = certify(claim, F, Domain(positive=set()), REF, details=details)
        if cert.status == PROVED:
            # certify reduced the identity branch; the claim still includes the series branch,
            # which no reduction of F covers: never PROVED (a REFUTED identity branch stays so).
            cert = replace(cert, status=NUMERICAL, method=f"identity branch: {cert.method}; series "
                           "branch: tail bound", details={**cert.details, "passed": True})
        return cert
    # Not PROVED: a truncated series is not an identity, however small its tail.
    return Certificate(claim, NUMERICAL, str(F), "", f"identity branch: {method}; series branch: tail bound",
                       time.perf_counter() - t0, REF, {**details, "passed": True})


def helper_certificate(cls: type) -> Certificate:
    """The (cached) certificate of one helper, as a fresh object."""
    c = _certificate(cls)
    return replace(c, details=dict(c.details))


def helper_certificates(exprs) -> list[Certificate]:
    """One certificate per helper the expressions use (values of special functions)."""
    return [helper_certificate(cls) for cls in helpers_used(exprs)]
