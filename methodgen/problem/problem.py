"""The problem description: a Hamiltonian system, possibly with holonomic constraints.

A :class:`Hamiltonian` is immutable plain data: ordered coordinates ``q``,
momenta ``p``, the Hamiltonian ``H(q, p)`` as a SymPy expression, parameter
symbols with default values, and constraint expressions ``g(q)``.  It is the
first stage of the pipeline (problem → derive → scheme → verify → lower → emit
→ runtime) and knows nothing about methods.
"""

from __future__ import annotations

import hashlib
import math
from typing import Iterable, Mapping, NamedTuple, Sequence

import sympy as sp

from ..errors import InputError, ParseError
from .parse import check_name, check_smooth, parse_expr
from .special import fold_removable_quotients

__all__ = ["Hamiltonian", "DeclaredInvariant", "builtin_monitor_names"]


class DeclaredInvariant(NamedTuple):
    """A quantity the user declared as a first integral: ``name``, ``expr``, ``source`` text.

    Declaring does not make it one: :func:`methodgen.symbolic.derive.invariants` marks it exact
    only when ``{I, H} = 0`` is shown symbolically, and ``methodgen verify`` proves or
    refutes it.
    """

    name: str
    expr: sp.Expr
    source: str


def builtin_monitor_names(dim: int, n_constraints: int) -> set[str]:
    """Names :mod:`methodgen.symbolic.derive` may give its own monitored quantities (a declared
    invariant may not use them): ``H``, ``H_phys``, the angular-momentum names of every
    coordinate plane (``L`` in 2D, ``Lx Ly Lz`` in 3D, ``L_<qi>_<qj>`` otherwise, see
    :func:`methodgen.symbolic.derive.angular_momenta`) and the constraint monitors ``g<i>``, ``g<i>_v``.
    """
    out = {"H", "H_phys"}
    if dim == 2:
        out.add("L")
    elif dim == 3:
        out.update({"Lx", "Ly", "Lz"})
    for i in range(n_constraints):
        out.update({f"g{i + 1}", f"g{i + 1}_v"})
    return out


#: Unknown symbols that get the hint to declare a time (``time="t"``).
_TIME_HINT_NAMES = ("t", "time")


def _time_name(time, qn, pn, parn) -> str | None:
    """The declared time's name (None for none); an error if a coordinate, momentum or
    parameter has it — a parameter named like the time would freeze it."""
    if time is None:
        return None
    if isinstance(time, sp.Symbol):
        time = time.name
    if not isinstance(time, str):
        raise InputError(f"time must be the name of the time variable, e.g. time=\"t\", got {time!r}")
    name = check_name(time, "time")
    if name in parn:
        raise InputError(f"parameter {name!r} has the name of the declared time time={name!r}: a parameter "
                         f"is a constant (it would freeze the time); remove {name!r} from params, or "
                         "name the time differently")
    if name in qn or name in pn:
        kind = "coordinate" if name in qn else "momentum"
        raise InputError(f"the declared time time={name!r} is also a {kind} name; the time is "
                         f"not a state variable of H (its momentum is added by the autonomous extension)")
    return name


def _names(items: Iterable, what: str) -> tuple[str, ...]:
    if isinstance(items, (str, bytes)):
        raise InputError(f"{what} must be a list of names, got the string {items!r}")
    out = []
    for item in items:
        if isinstance(item, sp.Symbol):
            item = item.name
        out.append(check_name(item, what))
    return tuple(out)


def param_values(params) -> tuple[tuple[str, ...], dict[str, float]]:
    """Check a parameter mapping (name or Symbol -> real number): its names and float values.

    Raises :class:`InputError` naming what is wrong (not a mapping, a bad name, a value that is
    not a finite real number).
    """
    params = {} if params is None else params
    if not isinstance(params, Mapping):
        raise InputError(f"params must be a mapping name -> value, got {type(params).__name__}")
    parn = _names(list(params), "parameter")
    values: dict[str, float] = {}
    for key, value in params.items():
        key = key.name if isinstance(key, sp.Symbol) else key
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"parameter {key!r} must be a real number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise InputError(f"parameter {key!r} must be finite, got {value!r}")
        values[key] = value
    return parn, values


