"""A lattice method as one numpy module for every size N: printing, writing, loading.

:func:`render` prints a :class:`methodgen.symbolic.lattice_scheme.LatticeScheme` through
``templates/lattice_module.py.j2``: per site term, its energy and its discrete-gradient pieces
(with their derivatives) as vectorised numpy over the term's sites, CSE'd; the index tables of a
size are built by the module at run time.  Nothing in the text depends on N, so the module is
derived, printed and imported once, in the time one template costs.  :func:`build_lattice` is
the cached entry point (the module cache and its trust checks of :mod:`methodgen.codegen.store` and
:mod:`methodgen.codegen.emit`).

A skew lattice (one field u, ``u' = S ∇H``) gets the same kernels over its one field (a state
row of N sites).  Both structures' Newton matrices are banded with half-bandwidth w sites
(:attr:`methodgen.problem.lattice.Lattice.half_width`) and solved over groups of w sites, the
numpy module by block cyclic reduction, the compiled one by bordered block elimination
(:mod:`methodgen.runtime.lattice_stepper`).
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

import sympy as sp

from .._version import __version__
from .emit import (HEADER_CONTENT, HEADER_SIGNATURE, _docsafe, _environment, generator_hash, template_dir,
                   template_hash, write_and_load)
from ..errors import GenerationError, InputError
from ..problem.lattice import Lattice
from ..symbolic.lattice_scheme import LATTICE_METHODS, LatticeScheme, discretize_lattice
from .lower import _HELPER_CALL, ScalarPrinter, VectorPrinter, _helper_closure
from . import kir
from .kir_build import code as _code
from .progress import phase
from ..problem.special import SPECIAL_FUNCTIONS
from .store import cache_dir

__all__ = ["render", "render2d", "lattice_signature", "build_lattice"]

TEMPLATE = "lattice_module.py.j2"
#: the template of a 2-D periodic lattice's module (the FFT-preconditioned simplified Newton)
TEMPLATE_2D = "lattice_2d_module.py.j2"
#: the errors of a lattice module's step, included by both templates
ERRORS_TEMPLATE = "lattice_errors.py.j2"
#: the info["carried"] record of a family module (continuing a run), included by the templates
CARRY_TEMPLATE = "lattice_carry.py.j2"


def _sources_hash() -> str:
    """SHA-256 of the lattice path's own sources (kept out of :func:`methodgen.codegen.emit.generator_hash`
    and ``template_hash``, so that a change here does not make every other module stale)."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in (root / "problem" / "lattice.py", root / "symbolic" / "lattice_scheme.py",
                 root / "codegen" / "lattice_emit.py", root / "runtime" / "lattice_stepper.py",
                 root / "runtime" / "lattice_driver.py",
                 template_dir() / TEMPLATE, template_dir() / TEMPLATE_2D, template_dir() / ERRORS_TEMPLATE, template_dir() / CARRY_TEMPLATE):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def lattice_signature(lattice: Lattice, method: str, backend: str = "numpy", order: int = 2,
                      composition: str | None = None) -> str:
    """Hash of everything the module depends on: the text, names, defaults and method, the
    versions, the printers and helpers it shares with other modules, and its own sources; above
    order 2 the order and the composition family (``composition`` resolved: the default family
    and its name give one module), so that modules of different orders never share a file."""
    from ..symbolic.compositions import stage_composition
    from ..symbolic.lattice_scheme import LATTICE_ORDERS

    comp = stage_composition(order, composition, offered=LATTICE_ORDERS, what=f"{method} for a lattice")
    sizes = ",".join(s.name for s in getattr(lattice, "sizes", (lattice.size,)))
    parts = [lattice.text, repr(sorted(lattice.invariant_texts.items())), lattice.q_name, str(lattice.p_name),
             lattice.structure, str(lattice.skew_text), sizes, lattice.name,
             repr(sorted(lattice.params.items())), method, __version__, sp.__version__,
             template_hash("numpy"), generator_hash(), _sources_hash()] + ([] if backend == "numpy" else [backend])
    if comp.order != 2:
        # (order 2 adds nothing: its signature is the one it had before compositions)
        parts.append(f"order {comp.order}, composition {comp.family}: {comp.floats()!r}")
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


