"""A particle method as one numpy module for every N: printing, writing, loading.

:func:`render` prints a :class:`methodgen.symbolic.particle_scheme.ParticleScheme` through
``templates/particles_module.py.j2``: the one-body values and velocities vectorised over the
particles, the pair values and forces (Störmer–Verlet) or the pair's discrete-gradient factor
``g`` (energy-momentum) vectorised over the pairs, the external potential's force or discrete
gradient ``G(q0_a, q1_a)`` (energy-momentum) vectorised over the particles, CSE'd; the stages of
a composition as a loop over its coefficients (``KICKS``/``DRIFTS``, ``GAMMAS``); the pair tables (``numpy.triu_indices``)
of a size are built by the module at run time and the forces accumulated per particle with
``numpy.bincount``.  Nothing in the text depends on N: the module is derived, printed and
imported once, in the time one template costs.

``backend="compiled"`` adds the same pieces as scalar kernels (:mod:`methodgen.codegen.kir`) for
the pair-loop stepper :mod:`methodgen.runtime.particle_stepper`, compiled through LLVM with the
kernels inlined (:mod:`methodgen.runtime.particle_driver`); the module then imports methodgen.
:func:`build_particles` is the cached entry point (the module cache and its trust checks of
:mod:`methodgen.codegen.store` and :mod:`methodgen.codegen.emit`).
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import sympy as sp

from .._version import __version__
from ..errors import InputError
from ..problem.particles import Particles, particle_symbol
from ..problem.special import SPECIAL_FUNCTIONS
from ..symbolic.particle_scheme import (PARTICLE_METHODS, ParticleScheme, discretize_particles, invariant_names)
from . import kir
from .emit import (HEADER_CONTENT, HEADER_SIGNATURE, _docsafe, _environment, generator_hash, template_dir,
                   template_hash, write_and_load)
from .lattice_emit import _cse_lines, _cse_trees, _kernel_text, _tuple, _v
from .lower import _HELPER_CALL, CheckPrinter, VectorPrinter, _helper_closure
from .progress import phase
from .store import cache_dir

__all__ = ["render", "particles_signature", "build_particles", "BACKENDS"]

TEMPLATE = "particles_module.py.j2"
ERRORS_TEMPLATE = "lattice_errors.py.j2"
#: the info["carried"] record of a family module (continuing a run), included by the templates
CARRY_TEMPLATE = "lattice_carry.py.j2"
BACKENDS = ("numpy", "compiled")


def _sources_hash() -> str:
    """SHA-256 of the particle path's own sources (outside :func:`methodgen.codegen.emit.generator_hash`)."""
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256()
    for path in (root / "problem" / "particles.py", root / "symbolic" / "particle_scheme.py",
                 root / "codegen" / "particle_emit.py", root / "runtime" / "particle_stepper.py",
                 root / "runtime" / "particle_driver.py", template_dir() / TEMPLATE, template_dir() / ERRORS_TEMPLATE, template_dir() / CARRY_TEMPLATE):
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def particles_signature(fam: Particles, method: str, order: int = 2, composition=None, backend: str = "numpy") -> str:
    """Hash of everything the module depends on: text, names, defaults, method and order, versions,
    the printers and helpers shared with other modules, and the particle path's own sources."""
    parts = [fam.text, repr(fam.q_names), repr(fam.p_names), repr(fam.array_names), fam.size.name, fam.name,
             repr(sorted(fam.params.items())), method, str(order), str(composition), __version__, sp.__version__,
             template_hash("numpy"), generator_hash(), _sources_hash(), backend]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


# --- numpy: gathers of the slots over the particles or the pairs ---------------------------------

def _bind(exprs, fam: Particles, pvar: str = "p") -> list[str]:
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    return [f"{s.name} = {pvar}[{k}]" for k, s in enumerate(fam.param_symbols) if s in used]


