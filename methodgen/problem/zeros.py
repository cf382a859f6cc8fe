"""Exact zero tests of SymPy expressions, with the cheap numerical screens that reject first.

"Zero" is always decided symbolically (``expand``, ``cancel``, ``simplify``, group by group
for large sums); a fixed sample point only ever *rejects* (clearly nonzero at 30 and 60
digits).  Used by the derivations (:mod:`methodgen.symbolic.derive`: first integrals, brackets) and
by the Poisson system (:mod:`methodgen.problem.poisson`: Casimirs), so it sits below both: it
imports SymPy and :mod:`methodgen.problem.special` only.
"""

from __future__ import annotations

import sympy as sp

__all__ = ["sample_points", "term_groups", "GROUP_MIN_TERMS"]


def _clearly_nonzero(expr: sp.Expr) -> bool:
    """``expr`` (elementary functions only) is clearly nonzero at one of the fixed sample points:
    then it is not identically 0.  Only ever used to reject; "zero" is always decided
    symbolically.

    Clearly nonzero: |value| > 1e-20 at 30 digits, *and* the same value at 60 digits (to 1e-3
    relative).  An absolute threshold alone took round-off for a value wherever the terms are
    large: ``exp(40x)(1 + y) − exp(40x) − y exp(40x)`` ≡ 0 evaluates to ~1e-11 at 30 digits
    (its terms ~1e19), and ``expand((x+y+z)**30) − (x+y+z)**30`` to more than 1e-20.  Doubling
    the precision shrinks such round-off by ~30 orders of magnitude and leaves a true value."""
    syms = sorted(expr.free_symbols, key=lambda s: s.name)
    for sample in sample_points(len(syms)):
        try:
            vals = []
            for digits in (30, 60):
                point = {s: sp.Float(v, digits) for s, v in zip(syms, sample)}
                vals.append(complex(expr.xreplace(point).evalf(digits)))
                if abs(vals[0]) <= 1e-20:
                    break
        except (TypeError, ValueError, ZeroDivisionError):
            return False
        if len(vals) == 2 and abs(vals[1]) > 1e-20 and abs(vals[0] - vals[1]) <= 1e-3 * abs(vals[1]):
            return True
    return False


def _zero_status(expr: sp.Expr, system=None, simplify_limit: int | None = None) -> str:
    """``"zero"`` (shown exactly), ``"nonzero"`` (clearly nonzero at a sample point) or ``"unknown"``.
    (``system``: not read; the derivations pass theirs.)

    ``expr`` is evaluated at two fixed points (floats); a clearly nonzero value
    rejects at once — most candidate invariants fail here, which keeps large
    systems (N bodies) fast.  Only survivors go to the exact test: ``expand``,
    then ``cancel``, then ``simplify`` (skipped above ``simplify_limit`` operations);
    the answer "zero" is always symbolic.
    """
    if expr == 0:
        return "zero"
    from .special import to_elementary

    elementary = to_elementary(expr)   # removable-singularity helpers as their quotients
    if _clearly_nonzero(elementary):
        return "nonzero"
    try:
        grouped = _zero_by_groups(expr)
    except Exception:   # a group SymPy cannot reduce: reduce the whole below
        grouped = False
    if grouped:
        return "zero"
    # With sinc_u and friends, a term may cancel only against the elementary form of another
    # (dsinc_u(u) against cos(u)/u - sin(u)/u²): reduce the elementary form as well.  It is
    # equal to expr wherever the quotients are defined, a dense set, and both are continuous,
    # so its exact 0 is expr's.
    forms = [expr] if elementary == expr else [expr, elementary]
    for form in forms:
        for reduce in (sp.expand, sp.cancel, sp.simplify):
            if reduce is sp.simplify and simplify_limit is not None and sp.count_ops(form) > simplify_limit:
                break
            if reduce(form) == 0:
                return "zero"
    return "unknown"


def sample_points(n: int, count: int = 2) -> list[list[float]]:
    """``count`` fixed pseudo-random points of ``n`` coordinates in (0.2, 1.4) (seeded: the
    same on every run) for the cheap numerical screens.

    Every coordinate differs from every other (almost surely, and checked), so a pair
    potential ``U(q_i - q_j)`` or ``1/|q_a - q_b|`` is never sampled at its singular
    point: a periodic pattern such as ``0.37 + 0.11·((i·k) mod 13)`` repeats after 13
    coordinates, which puts bodies a and a + 13 of a planar N-body system on one point.
    """
    import random

    rng = random.Random(20240516 + n)
    out = []
    for _ in range(count):
        while True:
            y = [rng.uniform(0.2, 1.4) for _ in range(n)]
            if len(set(y)) == n:
                break
        out.append(y)
    return out


#: Below this many terms an expression is reduced whole (:func:`term_groups`).
GROUP_MIN_TERMS = 8


def term_groups(expr: sp.Expr) -> list[sp.Expr] | None:
    """A large sum split into the sums of its terms grouped by their exact set of free
    symbols (products distributed over sums at top level only, nothing inside functions),
    or None when there are fewer than :data:`GROUP_MIN_TERMS` terms or only one group.

    If every group is 0, so is the sum (the groups partition it); the converse fails
    (terms with different symbols may cancel only together).  A bracket ``{P, H}`` of a
    pair potential is a sum over pairs that cancels pair by pair, so reducing the groups
    costs what one pair costs, times the pairs (N-body systems).
    """
    args = [t for a in sp.Add.make_args(expr) for t in sp.Add.make_args(sp.expand_mul(a, deep=False))]
    if len(args) < GROUP_MIN_TERMS:
        return None
    groups: dict = {}
    for a in args:
        groups.setdefault(frozenset(a.free_symbols), []).append(a)
    if len(groups) < 2:
        return None
    return [sp.Add(*terms) for terms in groups.values()]


def _zero_by_groups(expr: sp.Expr) -> bool:
    """``expr ≡ 0`` shown group by group (:func:`term_groups`), each by expand then cancel;
    False when not shown (the caller reduces the whole)."""
    parts = term_groups(expr)
    return parts is not None and all(
        part == 0 or sp.expand(part) == 0 or sp.cancel(part) == 0 for part in parts)