class Hamiltonian:
    """A Hamiltonian system ``H(q, p)`` with parameters and optional constraints.

    Parameters
    ----------
    H : str or sympy.Expr
        The Hamiltonian.  Text is parsed with the safe whitelist parser of
        :mod:`methodgen.problem.parse` (never evaluated); a SymPy expression may use any
        symbols whose *names* are declared below.  Both must be smooth: only
        numbers, ``pi``, ``E``, ``+ * **`` (so ``sqrt``) and ``exp log sin cos tan
        sinh cosh tanh atan`` are accepted (:func:`methodgen.problem.parse.check_smooth`);
        ``Abs`` — also as ``sqrt(q**2)`` —, ``Max``, ``sign``, ``Piecewise`` … are
        refused with the reason.
    q, p : sequence of str or sympy.Symbol, length d
        Coordinates and conjugate momenta, in the order of the state vector
        ``y = (q_1..q_d, p_1..p_d)``.
    params : mapping of str to float, optional
        Parameter names and their default numerical values (finite reals).
    constraints : sequence of str or sympy.Expr, optional
        Holonomic constraints ``g_i(q) = 0`` (functions of ``q`` and parameters).
    name : str, optional
        A label used in generated file names and reports.
    time : str or sympy.Symbol, optional
        The name of the time when ``H`` depends on it explicitly, ``time="t"``: H (and the
        declared invariants) may then use it.  The system stays the user's ``H(q, p, t)``
        on ``(q, p)``; every method integrates its autonomous extension ``K = H + e`` on
        ``(q, t; p, e)`` (:func:`methodgen.autonomise`, done by ``discretize``/``build``).
        Without it, ``t`` in H is an error (declaring ``t`` as a parameter would freeze time).
    invariants : mapping of str to (str or sympy.Expr), optional
        Quantities to monitor as first integrals, ``{"P": "p1 + p2 + p3"}``: text is parsed
        with the same whitelist parser as H (never evaluated), SymPy expressions are
        checked like H (declared symbols only, smooth).  Names follow the rules of the
        other names and must differ from the state, parameter and built-in monitor names
        (:func:`builtin_monitor_names`).  Monitored after H and the angular momenta;
        ``{I, H} = 0`` is proved or refuted by ``methodgen verify``, and a method claims
        to keep I only where that is a theorem for it (``Traits.preserved``).

    Attributes
    ----------
    H : sympy.Expr
    q, p : tuple of sympy.Symbol
    params : tuple of sympy.Symbol
    param_values : dict of str to float
    constraints : tuple of sympy.Expr
    source : str
        The Hamiltonian as the user wrote it (text) or ``str(H)``.
    declared_invariants : tuple of DeclaredInvariant
        The declared invariants, in the order given (empty when none).
    time : sympy.Symbol or None
        The declared time (``time=``), None for an autonomous H.

    Examples
    --------
    >>> import methodgen as mg
    >>> kepler = mg.Hamiltonian("(px**2+py**2)/(2*m) - k/sqrt(x**2+y**2)",
    ...                         q=["x", "y"], p=["px", "py"], params={"m": 1.0, "k": 1.0})
    >>> kepler.dim
    2
    """

    __slots__ = ("H", "q", "p", "params", "param_values", "constraints", "source",
                 "constraint_sources", "name", "_symbols", "time_transform",
                 "declared_invariants", "time")

    def __init__(self, H, q: Sequence, p: Sequence, params: Mapping[str, float] | None = None,
                 constraints: Sequence = (), name: str | None = None,
                 invariants: Mapping | None = None, time: str | sp.Symbol | None = None):
        qn = _names(q, "coordinate")
        pn = _names(p, "momentum")
        if len(qn) == 0:
            raise InputError("a Hamiltonian needs at least one coordinate q")
        if len(qn) != len(pn):
            raise InputError(f"q has {len(qn)} names but p has {len(pn)}: each coordinate needs one momentum "
                             "(for a non-canonical system y' = S(y)∇H use methodgen.PoissonSystem(H, y=[...], "
                             "S=[[...]]))")
        parn, values = param_values(params)
        allnames = qn + pn + parn
        seen: set[str] = set()
        for n in allnames:
            if n in seen:
                raise InputError(f"name {n!r} is declared twice (q, p and params must be distinct)")
            seen.add(n)
        tn = _time_name(time, qn, pn, parn)

        symbols = {n: sp.Symbol(n, real=True) for n in allnames + ((tn,) if tn else ())}
        object.__setattr__(self, "_symbols", symbols)
        object.__setattr__(self, "q", tuple(symbols[n] for n in qn))
        object.__setattr__(self, "p", tuple(symbols[n] for n in pn))
        object.__setattr__(self, "params", tuple(symbols[n] for n in parn))
        object.__setattr__(self, "param_values", values)
        object.__setattr__(self, "time", symbols[tn] if tn else None)

        expr, source = self._expr(H, "Hamiltonian")
        if not expr.free_symbols & set(self.p):
            raise InputError("the Hamiltonian does not depend on any momentum p; "
                             "it would not define a Hamiltonian flow")
        object.__setattr__(self, "H", expr)
        object.__setattr__(self, "source", source)

        if isinstance(constraints, (str, bytes)):
            raise InputError("constraints must be a list of expressions, got a single string")
        cons, csrc = [], []
        for i, c in enumerate(constraints):
            e, s = self._expr(c, f"constraint {i + 1}")
            if e.free_symbols & set(self.p):
                raise InputError(f"constraint {i + 1} ({s}) depends on momenta; only holonomic "
                                 "constraints g(q) = 0 are supported")
            if not e.free_symbols & set(self.q):
                raise InputError(f"constraint {i + 1} ({s}) does not depend on q")
            if self.time is not None and self.time in e.free_symbols:
                raise InputError(f"constraint {i + 1} ({s}) depends on the time {self.time.name!r}; only "
                                 "constraints g(q) = 0 that do not move with time are supported")
            cons.append(e)
            csrc.append(s)
        if len(cons) >= len(qn):
            raise InputError(f"{len(cons)} constraints on {len(qn)} coordinates leave no motion; "
                             "need fewer constraints than coordinates")
        object.__setattr__(self, "constraints", tuple(cons))
        object.__setattr__(self, "constraint_sources", tuple(csrc))
        if name is not None:
            check_name(name.replace("-", "_"), "system")
        object.__setattr__(self, "name", name)
        #: :class:`methodgen.symbolic.timetransform.TimeTransform` when this system is the Poincaré
        #: time transformation of another (set by :func:`methodgen.time_transform`), else None.
        object.__setattr__(self, "time_transform", None)
        object.__setattr__(self, "declared_invariants", self._declared(invariants, allnames))

    def _declared(self, invariants, allnames) -> tuple[DeclaredInvariant, ...]:
        if invariants is None:
            return ()
        if not isinstance(invariants, Mapping):
            raise InputError("invariants must be a mapping name -> expression, e.g. "
                             f"{{'P': 'p1 + p2'}}, got {type(invariants).__name__}")
        taken = set(allnames) | ({self.time.name} if self.time is not None else set())
        builtin = builtin_monitor_names(len(self.q), len(self.constraints))
        qd = [s.name for s in self.q]
        for i in range(len(qd)):          # the angular-momentum names of d > 3 (derive.angular_momenta)
            for j in range(i + 1, len(qd)):
                if len(qd) > 3:
                    builtin.add(f"L_{qd[i]}_{qd[j]}")
        out = []
        for key, value in invariants.items():
            key = key.name if isinstance(key, sp.Symbol) else key
            name = check_name(key, "invariant")
            if name in taken:
                raise InputError(f"invariant name {name!r} is already a coordinate, momentum or "
                                 "parameter name; choose another name")
            if name in builtin:
                raise InputError(f"invariant name {name!r} is the name of a quantity methodgen monitors "
                                 f"itself ({', '.join(sorted(builtin))}); choose another name")
            if name in {inv.name for inv in out}:   # pragma: no cover - a mapping has unique keys
                raise InputError(f"invariant {name!r} is declared twice")
            expr, source = self._expr(value, f"invariant {name!r}")
            if not expr.free_symbols & set(self.q + self.p):
                raise InputError(f"invariant {name!r} ({source}) does not depend on the state "
                                 f"({', '.join(self.state_names)}); it would be a constant")
            out.append(DeclaredInvariant(name, expr, source))
        return tuple(out)

    def _expr(self, value, what: str) -> tuple[sp.Expr, str]:
        """``(expr, source)``: parsed or mapped onto the declared symbols, checked, and with
        every ``sin(u)/u`` folded into ``sinc_u(u)`` (smooth at u = 0 and evaluated there,
        :mod:`methodgen.problem.special`) — H, constraints and declared invariants alike, so that
        brackets between them cancel symbol for symbol."""
        expr, source = self._checked(value, what)
        return fold_removable_quotients(expr), source

    def _checked(self, value, what: str) -> tuple[sp.Expr, str]:
        if isinstance(value, str):
            try:
                return parse_expr(value, self._symbols, what=what), value.strip()
            except ParseError as exc:
                raise ParseError(f"{exc}{self._time_hint(str(exc))}") from None
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = sp.Rational(repr(value)) if isinstance(value, float) else sp.Integer(value)
        if not isinstance(value, sp.Expr):
            raise InputError(f"{what} must be a string or a SymPy expression, got {type(value).__name__}")
        # Map the user's symbols onto ours by name (theirs may lack real=True).
        repl = {}
        for s in value.free_symbols:
            if s.name not in self._symbols:
                declared = ", ".join(sorted(self._symbols))
                msg = f"{what}: unknown symbol {s.name!r}; declared symbols are: {declared}"
                raise InputError(msg + self._time_hint(msg))
            repl[s] = self._symbols[s.name]
        expr = value.xreplace(repl)
        if expr.has(sp.I) or expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
            raise InputError(f"{what} is not a finite real expression: {expr}")
        # The same whitelist as for text: smooth functions only (Abs, Max, sign,
        # Piecewise, ... are refused with the reason; sqrt(q**2) is Abs(q) here).
        check_smooth(expr, what)
        return expr, str(value)

    def _time_hint(self, message: str) -> str:
        """A hint for an unknown symbol that reads like a time (``t``, ``time``) when none is declared."""
        if self.time is not None:
            return ""
        for name in _TIME_HINT_NAMES:
            if f"unknown symbol {name!r}" in message:
                return (f"; if {name!r} is the time (a time-dependent H), declare it: "
                        f'time = "{name}" in [system], or time="{name}" in the API '
                        "(a parameter would freeze it)")
        return ""

    def __setattr__(self, key, value):
        raise AttributeError("Hamiltonian is immutable")

    # -- convenience -------------------------------------------------------
    @property
    def dim(self) -> int:
        """Number of degrees of freedom d (the state has 2d components)."""
        return len(self.q)

    @property
    def autonomous(self) -> bool:
        """False when a time was declared (``time=``): H may depend on it explicitly."""
        return self.time is None

    @property
    def y(self) -> tuple[sp.Symbol, ...]:
        """State symbols ``(q..., p...)``."""
        return self.q + self.p

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.y)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.params)

    def symbol(self, name: str) -> sp.Symbol:
        """The SymPy symbol declared under ``name``."""
        return self._symbols[name]

    def fingerprint(self) -> str:
        """A stable SHA-256 over everything that defines the system.

        Used in the signature of generated modules; independent of dict order
        and of Python's hash randomisation.
        """
        parts = [
            "q=" + ",".join(s.name for s in self.q),
            "p=" + ",".join(s.name for s in self.p),
            "params=" + ",".join(f"{k}:{self.param_values[k]!r}" for k in self.param_names),
            "H=" + sp.srepr(self.H),
            "g=" + ";".join(sp.srepr(g) for g in self.constraints),
            f"name={self.name}",
        ]
        if self.time_transform is not None:
            parts.append("time_transform=" + self.time_transform.fingerprint())
        if self.time is not None:      # only when declared, so other systems keep their fingerprint
            parts.append(f"time={self.time.name}")
        if self.declared_invariants:   # only when declared, so other systems keep their fingerprint
            parts.append("invariants=" + ";".join(f"{inv.name}:{sp.srepr(inv.expr)}"
                                                  for inv in self.declared_invariants))
        return hashlib.sha256("\n".join(parts).encode()).hexdigest()

    def __repr__(self) -> str:
        extra = f", constraints={list(self.constraint_sources)}" if self.constraints else ""
        if self.declared_invariants:
            extra += f", invariants={ {inv.name: inv.source for inv in self.declared_invariants} }"
        if self.time is not None:
            extra += f", time={self.time.name!r}"
        return (f"Hamiltonian({self.source!r}, q={[s.name for s in self.q]}, "
                f"p={[s.name for s in self.p]}, params={self.param_values}{extra})")

    def _repr_latex_(self) -> str:
        from .special import to_elementary   # sin(u)/u as the user wrote it, not sinc_u
        return f"$H = {sp.latex(to_elementary(self.H))}$"
