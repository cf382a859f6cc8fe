"""Lowering of sums of like terms to loops (:class:`~methodgen.symbolic.schemes.base.LoopPlan`).

A scheme whose potential is a sum over families of like terms
(:mod:`methodgen.problem.families`) states its step equations with the sums left as symbols
(``A = Σ_t ∇̄U_t``, ``F = Σ_t ∇U_t(q0)``).  Here each kernel that uses such a symbol gets,
ahead of its straight-line code, one loop per family: it loads the instance's slots from
the state (``_y``), the increments (``_z``), the compensations (``_c``) and the
parameters (``_p``) through the family's index table, evaluates the template's
contributions (common subexpressions eliminated once, for the template) and adds them
into accumulator arrays, which are then unpacked into the scalar names the
straight-line code reads.  The code size and the compile time then grow with the number
of *families*, not of terms; the straight-line part (the Newton matrix, ``n²`` entries)
is linear in the accumulators.

Accumulators (``d`` = degrees of freedom):

========  =========  ==============================================================
``_sA``   (d,)       ``Σ_t ∇̄U_t(q0, q0 + Δq)`` (the discrete gradient's q-part)
``_sB``   (d, d)     ``Σ_t ∂∇̄U_t/∂Δq`` (for the Newton matrix, by the chain rule)
``_sF``   (d,)       ``Σ_t ∇U_t(q0)`` (the predictor's force)
``_sK``   (d,)       ``Σ_t ∇U_t(q0 + Δq)`` (the force at the step's end, for the
                     local error estimate)
``_sU``   (1,)       ``Σ_t U_t(q0)`` (the potential: H and the energy-jump scale in
                     the check kernels; ``adds`` with no columns add to entry 0)
``_sG``   (d,)       ``Σ_t ∇U_t(q0 + Δq)`` at the compensated end point (Störmer–Verlet's
                     end force, :func:`force_plan`; Δq from the kernel's first outputs)
``_sV``   (1,)       ``Σ_t U_t(q0 + Δq)`` (H at the step's end, for the energy jump)
========  =========  ==============================================================
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import sympy as sp

from ..symbolic.compensate import compensate
from .kir_build import code as _code

__all__ = ["Loop", "Accumulator", "ACC_PREFIXES", "acc_symbol", "force_plan", "jacobian_row_scales", "jacobian_via_sums",
           "loop_prefix", "potential_via_sums", "sum_pattern", "table_names"]

#: Accumulator array → what it sums (documentation and the symbols' name prefixes).
ACC_PREFIXES = ("_sA", "_sB", "_sF", "_sK", "_sU", "_sG", "_sV")
_ACC_RE = re.compile(r"^(_sA|_sF|_sK|_sU|_sG|_sV)(\d+)$|^(_sB)(\d+)_(\d+)$")
#: Accumulators of one scalar (the potential), not of one entry per coordinate.
_SCALAR_ACCS = ("_sU", "_sV")


@dataclass(frozen=True)
class Loop:
    """One loop over the instances of one family, in one kernel.

    Attributes
    ----------
    table, ptable : str
        Names of the module's index tables (coordinates; parameters, '' if none).
    size : int
        Number of instances.
    loads : tuple of (str, str, int)
        ``(variable, source, column)``: the slot variable is ``source[table[k, column]]``
        (``ptable`` for source ``"p"``), source one of ``"y"``, ``"z"``, ``"c"``, ``"p"``, or
        ``"d"``: the kernel's first outputs (Δq), computed before the loops (``Kernel.pre``).
    temps : tuple of (str, str)
        The template's common subexpressions.
    adds : tuple of (str, tuple of int, str)
        ``(accumulator, columns, code)``: ``accumulator[table[k, columns]] += code``;
        ``accumulator[0] += code`` where columns is ``()`` (a scalar accumulator, ``_sU``).
    """

    table: str
    ptable: str
    size: int
    loads: tuple[tuple[str, str, int], ...]
    temps: tuple[tuple[str, str], ...]
    adds: tuple[tuple[str, tuple[int, ...], str], ...]


@dataclass(frozen=True)
class Accumulator:
    """An accumulator array, zeroed before the loops, and its entries the code reads."""

    name: str
    shape: tuple[int, ...]
    unpack: tuple[tuple[str, tuple[int, ...]], ...]


def acc_symbol(prefix: str, *index: int) -> sp.Symbol:
    return sp.Symbol(prefix + "_".join(str(i) for i in index), real=True)


def table_names(f: int) -> tuple[str, str]:
    """Module-level names of family ``f``'s index tables."""
    return f"_IDX{f}", f"_PIDX{f}"


def _used(exprs) -> dict[str, set]:
    used: dict[str, set] = {}
    for e in exprs:
        for s in sp.sympify(e).free_symbols:
            m = _ACC_RE.match(s.name)
            if m:
                if m.group(1):
                    used.setdefault(m.group(1), set()).add((int(m.group(2)),))
                else:
                    used.setdefault("_sB", set()).add((int(m.group(4)), int(m.group(5))))
    return used


