"""The stage system of an s-stage implicit method, kept as structure instead of expanded.

Gauss collocation and energy-preserving collocation solve, per step, for s stage
increments ``Z_j`` (each of the state's length n) the system

    u_k = y + Σ_i P_ki Z_i   (k = 1..m),      R_j = Z_j − h σ_j Σ_k Q_jk f(u_k) = 0,

with ``f = J∇H`` (``S∇H`` for a Poisson system) and constant tables ``P`` (m × s), ``Q``
(s × m), ``σ`` (s):

* Gauss: m = s, ``P = I`` (``u_k = y + Z_k``), ``Q = A``, ``σ = 1``;
* energy collocation: the m quadrature nodes, ``P_ki = Λ_i(x_k)``, ``Q_jk = w_k ℓ_j(x_k)``,
  ``σ_j = 1/b_j``.

Its Newton matrix is ``∂R_j/∂Z_i = δ_ij I − h σ_j Σ_k Q_jk P_ki f'(u_k)``.  Expanded
symbolically, the residual holds s copies of f per stage and the Jacobian ``(s·n)²``
entries -- code (and derivation time and memory) growing like s²n².  Here only f and its
n × n Jacobian f' (sparse: only its structural nonzeros) are derived and emitted, once;
the module's residual and Newton-matrix kernels are loops over the stages with the
tables as module constants, so the generated code grows like the size of f and f' and
the tables, not with s².  The symbolic residual of the scheme stays what it was (the
verification reads it); only the lowering takes this route
(:func:`methodgen.codegen.lower.lower`, ``expanded=False``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import sympy as sp


@dataclass(frozen=True, eq=False)
class StageSystem:
    """The tables and the field of a stage system (see the module docstring).

    Attributes
    ----------
    field : tuple of sympy.Expr, length n
        ``f(y)`` in the state symbols.
    state : tuple of sympy.Symbol, length n
    stages : int
        s.
    weights : tuple of tuple of float, s × m
        ``Q``.
    points : tuple of tuple of float (m × s) or None
        ``P``; None for ``u_k = y + Z_k`` (m = s, Gauss).
    scale : tuple of float, length s
        ``σ``.
    """

    field: tuple
    state: tuple
    stages: int
    weights: tuple
    points: tuple | None
    scale: tuple

    @property
    def n(self) -> int:
        return len(self.state)

    @property
    def m(self) -> int:
        """Number of stage points (evaluations of f per residual)."""
        return len(self.weights[0])

    @cached_property
    def field_jacobian(self) -> sp.Matrix:
        """``f'(y)``, n × n, by SymPy's ``diff`` entry by entry (for checks; the module's f'
        comes from :attr:`derivative`)."""
        return sp.Matrix(self.field).jacobian(sp.Matrix(self.state))

    @cached_property
    def derivative(self) -> "FieldDerivative":
        """f and f' as one straight-line program (:func:`field_derivative`)."""
        return field_derivative(self.field, self.state)

    @property
    def pattern(self) -> tuple[tuple[int, int], ...]:
        """The structural nonzeros ``(a, b)`` of f', row-major: the only entries emitted."""
        return self.derivative.pattern

    def coupling(self, j: int, i: int, k: int) -> float:
        """``Q_jk P_ki`` (rounded once to float64): the weight of f'(u_k) in block (j, i)."""
        if self.points is None:
            return float(self.weights[j][k]) if i == k else 0.0
        return float(self.weights[j][k]) * float(self.points[k][i])

    def newton_pattern(self) -> list[tuple[int, int]]:
        """Structural nonzeros of the (s·n) × (s·n) Newton matrix: the diagonal and f''s
        pattern in every block (j, i) that some stage point couples."""
        n, s = self.n, self.stages
        out = [(r, r) for r in range(n * s)]
        for j in range(s):
            for i in range(s):
                if any(self.coupling(j, i, k) != 0.0 for k in range(self.m)):
                    out += [(j * n + a, i * n + b) for a, b in self.pattern]
        return out


@dataclass(frozen=True)
class FieldDerivative:
    """f and f' as a straight-line program: ``assignments`` ``(symbol, expr)`` in evaluation
    order (f's common subexpressions, each followed by its nonzero partial derivatives),
    then ``field`` (n) and ``jacobian``, the nonzero entries of f' at ``pattern``, all in
    the assigned symbols and the state."""

    assignments: tuple
    field: tuple
    pattern: tuple
    jacobian: tuple


