"""A numba module's kernels as kernel IR (:mod:`methodgen.codegen.kir`) functions.

The compiled runtime calls a module's kernels with fixed signatures
(:data:`methodgen.codegen.abi.KERNEL_TYPES`): inputs read from 1-D arrays (the state ``_y``, the
unknowns ``_z``, the compensation ``_c``, the carried force ``_g``, the parameters ``_p``) and
outputs written into arrays the caller owns.  This module builds such a kernel as a tree -- the
loads, the lowering's CSE'd assignments and the stores -- which the module prints twice: as
its Python function, and as a flat table (:func:`methodgen.codegen.kir.flatten`) that the
compiled route translates to machine code (:func:`methodgen.codegen.llvmkernels.kernel`), keyed
by the tree's digest.  The module's text is never read back.

Kernels with loops over like terms or rows (:mod:`methodgen.codegen.lower_loops`,
:mod:`methodgen.codegen.lower_rows`) are not built here yet: :func:`straight_kernel` returns None
and the template prints them as before.
"""

from __future__ import annotations

from . import kir

__all__ = ["straight_kernel", "kernel_text"]


def _load(var: str, array: str, i: int) -> tuple:
    return ("=", ("v", var), ("[]", array, (("n", i),)))


def _store(array: str, idx: tuple, code) -> tuple:
    return ("=", ("[]", array, tuple(("n", i) for i in idx)), _tree(code))


def _tree(code):
    tree = getattr(code, "tree", None)
    if tree is not None:
        return tree
    if code == "0.0":           # an entry without output (Kernel.entries)
        return ("n", 0.0)
    raise kir.Unsupported(f"code without a tree: {code[:40]!r}")


def straight_kernel(name: str, kern, ir, args, outs, step_alias: str | None = None):
    """The kernel ``name`` as a kernel-IR function, or None where it is not straight-line code
    (loops over like terms or rows, code ahead of loops) or has an expression without a tree.

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
    tuple or None
        ``("def", name, params, body)``.
    """
    from .lower_rows import row_body

    if kern.loops or kern.accs or kern.pre or kern.jac_rows or row_body(kern, ir, args, outs) is not None:
        return None
    try:
        return _build(name, kern, ir, args, outs, step_alias)
    except kir.Unsupported:
        return None


def _build(name, kern, ir, args, outs, step_alias):
    body = []
    if step_alias:
        body.append(("#", f"the stage's step h·γ_k ({step_alias}; _ha, _hd, _hb: h times KICK_A, DRIFT, KICK_B)"))
        body.append(("=", ("v", "_h"), ("v", step_alias)))
    sources = [("_y", ir.state_vars), ("_z", ir.unknown_vars), ("_c", ir.comp_vars), ("_g", ir.fsal_vars),
               ("_p", ir.param_vars)]
    for array, names in sources:
        if array in args or array == "_y":
            body += [_load(v, array, i) for i, v in enumerate(names)]
    body += [("=", ("v", var), _tree(code)) for var, code in kern.temps]
    flat = kern.entries()
    if not outs:
        body.append(("return", _tree(flat[0])))
    elif len(outs) == 2:
        n = ir.n_unknowns
        body += [_store(outs[0], (i,), flat[i]) for i in range(n)]
        body += [_store(outs[1], (i, j), flat[n + i * n + j]) for i in range(n) for j in range(n)]
    else:
        body += [_store(outs[0], (k,), c) for k, c in enumerate(flat)]
    return kir.function(name, tuple(args) + tuple(outs), body)


def kernel_text(fn, decorate: str) -> str:
    """A module's text of a kernel-IR function: the function, then its table and the line that
    compiles it (``decorate``: the expression binding the name anew, with ``{fn}`` and ``{table}``
    in it, e.g. ``"_kernel(_KT['res'], {table})({fn})"``)."""
    name = fn[1]
    table, _ = kir.flatten([fn])
    lines = kir.function_lines(fn)
    lines += ["", "",
              f"# {name} as data (methodgen.codegen.kir): the compiled route prints its machine code from this",
              f"# table, keyed by its digest; the function above is printed from the same tree",
              f"_KIR{name} = ("]
    lines += ["    " + line for line in kir.table_text(table, 96)]
    lines += [")", f"{name} = {decorate.format(fn=name, table='_KIR' + name)}"]
    return "\n".join(lines)
