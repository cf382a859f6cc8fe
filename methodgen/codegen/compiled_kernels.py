"""A compiled module's kernels as kernel IR (:mod:`methodgen.codegen.kir`) functions.

The compiled runtime calls a module's kernels with fixed signatures
(:data:`methodgen.codegen.abi.KERNEL_TYPES`): inputs read from 1-D arrays (the state ``_y``, the
unknowns ``_z``, the compensation ``_c``, the carried force ``_g``, the parameters ``_p``) and
outputs written into arrays the caller owns.  This module builds such a kernel as a tree -- the
loads, the lowering's CSE'd assignments and the stores -- which the module prints twice: as
its Python function, and as a flat table (:func:`methodgen.codegen.kir.flatten`) that the
compiled route translates to machine code (:func:`methodgen.codegen.llvmkernels.kernel`), keyed
by the tree's digest.  The module's text is never read back.

Built here: every kernel of the lowering (:func:`kernel_function`: straight-line code, loops over
families of like terms, :mod:`methodgen.codegen.lower_loops`, and over like rows,
:mod:`methodgen.codegen.lower_rows`), an s-stage method's loops over its stages
(:func:`stage_kernel`) and the lock-step block kernel (:func:`block_kernel`).  A kernel with an
expression the IR has no node for cannot be compiled: :class:`~methodgen.errors.GenerationError`
names it and the expression (the numpy backend runs any module).
"""

from __future__ import annotations

from ..errors import GenerationError
from . import kir

__all__ = ["kernel_function", "stage_kernel", "block_kernel", "kernel_text", "STACK_MAX"]


def _load(var: str, array: str, i: int) -> tuple:
    return ("=", ("v", var), ("[]", array, (("n", i),)))


def _store(array: str, idx: tuple, code) -> tuple:
    return ("=", ("[]", array, tuple(("n", i) for i in idx)), kir.tree_of(code))


def kernel_function(name: str, kern, ir, args, outs, step_alias: str | None = None):
    """The kernel ``name`` as a kernel-IR function -- straight-line code, loops over like terms
    and over like rows, code ahead of the loops.

    Parameters
    ----------
    name : str
        The function's name in the module (``_nb_res`` …).
    kern : methodgen.codegen.lower.Kernel
        The scalar flavour of the kernel.
    ir : methodgen.codegen.lower.ModuleIR
    args, outs : sequence of str
        Input and output parameters, in the kernel type's order (no outputs: the kernel returns
        its single entry).
    step_alias : str, optional
        ``"_hd"``: the body's ``_h`` is this argument (a stage's step, in a post kernel).

    Returns
    -------
    tuple
        ``("def", name, params, body)``.

    Raises
    ------
    methodgen.errors.GenerationError
        An expression of the kernel has no kernel-IR tree (named in the message).
    """
    from .lower_rows import row_body_ir

    try:
        return _build(name, kern, ir, args, outs, step_alias, row_body_ir(kern, ir, args, outs))
    except kir.Unsupported as exc:
        raise _refused(name, exc) from None


def _refused(name: str, exc: Exception) -> GenerationError:
    return GenerationError(f"the compiled backend cannot print the kernel {name}: {exc} has no kernel-IR "
                           "node (methodgen.codegen.kir); use backend=\"numpy\", which runs any module")


