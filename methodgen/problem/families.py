"""Sums of like terms: the additive terms of an expression grouped by template.

A pair potential ``Σ_{a<b} G m_a m_b / |q_a - q_b|``, a nearest-neighbour chain
``Σ_i V(q_{i+1} - q_i)`` or a sum over coordinates ``Σ_i q_i⁴`` is one *template* term
written in slot symbols, instantiated once per index set.  A scheme that derives the
template's discrete gradient once, and a module that loops over the index sets, cost
what one term costs to derive and to compile, not what the expanded sum costs
("model only what the scene requires").

The grouping is a renaming, so it is exact: each instance, the template with its slot
symbols replaced by the instance's coordinates and parameters, is checked to be the
original term *structurally* (SymPy ``==``, no simplification, no floating point) before
it is accepted, and a term whose renaming does not give it back forms a family of its
own.  So ``Σ_k template∘σ_k`` is the expression itself, term by term, and what is
proved of the template (a discrete-gradient identity, translation invariance) holds for
every instance: the renaming σ_k is a substitution of symbols, which commutes with every
algebraic identity.

References
----------
.. [1] R. A. LaBudde, D. Greenspan, J. Comput. Phys. 15 (1974) 134-167 (energy-momentum
   schemes for N-body problems built pair by pair).
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

__all__ = ["TermFamily", "term_families"]


@dataclass(frozen=True)
class TermFamily:
    """Additive terms that are one template under a renaming of symbols.

    Attributes
    ----------
    template : sympy.Expr
        The term in slot symbols.
    slots : tuple of sympy.Symbol, length k
        Coordinate slots ``_u0, _u1, …`` (each with the assumptions of the coordinates it
        stands for).
    pslots : tuple of sympy.Symbol, length m
        Parameter slots ``_w0, _w1, …``.
    index : tuple of tuple of int, shape (n_instances, k)
        For each instance, the position in ``q`` of the coordinate in each slot.
    pindex : tuple of tuple of int, shape (n_instances, m)
        For each instance, the position in ``params`` of the parameter in each slot.
    terms : tuple of sympy.Expr, length n_instances
        The original terms, in the order they appear in the expression.
    """

    template: sp.Expr
    slots: tuple[sp.Symbol, ...]
    pslots: tuple[sp.Symbol, ...]
    index: tuple[tuple[int, ...], ...]
    pindex: tuple[tuple[int, ...], ...]
    terms: tuple[sp.Expr, ...]

    @property
    def size(self) -> int:
        """Number of instances."""
        return len(self.index)

    def renaming(self, k: int, q, params) -> dict:
        """σ_k: slot symbol → the coordinate or parameter of instance k."""
        ren = {s: q[i] for s, i in zip(self.slots, self.index[k])}
        ren.update({w: params[i] for w, i in zip(self.pslots, self.pindex[k])})
        return ren

    def instance(self, expr: sp.Expr, k: int, q, params) -> sp.Expr:
        """``expr`` (written in this family's slots) for instance k."""
        return expr.xreplace(self.renaming(k, q, params))


def _slot(prefix: str, j: int, like: sp.Symbol) -> sp.Symbol:
    return sp.Symbol(f"{prefix}{j}", **like.assumptions0)


def _template(term: sp.Expr, qpos: dict, ppos: dict):
    qs = sorted((s for s in term.free_symbols if s in qpos), key=qpos.__getitem__)
    ps = sorted((s for s in term.free_symbols if s in ppos), key=ppos.__getitem__)
    slots = tuple(_slot("_u", j, s) for j, s in enumerate(qs))
    pslots = tuple(_slot("_w", j, s) for j, s in enumerate(ps))
    ren = dict(zip(qs, slots)) | dict(zip(ps, pslots))
    return (term.xreplace(ren), slots, pslots,
            tuple(qpos[s] for s in qs), tuple(ppos[s] for s in ps))


def term_families(expr: sp.Expr, q, params=()) -> tuple[TermFamily, ...]:
    """Group the additive terms of ``expr`` that depend on ``q`` into families.

    Parameters
    ----------
    expr : sympy.Expr or sequence of sympy.Expr
        The sum, or its additive terms as the caller grouped them (a term may itself be a sum:
        :func:`methodgen.symbolic.schemes.energy_momentum.decompose_families` groups the terms that
        together are a function of one quadratic form).
    q : sequence of sympy.Symbol
        The coordinates (slots are ordered by position in ``q``).
    params : sequence of sympy.Symbol
        Parameters that may differ between instances (masses, spring constants); they get
        slots too, ordered by position in ``params``.  Any other free symbol stays as it is.

    Returns
    -------
    tuple of TermFamily
        In order of first appearance of the family's first term in ``Add.make_args(expr)``.
        Terms free of ``q`` are left out (they have no gradient).
    """
    q, params = list(q), list(params)
    qpos = {s: i for i, s in enumerate(q)}
    ppos = {s: i for i, s in enumerate(params)}
    groups: dict = {}
    order = []
    for term in (expr if isinstance(expr, (list, tuple)) else sp.Add.make_args(expr)):
        if not (term.free_symbols & qpos.keys()):
            continue
        template, slots, pslots, idx, pidx = _template(term, qpos, ppos)
        back = dict(zip(slots, (q[i] for i in idx))) | dict(zip(pslots, (params[i] for i in pidx)))
        key = (template, slots, pslots)
        if template.xreplace(back) != term:   # not a pure renaming: a family of its own
            key = ("alone", term)
        if key not in groups:
            groups[key] = (template, slots, pslots, [], [], [])
            order.append(key)
        g = groups[key]
        g[3].append(idx)
        g[4].append(pidx)
        g[5].append(term)
    return tuple(TermFamily(groups[k][0], groups[k][1], groups[k][2], tuple(groups[k][3]),
                            tuple(groups[k][4]), tuple(groups[k][5])) for k in order)
