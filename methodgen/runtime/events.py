"""Event functions and Poincaré sections from text, for a generated module's :func:`solve`.

A generated module's ``solve(..., events=...)`` takes event functions ``g(t, y)`` with the
attributes of ``scipy.integrate.solve_ivp``'s (``terminal``, ``direction``) and two of its
own (``condition``, ``vectorized``), and locates each crossing on the method's own map (the
sub-step τ with ``g(Φ_τ(y_n)) = 0``), so that a located state keeps every invariant the
method keeps.  This module builds such functions from text over the module's state and
parameter names -- parsed with methodgen's whitelist parser (:func:`methodgen.problem.parse.parse_expr`,
never ``eval``), then compiled to a numpy function of the state's columns -- and runs a
Poincaré section as one call.

Examples
--------
>>> mod = mg.build(mg.load_scene("henon-heiles-2d").system, "energy-momentum")  # doctest: +SKIP
>>> t, pts, sol = mg.poincare(mod, y0, 0.05, "q1 = 0, p1 > 0", crossings=1000)  # doctest: +SKIP
"""

from __future__ import annotations

import re

import numpy as np
import sympy as sp

from ..errors import InputError
from ..problem.parse import parse_expr

__all__ = ["Event", "event", "section_event", "poincare"]

_COMPARISON = re.compile(r"^(?P<lhs>[^<>=!]+?)\s*(?P<op><=|>=|<|>)\s*(?P<rhs>[^<>=!]+)$")
_EQUATION = re.compile(r"^(?P<lhs>[^<>=!]+?)\s*=\s*(?P<rhs>[^<>=!]+)$")


class Event:
    """An event function ``g(t, y)`` of a module's state (vectorized over rows), with
    ``terminal``, ``direction`` and ``condition`` as :func:`solve` reads them.

    Attributes
    ----------
    text : str
        The expression g, as given.
    terminal : bool or int
        Stop at the first (True) or n-th crossing; False: record them all.
    direction : float
        0: every crossing; > 0: from g < 0 to g >= 0; < 0: the other way.
    condition : callable or None
        ``condition(t, y) -> bool``: a crossing counts only where it holds (at the located state).
    vectorized : bool
        True: ``g`` takes times (k,) and states (k, n).
    """

    vectorized = True

    def __init__(self, text, fn, terminal=False, direction=0.0, condition=None):
        self.text = text
        self._fn = fn
        self.terminal = terminal
        self.direction = float(direction)
        self.condition = condition

    def __call__(self, t, y):
        y = np.asarray(y, dtype=float)
        return self._fn(*np.moveaxis(y, -1, 0))

    def __repr__(self):
        return (f"Event({self.text!r}, terminal={self.terminal!r}, direction={self.direction!r}"
                f"{', with a condition' if self.condition is not None else ''})")


def _symbols(module) -> tuple[list[sp.Symbol], dict[str, sp.Symbol]]:
    names = list(module.STATE_NAMES)
    state = [sp.Symbol(n, real=True) for n in names]
    table = dict(zip(names, state))
    for p in module.PARAM_NAMES:
        table.setdefault(p, sp.Symbol(p, real=True))
    return state, table


def _compile(module, text, params, what: str):
    """A numpy function of the state's components for the expression ``text`` (text, parsed by
    the whitelist parser, or a SymPy expression whose symbols are named as the module's state
    components and parameters)."""
    state, table = _symbols(module)
    if isinstance(text, sp.Basic):
        unknown = sorted(str(s) for s in text.free_symbols if str(s) not in table)
        if unknown:
            raise InputError(f"{what} {text} uses {unknown}, which are not state components "
                             f"{list(module.STATE_NAMES)} or parameters {list(module.PARAM_NAMES)}")
        # the module's symbols by name (a user's Symbol('x') may lack real=True)
        expr = text.xreplace({s: table[str(s)] for s in text.free_symbols})
    else:
        expr = parse_expr(text, table, what=what)
    values = dict(module.DEFAULT_PARAMS)
    if params:
        unknown = sorted(set(params) - set(values))
        if unknown:
            raise InputError(f"unknown parameter(s) {unknown} for {what}; valid: {sorted(values)}")
        values.update(params)
    expr = expr.subs({table[k]: sp.Float(v) for k, v in values.items() if k in table})
    free = sorted(str(s) for s in expr.free_symbols - set(state))
    if free:
        raise InputError(f"{what} {text!r} uses {free}, which are not state components {list(module.STATE_NAMES)} "
                         f"or parameters {list(module.PARAM_NAMES)}")
    f = sp.lambdify(state, expr, modules="numpy")
    return lambda *cols: np.broadcast_to(np.asarray(f(*cols), dtype=float), np.shape(cols[0])).copy()