def _chain(expr, index: dict, partials: dict, assignments: list, tag: str) -> dict:
    """``{l: ∂expr/∂y_l}`` (nonzero ones) of an expression in the state and in assigned
    symbols whose partials are ``partials[symbol]`` (forward mode; symbols in name order,
    so the code is deterministic).  An outer derivative ``∂expr/∂t`` that serves several
    partials of ``t`` is assigned once (``_do<tag>_<i>``), not recomputed in each."""
    out: dict = {}
    for i, s in enumerate(sorted(expr.free_symbols, key=lambda x: x.name)):
        if s in index:
            inner = {index[s]: sp.S.One}
        elif s in partials:
            inner = partials[s]
        else:
            continue                                    # a parameter
        if not inner:
            continue
        outer = sp.diff(expr, s)
        if outer == 0:
            continue
        if len(inner) > 1 and not (outer.is_Atom or (-outer).is_Atom):
            sym = sp.Symbol(f"_do{tag}_{i}", real=True)
            assignments.append((sym, outer))
            outer = sym
        for l, d in inner.items():
            out[l] = out.get(l, sp.S.Zero) + outer * d
    return {l: d for l, d in out.items() if d != 0}


def field_derivative(field, state) -> FieldDerivative:
    """f' by the chain rule through f's common subexpressions.

    Differentiating the expanded entries of f one by one repeats the work on every shared
    subexpression (for the 18-DOF outer solar system ~5 s of SymPy ``diff`` for 342
    nonzeros, and large entries for CSE to take apart again).  Here f is reduced by CSE
    once; each subexpression ``t_k = e_k(y, t_<k)`` gets its partials
    ``∂t_k/∂y_l = ∂e_k/∂y_l + Σ_m ∂e_k/∂t_m ∂t_m/∂y_l`` as new assignments (only the
    nonzero ones, constants inline), and f''s entries follow the same way: the cost and
    the code grow like the size of f's program times the few state variables each
    subexpression depends on.  Exact: the same derivative, evaluated in a different order.
    """
    index = {v: l for l, v in enumerate(state)}
    temps, reduced = sp.cse(list(field), symbols=sp.numbered_symbols("_c"), order="canonical")
    assignments: list = []
    partials: dict = {}
    for k, (t, e) in enumerate(temps):
        assignments.append((t, e))
        own = {}
        for l, d in sorted(_chain(e, index, partials, assignments, str(k)).items()):
            if d.is_Number:
                own[l] = d
            else:
                ds = sp.Symbol(f"_dc{k}_{l}", real=True)
                assignments.append((ds, d))
                own[l] = ds
        partials[t] = own
    pattern, entries = [], []
    for a, r in enumerate(reduced):
        for b, d in sorted(_chain(r, index, partials, assignments, f"f{a}").items()):
            pattern.append((a, b))
            entries.append(d)
    assignments, outputs = _shared(assignments, list(reduced) + entries)
    return FieldDerivative(tuple(assignments), tuple(outputs[:len(reduced)]), tuple(pattern),
                           tuple(outputs[len(reduced):]))


def _shared(assignments: list, outputs: list) -> tuple[list, list]:
    """One CSE pass over the program's right-hand sides and outputs (the partials of one
    subexpression share factors such as ``r**-5``); each new temporary is placed just
    before its first use -- after every symbol it reads, which the expression it was taken
    from read too."""
    rhs = [e for _, e in assignments]
    temps, reduced = sp.cse(rhs + outputs, symbols=sp.numbered_symbols("_e"), order="canonical")
    body = dict(temps)
    done: set = set()
    program: list = []

    def need(expr):
        for t in sorted(expr.free_symbols & body.keys(), key=lambda x: int(x.name[2:])):
            if t not in done:
                need(body[t])
                done.add(t)
                program.append((t, body[t]))

    for (sym, _), e in zip(assignments, reduced):
        need(e)
        program.append((sym, e))
    for e in reduced[len(assignments):]:
        need(e)
    return program, list(reduced[len(assignments):])
