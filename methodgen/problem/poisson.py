"""Poisson systems ``y' = S(y) ∇H(y)``: a Hamiltonian with a non-canonical structure matrix.

A :class:`PoissonSystem` is immutable plain data, like :class:`~methodgen.problem.problem.Hamiltonian`
(it sits at the same stage of the pipeline): ordered state symbols ``y``, the Hamiltonian
``H(y)``, the structure matrix ``S(y)`` (n×n expressions in y and the parameters),
parameters with default values and declared invariants.  Text is parsed with the
whitelist parser of :mod:`methodgen.problem.parse` (never evaluated).

Checked here, exactly:

* **skew-symmetry** ``S + Sᵀ ≡ 0`` — at construction (an :class:`~methodgen.errors.InputError`
  names the first entry that fails).  Skew-symmetry alone makes H and every Casimir first
  integrals: ``Ḣ = ∇Hᵀ S ∇H = 0``.
* the **Jacobi identity** ``Σ_l (S_il ∂_l S_jk + S_jl ∂_l S_ki + S_kl ∂_l S_ij) = 0`` for all
  ``i < j < k`` — :meth:`PoissonSystem.jacobi` proves it or gives the failing index triple
  and a rational point where it fails.  Without it S is only *almost*-Poisson: the system
  still runs and keeps H and its Casimirs, but the flow is no longer a Poisson map (the
  claim it loses; ``methodgen verify`` reports it).
* **Casimirs** ``S(y) ∇C(y) ≡ 0`` where they are simple (:meth:`PoissonSystem.casimirs`):
  linear ones ``cᵀy`` and polynomials of degree ≤ 2, found as the exact nullspace of the
  linear system for their coefficients (S rational in y), each then reduced to 0 exactly.

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed.,
   Springer 2006, ch. VII.2 (Poisson systems, Casimirs, the Jacobi identity).
.. [MQR99] R. I. McLachlan, G. R. W. Quispel, N. Robidoux, "Geometric integration using
   discrete gradients", Phil. Trans. R. Soc. A 357 (1999) 1021-1045.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import math
from typing import Mapping, NamedTuple, Sequence

import sympy as sp

from ..errors import InputError
from .parse import check_name, check_smooth, parse_expr
from .special import fold_removable_quotients
from .zeros import _zero_status
from .problem import DeclaredInvariant, _names, param_values

__all__ = ["PoissonSystem", "JacobiResult", "Casimir", "is_poisson"]

#: Name of the (first) Casimir among the monitored quantities (``C1``, ``C2``, … for several).
CASIMIR_NAME = "C"


class JacobiResult(NamedTuple):
    """Outcome of the Jacobi-identity check.

    ``status`` is ``"proved"`` (every cyclic sum reduced to exactly 0), ``"refuted"`` (the
    sum for ``triple`` is nonzero at ``point``) or ``"undecided"`` (a sum was neither
    reduced to 0 nor found nonzero at the sample points).  ``expression`` is the cyclic
    sum for ``triple`` (the first that was not shown to vanish), or 0.
    """

    status: str
    triple: tuple[int, int, int] | None
    expression: sp.Expr
    point: dict | None
    detail: str


class Casimir(NamedTuple):
    """A Casimir function found for S: ``name``, ``expr`` and how it was found (``why``)."""

    name: str
    expr: sp.Expr
    why: str


def is_poisson(system) -> bool:
    """True for a :class:`PoissonSystem` (False for a canonical :class:`Hamiltonian`)."""
    return isinstance(system, PoissonSystem)


def _zero(expr: sp.Expr) -> str:
    """``"zero"`` (reduced exactly), ``"nonzero"`` (clearly nonzero at a sample point) or ``"unknown"``."""
    return _zero_status(sp.sympify(expr), None, simplify_limit=400)


def _rational_point(syms, k: int) -> dict:
    """A fixed rational sample point (no floats: exact evaluation)."""
    return {s: sp.Rational(3 + 2 * ((i * 7 + k * 5) % 11), 7 + k) for i, s in enumerate(syms)}


class PoissonSystem:
    """A Poisson system ``y' = S(y) ∇H(y)`` with parameters and declared invariants.

    Parameters
    ----------
    H : str or sympy.Expr
        The Hamiltonian H(y) (same grammar as :class:`methodgen.Hamiltonian`: smooth,
        whitelisted functions only).
    y : sequence of str or sympy.Symbol, length n ≥ 2
        The state variables, in the order of the state vector.
    S : n×n nested sequence (or sympy.Matrix) of str or sympy.Expr
        The structure matrix S(y), entries in y and the parameters; it must be
        skew-symmetric (checked exactly).
    params : mapping of str to float, optional
        Parameter names and their default values (finite reals).
    invariants : mapping of str to (str or sympy.Expr), optional
        Quantities to monitor as first integrals (``{I, H} = ∇Iᵀ S ∇H = 0`` is proved
        or refuted by ``methodgen verify``).
    name : str, optional
        A label used in generated file names and reports.

    Attributes
    ----------
    H : sympy.Expr
    y : tuple of sympy.Symbol
    S : sympy.ImmutableMatrix, shape (n, n)
    params : tuple of sympy.Symbol
    param_values : dict of str to float
    source : str
        The Hamiltonian as the user wrote it.
    S_sources : tuple of tuple of str
        The entries of S as text (as written, or ``str`` of the SymPy entry).
    declared_invariants : tuple of DeclaredInvariant
    constraints : tuple
        Always empty (a Poisson system here has no holonomic constraints).
    time_transform, time : None
        Always None (time transformations and time-dependent H need canonical coordinates).

    Examples
    --------
    >>> import methodgen as mg
    >>> body = mg.PoissonSystem("m1**2/(2*I1) + m2**2/(2*I2) + m3**2/(2*I3)",
    ...                         y=["m1", "m2", "m3"],
    ...                         S=[["0", "-m3", "m2"], ["m3", "0", "-m1"], ["-m2", "m1", "0"]],
    ...                         params={"I1": 2.0, "I2": 1.0, "I3": 2.0 / 3.0})
    >>> body.jacobi().status, [c.name for c in body.casimirs()]
    ('proved', ['C'])
    """

    __slots__ = ("H", "y", "S", "params", "param_values", "source", "S_sources", "name", "_symbols",
                 "declared_invariants", "constraints", "constraint_sources", "time_transform",
                 "time", "_cache")

    kind = "poisson"

    def __init__(self, H, y: Sequence | None = None, S=None, params: Mapping[str, float] | None = None,
                 invariants: Mapping | None = None, name: str | None = None, *, q=None, p=None):
        if q is not None or p is not None:
            raise InputError("a PoissonSystem takes its state as y=[...] and the structure matrix as "
                             "S=[[...]]; for canonical coordinates (q, p) use methodgen.Hamiltonian")
        if y is None or S is None:
            raise InputError("a PoissonSystem needs the state names y=[...] and the structure matrix "
                             "S=[[...]] (n×n, skew-symmetric)")
        yn = _names(y, "state")
        if len(yn) < 2:
            raise InputError(f"a Poisson system needs at least 2 state variables (a skew-symmetric "
                             f"1×1 matrix is 0), got {len(yn)}")
        parn, values = param_values(params)
        seen: set[str] = set()
        for n in yn + parn:
            if n in seen:
                raise InputError(f"name {n!r} is declared twice (y and params must be distinct)")
            seen.add(n)
        symbols = {n: sp.Symbol(n, real=True) for n in yn + parn}
        set_ = lambda k, v: object.__setattr__(self, k, v)
        set_("_symbols", symbols)
        set_("_cache", {})
        set_("y", tuple(symbols[n] for n in yn))
        set_("params", tuple(symbols[n] for n in parn))
        set_("param_values", values)
        set_("constraints", ())
        set_("constraint_sources", ())
        set_("time_transform", None)
        set_("time", None)
        expr, source = self._expr(H, "Hamiltonian")
        if not expr.free_symbols & set(self.y):
            raise InputError("the Hamiltonian does not depend on the state y; it would not define a flow")
        set_("H", expr)
        set_("source", source)
        S_mat, S_src = self._matrix(S, len(yn))
        set_("S", S_mat)
        set_("S_sources", S_src)
        self._check_skew()
        if all(e == 0 for e in S_mat):
            raise InputError("S is the zero matrix: y' = S∇H would not move")
        if name is not None:
            check_name(name.replace("-", "_"), "system")
        set_("name", name)
        set_("declared_invariants", self._declared(invariants))

    # -- construction helpers ---------------------------------------------------
    def _expr(self, value, what: str) -> tuple[sp.Expr, str]:
        """Text through the whitelist parser, SymPy input mapped onto the declared symbols by
        name; both checked finite, real and smooth (the rules of :class:`~methodgen.Hamiltonian`),
        every ``sin(u)/u`` folded into ``sinc_u(u)`` as there."""
        expr, source = self._checked(value, what)
        return fold_removable_quotients(expr), source

    def _checked(self, value, what: str) -> tuple[sp.Expr, str]:
        if isinstance(value, str):
            return parse_expr(value, self._symbols, what=what), value.strip()
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            value = sp.Rational(repr(value)) if isinstance(value, float) else sp.Integer(value)
        if not isinstance(value, sp.Expr):
            raise InputError(f"{what} must be a string or a SymPy expression, got {type(value).__name__}")
        repl = {}
        for s in value.free_symbols:
            if s.name not in self._symbols:
                declared = ", ".join(sorted(self._symbols))
                raise InputError(f"{what}: unknown symbol {s.name!r}; declared symbols are: {declared}")
            repl[s] = self._symbols[s.name]
        expr = value.xreplace(repl)
        if expr.has(sp.I) or expr.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
            raise InputError(f"{what} is not a finite real expression: {expr}")
        check_smooth(expr, what)
        return expr, str(value)

    def _matrix(self, S, n: int) -> tuple[sp.ImmutableMatrix, tuple[tuple[str, ...], ...]]:
        if isinstance(S, sp.MatrixBase):
            rows = S.tolist()
        elif isinstance(S, (str, bytes)) or not isinstance(S, Sequence):
            raise InputError(f"S must be an n×n list of lists (n = {n}, the length of y), got "
                             f"{type(S).__name__}")
        else:
            rows = list(S)
        if len(rows) != n:
            raise InputError(f"S has {len(rows)} rows but y has {n} names: S must be {n}×{n}")
        entries, texts = [], []
        for i, row in enumerate(rows):
            if isinstance(row, (str, bytes)) or not isinstance(row, (Sequence, sp.MatrixBase)):
                raise InputError(f"S row {i} must be a list of {n} entries, got {row!r}")
            row = list(row)
            if len(row) != n:
                raise InputError(f"S row {i} has {len(row)} entries but y has {n} names: S must be {n}×{n}")
            er, tr = [], []
            for j, v in enumerate(row):
                e, s = self._expr(v, f"S[{i}][{j}]")
                er.append(e)
                tr.append(s)
            entries.append(er)
            texts.append(tuple(tr))
        return sp.ImmutableMatrix(entries), tuple(texts)

    def _check_skew(self) -> None:
        """``S + Sᵀ ≡ 0`` shown exactly, else an InputError naming the entry."""
        n = len(self.y)
        for i in range(n):
            for j in range(i, n):
                e = self.S[i, j] + self.S[j, i]
                if e == 0:
                    continue
                status = _zero(e)
                if status == "zero":
                    continue
                a, b = self.y[i].name, self.y[j].name
                if i == j:
                    what = f"S[{i}][{i}] = {self.S[i, i]} is not 0 (the diagonal of a skew matrix is 0)"
                else:
                    what = (f"S[{i}][{j}] + S[{j}][{i}] = {sp.simplify(e) if sp.count_ops(e) < 100 else e} "
                            f"is not 0 (rows {a}, {b})")
                how = "" if status == "nonzero" else " (not shown to be 0 exactly)"
                raise InputError(f"S must be skew-symmetric (S + Sᵀ = 0): {what}{how}")

    def _declared(self, invariants) -> tuple[DeclaredInvariant, ...]:
        if invariants is None:
            return ()
        if not isinstance(invariants, Mapping):
            raise InputError("invariants must be a mapping name -> expression, e.g. "
                             f"{{'C': 'm1**2 + m2**2'}}, got {type(invariants).__name__}")
        taken = set(self._symbols)
        out = []
        for key, value in invariants.items():
            key = key.name if isinstance(key, sp.Symbol) else key
            name = check_name(key, "invariant")
            if name in taken:
                raise InputError(f"invariant name {name!r} is already a state or parameter name; "
                                 "choose another name")
            if name == "H":
                raise InputError("invariant name 'H' is the Hamiltonian, which methodgen monitors "
                                 "itself; choose another name")
            expr, source = self._expr(value, f"invariant {name!r}")
            if not expr.free_symbols & set(self.y):
                raise InputError(f"invariant {name!r} ({source}) does not depend on the state "
                                 f"({', '.join(self.state_names)}); it would be a constant")
            out.append(DeclaredInvariant(name, expr, source))
        return tuple(out)

    def __setattr__(self, key, value):
        raise AttributeError("PoissonSystem is immutable")

    # -- convenience ------------------------------------------------------------
    @property
    def n(self) -> int:
        """Length of the state vector."""
        return len(self.y)

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.y)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.params)

    def symbol(self, name: str) -> sp.Symbol:
        """The SymPy symbol declared under ``name``."""
        return self._symbols[name]

    def S_at(self, point) -> sp.Matrix:
        """``S`` with the state symbols replaced by ``point`` (a sequence of expressions)."""
        return sp.Matrix(self.S).xreplace(dict(zip(self.y, point)))

    @property
    def constant_structure(self) -> bool:
        """S does not depend on the state."""
        return not (self.S.free_symbols & set(self.y))

    # -- exact structure checks -------------------------------------------------
    def jacobi(self) -> JacobiResult:
        """The Jacobi identity of S, proved or refuted (cached; see :class:`JacobiResult`)."""
        hit = self._cache.get("jacobi")
        if hit is None:
            hit = self._cache["jacobi"] = self._jacobi()
        return hit

    def jacobi_sum(self, i: int, j: int, k: int) -> sp.Expr:
        """``Σ_l (S_il ∂_l S_jk + S_jl ∂_l S_ki + S_kl ∂_l S_ij)`` (zero for a Poisson S)."""
        S, y = self.S, self.y
        return sp.Add(*[S[i, l] * sp.diff(S[j, k], y[l]) + S[j, l] * sp.diff(S[k, i], y[l])
                        + S[k, l] * sp.diff(S[i, j], y[l]) for l in range(len(y))])

    def _jacobi(self) -> JacobiResult:
        n = len(self.y)
        if self.constant_structure:
            return JacobiResult("proved", None, sp.S.Zero, None,
                                "S is constant: every cyclic sum has only derivatives of constants")
        undecided = None
        for i, j, k in itertools.combinations(range(n), 3):
            e = self.jacobi_sum(i, j, k)
            status = _zero(e)
            if status == "zero":
                continue
            syms = sorted(e.free_symbols, key=lambda s: s.name)
            for t in range(6):
                pt = _rational_point(syms, t)
                pt.update({s: sp.Rational(repr(self.param_values[s.name])) for s in self.params if s in pt})
                try:
                    v = e.xreplace(pt)
                    v = sp.nsimplify(v) if v.has(sp.Float) else sp.simplify(v)
                except (ZeroDivisionError, TypeError, ValueError):
                    continue
                if v.is_number and v != 0 and v.is_finite:
                    return JacobiResult("refuted", (i, j, k), e, {str(s): str(pt[s]) for s in syms},
                                        f"the cyclic sum for (i, j, k) = ({i}, {j}, {k}) is {v} at this point")
            undecided = undecided or ((i, j, k), e)
        if undecided is not None:
            return JacobiResult("undecided", undecided[0], undecided[1], None,
                                "a cyclic sum was neither reduced to 0 nor found nonzero at a sample point")
        return JacobiResult("proved", None, sp.S.Zero, None,
                            f"all {math.comb(n, 3)} cyclic sums reduced to 0 exactly" if n >= 3 else
                            "n = 2: there is no triple of distinct indices (every skew 2×2 S is Poisson)")

    def casimirs(self) -> tuple[Casimir, ...]:
        """The simple Casimirs of S: linear ``cᵀy`` and polynomials of degree ≤ 2 with
        ``S(y)∇C(y) ≡ 0`` (cached).

        The coefficients solve an exact linear system: each row of ``S∇C`` (over a common
        denominator when S is rational in y) is a polynomial in y whose coefficients are
        linear in the unknown coefficients of C; its nullspace (reduced row-echelon basis,
        quadratic monomials first) gives the Casimirs, each then reduced to 0 exactly.
        Empty when S is not rational in y (the search is not made) or has none.
        Casimirs that are not polynomials of degree ≤ 2 are not searched for (``Σ log y_i``
        of the 3-d Lotka–Volterra system): declare them as invariants (``invariants=`` here,
        ``[invariants]`` in a scene) -- they are then monitored, ``verify`` decides that they
        are first integrals, and a method claims them where it keeps them.
        Names: ``C`` for one, ``C1, C2, …`` for several (a name already used by the state,
        a parameter or a declared invariant gets the suffix ``_S``); a Casimir equal to a
        declared invariant is left out (the declared name is used).
        """
        hit = self._cache.get("casimirs")
        if hit is None:
            hit = self._cache["casimirs"] = self._casimirs()
        return hit

    def _casimirs(self) -> tuple[Casimir, ...]:
        y = list(self.y)
        quad = [a * b for a, b in itertools.combinations_with_replacement(y, 2)]
        monos = quad + y                      # quadratic monomials first: they lead the basis
        coeffs = sp.symbols(f"_k0:{len(monos)}")
        C = sp.Add(*[c * m for c, m in zip(coeffs, monos)])
        rows = self.S * sp.Matrix([sp.diff(C, s) for s in y])
        eqs = []
        for r in rows:
            num = sp.numer(sp.together(sp.expand(r)))
            try:
                poly = sp.Poly(num, *y)
            except sp.PolynomialError:
                return ()
            if poly.free_symbols_in_domain & set(y):
                return ()
            eqs.extend(poly.coeffs())
        if not eqs:
            return ()
        A, _ = sp.linear_eq_to_matrix(eqs, coeffs)
        basis = A.nullspace()
        if not basis:
            return ()
        B = sp.Matrix.hstack(*basis).T.rref()[0]
        found = []
        for row in range(B.rows):
            vec = [B[row, j] for j in range(B.cols)]
            if all(v == 0 for v in vec):
                continue
            den = functools.reduce(lambda a, b: sp.lcm(a, b), [sp.fraction(sp.nsimplify(v))[1] for v in vec], 1)
            expr = sp.expand(sp.Add(*[sp.cancel(v * den) * m for v, m in zip(vec, monos)]))
            if expr == 0:
                continue
            check = self.S * sp.Matrix([sp.diff(expr, s) for s in y])
            if any(_zero(e) != "zero" for e in check):
                continue
            degree = sp.Poly(expr, *y).total_degree()
            found.append((expr, "linear" if degree == 1 else "quadratic"))
        found = self._independent(found)
        declared = {sp.expand(d.expr) for d in self.declared_invariants}
        found = [(e, k) for e, k in found if e not in declared and sp.expand(-e) not in declared]
        taken = set(self._symbols) | {d.name for d in self.declared_invariants} | {"H"}
        names = [CASIMIR_NAME] if len(found) == 1 else [f"{CASIMIR_NAME}{i + 1}" for i in range(len(found))]
        out = []
        for name, (expr, kind) in zip(names, found):
            while name in taken:
                name += "_S"
            taken.add(name)
            out.append(Casimir(name, expr, f"{kind} Casimir of S: S(y)∇{name}(y) ≡ 0 exactly"))
        return tuple(out)

    def _independent(self, found: list) -> list:
        """Linear Casimirs first; a quadratic one that is a combination of products of linear
        ones (``(a + b + c)²`` next to ``a + b + c``) says nothing new and is dropped."""
        linear = [e for e, k in found if k == "linear"]
        quadratic = [e for e, k in found if k == "quadratic"]
        if not linear:
            return found
        gens = linear + [a * b for a, b in itertools.combinations_with_replacement(linear, 2)]
        ks = sp.symbols(f"_g0:{len(gens)}")
        kept = []
        for e in quadratic:
            diff = sp.Poly(sp.expand(e - sp.Add(*[k * g for k, g in zip(ks, gens)])), *self.y)
            if not sp.solve(diff.coeffs(), ks, dict=True):
                kept.append(e)
        return [(e, "linear") for e in linear] + [(e, "quadratic") for e in kept]

    def fingerprint(self) -> str:
        """A stable SHA-256 over everything that defines the system (see Hamiltonian.fingerprint)."""
        parts = [
            "kind=poisson",
            "y=" + ",".join(s.name for s in self.y),
            "params=" + ",".join(f"{k}:{self.param_values[k]!r}" for k in self.param_names),
            "H=" + sp.srepr(self.H),
            "S=" + ";".join(sp.srepr(e) for e in self.S),
            f"name={self.name}",
        ]
        if self.declared_invariants:
            parts.append("invariants=" + ";".join(f"{inv.name}:{sp.srepr(inv.expr)}"
                                                  for inv in self.declared_invariants))
        return hashlib.sha256("\n".join(parts).encode()).hexdigest()

    def __repr__(self) -> str:
        extra = ""
        if self.declared_invariants:
            extra = f", invariants={ {inv.name: inv.source for inv in self.declared_invariants} }"
        return (f"PoissonSystem({self.source!r}, y={list(self.state_names)}, "
                f"S={[list(r) for r in self.S_sources]}, params={self.param_values}{extra})")

    def _repr_latex_(self) -> str:
        from .special import to_elementary   # sin(u)/u as the user wrote it, not sinc_u
        return (f"$\\dot y = S(y)\\nabla H,\\quad H = {sp.latex(to_elementary(self.H))},"
                f"\\quad S = {sp.latex(to_elementary(self.S))}$")