@dataclass(frozen=True)
class Differenced:
    """A term's pieces and their derivatives written in the differences of its slots.

    A coupling of neighbours such as ``(q[i+1] - q[i])**2`` gives pieces whose printed form
    subtracts values of the size of the field to get a result of the size of their difference:
    the derivation's expanded ``(N²q_0 − N²q_p1)/L² + …`` loses about log₂(|q| / |Δq|) bits
    per piece, and the loss has a sign, so the energy of a fine grid drifts linearly (sine-Gordon
    AVF, N = 4096, h = 0.01: 1.1e-14 relative over 10⁴ steps).  Here every slot of a field other
    than its reference slot (offset 0, else the first) is replaced by ``ref + d``, with ``d``
    bound in the kernel as the slot minus the reference (one subtraction of neighbouring values:
    exact where they are within a factor 2, Sterbenz); polynomial pieces are expanded so that
    what cancels cancels exactly in the algebra.  The expressions equal the derivation's exactly
    (``tests/codegen/test_lattice_differences.py`` checks it by substituting back).

    Attributes
    ----------
    pieces : tuple of sympy.Expr
        ``A_s`` per slot, as ``TermPieces.pieces``.
    jac : tuple of tuple of sympy.Expr
        ``∂A_a/∂z1_b``, as ``TermPieces.jac``.
    binds : tuple of (sympy.Symbol, sympy.Symbol, sympy.Symbol)
        ``(d, slot, reference)``: the kernel binds ``d = slot - reference`` after gathering the
        slots (start values first, then end values).
    """

    pieces: tuple
    jac: tuple
    binds: tuple


def differenced(tp) -> Differenced:
    """:class:`Differenced` of a term's pieces ``tp`` (a ``TermPieces``)."""
    slots = tp.term.slots
    sub, binds = {}, []
    for zs in (tp.z0, tp.z1):
        ref = {}
        for s, (f, o) in sorted(zip(zs, slots), key=lambda so: _reference_first(so[1][1])):
            ref.setdefault(f, s)
        for s, (f, o) in zip(zs, slots):
            if s is not ref[f]:
                d = sp.Symbol("_d" + s.name, real=True)
                sub[s] = ref[f] + d
                binds.append((d, s, ref[f]))
    if not sub:
        return Differenced(tuple(tp.pieces), tuple(tuple(r) for r in tp.jac), ())
    variables = tuple(tp.z0) + tuple(tp.z1) + tuple(d for d, _, _ in binds)

    def rewrite(e):
        e = e.xreplace(sub)
        return sp.factor_terms(sp.expand(e)) if e.is_polynomial(*variables) else e

    return Differenced(tuple(rewrite(e) for e in tp.pieces), tuple(tuple(rewrite(e) for e in row) for row in tp.jac),
                       tuple(binds))


def _reference_first(o):
    """Sort key of a slot's offset ``o`` (1-D: an int, 2-D: a pair): the site's own slot first,
    then the others in order."""
    return (o != (0 if isinstance(o, int) else (0, 0)), o)


def _difference_lines(binds) -> list[str]:
    return [f"{d.name} = {s.name} - {r.name}" for d, s, r in binds]


def _difference_ir(binds) -> list:
    return [("=", _v(d.name), ("-", _v(s.name), _v(r.name))) for d, s, r in binds]


def _cse_lines(exprs, printer, prefix: str) -> tuple[list[str], list[str]]:
    """CSE ``exprs``: (assignment lines, the printed outputs)."""
    syms = sp.numbered_symbols(prefix)
    temps, outs = sp.cse(list(exprs), symbols=syms, optimizations="basic")
    lines = [f"{printer.doprint(s)} = {printer.doprint(e)}" for s, e in temps]
    return lines, [printer.doprint(e) for e in outs]


def _full(t) -> bool:
    """The term is summed over every site (1 … N): its site tables are rotations, so gathers and
    scatters are numpy.roll (a copy) instead of fancy indexing (a gather, a scattered add)."""
    return (t.lo.from_end, t.lo.c, t.hi.from_end, t.hi.c) == (False, 1, True, 0)


def _gathers(symbols, names, source: str, fields, full: bool = False) -> list[str]:
    out = []
    for s, (f, o) in zip(symbols, names):
        if full:
            row = f"{source}[{fields.index(f)}]"
            out.append(f"{s.name} = {row}" if o == 0 else f"{s.name} = numpy.roll({row}, {-o})")
        else:
            out.append(f"{s.name} = {source}[{fields.index(f)}, ix[{o}]]")
    return out


def _bind(exprs, lattice: Lattice, size: str = "float(n)") -> list[str]:
    """Lines binding the parameters and the size the expressions use (``size``: the size's value
    as text in the kernel's ``n``)."""
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    lines = [f"{s.name} = p[{k}]" for k, s in enumerate(lattice.param_symbols) if s in used]
    if lattice.size in used:
        lines.append(f"{lattice.size.name} = {size}")
    return lines


