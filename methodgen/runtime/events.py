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
from collections.abc import Mapping

import numpy as np
import sympy as sp

from ..errors import InputError
from ..codegen.zeroin import zeroin
from ..problem.parse import parse_expr

__all__ = ["Event", "event", "section_event", "poincare", "solve_family", "family_state_names"]

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

    def __init__(self, text, fn, terminal=False, direction=0.0, condition=None, *, of_state=False):
        self.text = text
        self._fn = fn
        self._of_state = of_state       # fn takes the states; else their components (columns)
        self.terminal = terminal
        self.direction = float(direction)
        self.condition = condition

    def __call__(self, t, y):
        y = np.asarray(y, dtype=float)
        return self._fn(y) if self._of_state else self._fn(*np.moveaxis(y, -1, 0))

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
    values = _param_values(module, params, what)
    expr = expr.subs({table[k]: sp.Float(v) for k, v in values.items() if k in table})
    free = sorted(str(s) for s in expr.free_symbols - set(state))
    if free:
        raise InputError(f"{what} {text!r} uses {free}, which are not state components {list(module.STATE_NAMES)} "
                         f"or parameters {list(module.PARAM_NAMES)}")
    f = sp.lambdify(state, expr, modules="numpy")
    return lambda *cols: np.broadcast_to(np.asarray(f(*cols), dtype=float), np.shape(cols[0])).copy()


def event(module, text: str, *, terminal=False, direction: float = 0.0, condition: str | None = None,
          params: dict | None = None, arrays: dict | None = None) -> Event:
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
    arrays : dict, optional
        A particle family's per-particle arrays (``{"m": m}``, each of length N), when the text
        uses them (``m[1]*px[1]``); pass the run's.

    Returns
    -------
    Event

    Raises
    ------
    InputError
        Text that does not parse, names that are not the module's, a condition that is not one
        comparison; for a module of symbolic size (a lattice or particle family), text that is
        not over its indexed fields (see Notes).

    Notes
    -----
    A module of symbolic size (``mg.build_lattice``, ``mg.build_particles``) has no fixed list
    of state names: its state components are indexed, ``q[k]``, ``p[k]`` of a 1-D lattice and
    ``x[k]``, ``px[k]`` … of a particle (k = 1 … N).  Its events are text over these -- the
    index an integer, the size's name (``q[N]``) or index arithmetic on it (``q[N - 1]``),
    ``Sum(px[i], i, 1, N)`` -- parsed by the same whitelist parser once per size N met in a
    run (the indices resolve then; text is validated here at the smallest size its indices
    need).  SymPy expressions are refused for these modules (write the text), and so is text
    for a 2-D lattice (its sites are pairs of indices, which the parser does not take): give
    a callable ``g(t, y)``, y of shape (2, N, M), instead.
    """
    fam = _family(module)
    if fam is not None:
        return _family_event(module, fam, text, terminal, direction, condition, params, arrays)
    if arrays is not None:
        raise InputError("arrays= gives a particle family's per-particle arrays; this module has none")
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


def section_event(module, text: str, *, crossings: int | None = None, params: dict | None = None,
                  arrays: dict | None = None) -> Event:
    """The Poincaré section ``"lhs = rhs[, condition]"`` (``"q1 = 0, p1 > 0"``; for a family
    module over its indexed fields, ``"x[2] = 0, px[2] > 0"``, see :func:`event`) as an event:
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
                 params=params, arrays=arrays)