def potential_via_sums(system, plan) -> tuple[sp.Expr, sp.Expr] | None:
    """``(T, U)`` of a separable H with U written as its terms free of q plus the symbol
    ``_sU0`` (``Σ_t U_t(q)`` over the plan's families, accumulated by the loops), or None
    where the families are not U's q-dependent terms exactly.

    The families' instances are checked to be U's q-dependent additive terms as written
    (structurally, as a multiset): then ``T + rest + Σ_t U_t`` is H term by term, and H and
    the field at one state cost the loops plus a few operations, not the expanded U.
    """
    from ..symbolic.derive import separable_split

    sep = separable_split(system)
    if sep is None:
        return None
    q = set(system.q)
    terms = sp.Add.make_args(sep.U)
    rest = [t for t in terms if not t.free_symbols & q]
    inst = sorted((sp.srepr(t) for lf in plan.families for t in lf.family.terms))
    if inst != sorted(sp.srepr(t) for t in terms if t.free_symbols & q):
        return None
    return sep.T, sp.Add(*rest) + acc_symbol("_sU", 0)


def force_plan(system):
    """A :class:`~methodgen.symbolic.schemes.base.LoopPlan` of U's families of like terms for an
    explicit method (Störmer–Verlet): only their gradients (``_sF``, ``_sG``) and values
    (``_sU``, ``_sV``) are accumulated, so the step equations are left empty.  None where U
    has no family of like terms or H is not separable."""
    from ..symbolic.derive import separable_split
    from ..problem.families import term_families
    from ..symbolic.schemes.base import LoopFamily, LoopPlan

    sep = separable_split(system)
    if sep is None or sep.U == 0:
        return None
    fams = term_families(sep.U, system.q, system.params)
    if not fams:
        return None
    out = []
    for fam in fams:
        v = tuple(sp.Symbol(f"_v{j}", real=True) for j in range(len(fam.slots)))
        grad = tuple(sp.diff(fam.template, u) for u in fam.slots)
        out.append(LoopFamily(fam, v, grad, grad))
    empty = sp.zeros(0, 1)
    return LoopPlan(tuple(out), (), (), empty, empty, empty)


def sum_pattern(plan) -> list[tuple[int, int]]:
    """``[(i, l)]`` where some family's term couples ``A_i`` to ``Δq_l`` (``∂A_i/∂Δq_l`` is
    not identically 0): the sparsity pattern of ``_sB``, sorted."""
    pattern = set()
    for lf in plan.families:
        fam = lf.family
        pairs = [(a, b) for a in range(len(fam.slots)) for b in range(len(fam.slots))
                 if lf.jacobian[a][b] != 0]
        for idx in fam.index:
            pattern.update((idx[a], idx[b]) for a, b in pairs)
    return sorted(pattern)


def jacobian_via_sums(residual: sp.Matrix, unknowns, plan) -> tuple[list[sp.Expr], list]:
    """``∂R/∂z`` of a residual written in the sums ``A`` (chain rule, row-major list), with
    ``∂A_i/∂z_l`` as the symbols ``_sB<i>_<l>`` where some family's term couples them,
    and that pattern ``[(i, l)]``."""
    z = list(unknowns)
    pattern = sum_pattern(plan)
    n = len(z)
    J = [[sp.diff(r, zl) for zl in z] for r in residual]
    for r in range(n):
        for i, A in enumerate(plan.A):
            dRA = sp.diff(residual[r], A)
            if dRA == 0:
                continue
            for (ii, l) in pattern:
                if ii == i:
                    J[r][l] += dRA * acc_symbol("_sB", i, l)
    return [e for row in J for e in row], pattern


def jacobian_row_scales(residual: sp.Matrix, unknowns, plan) -> list[sp.Expr] | None:
    """``s`` with ``∂R/∂z = I + diag(s) ∂A/∂z`` when the residual has that form (the
    momenta-eliminated discrete gradient ``z - h M⁻¹(p0 - (h/2) A)`` with a diagonal
    ``M⁻¹``: ``s = (h²/2) diag(M⁻¹)``), else None.  The module then assembles the Newton
    matrix from the accumulated ``_sB`` in a loop instead of ``n²`` lines of code."""
    z = list(unknowns)
    n = len(z)
    if len(plan.A) != n:
        return None
    scales = []
    zs, As = set(z), set(plan.A)
    for r in range(n):
        # only the symbols the row contains have a nonzero derivative: n² diff calls were
        # the lowering's largest cost for a chain of 200
        present = residual[r].free_symbols
        if z[r] not in present:
            return None
        for l in range(n):
            if z[l] in present and sp.diff(residual[r], z[l]) != (1 if r == l else 0):
                return None
        for i, A in enumerate(plan.A):
            if A not in present:
                continue
            dRA = sp.diff(residual[r], A)
            if (i != r and dRA != 0) or dRA.free_symbols & (zs | As):
                return None
        scales.append(sp.diff(residual[r], plan.A[r]))
    return scales