def _build(name, kern, ir, args, outs, step_alias, rows=None):
    """The kernel's statements: the loads (every input of a straight-line kernel; of a looped one
    only what its code reads -- the loops load their slots themselves), the code ahead of the
    loops (Δq of a looped Störmer–Verlet step, written as the first outputs), the accumulators
    (in the caller's output arrays where they fit, else allocated), one loop per family of like
    terms through its index tables (:mod:`methodgen.codegen.lower_loops`), then the accumulated
    entries unpacked, the straight-line code and the outputs.  ``rows``: the loops over like rows
    (:func:`methodgen.codegen.lower_rows.row_body_ir`) that replace the code after the term loops
    (and ahead of them), loading only what the rest reads."""
    body = []
    if step_alias:
        body.append(("#", f"the stage's step h·γ_k ({step_alias}; _ha, _hd, _hb: h times KICK_A, DRIFT, KICK_B)"))
        body.append(("=", ("v", "_h"), ("v", step_alias)))
    sources = [("_y", ir.state_vars), ("_z", ir.unknown_vars), ("_c", ir.comp_vars), ("_g", ir.fsal_vars),
               ("_p", ir.param_vars)]
    needed = rows[0] if rows else None
    for array, names in sources:
        if array in args or array == "_y":
            # a looped kernel loads only what its straight-line code reads (the loops load their
            # slots themselves; the carried force is always loaded); with row loops, only what
            # the code left straight-line reads
            body += [_load(v, array, i) for i, v in enumerate(names)
                     if (v in needed if needed is not None else array == "_g" or not kern.loops or kern.reads(v))]
    if rows and kern.pre:
        body += rows[3]
    else:
        body += [("=", ("v", var), kir.tree_of(code)) for var, code in kern.pre]
        body += [("=", ("[]", outs[0], (("n", i),)), ("v", v)) for i, v in enumerate(kern.pre_out)]
    first_len = ir.n_unknowns if len(outs) == 2 else kern.shape[0]
    off = len(kern.pre_out)
    full = ("slice", None, None)
    for a in kern.accs:
        if len(a.shape) == 2 and len(outs) == 2:
            body += [("=", ("v", a.name), ("v", outs[1])), ("=", ("[]", a.name, (full, full)), ("n", 0.0))]
        elif len(a.shape) == 1 and outs and off + a.shape[0] <= first_len:
            view = ("[]", outs[0], (("slice", ("n", off), ("n", off + a.shape[0])),))
            body += [("=", ("v", a.name), view), ("=", ("[]", a.name, (full,)), ("n", 0.0))]
            off += a.shape[0]
        else:
            body.append(("=", ("v", a.name), ("zeros", tuple(a.shape))))
    consts = []
    tables = dict(ir.loop_tables)
    for L in kern.loops:
        k = ("v", "_k")
        inner = []
        for var, s, col in L.loads:
            if s == "p":
                src = ("[]", "_p", (("[]", L.ptable, (k, ("n", col))),))
            else:
                arr = outs[0] if s == "d" else "_" + s
                src = ("[]", arr, (("[]", L.table, (k, ("n", col))),))
            inner.append(("=", ("v", var), src))
        inner += [("=", ("v", var), kir.tree_of(code)) for var, code in L.temps]
        for acc, cols, code in L.adds:
            idx = tuple(("[]", L.table, (k, ("n", c))) for c in cols) or (("n", 0),)
            inner.append(("+=", ("[]", acc, idx), kir.tree_of(code)))
        body.append(("#", f"{L.size} instances of a like term (methodgen.codegen.lower_loops)"))
        body.append(_for("_k", ("n", L.size), inner))
        consts.append(kir.table_const(L.table, tables[L.table], "i"))
        if L.ptable:
            consts.append(kir.table_const(L.ptable, tables[L.ptable], "i"))
    if rows:
        return kir.function(name, tuple(args) + tuple(outs), body + list(rows[1]), consts)
    for a in kern.accs:
        body += [("=", ("v", var), ("[]", a.name, tuple(("n", i) for i in ix))) for var, ix in a.unpack]
    body += [("=", ("v", var), kir.tree_of(code)) for var, code in kern.temps]
    flat = kern.entries()
    if not outs:
        body.append(("return", kir.tree_of(flat[0])))
    elif len(outs) == 2 and kern.jac_rows:
        n = ir.n_unknowns
        body += [_store(outs[0], (i,), flat[i]) for i in range(n)]
        body.append(("#", f"Newton matrix I + diag(s) ∂A/∂Δq, A the accumulated discrete gradient (in place: _sB is {outs[1]})"))
        for i in range(n):
            body += [("=", ("v", "_js"), kir.tree_of(flat[n + i])),
                     _for("_b", ("n", n), [("=", ("[]", outs[1], (("n", i), ("v", "_b"))),
                                              ("*", ("v", "_js"), ("[]", "_sB", (("n", i), ("v", "_b")))))]),
                     ("+=", ("[]", outs[1], (("n", i), ("n", i))), ("n", 1.0))]
    elif len(outs) == 2:
        n = ir.n_unknowns
        body += [_store(outs[0], (i,), flat[i]) for i in range(n)]
        body += [_store(outs[1], (i, j), flat[n + i * n + j]) for i in range(n) for j in range(n)]
    else:
        body += [_store(outs[0], (k,), c) for k, c in enumerate(flat)]
    return kir.function(name, tuple(args) + tuple(outs), body, consts)


