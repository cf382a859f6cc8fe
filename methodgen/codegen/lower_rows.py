"""Loops over like rows: a compiled kernel's per-coordinate straight-line code as loops.

After :mod:`methodgen.codegen.lower_loops` has turned sums of like *terms* into loops, a kernel of a
large system is still linear in the number of coordinates: one load per state variable
(``p7 = _y[206]``), one unpacked accumulator entry per coordinate (``_sA7 = _sA[7]``), one
residual row, one row of the Newton matrix's assembly, … each a line.  numba compiles a
straight-line function in time that grows faster than its length (a Toda ring of 200: about
1 000 lines per kernel, 28 s for the Newton kernel alone).  Most of those lines are *alike*:
row r of the residual of a chain is ``_z[r] - _h*(_y[N + r] + (-_c0*_sA[r] + _c[N + r]))``
for every r — the same code with every array index at the same offset from r.

This module finds such rows and builds them as loops of the kernel IR (:mod:`methodgen.codegen.kir`),
working on the kernels' trees (:func:`row_body_ir`, used by :mod:`methodgen.codegen.compiled_kernels`):

1. the kernel's CSE temporaries that read per-coordinate names are inlined into the rows that
   use them when short (at most :data:`INLINE_MAX` characters of printed code): the temporary's
   tree becomes a subtree, so every operation is the same as in the straight-line code and the
   result is the same bitwise (a short temporary used by two rows is evaluated twice);
2. each output entry becomes a *template*: its per-coordinate names (state, unknown,
   compensation and carried-force variables, unpacked accumulator entries) replaced by the
   array element they are, indexed ``_i + offset`` with ``offset`` = element index − row;
3. runs of at least :data:`MIN_ROWS` consecutive entries with the same template become one
   loop ``for _i in range(a, b)``; the rows of the Newton matrix ``I + diag(s) _sB`` likewise
   from the templates of their scales ``s``;
4. the accumulators live in the output arrays (no allocation per call), so a loop must not
   read an accumulator entry that an earlier write has overwritten: a loop reading positions
   behind its own writes stays straight-line, and the loops run in an order where every loop
   reads before the loops that overwrite what it reads (a cycle: straight-line); entries left
   straight-line are written after all loops, from the names unpacked before any write.

Everything not in a loop is as before, and only what it reads is loaded and unpacked.  The
arithmetic of every entry is unchanged, so the loops give the straight-line kernel's results
bit for bit (``tests/codegen/test_row_loops.py``).  Systems with fewer than
:data:`MIN_KERNEL_ROWS` state components are left straight-line (their modules are unchanged).
"""

from __future__ import annotations

from .kir import Unsupported, tree_of

__all__ = ["row_body_ir", "MIN_ROWS", "MIN_KERNEL_ROWS", "INLINE_MAX", "MIN_TERMS"]

#: Shortest run of like rows printed as a loop.
MIN_ROWS = 6
#: Systems with fewer state components than this keep their kernels' straight-line bodies
#: (the outer solar system's 36: its rows differ body by body, and its compile time did not
#: drop with the loops that applied).
MIN_KERNEL_ROWS = 48
#: Longest temporary (characters, after its own inlining) inlined into the rows that use it.
INLINE_MAX = 120


def _aliases(kern, ir, outs) -> dict:
    """Accumulator name -> (output array, offset) for the 1-D accumulators that live in a
    piece of the first output (as the kernel macro places them), and the 2-D one in the
    second output."""
    out = {}
    if not outs:
        return out
    first_len = ir.n_unknowns if len(outs) == 2 else kern.shape[0]
    off = len(kern.pre_out)
    for a in kern.accs:
        if len(a.shape) == 2 and len(outs) == 2:
            out[a.name] = (outs[1], None)
        elif len(a.shape) == 1 and off + a.shape[0] <= first_len:
            out[a.name] = (outs[0], off)
            off += a.shape[0]
    return out


def _names(kern, ir, args) -> dict:
    """Per-coordinate name -> (array, index)."""
    m = {}
    for arr, names in (("_y", ir.state_vars), ("_z", ir.unknown_vars), ("_c", ir.comp_vars),
                       ("_g", ir.fsal_vars)):
        if arr in args:
            for i, v in enumerate(names):
                m[v] = (arr, i)
    for a in kern.accs:
        if len(a.shape) == 1:
            for var, ix in a.unpack:
                m[var] = (a.name, ix[0])
    return m


