"""Loops over like rows: a compiled kernel's per-coordinate straight-line code as loops.

After :mod:`methodgen.codegen.lower_loops` has turned sums of like *terms* into loops, a kernel of a
large system is still linear in the number of coordinates: one load per state variable
(``p7 = _y[206]``), one unpacked accumulator entry per coordinate (``_sA7 = _sA[7]``), one
residual row, one row of the Newton matrix's assembly, … each a line.  numba compiles a
straight-line function in time that grows faster than its length (a Toda ring of 200: about
1 000 lines per kernel, 28 s for the Newton kernel alone).  Most of those lines are *alike*:
row r of the residual of a chain is ``_z[r] - _h*(_y[N + r] + (-_c0*_sA[r] + _c[N + r]))``
for every r — the same code with every array index at the same offset from r.

This module finds such rows and prints them as loops, for the numba backend's kernels
(:func:`row_body`, called by ``templates/numba_kernels.py.j2``):

1. the kernel's CSE temporaries that read per-coordinate names are inlined into the rows that
   use them when short (at most :data:`INLINE_MAX` characters, parenthesised, so every
   operation is the same as in the straight-line code and the result is the same bitwise;
   a short temporary used by two rows is evaluated twice);
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

Everything not in a loop is printed as before, and only what it reads is loaded and unpacked.
The arithmetic of every entry is unchanged, so the loops give the straight-line kernel's
results bit for bit (``tests/test_row_loops.py``).  Systems with fewer than
:data:`MIN_KERNEL_ROWS` state components are left straight-line (their modules are unchanged).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = ["row_body", "RowBody", "MIN_ROWS", "MIN_KERNEL_ROWS", "INLINE_MAX"]

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
#: Shortest run of like rows printed as a loop.
MIN_ROWS = 6
#: Systems with fewer state components than this keep their kernels' straight-line bodies
#: (the outer solar system's 36: its rows differ body by body, and its compile time did not
#: drop with the loops that applied).
MIN_KERNEL_ROWS = 48
#: Longest temporary (characters, after its own inlining) inlined into the rows that use it.
INLINE_MAX = 120


@dataclass(frozen=True)
class RowBody:
    """The part of a kernel's body after its loops over like terms.

    Attributes
    ----------
    needed : frozenset of str
        Input variables (state, unknowns, compensation, carried force, parameters) that the
        straight-line code still reads: only these are loaded.
    lines : tuple of str
        The body's lines after the term loops (unpacked accumulator entries, temporaries,
        row loops and straight-line writes), indented relative to the function body.
    loops : int
        Number of row loops printed (0: the caller keeps its own body).
    """

    needed: frozenset
    lines: tuple
    loops: int
    #: Lines replacing the straight-line code ahead of the term loops (Störmer–Verlet's Δq,
    #: the kernel's ``pre``) and its writes into the first output; empty without ``pre``.
    pre_lines: tuple = ()


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


def _sub(code: str, repl) -> str:
    """``code`` with each identifier token ``t`` replaced by ``repl(t)`` (None: kept)."""
    out, last = [], 0
    for mt in _IDENT.finditer(code):
        s, e = mt.span()
        # an identifier right after a digit or a dot is part of a number (1e-5) or an attribute
        if s and (code[s - 1].isdigit() or code[s - 1] == "."):
            continue
        r = repl(mt.group())
        if r is not None:
            out.append(code[last:s])
            out.append(r)
            last = e
    out.append(code[last:])
    return "".join(out)


def _idents(code: str) -> set:
    return {t for t in _IDENT.findall(code)}


#: Shortest sum printed as an ordered loop (:func:`_reduction`).
MIN_TERMS = 16


def _split_sum(code: str):
    """Top-level terms of ``code`` as [(sign, term)] ('+' or '-'), split at the binary ' + ' and
    ' - ' of parenthesis depth 0 (as SymPy prints an Add), or None if it is not such a sum."""
    out, depth, start, sign = [], 0, 0, "+"
    i = 0
    while i < len(code):
        ch = code[i]
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif depth == 0 and code.startswith((" + ", " - "), i):
            out.append((sign, code[start:i]))
            sign = code[i + 1]
            start = i + 3
            i += 3
            continue
        i += 1
    out.append((sign, code[start:]))
    return out if len(out) > 1 else None


def _reduction(code: str, names: dict, rowtemp: set):
    """Lines computing ``_red`` = the sum ``code`` term by term in its printed order, as one
    loop over a table of (term index, template) codes, or None.

    ``a + b + c`` is evaluated ((a + b) + c); the loop starts from the first term and adds
    (or subtracts) each next one, so the result is the straight-line sum's, bitwise.  A term's
    template has its per-coordinate names as array elements indexed ``_k + offset``, ``_k``
    the index of its first such name; terms with no such name are a template of their own.
    Up to 8 templates (a branch per term picks it)."""
    terms = _split_sum(code)
    if terms is None or len(terms) < MIN_TERMS:
        return None
    tpls, table = [], []
    for sign, term in terms:
        first = [None]
        bad = [False]

        def repl(t):
            if t in names:
                arr, idx = names[t]
                if first[0] is None:
                    first[0] = idx
                off = idx - first[0]
                return f"{arr}[_k{'' if off == 0 else f' + {off}' if off > 0 else f' - {-off}'}]"
            if t in rowtemp:
                bad[0] = True
            return None

        tpl = _sub(term, repl)
        if bad[0]:
            return None
        key = (sign, tpl)
        if key not in tpls:
            tpls.append(key)
        table.append((tpls.index(key), first[0] or 0))
    if len(tpls) > 8:
        return None
    (g0, k0), rest = table[0], table[1:]
    sign0, t0 = tpls[g0]
    lines = [f"_k = {k0}", f"_red = {'-' if sign0 == '-' else ''}({t0})"]
    lines.append(f"for _e in ({', '.join(str(k * 8 + g) for g, k in rest)},):  "
                 f"# {len(rest) + 1} terms in their printed order (methodgen.codegen.lower_rows)")
    lines.append("    _k = _e >> 3")
    for j, (sign, tpl) in enumerate(tpls):
        kw = "if" if j == 0 else "elif"
        lines.append(f"    {kw} _e & 7 == {j}:" if len(tpls) > 1 else "    if True:")
        lines.append(f"        _red = _red {sign} ({tpl})")
    return lines


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


def row_body(kern, ir, args, outs) -> RowBody | None:
    """Row loops for ``kern`` (a scalar :class:`~methodgen.codegen.lower.Kernel`) printed with inputs
    ``args`` and outputs ``outs`` by the numba kernel macro, or None when nothing is looped
    (the macro then prints its straight-line body).  See the module docstring."""
    if not outs:
        return None
    flat = kern.entries()
    npre = len(kern.pre_out)
    pre_assign = dict(kern.pre)
    if npre and (len(outs) != 1 or any(v not in pre_assign for v in kern.pre_out)
                 or any(flat[r] != v for r, v in enumerate(kern.pre_out))):
        return None
    if len(outs) == 2:
        if not kern.jac_rows:
            return None
        n = ir.n_unknowns
        res, scales = flat[:n], flat[n:2 * n]
    else:
        n = len(flat)
        res, scales = flat, []
    if ir.n_state < MIN_KERNEL_ROWS:       # a small system: left as it is
        return None
    names = _names(kern, ir, args)
    aliases = _aliases(kern, ir, outs)
    pre_out = set(kern.pre_out)
    for r, v in enumerate(kern.pre_out):     # Δq: element r of the first output once written
        names[v] = (outs[0], r)
    pre_temps = [(v, c) for v, c in kern.pre if v not in pre_out]
    pre_rows = [pre_assign[v] for v in kern.pre_out]

    # 1. temporaries: which read per-coordinate names, and their inlined (expanded) code
    #    (the temporaries of Δq ahead of the term loops first: they precede all others)
    temps = pre_temps + list(kern.temps)
    rowtemp, expanded = set(), {}
    for var, code in temps:
        ids = _idents(code)
        if ids & names.keys() or ids & rowtemp:
            rowtemp.add(var)
            exp = _sub(code, lambda t: f"({expanded[t]})" if t in expanded else None)
            if len(exp) <= INLINE_MAX:
                expanded[var] = exp

    def expand(code):
        return _sub(code, lambda t: f"({expanded[t]})" if t in expanded else None)

    def template(code, r):
        """(template, [(alias array, offset, acc name, element offset)]) of entry ``code`` at row r."""
        reads = []
        ok = [True]

        def repl(t):
            if t in names:
                arr, idx = names[t]
                off = idx - r
                if arr in aliases:
                    reads.append((arr, off))
                return f"{arr}[_i{'' if off == 0 else f' + {off}' if off > 0 else f' - {-off}'}]"
            if t in rowtemp:          # a per-coordinate temporary too long to inline
                ok[0] = False
            return None

        s = _sub(expand(code), repl)
        return (s if ok[0] else None), reads

    def blocks(codes):
        """Runs [a, b) of equal templates, at least MIN_ROWS long: [(a, b, template, reads)]."""
        tpl = [template(c, r) for r, c in enumerate(codes)]
        out, a = [], 0
        while a < len(codes):
            b = a + 1
            while b < len(codes) and tpl[b][0] is not None and tpl[b][0] == tpl[a][0]:
                b += 1
            if tpl[a][0] is not None and b - a >= MIN_ROWS:
                out.append((a, b, tpl[a][0], tpl[a][1]))
            a = b
        return out

    # Δq ahead of the term loops (first outputs 0 … npre - 1, never written again: the
    # accumulators follow them): row loops of their own, then read as elements of the output
    pre_blocks = blocks(pre_rows) if npre else []
    if npre:
        res = ["0.0"] * npre + list(res[npre:])      # already written: not looped again below
    res_blocks = [B for B in blocks(res) if B[0] >= npre]
    # 4. hazards: positions of outs[0] each block reads through an aliased accumulator
    def read_positions(a, b, reads):
        pos = set()
        for acc, off in reads:
            _, base = aliases[acc]
            if base is None:
                continue
            pos.update(range(a + off + base, b + off + base))
        return pos

    def self_hazard(a, b, reads):
        """Row r reads position r + d of the first output (d = offset + the accumulator's place):
        written by an earlier row of the same loop when d < 0 and r + d >= a."""
        for acc, off in reads:
            base = aliases[acc][1]
            if base is not None and off + base < 0 and (b - 1) + off + base >= a:
                return True
        return False

    safe = []
    for a, b, tpl, reads in res_blocks:
        if self_hazard(a, b, reads):
            continue                  # it would read what it has already overwritten
        safe.append((a, b, tpl, read_positions(a, b, reads)))
    order = _order(safe)
    looped = set()
    for a, b, _, _ in order:
        looped.update(range(a, b))
    # the scales are read after the residual rows are written: none may read an accumulator
    # that lives in the first output (the straight-line rows read its unpacked names instead)
    scale_blocks = [B for B in (blocks(scales) if scales else [])
                    if not any(aliases[acc][1] is not None for acc, _ in B[3])]
    sloop = set()
    for a, b, _, _ in scale_blocks:
        sloop.update(range(a, b))
    looped.update(range(npre))                        # written ahead of the term loops

    # straight-line entries that are long sums of like terms: ordered loops (see _reduction)
    reductions = {}
    for r, c in enumerate(res):
        if r not in looped:
            red = _reduction(expand(c), names, rowtemp)
            if red is not None:
                reductions[r] = red
    # what the straight-line rest reads: temporaries (closure) and inputs
    straight = [c for r, c in enumerate(res) if r not in looped and r not in reductions] + \
               [c for r, c in enumerate(scales) if r not in sloop]
    loop_tpls = [tpl for _, _, tpl, _ in order] + [tpl for _, _, tpl, _ in scale_blocks] + \
                [line for red in reductions.values() for line in red]
    pre_looped = set()
    for a, b, _, _ in pre_blocks:
        pre_looped.update(range(a, b))
    pre_straight = [c for r, c in enumerate(pre_rows) if r not in pre_looped]
    need = set()
    for c in straight + loop_tpls + pre_straight + [tpl for _, _, tpl, _ in pre_blocks]:
        need |= _idents(c)
    # long temporaries that are sums of like terms (a kinetic energy at the end state, used by
    # two outputs): ordered loops too, computed where the temporary was
    temp_red = {}
    for var, code in temps:
        if var in rowtemp and var not in expanded:
            red = _reduction(expand(code), names, rowtemp)
            if red is not None:
                temp_red[var] = [line.replace("_red", var) for line in red]
    kept = []
    for var, code in reversed(temps):
        if var in need:
            kept.append((var, code))
            need |= _idents("\n".join(temp_red[var])) if var in temp_red else _idents(code)
    kept.reverse()
    if not (order or scale_blocks or pre_blocks or reductions or any(v in temp_red for v, _ in kept)):
        return None                   # nothing to loop: the straight-line body as it was
    # ahead of the term loops: the kept temporaries of Δq, its loops and straight rows
    pre_names = {v for v, _ in pre_temps}
    pre_lines = [line for var, code in kept if var in pre_names
                 for line in (temp_red[var] if var in temp_red else [f"{var} = {code}"])]
    kept = [(v, c) for v, c in kept if v not in pre_names]
    for a, b, tpl, _ in pre_blocks:
        pre_lines.append(f"for _i in range({a}, {b}):  # {b - a} like rows (methodgen.codegen.lower_rows)")
        pre_lines.append(f"    {outs[0]}[_i] = {tpl}")
    for r, v in enumerate(kern.pre_out):
        if r not in pre_looped:
            pre_lines.append(f"{v} = {pre_rows[r]}")
            pre_lines.append(f"{outs[0]}[{r}] = {v}")
    lines = []
    for r, v in enumerate(kern.pre_out):     # a looped Δq that straight-line code reads by name
        if r in pre_looped and v in need:
            lines.append(f"{v} = {outs[0]}[{r}]")
    for a in kern.accs:
        for var, ix in a.unpack:
            if var in need:
                lines.append(f"{var} = {a.name}[{', '.join(map(str, ix))}]")
    for var, code in kept:
        lines += temp_red[var] if var in temp_red else [f"{var} = {code}"]
    o0 = outs[0]
    # the sums first: they read the accumulators before any output is written
    for r, red in reductions.items():
        lines += [line.replace("_red", f"_red{r}") for line in red]
    for a, b, tpl, _ in order:
        lines.append(f"for _i in range({a}, {b}):  # {b - a} like rows (methodgen.codegen.lower_rows)")
        lines.append(f"    {o0}[_i] = {tpl}")
    for r, c in enumerate(res):
        if r in reductions:
            lines.append(f"{o0}[{r}] = _red{r}")
        elif r not in looped:
            lines.append(f"{o0}[{r}] = {c}")
    if len(outs) == 2:
        o1 = outs[1]
        lines.append("# Newton matrix I + diag(s) ∂A/∂Δq, A the accumulated discrete gradient (in place:")
        lines.append(f"# _sB is {o1})")
        for a, b, tpl, _ in scale_blocks:
            lines.append(f"for _i in range({a}, {b}):  # {b - a} like rows (methodgen.codegen.lower_rows)")
            lines.append(f"    _js = {tpl}")
            lines.append(f"    for _b in range({n}):")
            lines.append(f"        {o1}[_i, _b] = _js * _sB[_i, _b]")
            lines.append(f"    {o1}[_i, _i] += 1.0")
        for r, c in enumerate(scales):
            if r not in sloop:
                lines.append(f"_js = {c}")
                lines.append(f"for _b in range({n}):")
                lines.append(f"    {o1}[{r}, _b] = _js * _sB[{r}, _b]")
                lines.append(f"{o1}[{r}, {r}] += 1.0")
    inputs = set(ir.state_vars) | set(ir.unknown_vars) | set(ir.comp_vars) | set(ir.fsal_vars) | \
        set(ir.param_vars)
    return RowBody(frozenset(need & inputs), tuple(lines), len(order) + len(scale_blocks) + len(pre_blocks),
                   tuple(pre_lines))