def poincare(module, y0, h: float, section: str, *, crossings: int | None = 1000, t_max: float | None = None,
             params: dict | None = None, **options):
    """A Poincaré section: the first ``crossings`` crossings of ``section`` by the trajectory
    from ``y0``, each located on the method's own map (``module.solve`` with the section as a
    terminal event, :func:`section_event`).

    Parameters
    ----------
    module : generated module
        An ordinary module, or a lattice or particle family's (``mg.build_lattice``,
        ``mg.build_particles``: the section is text over its indexed fields, ``"x[2] = 0, px[2] > 0"``;
        a 2-D lattice takes no text sections -- give its ``solve`` a callable event).
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
        Passed to ``module.solve`` (``maxiter``, ``solver`` …; a particle family's ``arrays``,
        which the section's text may also use).

    Returns
    -------
    t : numpy.ndarray, shape (k,)
    y : numpy.ndarray, shape (k, n)
        The located states, k = ``crossings`` unless ``t_max`` came first.
    solution : Solution
        The run (``status`` 1: the crossings were reached; 0: ``t_max`` was; -1: a step failed).
    """
    ev = section_event(module, section, crossings=crossings, params=params, arrays=options.get("arrays"))
    h = abs(float(h))
    t_end = float(t_max) if t_max is not None else 1e6 * h
    sol = module.solve(y0, (0.0, t_end), h, params, events=ev, save_every=1 << 62, **options)
    return sol.t_events[0], sol.y_events[0], sol


# --- modules of symbolic size: lattice (1-D, 2-D) and particle families ---------------------------
#
# A family module (one module for every N) has no fixed state names; its solve(..., events=...)
# forwards here, so that the crossings are found and located by one implementation for all of
# them (the ordinary modules carry theirs in the template: they import numpy only).