def event(module, text: str, *, terminal=False, direction: float = 0.0, condition: str | None = None,
          params: dict | None = None) -> Event:
    """The event function g = ``text`` (an expression of the module's state and parameter names,
    or an equation ``lhs = rhs`` for g = lhs - rhs) for ``module.solve(..., events=...)``.

    Parameters
    ----------
    module : generated module
        Its STATE_NAMES, PARAM_NAMES and DEFAULT_PARAMS name what ``text`` may use.
    text : str or sympy.Expr or sympy.Eq
        ``"q1"``, ``"x**2 + y**2 = 1"`` … (text is parsed by the whitelist parser, never
        evaluated), or a SymPy expression or equation in symbols named as the module's state
        components and parameters.
    terminal : bool or int
        Stop at the first (True) or the n-th crossing.
    direction : float
        0 every crossing; > 0 only from g < 0 to g >= 0; < 0 only the other way.
    condition : str, optional
        A comparison (``"p1 > 0"``) that must hold at a crossing for it to count.
    params : dict, optional
        Parameter values (default the module's DEFAULT_PARAMS; pass the run's).

    Returns
    -------
    Event

    Raises
    ------
    InputError
        Text that does not parse, names that are not the module's, a condition that is not one
        comparison.
    """
    if isinstance(text, sp.Equality):
        body = text.lhs - text.rhs
    elif isinstance(text, sp.Expr):
        body = text
    elif isinstance(text, str):
        m = _EQUATION.match(text.strip())
        body = f"({m['lhs']}) - ({m['rhs']})" if m else text
    else:
        raise InputError(f"an event must be text or a SymPy expression, got {type(text).__name__}")
    fn = _compile(module, body, params, "event")
    cond = None
    if condition is not None:
        cond = _condition(module, condition, params)
    return Event(str(text), fn, terminal=terminal, direction=direction, condition=cond)


def _condition(module, text: str, params):
    m = _COMPARISON.match(text.strip()) if isinstance(text, str) else None
    if m is None:
        raise InputError(f"a condition must be one comparison such as 'px > 0' (<, <=, >, >=), got {text!r}")
    f = _compile(module, f"({m['lhs']}) - ({m['rhs']})", params, "condition")
    op = m["op"]

    def holds(t, y):
        v = float(f(*np.asarray(y, dtype=float)))
        return {"<": v < 0.0, "<=": v <= 0.0, ">": v > 0.0, ">=": v >= 0.0}[op]
    holds.text = text
    return holds


def section_event(module, text: str, *, crossings: int | None = None, params: dict | None = None) -> Event:
    """The Poincaré section ``"lhs = rhs[, condition]"`` (``"q1 = 0, p1 > 0"``) as an event:
    its crossings of the surface lhs = rhs where the condition holds; terminal at the
    ``crossings``-th one when given."""
    if not isinstance(text, str):
        raise InputError(f"a section must be text such as 'x = 0, px > 0', got {type(text).__name__}")
    parts = [p.strip() for p in text.split(",")]
    if not parts[0] or _EQUATION.match(parts[0]) is None or len(parts) > 2:
        raise InputError(f"a section is a surface and at most one side, 'lhs = rhs[, condition]' "
                         f"(e.g. 'x = 0, px > 0'), got {text!r}")
    if crossings is not None and (isinstance(crossings, bool) or not isinstance(crossings, int) or crossings < 1):
        raise InputError(f"crossings must be a positive integer, got {crossings!r}")
    return event(module, parts[0], terminal=crossings or False, condition=parts[1] if len(parts) == 2 else None,
                 params=params)


def poincare(module, y0, h: float, section: str, *, crossings: int | None = 1000, t_max: float | None = None,
             params: dict | None = None, **options):
    """A Poincaré section: the first ``crossings`` crossings of ``section`` by the trajectory
    from ``y0``, each located on the method's own map (``module.solve`` with the section as a
    terminal event, :func:`section_event`).

    Parameters
    ----------
    module : generated module
    y0 : array_like, shape (n,)
    h : float
        Step size (> 0).
    section : str
        ``"lhs = rhs[, condition]"``, e.g. ``"q1 = 0, p1 > 0"``.
    crossings : int or None
        How many crossings to collect (None: every one up to ``t_max``).
    t_max : float, optional
        Give up at this time (default ``1e6 * h``): fewer crossings are returned then.
    params : dict, optional
    **options
        Passed to ``module.solve`` (``maxiter``, ``solver`` …).

    Returns
    -------
    t : numpy.ndarray, shape (k,)
    y : numpy.ndarray, shape (k, n)
        The located states, k = ``crossings`` unless ``t_max`` came first.
    solution : Solution
        The run (``status`` 1: the crossings were reached; 0: ``t_max`` was; -1: a step failed).
    """
    ev = section_event(module, section, crossings=crossings, params=params)
    h = abs(float(h))
    t_end = float(t_max) if t_max is not None else 1e6 * h
    sol = module.solve(y0, (0.0, t_end), h, params, events=ev, save_every=1 << 62, **options)
    return sol.t_events[0], sol.y_events[0], sol
