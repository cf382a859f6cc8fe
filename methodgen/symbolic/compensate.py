"""Compensated stage sums: evaluate a step at the exact numerical state ``y + c``.

The runtime adds each increment with compensated (Kahan) summation, so the exact
numerical state is ``y + c``: ``y`` the stored double, ``c`` the rounding error carried
along (``|c| <= ulp(y)/2``).  A step that evaluates its equations at ``y`` alone applies
the map at a point ``c`` away from that state.  The error is of round-off size, but it
is *correlated* with the motion: ``c`` is the part of the last increments below
``ulp(y)``, so it leans the way the state moves, and the energy picks up a systematic
drift ``~h (∇H)ᵀ f'(y) c`` per step.  Over 10⁶ steps that drift, not the random walk of
the roundings, dominates: the energy error grows like ``t^0.7–0.8`` instead of Brouwer's
``√t`` (measured: Kepler t^0.68, the outer solar system t^0.82 with h = 0.01).

``fl(y + c) = y``, so ``c`` cannot simply be added to the state.  It *can* be added
where the state is shifted by a small quantity: a stage point ``y + w·z`` (``z`` an
increment, ``w`` a weight) becomes ``y + (w·z + c)`` — the small sum is formed first,
where ``c`` is representable, and one rounding puts it on ``y``.  This module rewrites
the scheme's equations that way (:func:`compensate`): every state symbol ``y_i`` is
replaced by ``y_i + c_i`` and every sum that contains a multiple of ``y_i`` together
with other terms is regrouped as ``a·y_i + (rest)`` with the compensation inside
``rest``; a state symbol alone (``U(q0)``, ``|q0|``) keeps no ``c`` (it would round
away).  The grouping is kept through common-subexpression elimination and printing by
the unevaluated function :class:`grouped`, which prints as parentheses and
differentiates as the identity.

With ``c = 0`` the equations are the scheme's own (only the association of some sums
differs), so the generated residual/Jacobian at ``c = 0`` are the scheme's; the
verification layer works on the scheme, never on the rewritten equations.

References
----------
.. [1] E. Hairer, R. I. McLachlan, A. Razakarivony, Achieving Brouwer's law with
   implicit Runge–Kutta methods, BIT 48 (2008) 231–243 (compensated summation, and
   why the remaining round-off must be uncorrelated for √t).
.. [2] W. Kahan, Further remarks on reducing truncation errors, Comm. ACM 8 (1965) 40.
"""

from __future__ import annotations

from typing import Iterable, Mapping

import sympy as sp

__all__ = ["grouped", "compensate", "compensation_symbols"]


class grouped(sp.Function):
    """``grouped(u)`` is ``u``, evaluated as one parenthesised sum.

    SymPy flattens nested sums (``y + (z + c)`` becomes ``y + z + c``, printed in
    canonical order), which would let ``c`` be added to ``y`` first and vanish.  This
    wrapper is opaque to flattening and to common-subexpression elimination, prints as
    ``(u)`` (see the printers in :mod:`methodgen.codegen.lower`) and differentiates as ``u``.
    """

    nargs = 1

    def fdiff(self, argindex=1):
        return sp.S.One

    def _eval_is_real(self):
        return self.args[0].is_real

    # lambdify (verification at 60 digits, the scipy peer): the parenthesised argument
    def _print_parenthesised(self, printer):
        return "(" + printer._print(self.args[0]) + ")"

    _lambdacode = _pythoncode = _numpycode = _mpmathcode = _print_parenthesised


def compensation_symbols(states: Iterable[sp.Symbol]) -> dict[sp.Symbol, sp.Symbol]:
    """``{y_i: _c_<name>}``: the symbol of each state component's compensation.

    Internal names start with an underscore, so they never collide with a user's names.
    """
    return {s: sp.Symbol("_c_" + s.name, real=True) for s in states}


def _regroup(e: sp.Expr, states: frozenset, comps: frozenset, memo: dict) -> sp.Expr:
    # memo: each distinct subexpression once (a stage's equations share most of theirs: a
    # tree walk visited them ~200 times each); a node whose arguments are unchanged is kept
    # as it is, not rebuilt
    if e.is_Atom:
        return e
    got = memo.get(e)
    if got is None:
        got = memo[e] = _regroup_node(e, states, comps, memo)
    return got


def _regroup_node(e: sp.Expr, states: frozenset, comps: frozenset, memo: dict) -> sp.Expr:
    args = [_regroup(a, states, comps, memo) for a in e.args]
    if isinstance(e, sp.Add):
        state_terms, rest = [], []
        for a in args:
            _, factor = a.as_coeff_Mul()
            (state_terms if factor in states else rest).append(a)
        if state_terms and any(a.free_symbols & comps for a in rest):
            if len(state_terms) == 1 and all(a.free_symbols and a.free_symbols <= comps for a in rest):
                # y + c alone: c is below ulp(y) and would round away; leave it out.
                return state_terms[0]
            # Several states (q1 - q2: a difference may cancel, then c1 - c2 counts): the
            # states' sum and the small sum are formed apart and added once.
            head = state_terms[0] if len(state_terms) == 1 else grouped(sp.Add(*state_terms))
            return head + grouped(sp.Add(*rest))
    if all(a is b for a, b in zip(args, e.args)):
        return e
    return e.func(*args)


def compensate(exprs: Iterable[sp.Expr], comp: Mapping[sp.Symbol, sp.Symbol]) -> list[sp.Expr]:
    """The expressions evaluated at ``y + c`` with compensated stage sums.

    Parameters
    ----------
    exprs : iterable of sympy.Expr
        Equations of one step in the start-state symbols ``y`` (and increments, h,
        parameters).
    comp : mapping state symbol -> compensation symbol
        From :func:`compensation_symbols`.

    Returns
    -------
    list of sympy.Expr
        Each expression with ``y_i → y_i + c_i`` and every sum ``a·y_i + rest`` written
        ``a·y_i + grouped(rest)`` (``rest`` holding ``a·c_i``); equal to the input at
        ``c = 0`` (substitute and replace :class:`grouped` by its argument).

    Examples
    --------
    >>> import sympy as sp
    >>> x, dx = sp.symbols("x _d_x", real=True)
    >>> c = compensation_symbols([x])
    >>> compensate([x + dx / 2], c)[0]
    x + grouped(_c_x + _d_x/2)
    >>> compensate([sp.sqrt(x**2 + 1)], c)[0]      # x alone: its c would round away
    sqrt(x**2 + 1)
    """
    states = frozenset(comp)
    comps = frozenset(comp.values())
    shift = {s: s + comp[s] for s in states}
    memo: dict = {}
    return [_regroup(sp.sympify(e).xreplace(shift), states, comps, memo) for e in exprs]