def _tuple(items) -> str:
    return "(" + ", ".join(items) + ("," if len(items) == 1 else "") + ")"


def _bound_text(b) -> str:
    """A range bound as 0-based Python text in ``n``."""
    return f"n + {b.c - 1}" if b.from_end else str(b.c - 1)


def _cse_trees(exprs, printer, prefix: str) -> tuple[list, list]:
    """CSE ``exprs``: (assignment statements, the outputs' trees) of the kernel IR."""
    temps, outs = sp.cse(list(exprs), symbols=sp.numbered_symbols(prefix), optimizations="basic")
    return ([("=", ("v", s.name), _tree(printer, e)) for s, e in temps], [_tree(printer, e) for e in outs])


def _tree(printer, e):
    got = _code(printer, e)
    tree = getattr(got, "tree", None)
    if tree is None:
        raise GenerationError(f"the lattice kernel's expression {str(e)[:60]} has no kernel-IR node")
    return tree


def _v(name):
    return ("v", name)


def _num(c: int):
    return ("n", c) if c >= 0 else ("neg", ("n", -c))


def _plus(a, c: int):
    """``a + c`` for an integer c (``a`` itself for 0)."""
    return a if c == 0 else ("+", a, ("n", c)) if c > 0 else ("-", a, ("n", -c))


def _bind_ir(exprs, lattice: Lattice, size) -> list:
    """Statements binding the parameters and the size (``size``: its value, a tree in ``n``) the
    expressions use."""
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    out = [("=", _v(s.name), ("[]", "p", (("n", k),))) for k, s in enumerate(lattice.param_symbols) if s in used]
    if lattice.size in used:
        out.append(("=", _v(lattice.size.name), size))
    return out


#: the rows of the stepper's work array the kernel reads z from (``_IZ`` of
#: :mod:`methodgen.runtime.lattice_stepper`; ∇̄H goes to the rows from 0)
KERNEL_Z_ROW = 2