def _gather(exprs, fam: Particles, roles: str, source: str) -> list[str]:
    """Lines binding the slots ``exprs`` use: over the particles (``roles == "a"``: ``x_a = Q[:, 0]``)
    or over the pairs (``x_a = Q[I, 0]``, ``x_b = Q[J, 0]``); arrays from ``M``, momenta from ``P``."""
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    out = []
    for role, idx in (("a", "I"), ("b", "J")):
        if role not in roles:
            continue
        at = ":" if roles == "a" else idx
        for k, f in enumerate(fam.q_names):
            s = particle_symbol(f, role)
            if s in used:
                out.append(f"{s.name} = {source}[{at}, {k}]")
        for k, f in enumerate(fam.p_names):
            s = particle_symbol(f, role)
            if s in used:
                out.append(f"{s.name} = P[{at}, {k}]")
        for k, f in enumerate(fam.array_names):
            s = particle_symbol(f, role)
            if s in used:
                out.append(f"{s.name} = M[{k}]" if roles == "a" else f"{s.name} = M[{k}][{idx}]")
    return out


def _slots(fam: Particles, roles: str) -> set:
    """The symbols :func:`_gather` binds to arrays over the particles or the pairs (``roles``)."""
    names = (*fam.q_names, *fam.p_names, *fam.array_names)
    return {particle_symbol(f, role) for role in roles for f in names}


def _shaped(outs, exprs, slots, shape: str) -> list[str]:
    """The returned values: an output that depends on an array slot (``slots``) is already an array
    of ``shape``; only one of the parameters alone (a constant, or 0) is broadcast to it.  (A
    broadcast_to per output was most of a small system's numpy step: about 3 µs a call.)"""
    return [x if e.free_symbols & slots else f"numpy.broadcast_to({x}, {shape})" for x, e in zip(outs, exprs)]


def _vector_fn(exprs, fam, roles, source, shape, printer, prefix) -> list[str]:
    pre, outs = _cse_lines(list(exprs), printer, prefix)
    return (_bind(list(exprs), fam) + _gather(exprs, fam, roles, source) + pre
            + [f"return {_tuple(_shaped(outs, exprs, _slots(fam, roles), shape))}"])


def _ends(exprs, scheme: ParticleScheme, source: str) -> list[str]:
    """Lines binding the end positions ``x_a1 = Q1[:, 0]``, … that ``exprs`` use (the external
    potential's discrete gradient, energy-momentum)."""
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    return [f"{s.name} = {source}[:, {k}]" for k, s in enumerate(scheme.q1_slots) if s in used]


# --- compiled: scalar kernels of one particle or one pair ---------------------------------------

def _scalar_bind(exprs, fam, roles_at, sources) -> list:
    """Statements binding the parameters and the slots ``exprs`` use (``roles_at``: role → index
    variable; ``sources``: "q", "p" → the array read)."""
    used = set().union(*[e.free_symbols for e in exprs]) if exprs else set()
    out = [("=", _v(s.name), ("[]", "_p", (("n", k),))) for k, s in enumerate(fam.param_symbols) if s in used]
    for role, at in roles_at.items():
        for kind, names in (("q", fam.q_names), ("p", fam.p_names)):
            for k, f in enumerate(names):
                s = particle_symbol(f, role)
                if s in used:
                    out.append(("=", _v(s.name), ("[]", sources[kind], (_v(at), ("n", k)))))
        for k, f in enumerate(fam.array_names):
            s = particle_symbol(f, role)
            if s in used:
                out.append(("=", _v(s.name), ("[]", "_M", (("n", k), _v(at)))))
    return out


def _cse_bases(exprs, printer, prefix: str = "_t") -> tuple[list, list]:
    """:func:`methodgen.codegen.lattice_emit._cse_trees` with the base of every half-integer power
    bound to a name first, so that the check printer writes ``u**(3/2)`` as ``u*math.sqrt(u)``
    (products and square roots: the same bits compiled and in CPython)."""
    bases = []
    for e in exprs:
        for x in sp.preorder_traversal(e):
            if (x.is_Pow and x.exp.is_Rational and x.exp.q == 2 and not x.base.is_Symbol
                    and x.base not in bases):
                bases.append(x.base)
    if not bases:
        return _cse_trees(exprs, printer, prefix)
    names = [sp.Symbol(f"{prefix}u{k}", real=True) for k in range(len(bases))]
    pre, trees = _cse_trees(bases, printer, f"{prefix}b")
    sub = dict(zip(bases, names))
    body, outs = _cse_trees([e.xreplace(sub) for e in exprs], printer, prefix)
    return pre + [("=", _v(u.name), t) for u, t in zip(names, trees)] + body, outs


