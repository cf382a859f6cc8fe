"""Run a compiled lattice module's steps: :mod:`methodgen.runtime.lattice_stepper` with the module's
kernel bound, compiled through LLVM once per kernel text (machine code cached on disk, keyed by
that text), or run as plain Python where llvmlite is missing or ``python=True``."""

from __future__ import annotations

import math
import types

import numpy

from ..codegen import ktypes as _t
from . import lattice_stepper as _ls
from . import stepper as _stepper

__all__ = ["run_steps", "gradient_2d"]

_f8, _i8, _V, _M = _t.float64, _t.int64, _t.float64[::1], _t.float64[:, ::1]
#: Y (nf, n), T (rows, nf n), its, fst (5), p, n, h, steps, every, maxiter, tol, chk, simpl, maxdis, W, D, P, F, cs,
#: gammas, stages, DH (2 stages nf, n), s0 (the steps behind DH: 0, 1, 2)
SIG = _t.void(_M, _M, _V, _V, _V, _i8, _f8, _i8, _i8, _i8, _f8, _i8, _i8, _f8, _M, _M, _M, _V, _V, _V, _i8, _M, _i8)

_LOOPS: dict = {}
#: the stepper's functions the step loop calls (bound with the problem's shape)
_FUNCTIONS = ("factor", "solve", "flow", "newton", "assemble", "invert", "copy", "add", "mul")


def shape_constants(n: int, nf: int, jac_half_width: int, stencil_half_width: int = 0, skew: bool = False) -> dict:
    """The constants :mod:`methodgen.runtime.lattice_stepper` is bound with for n sites: fields per
    site, the group size g = max(w, 1) (w = wH + sw), the blocks' sizes m = nf g and mB = nf (g +
    n mod g), the structure and the half-widths."""
    w = jac_half_width + stencil_half_width
    g = max(w, 1)
    q, m, mb = _ls.layout(n, nf, g)
    return {"_NF": nf, "_GS": g, "_BM": m, "_BB": mb, "_SK": int(skew), "_SW": stencil_half_width,
            "_WH": jac_half_width, "_W2": 2 * w + 1}


def _bound(grad, shape: dict) -> dict:
    consts = {k: v for k, v in vars(_ls).items() if k.startswith(("_I", "_M", "_N")) and isinstance(v, int)}
    consts.update(shape)
    consts.update(math=math, grad=grad)
    for name in _FUNCTIONS:
        consts[name] = types.FunctionType(getattr(_ls, name).__code__, consts, name)
    consts["settled"] = types.FunctionType(_stepper.settled.__code__, consts, "settled")
    return consts


def stepper_functions(shape: dict) -> types.SimpleNamespace:
    """The stepper's functions bound with ``shape`` (:func:`shape_constants`), as plain Python (for
    tests of the solve: ``newton(D, P, n, h, cs)``, ``factor(P, F, n)``, ``solve(W, F, n)``)."""
    consts = _bound(None, shape)
    return types.SimpleNamespace(**{k: consts[k] for k in _FUNCTIONS})


def _loop(grad, python: bool, shape: dict):
    """The step loop for the module kernel ``grad`` and the problem's ``shape``: compiled (cached
    per kernel and shape: a module runs at most g shapes, one per n mod g) or Python."""
    consts = _bound(grad, shape)
    fn = types.FunctionType(_ls.lattice_run.__code__, consts, "lattice_run")
    if python:
        return fn, False
    return _compiled(_LOOPS, grad, fn, SIG, consts, "the lattice step loop", tuple(sorted(shape.items()))), True


def _compiled(cache: dict, kernel, fn, sig, globals_, what: str, variant=()):
    """``fn`` compiled for ``sig`` with a C entry, cached in ``cache`` per module kernel
    ``kernel`` (kept with it, so its code's id is not reused while the entry lives) and
    ``variant``."""
    from ..codegen import llvmkernels as _lk
    key = (id(kernel.__code__), variant)
    got = cache.get(key)
    if got is None or got[1] is not kernel:
        try:
            compiled = _lk.compile_kernel(fn, sig, globals_=globals_, c_entry=True)
        except _lk.Unsupported as exc:        # pragma: no cover - the printed kernels are in the subset
            raise RuntimeError(f"{what} could not be compiled: {exc}") from None
        cache[key] = got = (compiled, kernel)
    return got[0]


