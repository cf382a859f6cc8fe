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
(:func:`methodgen.lower.lower`, ``expanded=False``).
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
        """``f'(y)``, n × n (derived once, not per stage)."""
        return sp.Matrix(self.field).jacobian(sp.Matrix(self.state))

    @cached_property
    def pattern(self) -> tuple[tuple[int, int], ...]:
        """The structural nonzeros ``(a, b)`` of f', row-major: the only entries emitted."""
        J = self.field_jacobian
        return tuple((a, b) for a in range(self.n) for b in range(self.n) if J[a, b] != 0)

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