def _kernels(scheme: ParticleScheme, printer) -> list:
    """The scalar kernels the compiled stepper inlines (:mod:`methodgen.runtime.particle_stepper`):
    ``_vel(_P, _V, _a, _M, _p)`` (∇T at the particle a into ``_V[_a]``), and either
    ``_fpair(_Q, _F, _a, _b, _M, _p)`` and ``_fext(_Q, _F, _a, _M, _p)`` (forces added into ``_F``,
    Störmer–Verlet) or ``_gpair(_Q, _D, _A, _a, _b, _M, _p)`` (the pair's ``±g (r0 + r1)`` added
    into ``_A``, r1 = r0 + D_a - D_b) and ``_gext(_Q, _D, _A, _a, _M, _p)`` (the external
    potential's discrete gradient ``G(q0_a, q0_a + D_a)`` added into ``_A[_a]``; energy-momentum).
    A kernel the stepper does not call (no W: ``HAS_EXTERNAL`` 0) still exists, a no-op, so the
    stepper compiles with the same globals."""
    fam = scheme.family
    d = fam.dim
    fns = []
    pre, outs = _cse_bases(scheme.velocity, printer, "_t")
    body = (_scalar_bind(list(scheme.velocity), fam, {"a": "_a"}, {"q": "_Q", "p": "_P"}) + pre
            + [("=", ("[]", "_V", (_v("_a"), ("n", k))), outs[k]) for k in range(d)])
    fns.append(kir.function("_vel", ("_P", "_V", "_a", "_M", "_p"), body))
    if scheme.method == "stormer-verlet":
        fa, fb = scheme.pair_force
        exprs = list(fa) + list(fb)
        pre, outs = _cse_bases(exprs, printer, "_t")
        body = (_scalar_bind(exprs, fam, {"a": "_a", "b": "_b"}, {"q": "_Q", "p": "_P"}) + pre
                + [("+=", ("[]", "_F", (_v("_a"), ("n", k))), outs[k]) for k in range(d)]
                + [("+=", ("[]", "_F", (_v("_b"), ("n", k))), outs[d + k]) for k in range(d)])
        fns.append(kir.function("_fpair", ("_Q", "_F", "_a", "_b", "_M", "_p"), body))
        ext = list(scheme.external_force)
        if any(e != 0 for e in ext):
            pre, outs = _cse_bases(ext, printer, "_t")
            body = (_scalar_bind(ext, fam, {"a": "_a"}, {"q": "_Q", "p": "_P"}) + pre
                    + [("+=", ("[]", "_F", (_v("_a"), ("n", k))), outs[k]) for k in range(d)])
        else:       # (the stepper does not call it: HAS_EXTERNAL is 0)
            body = [("+=", ("[]", "_F", (_v("_a"), ("n", 0))), ("n", 0.0))]
        fns.append(kir.function("_fext", ("_Q", "_F", "_a", "_M", "_p"), body))
        return fns
    # energy-momentum: r0 = q_a - q_b, r1 = r0 + D_a - D_b, s0 = |r0|², s1 = |r1|², g(s0, s1)
    qa = fam.q_slots[0]
    body = [("=", _v(f"_r0{k}"), ("-", ("[]", "_Q", (_v("_a"), ("n", k))), ("[]", "_Q", (_v("_b"), ("n", k)))))
            for k in range(d)]
    body += [("=", _v(f"_r1{k}"), ("+", _v(f"_r0{k}"), ("-", ("[]", "_D", (_v("_a"), ("n", k))),
                                                         ("[]", "_D", (_v("_b"), ("n", k))))))
             for k in range(d)]
    for which in ("0", "1"):
        acc = ("*", _v(f"_r{which}0"), _v(f"_r{which}0"))
        for k in range(1, d):
            acc = ("+", acc, ("*", _v(f"_r{which}{k}"), _v(f"_r{which}{k}")))
        body.append(("=", _v(f"s{which}"), acc))
    g = scheme.g
    pre, (gt,) = _cse_bases([g], printer, "_t")
    body += _scalar_bind([g], fam, {"a": "_a", "b": "_b"}, {"q": "_Q", "p": "_P"}) + pre
    body.append(("=", _v("_g"), gt))
    for k in range(d):
        body.append(("=", _v(f"_c{k}"), ("*", _v("_g"), ("+", _v(f"_r0{k}"), _v(f"_r1{k}")))))
        body.append(("+=", ("[]", "_A", (_v("_a"), ("n", k))), _v(f"_c{k}")))
        body.append(("-=", ("[]", "_A", (_v("_b"), ("n", k))), _v(f"_c{k}")))
    del qa
    fns.append(kir.function("_gpair", ("_Q", "_D", "_A", "_a", "_b", "_M", "_p"), body))
    G = list(scheme.external_dg)
    if G:
        used = set().union(*[e.free_symbols for e in G])
        # the end position as the numpy module forms it (Q1 = Q0 + D): the same bits
        ends = [("=", _v(s1.name), ("+", ("[]", "_Q", (_v("_a"), ("n", k))), ("[]", "_D", (_v("_a"), ("n", k)))))
                for k, s1 in enumerate(scheme.q1_slots) if s1 in used]
        pre, outs = _cse_bases(G, printer, "_t")
        body = (_scalar_bind(G, fam, {"a": "_a"}, {"q": "_Q", "p": "_P"}) + ends + pre
                + [("+=", ("[]", "_A", (_v("_a"), ("n", k))), outs[k]) for k in range(d)])
    else:       # (the stepper does not call it: HAS_EXTERNAL is 0)
        body = [("+=", ("[]", "_A", (_v("_a"), ("n", 0))), ("n", 0.0))]
    fns.append(kir.function("_gext", ("_Q", "_D", "_A", "_a", "_M", "_p"), body))
    return fns