#: Shortest sum printed as an ordered loop (:func:`_reduction_ir`).
MIN_TERMS = 16


def _order(blocks):
    """``blocks`` [(a, b, template, positions read)] in an order where each runs before every
    block that writes a position it reads; blocks on a cycle are left out (straight-line)."""
    order, left = [], list(blocks)
    while left:
        # B may run now when no other remaining block reads a position B writes
        free = [B for B in left if not any(set(range(B[0], B[1])) & C[3] for C in left if C is not B)]
        if not free:
            break
        for B in free:
            order.append(B)
            left.remove(B)
    return order


def _subst(tree, repl):
    """``tree`` with each variable node ``("v", t)`` replaced by ``repl(t)`` (None: kept)."""
    op = tree[0]
    if op == "v":
        got = repl(tree[1])
        return tree if got is None else got
    if op == "n":
        return tree
    if op == "call":
        return ("call", tree[1], tuple(_subst(a, repl) for a in tree[2]))
    if op == "[]":
        return ("[]", tree[1], tuple(_subst(a, repl) for a in tree[2]))
    return (op,) + tuple(_subst(a, repl) for a in tree[1:])


def _vars(tree) -> set:
    from .kir import read_names
    return read_names(tree)


def _at(arr, var, off):
    i = ("v", var)
    return ("[]", arr, (i if off == 0 else ("+", i, ("n", off)) if off > 0 else ("-", i, ("n", -off)),))


def _key(tree) -> str:
    # tuples of numbers compare 0 == 0.0: templates are equal only with the same constants' types
    return repr(tree)


def _terms(tree):
    """``[(sign, term)]`` of the left spine of ``+``/``-`` (the printed order of a sum: the chain
    evaluates ((a + b) - c) …), or None for fewer than two terms."""
    out = []
    while tree[0] in ("+", "-"):
        out.append((tree[0], tree[2]))
        tree = tree[1]
    if not out:
        return None
    out.append(("+", tree))
    out.reverse()
    return out


def _reduction_ir(tree, names: dict, rowtemp: set, target: str):
    """Statements computing ``target`` = the sum ``tree`` term by term in its order, as one loop
    over a constant tuple of (term index, template) codes, or None.

    ``a + b + c`` is evaluated ((a + b) + c); the loop starts from the first term and adds (or
    subtracts) each next one, so the result is the straight-line sum's, bitwise.  A term's
    template has its per-coordinate names as array elements indexed ``_k + offset``, ``_k`` the
    index of its first such name; terms with no such name are a template of their own.  Up to 8
    templates (a branch per term picks it, decided when the loop is unrolled)."""
    terms = _terms(tree)
    if terms is None or len(terms) < MIN_TERMS:
        return None
    tpls, keys, table = [], [], []
    for sign, term in terms:
        first = [None]
        bad = [False]

        def repl(t):
            if t in names:
                arr, idx = names[t]
                if first[0] is None:
                    first[0] = idx
                return _at(arr, "_k", idx - first[0])
            if t in rowtemp:
                bad[0] = True
            return None

        tpl = _subst(term, repl)
        if bad[0]:
            return None
        key = (sign, _key(tpl))
        if key not in keys:
            keys.append(key)
            tpls.append((sign, tpl))
        table.append((keys.index(key), first[0] or 0))
    if len(tpls) > 8:
        return None
    (g0, k0), rest = table[0], table[1:]
    sign0, t0 = tpls[g0]
    red = ("v", target)
    out = [("=", ("v", "_k"), ("n", k0)), ("=", red, ("neg", t0) if sign0 == "-" else t0)]
    branches = ()
    for j in reversed(range(len(tpls))):
        sign, tpl = tpls[j]
        step = (("=", red, (sign, red, tpl)),)
        branches = step if len(tpls) == 1 else (("if", ("==", ("&", ("v", "_e"), ("n", 7)), ("n", j)), step, branches),)
    out.append(("#", f"{len(rest) + 1} terms in their printed order (methodgen.codegen.lower_rows)"))
    out.append(("forin", "_e", tuple(k * 8 + g for g, k in rest),
                (("=", ("v", "_k"), (">>", ("v", "_e"), ("n", 3))),) + branches))
    return out