def kernel_text(fn, decorate: str | None) -> str:
    """A module's text of a kernel-IR function: the function, then its table (``_KIR<name>``) and
    the line that compiles it (``decorate``: the expression binding the name anew, with ``{fn}``
    and ``{table}`` in it, e.g. ``"_kernel(_KT['res'], {table})({fn})"``; None: no such line, the
    module compiles it later from the table)."""
    name = fn[1]
    table, _ = kir.flatten([fn])
    lines = kir.function_lines(fn)
    lines += ["", "",
              f"# {name} as data (methodgen.codegen.kir): the compiled route prints its machine code from this",
              f"# table, keyed by its digest; the function above is printed from the same tree",
              f"_KIR{name} = ("]
    lines += ["    " + line for line in kir.table_text(table, 96)]
    lines.append(")")
    if decorate:
        lines.append(f"{name} = {decorate.format(fn=name, table='_KIR' + name)}")
    return "\n".join(lines)


# --- helpers of the looped kernels -------------------------------------------------------------

def _v(name):
    return ("v", name)


def _n(value):
    return ("n", value)


def _el(array, *idx):
    return ("[]", array, tuple(idx))


def _add(a, b):
    return ("+", a, b)


def _mul(a, b):
    return ("*", a, b)


def _for(var, stop, body, start=("n", 0)):
    return ("for", var, start, stop, tuple(body))


#: the largest work array kept on a compiled kernel's stack (floats); larger ones are allocated
STACK_MAX = 32768


def _work(shape, on_stack: bool):
    total = 1
    for k in shape:
        total *= k
    return ("buffer", tuple(shape)) if on_stack and total <= STACK_MAX else ("empty", tuple(shape))