def _scalar_kernel(scheme: LatticeScheme) -> tuple:
    """``_grad_sites(Y0, W, D, n, p, jac)`` as a kernel-IR function (:mod:`methodgen.codegen.kir`):
    ∇̄H(y0, z) into W[0:nf] (z the rows W[KERNEL_Z_ROW:KERNEL_Z_ROW + nf]) and, with ``jac``, its
    derivative's site diagonals into D (row ``(e + wH) nf² + f nf + f'``: ∂∇̄H_(f, j)/∂z_(f', j + e) at
    column j, wH the lattice's :attr:`~methodgen.problem.lattice.Lattice.jacobian_half_width`), a loop
    over the sites of each term -- the scalar form of the module's vectorised kernels, for both
    structures (a skew lattice's one field is nf = 1).  The module prints it as Python and holds
    it as a table; :mod:`methodgen.runtime.lattice_stepper` inlines it, compiled from the tree.
    Sites are (i + o) % n with Python's floor modulo (the translator's too)."""
    lat = scheme.lattice
    printer = ScalarPrinter({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
    fields = lat.fields
    n = _v("n")
    allx = [e for tp in scheme.terms for e in list(tp.pieces) + [x for row in tp.jac for x in row]]
    body = _bind_ir(allx, lat, ("*", n, ("n", 1.0)))
    for tp in scheme.terms:
        t = tp.term
        if not t.slots:
            continue              # a constant: no gradient
        lo = _plus(n, t.lo.c - 1) if t.lo.from_end else ("n", t.lo.c - 1)
        stop = _plus(n, t.hi.c) if t.hi.from_end else ("n", t.hi.c)
        inner = []
        for o in sorted({o for _, o in t.slots}):
            # every site modulo n (floor modulo, as Python's: a range may start at 0 or end past N)
            inner.append(("=", _v(f"i{_otag(o)}"), ("%", _plus(_v("i"), o), n)))
        for s0, s1, (f, o) in zip(tp.z0, tp.z1, t.slots):
            site = _v(f"i{_otag(o)}")
            inner.append(("=", _v(s0.name), ("[]", "Y0", (("n", fields.index(f)), site))))
            inner.append(("=", _v(s1.name), ("[]", "W", (("n", KERNEL_Z_ROW + fields.index(f)), site))))
        dt = differenced(tp)
        inner += _difference_ir(dt.binds)
        kk = len(dt.pieces)
        flat_jac = [e for row in dt.jac for e in row]
        g_pre, g_out = _cse_trees(dt.pieces, printer, "_g")
        j_pre, j_out = _cse_trees(list(dt.pieces) + flat_jac, printer, "_j")

        def scatter(outs, t=t):
            return [("+=", ("[]", "W", (("n", fields.index(f)), _v(f"i{_otag(o)}"))), outs[a])
                    for a, (f, o) in enumerate(t.slots)]

        jac = j_pre + scatter(j_out[:kk])
        nf, wh = len(fields), lat.jacobian_half_width
        for a, (f, o) in enumerate(t.slots):
            for b, (g, o2) in enumerate(t.slots):
                row = (o2 - o + wh) * nf * nf + nf * fields.index(f) + fields.index(g)
                jac.append(("+=", ("[]", "D", (("n", row), _v(f"i{_otag(o)}"))), j_out[kk + a * kk + b]))
        inner.append(("if", ("!=", _v("jac"), ("n", 0)), tuple(jac), tuple(g_pre + scatter(g_out))))
        body.append(("#", _docsafe(t.source)))
        body.append(("for", "i", lo, stop, tuple(inner)))
    return kir.function("_grad_sites", ("Y0", "W", "D", "n", "p", "jac"), body)


def _kernel_text(fn, name: str = "_grad_sites", use: str = "the compiled step loop inlines this tree") -> list[str]:
    """The module's lines of the scalar kernel ``name``: its Python, its table, and the line
    attaching the table (the compiled code reads the tree, never this text)."""
    table, _ = kir.flatten([fn])
    return (kir.function_lines(fn)
            + ["", "", f"# {name} as data (methodgen.codegen.kir): {use}",
               f"_KIR{name} = ("] + ["    " + ln for ln in kir.table_text(table, 96)]
            + [")", f"{name} = _kir.attach({name}, _KIR{name})"])


def _otag(o: int) -> str:
    return "0" if o == 0 else (f"p{o}" if o > 0 else f"m{-o}")


def _front(env, code: str, scheme: LatticeScheme, backend: str, sig: str, template: str, kind: str, what: str):
    """``(special, defaults, description, header)`` of a lattice module: the source of the scalar
    helpers ``code`` calls, the parameters' defaults as text, the module docstring's description
    (``kind`` after the method's name) and the provenance header (``what``: the lattice's kind)."""
    lat = scheme.lattice
    known = {v[1:] for v in SPECIAL_FUNCTIONS.values()}
    helpers = _helper_closure({m for m in _HELPER_CALL.findall(code) if m in known})
    special = env.get_template("_special.py.j2").render(ir=type("HelperSet", (), {"helpers": helpers}))
    if helpers:
        special = "\n\n" + special.strip("\n") + "\n"
    defaults = "{" + ", ".join(f"{k!r}: {v!r}" for k, v in lat.params.items()) + "}"
    description = (f"{LATTICE_METHODS[scheme.method]}{kind}; "
                   + ("keeps H exactly up to round-off." if scheme.traits["energy_preserving"] else
                      "H is not kept exactly (bounded for a symplectic method)."))
    if scheme.order != 2:
        description += (f"\nComposed symmetrically to order {scheme.order} ({scheme.composition} composition, "
                        f"{len(scheme.gammas)} stages): each step is the order-2 step taken {len(scheme.gammas)} "
                        "times, of sizes GAMMAS[k] h (Σ GAMMAS = 1, negative ones included); each stage keeps "
                        "what the order-2 step keeps, so the step does (Yoshida 1990; Suzuki 1990; Hairer, "
                        "Lubich & Wanner, GNI II.4, V.3).")
    if scheme.notes:
        description += "\n" + "\n".join(scheme.notes)
    header = [f"Generated by methodgen {__version__} from templates/{template} -- do not edit.",
              f"system: {lat.name}; method: {scheme.method} ({what}); backend: {backend}",
              f"H = {_docsafe(lat.text)}",
              f"methodgen {__version__}; sympy {sp.__version__}; templates sha256 {template_hash('numpy')[:16]}",
              HEADER_SIGNATURE[2:] + sig]
    return special, defaults, description, header


def render(scheme: LatticeScheme, sig: str, backend: str = "numpy") -> str:
    """The module's source text (deterministic: the same scheme gives the same bytes).

    ``backend="compiled"`` adds the scalar kernel (:func:`_scalar_kernel`) and runs the steps on
    :mod:`methodgen.runtime.lattice_stepper` compiled through LLVM (the module then imports methodgen)."""
    lat = scheme.lattice
    printer = VectorPrinter({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
    fields = lat.fields
    def values(t, z0):
        pre, (value,) = _cse_lines([t.template], printer, "_e")
        return (_bind([t.template], lat) + _gathers(z0, t.slots, "Y", fields, _full(t)) + pre
                + [f"return numpy.broadcast_to({value}, ix[0].shape)"])

    def entry(t):
        return {"source": _docsafe(t.source), "lo": (t.lo.from_end, t.lo.c), "hi": (t.hi.from_end, t.hi.c),
                "offsets": sorted({o for _, o in t.slots} | {0})}

    terms = []
    for tp in scheme.terms:
        t = tp.term
        dt = differenced(tp)
        flat_jac = [e for row in dt.jac for e in row]
        g_pre, g_out = _cse_lines(dt.pieces, printer, "_g")
        j_pre, j_out = _cse_lines(list(dt.pieces) + flat_jac, printer, "_j")
        k = len(dt.pieces)
        jac_rows = [_tuple(j_out[k + a * k:k + (a + 1) * k]) for a in range(k)]
        piece_lines = (_bind(list(dt.pieces) + flat_jac, lat)
                       + _gathers(tp.z0, t.slots, "Y0", fields, _full(t))
                       + _gathers(tp.z1, t.slots, "Z", fields, _full(t))
                       + _difference_lines(dt.binds)
                       + ["if not jac:"] + ["    " + ln for ln in g_pre] + [f"    return {_tuple(g_out)}, None"]
                       + j_pre + [f"return {_tuple(j_out[:k])}, {_tuple(jac_rows)}"])
        terms.append({**entry(t), "index": len(terms), "full": _full(t),
                      "slots": [(fields.index(f), o) for f, o in t.slots],
                      "slot_names": [s.name for s in tp.z0],
                      "energy_lines": values(t, tp.z0), "piece_lines": piece_lines})
    quantities = [("H", list(range(len(terms))))]
    extra = []
    for name, its_terms in lat.invariants.items():
        first = len(terms) + len(extra)
        for t in its_terms:
            extra.append({**entry(t), "energy_lines": values(t, t.symbols()), "piece_lines": []})
        quantities.append((name, list(range(first, first + len(its_terms)))))
    scalar = _kernel_text(_scalar_kernel(scheme)) if backend == "compiled" else []
    skew = lat.structure == "skew"
    skew_lines = []
    sw = max((abs(k) for k in lat.stencil), default=0)
    if skew:
        # c_(-sw) … c_sw, the zeros too (the flow's sum runs over every offset, as the stepper's)
        cs = [lat.stencil.get(k, sp.S.Zero) for k in range(-sw, sw + 1)]
        skew_lines = _bind(cs, lat) + ["return ("] + [f"    float({printer.doprint(c)}),  # c_{k}"
                                                      for k, c in zip(range(-sw, sw + 1), cs)] + [")"]
    code = "\n".join([ln for t in terms + extra for ln in t["energy_lines"] + t["piece_lines"]] + scalar)
    env = _environment()
    special, defaults, description, header = _front(
        env, code, scheme, backend, sig, TEMPLATE, "" if not skew else ", for u' = S ∇H", "lattice, any N")
    traits = scheme.traits
    text = env.get_template(TEMPLATE).render(
        header=header, method=scheme.method, name=lat.name, source=_docsafe(lat.text), description=description,
        q=lat.q_name, p=lat.p_name, size=lat.size.name, skew=skew, nf=len(lat.fields),
        field_names=list(lat.fields), structure=lat.structure, skew_text=_docsafe(lat.skew_text or ""),
        skew_lines=skew_lines, nmin=lat.nmin, param_names=list(lat.params),
        jac_half_width=lat.jacobian_half_width, half_width=lat.half_width, stencil_half_width=sw,
        group=max(lat.half_width, 1), order=scheme.order, gammas=scheme.gammas,
        defaults_text=defaults, traits=traits, signature=sig, terms=terms, special=special, extra=extra,
        quantities=quantities, quantity_names=[q for q, _ in quantities], backend=backend, scalar=scalar)
    text = re.sub(r"\n{4,}", "\n\n\n", text).rstrip() + "\n"
    return HEADER_CONTENT + hashlib.sha256(text.encode()).hexdigest() + "\n" + text


def _bind2(exprs, lattice) -> list[str]:
    """Lines binding the parameters and the two sizes (as floats of the kernel's n, m) the
    expressions use."""
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    # (the kernels' own names start with "_", which no user name may: no parameter shadows them)
    lines = [f"{s.name} = _p[{k}]" for k, s in enumerate(lattice.param_symbols) if s in used]
    lines += [f"{s.name} = float({v})" for s, v in zip(lattice.sizes, ("_n", "_m")) if s in used]
    return lines


def _gathers2(symbols, slots, source: str, fields) -> list[str]:
    """The slot (f, (a, b)) at every site (i, j) is the field at (i + a, j + b), cyclically: a roll."""
    out = []
    for s, (f, (a, b)) in zip(symbols, slots):
        row = f"{source}[{fields.index(f)}]"
        out.append(f"{s.name} = {row}" if (a, b) == (0, 0) else f"{s.name} = numpy.roll({row}, ({-a}, {-b}), axis=(0, 1))")
    return out


def _scalar_kernel_2d(scheme: LatticeScheme, pieces_of) -> tuple:
    """``_grad2d(_Y0, _Z, _G, _n, _m, _p)`` as a kernel-IR function: ∇̄H(y0, z) added into ``_G``
    (2, n·m), the states (2, n·m) with the site (i, j) at i·m + j; a loop over the sites of each
    term, the slot (f, (a, b)) at ((i + a) % n)·m + (j + b) % m (Python's floor modulo, the
    translator's too).  The scalar form of the numpy module's rolls; compiled through LLVM by
    :mod:`methodgen.runtime.lattice_driver`.  Its own names start with "_" (no user name does: no
    parameter shadows them)."""
    lat = scheme.lattice
    printer = ScalarPrinter({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
    fields = lat.fields
    n, m = _v("_n"), _v("_m")
    allx = [e for tp in scheme.terms for e in pieces_of(tp)]
    used = set().union(*[e.free_symbols for e in allx]) if allx else set()
    body = [("=", _v(s.name), ("[]", "_p", (("n", k),))) for k, s in enumerate(lat.param_symbols) if s in used]
    body += [("=", _v(s.name), ("*", v, ("n", 1.0))) for s, v in zip(lat.sizes, (n, m)) if s in used]
    for tp in scheme.terms:
        t = tp.term
        if not t.slots:
            continue              # a constant: no gradient
        inner = []
        offs = sorted({o for _, o in t.slots})
        for a in sorted({o[0] for o in offs}):
            inner.append(("=", _v(f"_i{_otag(a)}"), ("%", _plus(_v("_i"), a), n)))
        for b in sorted({o[1] for o in offs}):
            inner.append(("=", _v(f"_j{_otag(b)}"), ("%", _plus(_v("_j"), b), m)))
        site = {o: _v(f"_s{_otag(o[0])}_{_otag(o[1])}") for o in offs}
        for o in offs:
            inner.append(("=", site[o], ("+", ("*", _v(f"_i{_otag(o[0])}"), m), _v(f"_j{_otag(o[1])}"))))
        for s0, s1, (f, o) in zip(tp.z0, tp.z1, t.slots):
            inner.append(("=", _v(s0.name), ("[]", "_Y0", (("n", fields.index(f)), site[o]))))
            inner.append(("=", _v(s1.name), ("[]", "_Z", (("n", fields.index(f)), site[o]))))
        inner += _difference_ir(differenced(tp).binds)
        pre, outs = _cse_trees(pieces_of(tp), printer, "_g")
        inner += pre + [("+=", ("[]", "_G", (("n", fields.index(f)), site[o])), outs[k])
                        for k, (f, o) in enumerate(t.slots)]
        body.append(("#", _docsafe(t.source)))
        body.append(("for", "_i", ("n", 0), n, (("for", "_j", ("n", 0), m, tuple(inner)),)))
    return kir.function("_grad2d", ("_Y0", "_Z", "_G", "_n", "_m", "_p"), body)


def _horner(expr: sp.Expr, slots) -> sp.Expr:
    """A piece that is a polynomial in the slots in Horner form (measured: about half the array
    operations of the derivation's expanded form on a 128 × 128 grid); any other piece as it is."""
    flat = sp.expand(expr)
    if not flat.is_polynomial(*slots):
        return expr
    return sp.horner(flat, *slots)


def _horner_pieces(dt: Differenced, tp) -> list:
    """The differenced pieces ``dt`` of ``tp`` in Horner form in all their variables."""
    return [_horner(x, tuple(tp.z0) + tuple(tp.z1) + tuple(d for d, _, _ in dt.binds)) for x in dt.pieces]


def _jacobian_lines(tp, dt: Differenced, lattice, printer) -> tuple[list, list[str]]:
    """A 2-D term's site Jacobian ``∂A_a/∂z1_b`` (the derivative of its AVF pieces in the step's end
    values, :attr:`Differenced.jac`) as vectorised numpy: ``(pairs, lines)``, ``pairs`` the nonzero
    entries as ``(f_a, o_a, f_b, o_b)`` (the field and offset of slot a's piece and of slot b's end
    value) and ``lines`` the body returning one (n, m) array per pair, in that order.  Only the slots
    the entries use are gathered (an unused roll is a copy of a field).  The module's exact Newton
    matrix and its matrix-free products are assembled from these (``_site_jacobian``)."""
    t = tp.term
    fields = lattice.fields
    pairs, exprs = [], []
    for a, (f, o) in enumerate(t.slots):
        for b, (g, o2) in enumerate(t.slots):
            e = dt.jac[a][b]
            if e != 0:                 # identically zero (the site's structure): no entry at all
                pairs.append((fields.index(f), tuple(o), fields.index(g), tuple(o2)))
                exprs.append(e)
    if not exprs:
        return [], []
    used = set().union(*[e.free_symbols for e in exprs])
    binds = [bd for bd in dt.binds if bd[0] in used]
    used |= {x for _, s, r in binds for x in (s, r)}
    z0 = [(s, sl) for s, sl in zip(tp.z0, t.slots) if s in used]
    z1 = [(s, sl) for s, sl in zip(tp.z1, t.slots) if s in used]
    pre, outs = _cse_lines(exprs, printer, "_k")
    lines = (_bind2(exprs, lattice) + _gathers2([s for s, _ in z0], [sl for _, sl in z0], "_Y0", fields)
             + _gathers2([s for s, _ in z1], [sl for _, sl in z1], "_Z", fields) + _difference_lines(binds) + pre
             + [f"return {_tuple([f'numpy.broadcast_to({x}, _Y0.shape[1:])' for x in outs])}"])
    return pairs, lines


def render2d(scheme: LatticeScheme, sig: str, backend: str = "numpy") -> str:
    """The module text of a 2-D periodic lattice (``templates/lattice_2d_module.py.j2``): per term its
    values and its pieces as vectorised numpy over the N × M sites (rolls), the linear part's
    stencil (:func:`methodgen.symbolic.lattice_scheme.linear_stencil`) as formulas in the sizes and
    parameters; deterministic, one module for every N × M.  ``backend="compiled"`` adds the
    site kernel :func:`_scalar_kernel_2d` (the residual's gradient then runs compiled through
    LLVM, :mod:`methodgen.runtime.lattice_driver`; the FFT solve stays numpy's; the module then
    imports methodgen), otherwise the module imports numpy only."""
    from ..symbolic.lattice_scheme import linear_stencil

    lat = scheme.lattice
    printer = VectorPrinter({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
    fields = lat.fields

    def values(t, z0):
        pre, (value,) = _cse_lines([t.template], printer, "_e")
        return (_bind2([t.template], lat) + _gathers2(z0, t.slots, "_Y", fields) + pre
                + [f"return numpy.broadcast_to({value}, _Y.shape[1:])"])

    terms = []
    for tp in scheme.terms:
        t = tp.term
        dt = differenced(tp)
        pieces = _horner_pieces(dt, tp)
        g_pre, g_out = _cse_lines(pieces, printer, "_g")
        lines = (_bind2(pieces, lat) + _gathers2(tp.z0, t.slots, "_Y0", fields)
                 + _gathers2(tp.z1, t.slots, "_Z", fields) + _difference_lines(dt.binds) + g_pre
                 + [f"return {_tuple([f'numpy.broadcast_to({x}, _Y0.shape[1:])' for x in g_out])}"])
        pairs, jac_lines = _jacobian_lines(tp, dt, lat, printer)
        terms.append({"source": _docsafe(t.source), "index": len(terms), "slots": [(fields.index(f), o) for f, o in t.slots],
                      "slot_names": [s.name for s in tp.z0], "energy_lines": values(t, tp.z0), "piece_lines": lines,
                      "jac_pairs": pairs, "jac_lines": jac_lines})
    quantities = [("H", list(range(len(terms))))]
    extra = []
    for name, its_terms in lat.invariants.items():
        first = len(terms) + len(extra)
        for t in its_terms:
            extra.append({"source": _docsafe(t.source), "energy_lines": values(t, t.symbols())})
        quantities.append((name, list(range(first, first + len(its_terms)))))
    scalar = []
    if backend == "compiled":
        horner = {id(tp): _horner_pieces(differenced(tp), tp) for tp in scheme.terms}
        scalar = _kernel_text(_scalar_kernel_2d(scheme, lambda tp: horner[id(tp)]), "_grad2d",
                              "methodgen.runtime.lattice_driver compiles this tree")
    K = linear_stencil(lat)
    stencil_lines = _bind2(list(K.values()), lat) + ["return ("] + [
        f"    ({f}, {g}, {a}, {b}, {printer.doprint(c)})," for (f, g, (a, b)), c in K.items()] + [")"]
    code = "\n".join([ln for t in terms + extra for ln in t["energy_lines"] + t.get("piece_lines", [])
                      + t.get("jac_lines", [])]
                     + stencil_lines + scalar)
    env = _environment()
    special, defaults, description, header = _front(
        env, code, scheme, backend, sig, TEMPLATE_2D, ", on a periodic N × M lattice",
        "2-D periodic lattice, any N × M")
    traits = scheme.traits
    text = env.get_template(TEMPLATE_2D).render(
        header=header, method=scheme.method, name=lat.name, source=_docsafe(lat.text), description=description,
        q=lat.q_name, p=lat.p_name, sizes=[s.name for s in lat.sizes], nmin=lat.nmin,
        field_names=list(lat.fields), param_names=list(lat.params), defaults_text=defaults, traits=traits,
        signature=sig, terms=terms, extra=extra, special=special, quantities=quantities,
        quantity_names=[q for q, _ in quantities], stencil_lines=stencil_lines,
        backend=backend, scalar=scalar)
    text = re.sub(r"\n{4,}", "\n\n\n", text).rstrip() + "\n"
    return HEADER_CONTENT + hashlib.sha256(text.encode()).hexdigest() + "\n" + text


BACKENDS = ("numpy", "compiled")


def build_lattice(lattice: Lattice, method: str = "avf", path=None, *, backend: str = "numpy", progress=None,
                  order: int = 2, composition: str | None = None):
    """The generated module of ``method`` for ``lattice``: one module for every N.

    Derived, printed and written once (to ``path``, default the per-user cache under a name with
    the signature); a current file is imported without deriving.

    Parameters
    ----------
    lattice : Lattice
    method : {"avf", "midpoint"}
    path : path-like, optional
    backend : {"numpy", "compiled"}
        "numpy": vectorised numpy, the module imports numpy only.  "compiled": the steps run on
        :mod:`methodgen.runtime.lattice_stepper` compiled through LLVM (needs llvmlite; the module
        imports methodgen); the same results to round-off.
    progress : callable, optional
        ``progress(phase, elapsed, done)`` for derive, render, write and load.
    order : {2, 4, 6, 8}
        A 1-D lattice: above 2 each step is the order-2 step taken s times, of sizes ``γ_k h``, a
        symmetric composition (:func:`methodgen.symbolic.lattice_scheme.discretize_lattice`); the
        module's ``ORDER``, ``GAMMAS`` and ``TRAITS`` say which.
    composition : str, optional
        The composition family for order > 2 (default the order's
        :data:`~methodgen.symbolic.compositions.DEFAULT_FAMILY`).

    Returns
    -------
    module

    Raises
    ------
    InputError
        An unknown method or backend; an order not 2, 4, 6 or 8 (the message names them), an
        unknown family; order > 2 for a 2-D lattice (its template runs one stage).
    """
    if method not in LATTICE_METHODS:
        discretize_lattice(lattice, method)     # raises with the list of methods
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r} for a lattice; backends are {', '.join(BACKENDS)}")
    sig = lattice_signature(lattice, method, backend, order, composition)     # (checks the order)
    if order != 2 and getattr(lattice, "dims", 1) == 2:
        raise InputError(f"order {order}: a 2-D lattice's module runs the order-2 step only (compositions are "
                         "offered for 1-D lattices); use order=2")
    if path is None:
        suffix = "" if backend == "numpy" else f"_{backend}"
        suffix += "" if order == 2 else f"_order{order}"
        path = cache_dir() / f"{lattice.name}_{method}_lattice{suffix}_{sig[:12]}.py".replace("-", "_")

    def source() -> str:
        with phase("derive", progress):
            scheme = discretize_lattice(lattice, method, order, composition)
        with phase("render", progress):
            if getattr(lattice, "dims", 1) == 2:
                return render2d(scheme, sig, backend)
            return render(scheme, sig, backend)

    return write_and_load(path, sig, source, progress)