def row_body_ir(kern, ir, args, outs):
    """Row loops for ``kern`` (a scalar :class:`~methodgen.codegen.lower.Kernel`) with inputs
    ``args`` and outputs ``outs``: ``(needed, statements, loops, pre statements)`` of the kernel
    IR -- the inputs the code still reads (only these are loaded), the body after the term loops,
    the number of row loops, and the statements replacing the code ahead of the term loops --
    or None when nothing is looped (the kernel keeps its straight-line body) or an expression
    has no tree.  See the module docstring."""
    try:
        return _row_body_ir(kern, ir, args, outs)
    except Unsupported:
        return None


def _row_body_ir(kern, ir, args, outs):
    if not outs:
        return None
    flat = [tree_of(c) for c in kern.entries()]
    npre = len(kern.pre_out)
    pre_assign = {v: tree_of(c) for v, c in kern.pre}
    if npre and (len(outs) != 1 or any(v not in pre_assign for v in kern.pre_out)
                 or any(_key(flat[r]) != _key(("v", v)) for r, v in enumerate(kern.pre_out))):
        return None
    if len(outs) == 2:
        if not kern.jac_rows:
            return None
        n = ir.n_unknowns
        res, scales = flat[:n], flat[n:2 * n]
    else:
        n = len(flat)
        res, scales = flat, []
    if ir.n_state < MIN_KERNEL_ROWS:
        return None
    from .kir import python

    names = _names(kern, ir, args)
    aliases = _aliases(kern, ir, outs)
    pre_out = set(kern.pre_out)
    for r, v in enumerate(kern.pre_out):
        names[v] = (outs[0], r)
    pre_temps = [(v, pre_assign[v]) for v, _ in kern.pre if v not in pre_out]
    pre_rows = [pre_assign[v] for v in kern.pre_out]

    temps = pre_temps + [(v, tree_of(c)) for v, c in kern.temps]
    rowtemp, expanded = set(), {}

    def expand(tree):
        return _subst(tree, lambda t: expanded.get(t))

    for var, tree in temps:
        ids = _vars(tree)
        if ids & names.keys() or ids & rowtemp:
            rowtemp.add(var)
            exp = expand(tree)
            if len(python(exp)) <= INLINE_MAX:
                expanded[var] = exp

    def template(tree, r):
        reads = []
        ok = [True]

        def repl(t):
            if t in names:
                arr, idx = names[t]
                off = idx - r
                if arr in aliases:
                    reads.append((arr, off))
                return _at(arr, "_i", off)
            if t in rowtemp:
                ok[0] = False
            return None

        s = _subst(expand(tree), repl)
        return (s if ok[0] else None), reads

    def blocks(trees):
        tpl = [template(c, r) for r, c in enumerate(trees)]
        keys = [None if t is None else _key(t) for t, _ in tpl]
        out, a = [], 0
        while a < len(trees):
            b = a + 1
            while b < len(trees) and keys[b] is not None and keys[b] == keys[a]:
                b += 1
            if keys[a] is not None and b - a >= MIN_ROWS:
                out.append((a, b, tpl[a][0], tpl[a][1]))
            a = b
        return out

    pre_blocks = blocks(pre_rows) if npre else []
    if npre:
        res = [("n", 0.0)] * npre + list(res[npre:])
    res_blocks = [B for B in blocks(res) if B[0] >= npre]

    def read_positions(a, b, reads):
        pos = set()
        for acc, off in reads:
            _, base = aliases[acc]
            if base is None:
                continue
            pos.update(range(a + off + base, b + off + base))
        return pos

    def self_hazard(a, b, reads):
        for acc, off in reads:
            base = aliases[acc][1]
            if base is not None and off + base < 0 and (b - 1) + off + base >= a:
                return True
        return False

    safe = [(a, b, tpl, read_positions(a, b, reads)) for a, b, tpl, reads in res_blocks
            if not self_hazard(a, b, reads)]
    order = _order(safe)
    looped = set()
    for a, b, _, _ in order:
        looped.update(range(a, b))
    scale_blocks = [B for B in (blocks(scales) if scales else [])
                    if not any(aliases[acc][1] is not None for acc, _ in B[3])]
    sloop = set()
    for a, b, _, _ in scale_blocks:
        sloop.update(range(a, b))
    looped.update(range(npre))

    reductions = {}
    for r, c in enumerate(res):
        if r not in looped:
            red = _reduction_ir(expand(c), names, rowtemp, f"_red{r}")
            if red is not None:
                reductions[r] = red
    straight = [c for r, c in enumerate(res) if r not in looped and r not in reductions] + \
               [c for r, c in enumerate(scales) if r not in sloop]
    loop_trees = [tpl for _, _, tpl, _ in order] + [tpl for _, _, tpl, _ in scale_blocks] + \
                 [st for red in reductions.values() for st in red]
    pre_looped = set()
    for a, b, _, _ in pre_blocks:
        pre_looped.update(range(a, b))
    pre_straight = [c for r, c in enumerate(pre_rows) if r not in pre_looped]
    need = set()
    for c in straight + loop_trees + pre_straight + [tpl for _, _, tpl, _ in pre_blocks]:
        need |= _vars(c)
    temp_red = {}
    for var, tree in temps:
        if var in rowtemp and var not in expanded:
            red = _reduction_ir(expand(tree), names, rowtemp, var)
            if red is not None:
                temp_red[var] = red
    kept = []
    for var, tree in reversed(temps):
        if var in need:
            kept.append((var, tree))
            need |= _vars(tuple(temp_red[var])) if var in temp_red else _vars(tree)
    kept.reverse()
    if not (order or scale_blocks or pre_blocks or reductions or any(v in temp_red for v, _ in kept)):
        return None
    o0 = outs[0]
    pre_names = {v for v, _ in pre_temps}
    pre_st = [st for var, tree in kept if var in pre_names
              for st in (temp_red[var] if var in temp_red else [("=", ("v", var), tree)])]
    kept = [(v, c) for v, c in kept if v not in pre_names]

    def row_loop(a, b, inner):
        return [("#", f"{b - a} like rows (methodgen.codegen.lower_rows)"),
                ("for", "_i", ("n", a), ("n", b), tuple(inner))]

    for a, b, tpl, _ in pre_blocks:
        pre_st += row_loop(a, b, [("=", ("[]", o0, (("v", "_i"),)), tpl)])
    for r, v in enumerate(kern.pre_out):
        if r not in pre_looped:
            pre_st += [("=", ("v", v), pre_rows[r]), ("=", ("[]", o0, (("n", r),)), ("v", v))]
    st = []
    for r, v in enumerate(kern.pre_out):
        if r in pre_looped and v in need:
            st.append(("=", ("v", v), ("[]", o0, (("n", r),))))
    for a in kern.accs:
        for var, ix in a.unpack:
            if var in need:
                st.append(("=", ("v", var), ("[]", a.name, tuple(("n", i) for i in ix))))
    for var, tree in kept:
        st += temp_red[var] if var in temp_red else [("=", ("v", var), tree)]
    for r, red in reductions.items():
        st += red
    for a, b, tpl, _ in order:
        st += row_loop(a, b, [("=", ("[]", o0, (("v", "_i"),)), tpl)])
    for r, c in enumerate(res):
        if r in reductions:
            st.append(("=", ("[]", o0, (("n", r),)), ("v", f"_red{r}")))
        elif r not in looped:
            st.append(("=", ("[]", o0, (("n", r),)), c))
    if len(outs) == 2:
        o1 = outs[1]
        st.append(("#", f"Newton matrix I + diag(s) ∂A/∂Δq, A the accumulated discrete gradient (in place: _sB is {o1})"))

        def scale_row(i):
            return [("for", "_b", ("n", 0), ("n", n), (("=", ("[]", o1, (i, ("v", "_b"))),
                                                          ("*", ("v", "_js"), ("[]", "_sB", (i, ("v", "_b"))))),)),
                    ("+=", ("[]", o1, (i, i)), ("n", 1.0))]

        for a, b, tpl, _ in scale_blocks:
            st += row_loop(a, b, [("=", ("v", "_js"), tpl)] + scale_row(("v", "_i")))
        for r, c in enumerate(scales):
            if r not in sloop:
                st += [("=", ("v", "_js"), c)] + scale_row(("n", r))
    inputs = set(ir.state_vars) | set(ir.unknown_vars) | set(ir.comp_vars) | set(ir.fsal_vars) | \
        set(ir.param_vars)
    return frozenset(need & inputs), st, len(order) + len(scale_blocks) + len(pre_blocks), pre_st