def loop_prefix(exprs, plan, printer, dim: int, compensated: bool,
                whole: tuple[str, ...] = (), vsource: str = "z") -> tuple[tuple, tuple]:
    """The loops and accumulators a kernel over ``exprs`` needs (empty if it uses no sum).

    Parameters
    ----------
    exprs : sequence of sympy.Expr
        Everything the kernel evaluates (accumulator symbols are found in them).
    plan : LoopPlan
    printer : sympy code printer of the kernel's flavour
    dim : int
        Degrees of freedom d.
    compensated : bool
        Evaluate ``A`` and ``B`` at the compensated state ``q0 + c`` (as the step's other
        equations are, :func:`methodgen.symbolic.compensate.compensate`).
    whole : tuple of str
        Accumulators the kernel reads as arrays (``_sB`` for a Newton matrix assembled by
        :func:`jacobian_row_scales`), accumulated even where no symbol of theirs is used.
    vsource : str
        Where the slots' increments ``v`` are loaded from: ``"z"`` (the unknowns) or ``"d"``
        (the kernel's first outputs, Δq computed ahead of the loops).
    """
    used = _used(exprs)
    for name in whole:
        used.setdefault(name, set())
    if not used:
        return (), ()
    accs = []
    for name in ACC_PREFIXES:
        if name in used:
            shape = (dim, dim) if name == "_sB" else (1,) if name in _SCALAR_ACCS else (dim,)
            entries = tuple((str(acc_symbol(name, *ix)), ix) for ix in sorted(used[name]))
            accs.append(Accumulator(name, shape, entries))
    loops = []
    for f, lf in enumerate(plan.families):
        fam = lf.family
        temps, reduced, contrib, loads = _template_code(f, lf, frozenset(used), compensated, vsource)
        table, ptable = table_names(f)
        loops.append(Loop(table, ptable if fam.pslots else "", fam.size, loads,
                          tuple((str(s), _code(printer, e)) for s, e in temps),
                          tuple((a, c, _code(printer, e)) for (a, c, _), e in zip(contrib, reduced))))
    return tuple(loops), tuple(accs)


#: (family number, accumulators, compensated) -> (family, its reduced template code): the
#: scalar and vector flavours of a kernel, and kernels that read the same sums, share it.
_TEMPLATE_CACHE: dict = {}


def _template_code(f: int, lf, used: frozenset, compensated: bool, vsource: str = "z"):
    """The template's contributions to the accumulators ``used`` (common subexpressions
    eliminated), memoised per family: ``(temps, reduced, contributions, loads)``."""
    key = (f, used, compensated, vsource)
    hit = _TEMPLATE_CACHE.get(key)
    if hit is not None and hit[0] is lf:
        return hit[1]
    out = _template_code_uncached(f, lf, used, compensated, vsource)
    if len(_TEMPLATE_CACHE) > 64:
        _TEMPLATE_CACHE.clear()
    _TEMPLATE_CACHE[key] = (lf, out)
    return out


def _template_code_uncached(f: int, lf, used: frozenset, compensated: bool, vsource: str = "z"):
    fam = lf.family
    k = len(fam.slots)
    end = {u: u + v for u, v in zip(fam.slots, lf.vslots)}
    contrib = []   # (accumulator, slot columns, expression)
    if "_sA" in used:
        contrib += [("_sA", (j,), lf.dg[j]) for j in range(k)]
    if "_sB" in used:
        contrib += [("_sB", (a, b), lf.jacobian[a][b]) for a in range(k) for b in range(k)]
    if "_sG" in used:
        contrib += [("_sG", (j,), lf.grad[j].xreplace(end)) for j in range(k)]
    if compensated:
        cslots = {u: sp.Symbol(f"_cu{j}", real=True) for j, u in enumerate(fam.slots)}
        contrib = [(a, c, e) for (a, c, _), e in zip(contrib, compensate([e for *_, e in contrib], cslots))]
    if "_sF" in used:
        contrib += [("_sF", (j,), lf.grad[j]) for j in range(k)]
    if "_sK" in used:
        contrib += [("_sK", (j,), lf.grad[j].xreplace(end)) for j in range(k)]
    if "_sU" in used:
        contrib += [("_sU", (), fam.template)]
    if "_sV" in used:
        contrib += [("_sV", (), fam.template.xreplace(end))]
    contrib = [(a, c, e) for a, c, e in contrib if e != 0]
    temps, reduced = sp.cse([e for *_, e in contrib], symbols=sp.numbered_symbols(f"_t{f}_"),
                            order="canonical")
    free = set()
    for e in list(reduced) + [e for _, e in temps]:
        free |= e.free_symbols
    loads = []
    for j, u in enumerate(fam.slots):
        for sym, src in ((u, "y"), (lf.vslots[j], vsource), (sp.Symbol(f"_cu{j}", real=True), "c")):
            if sym in free:
                loads.append((sym.name, src, j))
    loads += [(w.name, "p", j) for j, w in enumerate(fam.pslots) if w in free]
    return temps, reduced, contrib, tuple(loads)