def run_steps(grad, Y, h, steps, every, p, maxiter, tol, check_resolution, simplified, maxdis, *, python=False,
              jac_half_width=1, stencil=None, gammas=(1.0,), history=None):
    """``steps`` steps from ``Y`` (nf, n), updated in place: ``(rows, its, status)`` with rows
    (steps // every + 1 + ..., nf n) (row 0 the start), Newton iterations per step (summed over
    its stages), and ``(code, step, iterations, value, stage)`` of a failure (code 0: none, and
    stage 0; a failure's stage 1-based).

    ``gammas``: the stage sizes in units of h (a module's ``GAMMAS``: a symmetric composition of
    the order-2 step; (1.0,) is the order-2 step itself).

    ``jac_half_width``: the half-bandwidth wH in sites of the kernel's ∂∇̄H (its rows
    ``(2 wH + 1) nf²``); ``stencil``: a skew lattice's coefficients ``c_(-sw) … c_sw`` at this n
    (then Y is (1, n)), None for a canonical lattice.  The Newton matrix's sites are grouped by
    g = max(wH + sw, 1) (:mod:`methodgen.runtime.lattice_stepper`).

    ``history``: None (a new run), or each stage's last two increments, an array (2, stages, nf, n)
    -- ``history[0, k]`` stage k's increment at the last step, ``history[1, k]`` at the one before,
    NaN where the run has not taken that step -- read as the run's past and overwritten with
    the history at the end (on success), so that a run continued in chunks is bitwise the run in
    one piece."""
    nf, n = Y.shape
    nrows = steps // every + (1 if steps % every else 0) + 1
    T = numpy.zeros((nrows, nf * n))
    T[0] = Y.reshape(-1)
    its = numpy.zeros(max(steps, 1))
    fst = numpy.zeros(5)
    gam = numpy.ascontiguousarray(gammas, dtype=numpy.float64)
    if gam.ndim != 1 or gam.size < 1:
        raise ValueError(f"gammas must be a non-empty sequence of stage sizes, got {gammas!r}")
    DH = numpy.zeros((2 * gam.size * nf, n))
    s0 = 0
    if history is not None:
        if history.shape != (2, gam.size, nf, n):
            raise ValueError(f"history must have shape {(2, gam.size, nf, n)} (two increments per stage), "
                             f"got {history.shape}")
        # the steps behind it: NaN marks an increment the run has not taken (all of a stage's
        # or none: the module's record)
        s0 = 0 if numpy.isnan(history[0, 0, 0, 0]) else 1 if numpy.isnan(history[1, 0, 0, 0]) else 2
        for k in range(gam.size):
            for r in range(s0):
                DH[(2 * k + r) * nf:(2 * k + r + 1) * nf] = history[r, k]
    W = numpy.zeros((_ls.W_ROWS, n))
    wh = int(jac_half_width)
    cs = numpy.zeros(1) if stencil is None else numpy.ascontiguousarray(stencil, dtype=numpy.float64)
    sw = 0 if stencil is None else (cs.size - 1) // 2
    shape = shape_constants(n, nf, wh, sw, stencil is not None)
    D = numpy.zeros(((2 * wh + 1) * nf * nf, n))
    P = numpy.zeros((shape["_W2"] * nf * nf, n))
    F = numpy.zeros(_ls.factor_size(n, nf, shape["_GS"]))
    p = numpy.ascontiguousarray(p, dtype=numpy.float64)
    if p.size == 0:
        p = numpy.zeros(1)
    loop, compiled = _loop(grad, python, shape)
    args = (Y, T, its, fst, p, int(n), float(h), int(steps), int(every), int(maxiter), float(tol),
            int(bool(check_resolution)), int(bool(simplified)), float(maxdis), W, D, P, F, cs, gam, int(gam.size), DH,
            int(s0))
    if compiled:
        from .fused import _drive
        _drive(loop, *args)
    else:
        loop(*args)
    code = int(fst[0])
    done = int(fst[1]) if code else steps
    kept = done // every + 1 + (1 if code == 0 and steps % every else 0)
    if history is not None and code == 0:
        got = min(s0 + steps, 2)
        for k in range(gam.size):
            for r in range(2):
                history[r, k] = DH[(2 * k + r) * nf:(2 * k + r + 1) * nf] if r < got else numpy.nan
    return (T[:kept], its[:steps].astype(numpy.int64),
            (code, int(fst[1]), int(fst[2]), float(fst[3]), int(fst[4]) + 1 if code else 0))


#: _Y0, _Z, _G (2, n·m), _n, _m, _p: a 2-D lattice module's site kernel _grad2d
SIG_2D = _t.void(_M, _M, _M, _i8, _i8, _V)
_KERNELS_2D: dict = {}


def _kernel_2d(kernel, python: bool):
    """``kernel`` compiled (cached per kernel, as :func:`_loop`), or itself (plain Python) where
    llvmlite is missing or ``python``."""
    if python:
        return kernel, False
    return _compiled(_KERNELS_2D, kernel, kernel, SIG_2D, None, "the 2-D lattice site kernel"), True


def gradient_2d(kernel, Y0, Z, n, m, p, *, python=False):
    """∇̄H(y0, z) of a 2-D lattice module, (2, n, m), by its site kernel ``kernel`` (``_grad2d``):
    compiled through LLVM and called through its C entry, or run as Python."""
    y0 = numpy.ascontiguousarray(Y0, dtype=numpy.float64).reshape(2, n * m)
    z = numpy.ascontiguousarray(Z, dtype=numpy.float64).reshape(2, n * m)
    G = numpy.zeros((2, n * m))
    p = numpy.ascontiguousarray(p, dtype=numpy.float64)
    if p.size == 0:
        p = numpy.zeros(1)
    fn, compiled = _kernel_2d(kernel, python)
    if compiled:
        from .fused import _drive
        _drive(fn, y0, z, G, int(n), int(m), p)
    else:
        fn(y0, z, G, int(n), int(m), p)
    return G.reshape(2, n, m)