def render(scheme: ParticleScheme, sig: str, backend: str = "numpy") -> str:
    """The module's source text (deterministic: the same scheme gives the same bytes)."""
    fam = scheme.family
    printer = VectorPrinter({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
    em = scheme.method == "energy-momentum"
    d = fam.dim
    one = fam.kinetic + fam.external
    lines = {
        "one_value": _vector_fn([one], fam, "a", "Q", "(Q.shape[0],)", printer, "_e"),
        "pair_value": _vector_fn([fam.pair], fam, "ab", "Q", "I.shape", printer, "_e"),
        "velocity": _vector_fn(list(scheme.velocity), fam, "a", "Q", "(P.shape[0],)", printer, "_t"),
        "external": _vector_fn(list(scheme.external_force), fam, "a", "Q", "(Q.shape[0],)", printer, "_t"),
    }
    if em:
        g = scheme.g
        pre, (gout,) = _cse_lines([g], printer, "_t")
        lines["pair"] = (_bind([g], fam) + _gather([g], fam, "ab", "Q") + pre
                         + [f"return {_shaped([gout], [g], _slots(fam, 'ab') | {scheme.s0, scheme.s1}, 's0.shape')[0]}"])
        G = list(scheme.external_dg)
        if G:
            pre, outs = _cse_lines(G, printer, "_t")
            lines["external_dg"] = (_bind(G, fam) + _gather(G, fam, "a", "Q0") + _ends(G, scheme, "Q1") + pre
                                    + [f"return {_tuple(_shaped(outs, G, _slots(fam, 'a') | set(scheme.q1_slots), '(Q0.shape[0],)'))}"])
        else:
            lines["external_dg"] = ["return ()"]
    else:
        fa, fb = scheme.pair_force
        lines["pair"] = _vector_fn(list(fa) + list(fb), fam, "ab", "Q", "I.shape", printer, "_t")
    scalar = []
    if backend == "compiled":
        # small powers as products and u**(3/2) as u*sqrt(u) (the check flavour): the compiled code and
        # CPython then do the same operations (CPython's float ** is libm's pow, the compiled
        # code's integer powers repeated squaring), so the Python run is the compiled run's bits
        sprinter = CheckPrinter({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
        for fn in _kernels(scheme, sprinter):
            scalar += _kernel_text(fn, fn[1], "methodgen.runtime.particle_driver inlines this tree") + ["", ""]
    code = "\n".join([ln for v in lines.values() for ln in v] + scalar)
    known = {v[1:] for v in SPECIAL_FUNCTIONS.values()}
    helpers = _helper_closure({m for m in _HELPER_CALL.findall(code) if m in known})
    env = _environment()
    special = env.get_template("_special.py.j2").render(ir=type("HelperSet", (), {"helpers": helpers}))
    if helpers:
        special = "\n\n" + special.strip("\n") + "\n"
    defaults = "{" + ", ".join(f"{k!r}: {v!r}" for k, v in fam.params.items()) + "}"
    if em:
        kept = "H (to round-off), the total linear and angular momentum"
        if scheme.external_kind == "central":
            kept += " (the external potential is central: G = W_σ[σ0, σ1] (q0 + q1))"
        elif scheme.external_kind == "itoh-abe":
            kept += " (the external potential's discrete gradient is Itoh–Abe's: not L)"
    else:
        kept = "a modified energy near H (symplectic); the total linear and angular momentum"
    description = f"{PARTICLE_METHODS[scheme.method]}; keeps {kept} where the certificates prove them."
    comp = "" if scheme.order == 2 else f", composed to order {scheme.order} ({scheme.composition})"
    header = [f"Generated by methodgen {__version__} from templates/{TEMPLATE} -- do not edit.",
              f"system: {fam.name}; method: {scheme.method}{comp} (particles, any N); backend: {backend}",
              f"H = {_docsafe(fam.text)}",
              f"methodgen {__version__}; sympy {sp.__version__}; templates sha256 {template_hash('numpy')[:16]}",
              HEADER_SIGNATURE[2:] + sig]
    planes = [(k, l) for k in range(d) for l in range(k + 1, d)]
    text = env.get_template(TEMPLATE).render(
        header=header, method=scheme.method, order=scheme.order, name=fam.name, source=_docsafe(fam.text),
        description=description, traits=scheme.traits, signature=sig, size=fam.size.name, nmin=fam.nmin, dim=d,
        q_fields=list(fam.q_names), p_fields=list(fam.p_names), array_names=list(fam.array_names),
        param_names=list(fam.params), defaults_text=defaults, invariant_names=list(invariant_names(fam)),
        planes=planes, kicks=list(scheme.kicks), drifts=list(scheme.drifts), gammas=list(scheme.gammas), em=em,
        has_external=any(e != 0 for e in scheme.external_force), lines=lines, special=special,
        backend=backend, scalar=scalar)
    text = re.sub(r"\n{4,}", "\n\n\n", text).rstrip() + "\n"
    return HEADER_CONTENT + hashlib.sha256(text.encode()).hexdigest() + "\n" + text


def build_particles(fam: Particles, method: str = "stormer-verlet", path=None, *, order: int = 2,
                    composition: str | None = None, backend: str = "numpy", progress=None):
    """The generated module of ``method`` for the particle family ``fam``: one module for every N.

    Derived, printed and written once (to ``path``, default the per-user cache under a name with
    the signature); a current file is imported without deriving.

    Parameters
    ----------
    fam : Particles
    method : {"stormer-verlet", "energy-momentum"}
    path : path-like, optional
    order : {2, 4, 6, 8}
        Either method composed symmetrically to this order (Störmer–Verlet's kick-drift-kick
        stages, energy-momentum steps of size ``γ_k h``).
    composition : str, optional
        The composition family (default :data:`methodgen.symbolic.compositions.DEFAULT_FAMILY`).
    backend : {"numpy", "compiled"}
        "numpy": vectorised pair tables, the module imports numpy only.  "compiled": the steps
        run as pair loops compiled through LLVM (:mod:`methodgen.runtime.particle_stepper`; needs
        llvmlite, the module imports methodgen).
    progress : callable, optional

    Returns
    -------
    module
    """
    if method not in PARTICLE_METHODS:
        raise InputError(f"method {method!r} is not available for particles; available: "
                         f"{', '.join(PARTICLE_METHODS)}")
    if backend not in BACKENDS:
        raise InputError(f"unknown backend {backend!r} for particles; backends are {', '.join(BACKENDS)}")
    sig = particles_signature(fam, method, order, composition, backend)
    if path is None:
        suffix = "" if backend == "numpy" else f"_{backend}"
        path = cache_dir() / f"{fam.name}_{method}{order}_particles{suffix}_{sig[:12]}.py".replace("-", "_")

    def source() -> str:
        with phase("derive", progress):
            scheme = discretize_particles(fam, method, order, composition)
        with phase("render", progress):
            return render(scheme, sig, backend)

    return write_and_load(path, sig, source, progress)