def stage_kernel(name: str, ir, kind: str, sig: bool = True):
    """An s-stage method's residual (``kind`` "res") or residual and Newton matrix ("resjac") as
    loops over the stages (:mod:`methodgen.symbolic.stages`), in the order of the numpy module's
    ``_s_res`` / ``_s_resjac``: the stage points u_k = y + Σ_i P_ki Z_i (y + Z_k without P), f and
    f' there (the ``_nb_field`` / ``_nb_fieldjac`` kernels, inlined), R_j = Z_j − h σ_j Σ_k Q_jk
    f(u_k) summed from both ends, and δ_ij I − h σ_j Σ_k Q_jk P_ki f'(u_k) on f''s nonzeros.  Its
    small work arrays live on the kernel's stack (``sig``: compiled for the runtime's kernel
    type) up to :data:`STACK_MAX` floats, else they are allocated per call.

    Returns
    -------
    tuple
        The kernel-IR function, with the stage tables among its constants.
    """
    st = ir.stage
    d, m, nnz, s = ir.n_state, st["m"], st["nnz"], st["s"]
    jac = kind == "resjac"
    DIM, NM, NS = _v("_DIM"), _v("_NM"), _v("_NS")
    body = [("=", _v("_F"), _work((m, d), sig))]
    if jac:
        body += [("=", _v("_G"), _work((m, nnz), sig)), ("=", _v("_fg"), _work((d + nnz,), sig))]
    body.append(("=", _v("_u"), _work((d,), sig)))
    zk = _el("_z", _add(_mul(_v("_k"), DIM), _v("_l")))
    if st["P"]:
        point = [("=", _v("_a"), _n(0.0)),
                 _for("_i", NS, [("+=", _v("_a"), _mul(_el("_SP", _v("_k"), _v("_i")),
                                                       _el("_z", _add(_mul(_v("_i"), DIM), _v("_l")))))]),
                 ("=", _el("_u", _v("_l")), _add(_el("_y", _v("_l")), _v("_a")))]
    else:
        point = [("=", _el("_u", _v("_l")), _add(_el("_y", _v("_l")), zk))]
    per_point = [_for("_l", DIM, point)]
    if jac:
        per_point += [("expr", ("call", "_nb_fieldjac", (_v("_u"), _v("_p"), _v("_fg")))),
                      _for("_l", DIM, [("=", _el("_F", _v("_k"), _v("_l")), _el("_fg", _v("_l")))]),
                      _for("_e", _v("_NNZ"), [("=", _el("_G", _v("_k"), _v("_e")),
                                                _el("_fg", _add(DIM, _v("_e"))))])]
    else:
        per_point.append(("expr", ("call", "_nb_field", (_v("_u"), _v("_p"), _el("_F", _v("_k"))))))
    body.append(_for("_k", NM, per_point))
    last = ("-", ("-", NM, _n(1)), _v("_k"))
    half = ("//", NM, _n(2))
    pair = _add(_mul(_el("_SQ", _v("_j"), _v("_k")), _el("_F", _v("_k"), _v("_l"))),
                _mul(_el("_SQ", _v("_j"), last), _el("_F", last, _v("_l"))))
    row = _add(_mul(_v("_j"), DIM), _v("_l"))
    body.append(_for("_j", NS, [
        ("=", _v("_hs"), _mul(_v("_h"), _el("_SG", _v("_j")))),
        _for("_l", DIM, [
            ("=", _v("_a"), _n(0.0)),
            _for("_k", half, [("+=", _v("_a"), pair)]),
            ("if", ("%", NM, _n(2)),
             (("+=", _v("_a"), _mul(_el("_SQ", _v("_j"), half), _el("_F", half, _v("_l")))),), ()),
            ("=", _el("_r", row), ("-", _el("_z", row), _mul(_v("_hs"), _v("_a")))),
        ]),
    ]))
    if jac:
        full = ("slice", None, None)
        entry = _el("_J", _add(_mul(_v("_j"), DIM), _el("_JFR", _v("_e"))),
                    _add(_mul(_v("_i"), DIM), _el("_JFC", _v("_e"))))
        hsg = _mul(_v("_h"), _el("_SG", _v("_j")))
        if st["P"]:
            inner = [_for("_k", NM, [
                ("=", _v("_w"), _mul(hsg, _mul(_el("_SQ", _v("_j"), _v("_k")), _el("_SP", _v("_k"), _v("_i"))))),
                _for("_e", _v("_NNZ"), [("-=", entry, _mul(_v("_w"), _el("_G", _v("_k"), _v("_e"))))])])]
        else:
            inner = [("=", _v("_w"), _mul(hsg, _el("_SQ", _v("_j"), _v("_i")))),
                     _for("_e", _v("_NNZ"), [("-=", entry, _mul(_v("_w"), _el("_G", _v("_i"), _v("_e"))))])]
        body += [("=", _el("_J", full, full), _n(0.0)),
                 _for("_j", NS, [_for("_i", NS, inner)]),
                 _for("_l", _v("_N"), [("+=", _el("_J", _v("_l"), _v("_l")), _n(1.0))])]
    consts = [("_DIM", d), ("_N", ir.n_unknowns), ("_NS", s), ("_NM", m), ("_NNZ", nnz),
              kir.table_const("_SQ", st["Q"]), kir.table_const("_SG", st["sigma"]),
              kir.table_const("_JFR", st["rows"], "i"), kir.table_const("_JFC", st["cols"], "i")]
    if st["P"]:
        consts.append(kir.table_const("_SP", st["P"]))
    params = ("_z", "_y", "_c", "_h", "_p", "_r") + (("_J",) if jac else ())
    used = kir.read_names(tuple(body))
    return kir.function(name, params, body, [c for c in consts if c[0] in used])