class _Layout:
    """Where a family module's indexed state components sit in its flat state.

    The state is ``len(fields) // width`` blocks of N sites, ``width`` numbers per site: a 1-D
    lattice's (q[1..N], p[1..N]) is two blocks of width 1, a particle family's
    (q[1..N], p[1..N]) with q[k] = (x[k], y[k]) two blocks of width DIM.  The component
    ``fields[f]`` of the site k (1-based) is at ``(f // width) * width * N + (k - 1) * width + f % width``.
    """

    def __init__(self, kind, size, fields, width, arrays=(), nmin=1):
        self.kind, self.size, self.fields, self.width = kind, size, tuple(fields), int(width)
        self.arrays, self.nmin = tuple(arrays), int(nmin)

    def flat(self, f, k, n):
        w = self.width
        return (f // w) * w * n + (k - 1) * w + f % w

    def sites(self, y, what):
        """N of the flat state(s) y (..., len(fields) N)."""
        L = y.shape[-1] if y.ndim else 0
        nf = len(self.fields)
        if L % nf or L // nf < 1:
            raise InputError(f"{what}: a state of this family has {nf}N numbers "
                             f"({', '.join(self.fields)} at N sites), got {L}")
        return L // nf

    def valid(self):
        return (f"{', '.join(f + '[k]' for f in self.fields)} with k = 1 … {self.size} (an integer, "
                f"{self.size}, {self.size} - 1 …, or a Sum's index)")


def family_state_names(module, n: int) -> list:
    """The names of a family module's flat state components at N = ``n`` sites, in the state's
    order: ``x[1], y[1], x[2], …, px[1], …`` for particles, ``q[1] … q[N], p[1] … p[N]`` for a 1-D
    lattice (the text an event or a section names them by); None for another module or a 2-D
    lattice (its state has no flat text names)."""
    fam = _family(module)
    if fam is None or fam.kind == "lattice-2d":
        return None
    out = [None] * (len(fam.fields) * int(n))
    for f, name in enumerate(fam.fields):
        for k in range(1, int(n) + 1):
            out[fam.flat(f, k, int(n))] = f"{name}[{k}]"
    return out


def _family(module):
    """The :class:`_Layout` of a lattice or particle family's module, None for another module."""
    if hasattr(module, "Q_FIELDS") and hasattr(module, "SIZE_NAME"):
        return _Layout("particles", module.SIZE_NAME, tuple(module.Q_FIELDS) + tuple(module.P_FIELDS),
                       module.DIM, module.ARRAY_NAMES, module.MIN_SIZE)
    if hasattr(module, "SIZE_NAMES"):
        return _Layout("lattice-2d", "×".join(module.SIZE_NAMES), module.FIELD_NAMES, 1, (), module.MIN_SIZE)
    if hasattr(module, "SIZE_NAME") and hasattr(module, "FIELD_NAMES"):
        return _Layout("lattice", module.SIZE_NAME, module.FIELD_NAMES, 1, (), module.MIN_SIZE)
    return None


class _Names(Mapping):
    """The symbol table of a family's text at size n, built on demand: ``x3`` (what the parser
    makes of ``x[3]``) for each field and per-particle array, k = 1 … n, and the parameters.
    Iterating lists each indexed name at k = 1 and n only (the parser's error messages
    show the range ``x1 … xN`` from them), not all n."""

    def __init__(self, layout, params, n):
        self.layout, self.params, self.n = layout, tuple(params), int(n)
        self._made = {}

    def _split(self, name):
        """(kind, position, k) of an indexed name ('state' or 'array'), or None."""
        for kind, names in (("state", self.layout.fields), ("array", self.layout.arrays)):
            for pos, base in sorted(enumerate(names), key=lambda e: -len(e[1])):
                tail = name[len(base):]
                if name.startswith(base) and tail.isdigit() and not tail.startswith("0"):
                    k = int(tail)
                    if 1 <= k <= self.n:
                        return kind, pos, k
        return None

    def __getitem__(self, name):
        sym = self._made.get(name)
        if sym is None:
            if name not in self.params and self._split(name) is None:
                raise KeyError(name)
            sym = self._made[name] = sp.Symbol(name, real=True)
        return sym

    def __iter__(self):
        for base in self.layout.fields + self.layout.arrays:
            yield f"{base}1"
            if self.n > 1:
                yield f"{base}{self.n}"
        yield from self.params

    def __len__(self):
        return (len(self.layout.fields) + len(self.layout.arrays)) * self.n + len(self.params)


_LITERAL_INDEX = re.compile(r"\[\s*(\d+)\s*\]")


def _param_values(module, params, what) -> dict:
    """The module's parameter values with ``params`` over its defaults; an unknown name is refused,
    naming the valid ones."""
    values = dict(module.DEFAULT_PARAMS)
    if params:
        unknown = sorted(set(params) - set(values))
        if unknown:
            raise InputError(f"unknown parameter(s) {unknown} for {what}; valid: {sorted(values)}")
        values.update(params)
    return values


class _FamilyExpr:
    """A numpy function of a family's flat states (..., len(fields) N) for an expression in its
    indexed fields: parsed (whitelist parser) and compiled once per size N met, the index of
    each component resolved at that N."""

    def __init__(self, module, layout, text, params, arrays, what, shown=None):
        self.layout, self.text, self.what = layout, text, what
        self.shown = text if shown is None else shown        # the user's text, for the messages
        self.values = {k: float(v) for k, v in _param_values(module, params, what).items()}
        self.arrays = {}
        for name, a in dict(arrays or {}).items():
            if name not in layout.arrays:
                raise InputError(f"unknown array {name!r} for {what}; the arrays are {list(layout.arrays)}")
            self.arrays[name] = np.asarray(a, dtype=float).reshape(-1)
        # a bare field (``x`` for ``x[1]``) is the likeliest slip: say what is valid
        for name in re.findall(r"(?<![\w.])([A-Za-z]\w*)(?!\w)(?!\s*\[)", text):
            if name in layout.fields or name in layout.arrays:
                raise InputError(f"{what} {self.shown!r}: {name!r} is indexed in this {layout.kind} module: write "
                                 f"{name}[k]; valid: {layout.valid()}")
        for name in re.findall(r"(?<![\w.])([A-Za-z]\w*)\s*\[", text):
            if name not in layout.fields and name not in layout.arrays:
                arrays = f"; its arrays {', '.join(layout.arrays)}" if layout.arrays else ""
                raise InputError(f"{what} {self.shown!r}: {name!r} is not a field of this {layout.kind} module (its "
                                 f"fields are {', '.join(layout.fields)}{arrays}); valid: {layout.valid()}")
        self._at = {}
        # parse now (a bad text is refused when the event is made, not at the first step), at a
        # size its integer indices allow (the arrays' size where given): the largest literal index,
        # doubled where the size's name enters (q[N - 15], q[N // 2 + 3]); a size a run meets
        # where an index falls outside 1 … N is refused then, at the first evaluation
        literals = [int(k) for inside in re.findall(r"\[([^\]]*)\]", text) for k in re.findall(r"\d+", inside)]
        n0 = max([layout.nmin] + [int(k) for k in _LITERAL_INDEX.findall(text)])
        if re.search(rf"(?<![\w.]){re.escape(layout.size)}(?!\w)", text):
            n0 = max(n0, 2 * (max(literals, default=0) + 1))
        sizes = {len(a) for a in self.arrays.values()}
        self.at(sizes.pop() if len(sizes) == 1 else n0)

    def at(self, n):
        got = self._at.get(n)
        if got is not None:
            return got
        size = self.layout.size
        text = self.text
        if re.search(rf"(?<![\w.]){re.escape(size)}(?!\w)", text):
            # the size's name as an index (q[N - 1]) or a Sum's bound: a Sum over N from n to n binds it
            text = f"Sum({text}, {size}, {n}, {n})"
        names = _Names(self.layout, self.values, n)
        expr = parse_expr(text, names, what=self.what)
        subs, cols = {}, []
        for s in sorted(expr.free_symbols, key=lambda s: s.name):
            if s.name in self.values:
                subs[s] = sp.Float(self.values[s.name])
                continue
            kind, pos, k = names._split(s.name)
            if kind == "array":
                base = self.layout.arrays[pos]
                a = self.arrays.get(base)
                if a is None:
                    raise InputError(f"{self.what} {self.shown!r} uses the per-particle array {base!r}: pass "
                                     f"arrays={{{base!r}: ...}} (the run's) to the event")
                if len(a) != n:
                    raise InputError(f"{self.what}: the array {base!r} has {len(a)} values, the state N = {n}")
                subs[s] = sp.Float(float(a[k - 1]))
            else:
                cols.append((s, self.layout.flat(pos, k, n)))
        expr = expr.subs(subs)
        syms = [s for s, _ in cols]
        f = sp.lambdify(syms, expr, modules="numpy")
        got = self._at[n] = (np.array([i for _, i in cols], dtype=np.int64), f)
        return got

    def __call__(self, y):
        y = np.asarray(y, dtype=float)
        idx, f = self.at(self.layout.sites(y, self.what))
        cols = np.moveaxis(y[..., idx], -1, 0)
        return np.broadcast_to(np.asarray(f(*cols), dtype=float), y.shape[:-1]).copy()


def _family_event(module, layout, text, terminal, direction, condition, params, arrays):
    """:func:`event` for a family module (text over its indexed fields)."""
    if layout.kind == "lattice-2d":
        raise InputError("text events address a 1-D lattice's q[k] or a particle's x[k]; a 2-D lattice's sites "
                         "are index pairs, which the expression parser does not take: give the module's solve a "
                         "callable g(t, y), y of shape (2, N, M) (e.g. lambda t, y: y[..., 0, 0, 0])")
    if arrays is not None and not layout.arrays:
        raise InputError(f"arrays= gives a particle family's per-particle arrays; this {layout.kind} module has none")
    if not isinstance(text, str):
        raise InputError(f"a {layout.kind} module's event is text over its indexed fields ({layout.valid()}), "
                         f"e.g. '{layout.fields[0]}[1] = 0', or a callable g(t, y); got {type(text).__name__}")
    m = _EQUATION.match(text.strip())
    body = f"({m['lhs']}) - ({m['rhs']})" if m else text
    fn = _FamilyExpr(module, layout, body, params, arrays, "event", text)
    cond = None
    if condition is not None:
        c = _COMPARISON.match(condition.strip()) if isinstance(condition, str) else None
        if c is None:
            raise InputError(f"a condition must be one comparison such as '{layout.fields[-1]}[1] > 0' "
                             f"(<, <=, >, >=), got {condition!r}")
        cf = _FamilyExpr(module, layout, f"({c['lhs']}) - ({c['rhs']})", params, arrays, "condition", condition)
        op = c["op"]

        def cond(t, y):
            v = float(cf(np.asarray(y, dtype=float)))
            return {"<": v < 0.0, "<=": v <= 0.0, ">": v > 0.0, ">=": v >= 0.0}[op]
        cond.text = condition
    return Event(text, fn, terminal=terminal, direction=direction, condition=cond, of_state=True)


#: Numbers held per chunk of a family run with events (its rows are held to find the crossings).
_FAMILY_CHUNK_NUMBERS = 1 << 21
#: Steps per chunk at most.
_FAMILY_CHUNK_STEPS = 4096
#: A fresh step of size h from a saved row may differ from the run's next row by the run's
#: carried state (compensation, the predictor's history); beyond this (relative, max-norm) the
#: two are not the same step, and a crossing whose sign only the run's row shows is reported.
_FRESH_AGREEMENT = 1e-9


class _LocateFailure(Exception):
    """A crossing that could not be located (a failed step, or no bracket): reported, never guessed."""


def _values(fn, t, Y):
    """g at the states ``Y`` (k, *shape) at times ``t`` (k,): (k,)."""
    if getattr(fn, "vectorized", False):
        v = np.asarray(fn(t, Y), dtype=float)
        if v.shape == t.shape:
            return v
    return np.array([float(fn(ti, yi)) for ti, yi in zip(t.tolist(), Y)])


def solve_family(integrate, y0, t0, h, steps, params, events, *, save_every=1, options=None,
                 invariants, solution, failures, iterations=None):
    """``solve(..., events=...)`` of a lattice (1-D, 2-D) or particle family's module: the run in
    chunks, g tested at every step, each crossing located on the method's own map.

    Each chunk continues the one before with its carried state (one ``info`` through all of
    them: the compensation, the predictor's history; ``integrate(..., info=...)``), so the rows
    are bitwise those of the run without events.

    The crossings of g between the saved states y_n, y_(n+1) of the run (a sign change; with
    ``direction`` only the one way) are located by Brent's method on the sub-step τ in (0, h]:
    each evaluation is one step of size τ of the module's own method from y_n
    (``integrate(y_n, τ, 1, params, **options)``, so the same parameters and arrays), stopped
    at adjacent floats in τ.  The located state is that step -- bitwise ``step(y_n, τ)`` -- and
    keeps every invariant the method keeps (an interpolant between the steps would not).  The
    bracket's end is a fresh step of size h from y_n: the run's row y_(n+1) carries the run's
    state (compensation, the predictor's history), so it agrees with that step to round-off
    only.  A crossing that a fresh step does not bracket, where the two ends differ by more
    than round-off, or a step that fails while locating, ends the run with ``status`` -1 and
    says so (never a guessed point).

    Parameters
    ----------
    integrate : callable
        The module's ``integrate(y0, h, steps, params, *, save_every, info, **options)``.
    y0 : array_like
        One state: shape (nf N,) (1-D lattice, particles) or (2, N, M) (2-D lattice).
    t0, h : float
        Start and step (``t_span[1] = t0 + steps h``; h may be negative).
    steps : int
    params : dict or None
    events : callable or list of callables
        ``g(t, y)`` with the attributes of scipy's ``solve_ivp`` (``terminal``: bool or the
        count n, stop at the n-th crossing; ``direction``) and methodgen's ``condition(t, y)``
        (a crossing counts where it holds at the located state) and ``vectorized`` (g takes
        times (k,) and states ``(k, *y0.shape)``); :func:`event` makes them from text.
    save_every : int
        Rows of ``Solution.y``: every k-th step (and the last, and the located state of a
        terminal event).
    options : dict
        The module's ``integrate`` options (``maxiter``, ``tol``, ``arrays`` …): ``info``, a
        batch and options ``integrate`` does not take are refused.
    invariants : callable
        ``invariants(y) -> dict`` at one state (the run's params and arrays bound).
    solution : type
        The module's Solution (keyword constructor).
    failures : tuple of exception types
        The module's step failures (their ``step`` and ``trajectory``).
    iterations : str, optional
        The ``info`` key of the iterations per step, reported as ``newton_iterations``.

    Returns
    -------
    Solution
        As the module's ``solve``, with ``status`` 1 where a terminal event stopped the run
        (``t``, ``y`` end at the located state; the message names the event), and per event
        function: ``t_events`` (k,), ``y_events`` ``(k, *y0.shape)``, ``n_events`` (k,) the step n
        each crossing lies in (from the run's state y_n, the n-th row of a ``save_every=1``
        run) and ``tau_events`` (k,) its sub-step τ: the located state is ``step(y_n, τ)``.

    Raises
    ------
    ValueError
        Events that are not callables, a terminal that is not a bool or count, options that
        cannot go with events (the message names the valid ones).
    """
    import inspect

    fns = list(events) if isinstance(events, (list, tuple)) else [events]
    if not fns or not all(callable(f) for f in fns):
        bad = next((f for f in fns if not callable(f)), None)
        raise ValueError("events must be a callable g(t, y) (with optional terminal, direction, condition, "
                         "vectorized attributes; mg.event(module, text) makes one) or a list of them, got "
                         f"{type(bad).__name__ if fns else 'an empty list'}")
    options = dict(options or {})
    takes = [k for k, p in inspect.signature(integrate).parameters.items()
             if p.kind == p.KEYWORD_ONLY and k not in ("save_every", "info")]
    wrong = sorted(set(options) - set(takes))
    if wrong:
        raise ValueError(f"solve(..., events=...) of this family module takes the options {takes} "
                         f"(and save_every); not {wrong}" + (" (t_eval cannot go with events: use save_every)"
                                                             if "t_eval" in wrong else ""))
    if isinstance(save_every, bool) or not isinstance(save_every, (int, np.integer)) or save_every < 1:
        raise ValueError(f"save_every must be a positive integer, got {save_every!r}")
    terminal = []
    for f in fns:
        term = getattr(f, "terminal", False)
        if isinstance(term, (bool, np.bool_)):
            term = 1 if term else 0
        if not isinstance(term, (int, np.integer)) or term < 0:
            raise ValueError(f"an event's terminal must be a bool or a count >= 1, got {term!r}")
        terminal.append(int(term))
    direction = [float(getattr(f, "direction", 0.0)) for f in fns]
    y0 = np.asarray(y0, dtype=float)
    first = integrate(y0, h, 0, params, **options)      # the module's own checks of y0 (one state)
    y0 = first[0]
    every = int(save_every)
    cap = max(1, min(_FAMILY_CHUNK_STEPS, _FAMILY_CHUNK_NUMBERS // max(1, y0.size)))
    # chunks of 64 steps, doubling up to the cap: a terminal event early in a long span (a
    # Poincaré section's default span is 1e6 h) runs at most about twice the steps it needs
    chunk = min(64, cap)

    def phi(yk, tk, tau, fn):
        try:
            y1 = integrate(yk, tau, 1, params, **options)[-1]
        except failures as exc:
            raise _LocateFailure(f"a step of size τ = {tau!r} from t = {tk!r} failed while locating a "
                                 f"crossing: {exc}") from None
        return float(_values(fn, np.array([tk + tau]), y1[None])[0]), y1

    t_ev, y_ev, n_ev, tau_ev = ([[] for _ in fns] for _ in range(4))
    rows_t, rows_y, its = [t0], [y0], []
    y, done = y0, 0
    status, message = 0, None
    g_prev = [float(_values(f, np.array([t0]), y0[None])[0]) for f in fns]
    # one info through all chunks: each integrate call continues from the carried state (the
    # compensation, the predictor's history) the one before left in it, so that the rows are
    # bitwise the run's without events
    info = {}
    while done < steps and status == 0:
        m = min(chunk, steps - done)
        chunk = min(2 * chunk, cap)
        info.pop(iterations, None)
        try:
            part = integrate(y, h, m, params, info=info, **options)
        except failures as exc:
            part = exc.trajectory
            m = min(int(getattr(exc, "step", 0)), len(part) - 1)
            part = part[:m + 1]
            status, message = -1, str(exc)
        got = info.get(iterations) if iterations else None
        its.append(None if got is None else np.asarray(got)[:m])
        ts = t0 + (done + np.arange(m + 1)) * h
        stop = None              # (step within the chunk, located time, state) of a terminal crossing
        if m:
            G = [_values(f, ts[1:], part[1:]) for f in fns]
            P = [np.concatenate([[g_prev[j]], G[j][:-1]]) for j in range(len(fns))]
            hits = {}            # step within the chunk -> the events crossing in it
            for j in range(len(fns)):
                up = (P[j] < 0.0) & (G[j] >= 0.0)
                down = (P[j] > 0.0) & (G[j] <= 0.0)
                hit = up if direction[j] > 0 else down if direction[j] < 0 else (up | down)
                for k in np.flatnonzero(hit).tolist():
                    hits.setdefault(k, []).append(j)
                g_prev[j] = float(G[j][-1])
            for k in sorted(hits):
                tk, yk = float(ts[k]), part[k]
                located = []
                try:
                    for j in hits[k]:
                        f = fns[j]
                        gk = float(P[j][k])
                        g_end, y_end = phi(yk, tk, h, f)
                        if g_end == 0.0 or (g_end > 0.0) != (gk > 0.0):
                            tau, y_at = (h, y_end) if g_end == 0.0 else \
                                zeroin(lambda x: phi(yk, tk, x, f), h, gk, g_end)[::2]
                        else:
                            # the run's row shows a sign the fresh step does not: the same crossing
                            # at the step's end where the two agree to round-off, else reported
                            gap = float(np.max(np.abs(y_end - part[k + 1])))
                            if gap > _FRESH_AGREEMENT * max(1.0, float(np.max(np.abs(part[k + 1])))):
                                raise _LocateFailure(
                                    f"event {j}: g changes sign in the step from t = {tk!r} in the run, but not "
                                    f"over a fresh step of h from the same state (the two ends differ by "
                                    f"{gap:.3g}): the crossing cannot be located on the method's map")
                            tau, y_at = h, y_end
                        cond = getattr(f, "condition", None)
                        if cond is None or cond(tk + tau, y_at):
                            located.append((tau, j, y_at))
                except _LocateFailure as exc:
                    stop = (k, None, None)
                    status, message = -1, f"{exc} (the run stops at t = {tk!r})"
                    break
                for tau, j, y_at in sorted(located, key=lambda e: (e[0], e[1])):
                    t_ev[j].append(tk + tau)
                    y_ev[j].append(y_at)
                    n_ev[j].append(done + k)
                    tau_ev[j].append(tau)
                    if terminal[j] and len(t_ev[j]) >= terminal[j]:
                        stop = (k, tk + tau, y_at)
                        status, message = 1, (f"a terminal event (event {j}) at t = {tk + tau!r} after "
                                              f"{done + k} steps")
                        break
                if stop is not None:
                    break
        keep = m if stop is None else stop[0]
        sel = [i for i in range(1, keep + 1) if (done + i) % every == 0]
        rows_t += ts[sel].tolist()
        rows_y += [part[i] for i in sel]
        if stop is not None:
            if rows_t[-1] != float(ts[keep]):
                rows_t.append(float(ts[keep]))
                rows_y.append(part[keep])
            y = part[keep]
            if stop[1] is not None:
                rows_t.append(stop[1])
                rows_y.append(stop[2])
            done += keep
            if its[-1] is not None:
                its[-1] = its[-1][:keep]
            break
        done += m
        y = part[-1]
    if status == 0:
        message = f"reached t = {t0 + steps * h!r} in {steps} steps of h = {h!r}"
        if steps % every:
            rows_t.append(float(t0 + steps * h))
            rows_y.append(y)
    elif status == -1 and done and rows_t[-1] != float(t0 + done * h):
        rows_t.append(float(t0 + done * h))
        rows_y.append(y)
    Y = np.array(rows_y)
    with np.errstate(all="ignore"):
        values = [invariants(r) for r in Y]
    errors = {k: max(abs(v[k] - values[0][k]) for v in values) for k in values[0]}
    kw = dict(t=np.array(rows_t), y=Y, status=status, success=status >= 0, message=message, h=h, nsteps=done,
              invariant_errors=errors)
    if iterations:
        kw["newton_iterations"] = None if any(i is None for i in its) else \
            np.concatenate(its) if its else np.zeros(0, dtype=np.int64)
    sol = solution(**kw)
    sol.t_events = [np.array(v, dtype=float) for v in t_ev]
    sol.y_events = [np.array(v, dtype=float).reshape((-1,) + y0.shape) for v in y_ev]
    sol.n_events = [np.array(v, dtype=np.int64) for v in n_ev]
    sol.tau_events = [np.array(v, dtype=float) for v in tau_ev]
    return sol