def block_kernel(name: str, kern, ir, lanes: int):
    """The step of an explicit stage for a block of lanes (:func:`methodgen.runtime.stepper.lockstep`):
    the one-lane ``post`` kernel's straight-line code, reading lane ``_l`` of the component-major
    block arrays ``_y``, ``_c``, ``_g`` (component i of lane l at ``i * _BLOCK_LANES + l``), then
    what the one-lane path does with its output: the update of y (compensated or not) and the
    carried force in place, the check values into ``_out`` (rows from DIM + NF on).  Returns how
    many updated components are not finite.  No branch in the lane loops and no reduction but
    that integer count, so LLVM vectorises them; the expressions are the one-lane kernel's and
    the runtime's update, operation for operation (the same results, bitwise).  None where the
    post kernel is not straight-line; :class:`~methodgen.errors.GenerationError` for an
    expression without a tree."""
    if kern.loops or kern.accs or kern.pre:
        return None
    try:
        return _block(name, kern, ir, lanes)
    except kir.Unsupported as exc:
        raise _refused(name, exc) from None


def _block(name, kern, ir, lanes):
    flat = kern.entries()
    d, nf = ir.n_state, len(ir.fsal_vars)
    L = _v("_BLOCK_LANES")

    def at(array, i):
        return _el(array, _add(_mul(_n(i), L), _v("_l")))

    lane = [("=", _v(v), at("_y", i)) for i, v in enumerate(ir.state_vars)]
    lane += [("=", _v(v), at("_c", i)) for i, v in enumerate(ir.comp_vars)]
    lane += [("=", _v(v), at("_g", i)) for i, v in enumerate(ir.fsal_vars)]
    lane += [("=", _v(var), kir.tree_of(code)) for var, code in kern.temps]
    lane += [("=", _v(f"_bd{i}"), kir.tree_of(c)) for i, c in enumerate(flat[:d])]
    lane += [("=", at("_g", i), kir.tree_of(c)) for i, c in enumerate(flat[d:d + nf])]
    lane += [("=", at("_out", d + nf + i), kir.tree_of(c)) for i, c in enumerate(flat[d + nf:])]
    bad = ("if", ("not", ("==", ("-", _v("_us"), _v("_us")), _n(0.0))), (("+=", _v("_ubad"), _n(1)),), ())
    comp, plain, merged = list(lane), list(lane), list(lane)
    # merged kicks (ModuleIR.merged_kicks; _comp 2): _c holds D, y stays; D_q takes the drift,
    # D_p the stage's kick (the stepper's sums, operation for operation)
    for i in range(nf if ir.merged_kicks else 0):
        merged += [("=", at("_c", i), _add(_v(ir.comp_vars[i]), _v(f"_bd{i}")))]
    for i in range(nf if ir.merged_kicks else 0):
        merged += [("=", at("_c", nf + i), ("-", _v(ir.comp_vars[nf + i]), _mul(_v("_ha"), _v(ir.fsal_vars[i]))))]
    for i, v in enumerate(ir.state_vars):
        comp += [("=", _v("_ua"), _add(_v(f"_bd{i}"), _v(ir.comp_vars[i]))),
                 ("=", _v("_us"), _add(_v(v), _v("_ua"))),
                 ("=", at("_c", i), ("-", _v("_ua"), ("-", _v("_us"), _v(v)))),
                 ("=", at("_y", i), _v("_us")),
                 ("#", "inf - inf and NaN are NaN"), bad]
        plain += [("=", _v("_us"), _add(_v(v), _v(f"_bd{i}"))),
                  ("=", at("_y", i), _v("_us")), bad]
    body = [("#", "the stage's step h·γ_k"), ("=", _v("_h"), _v("_hd"))]
    body += [("=", _v(v), _el("_p", _n(i))) for i, v in enumerate(ir.param_vars)]
    body += [("=", _v("_ubad"), _n(0)),
             ("if", ("==", _v("_comp"), _n(2)), (_for("_l", _v("_nl"), merged),),
              (("if", ("!=", _v("_comp"), _n(0)), (_for("_l", _v("_nl"), comp),), (_for("_l", _v("_nl"), plain),)),)),
             ("#", "(an integer count in the loops: a float sum would not vectorise)"),
             ("return", _mul(_n(1.0), _v("_ubad")))]
    params = ("_y", "_c", "_g", "_ha", "_hd", "_hb", "_p", "_out", "_nl", "_comp")
    return kir.function(name, params, body, [("_BLOCK_LANES", int(lanes))])
