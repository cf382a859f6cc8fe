"""The shared compiled runtime's interface, without numba: what a numba module needs to load
and run on its fused loop.

A generated numba module (:mod:`methodgen.nbruntime`'s route) imports this module as ``_rt``.
It holds the runtime's contract as plain data -- the kernels' signatures
(:data:`KERNEL_TYPES`, :mod:`methodgen.ktypes`), the layout of the configuration arrays
(:data:`CFG`, :data:`FCFG`), the status codes -- and :func:`run`, which runs a call on the
module's fused loop (:mod:`methodgen.fused`: machine code from llvmlite, called through
ctypes) and imports the numba runtime only when that loop does not apply or hands the call
back.  So a cached module that runs fused never imports numba (0.18 s of a 0.3 s warm start).

numba is imported, on first need, through :func:`methodgen.nbcache.numba`: by the lazy
decorators :func:`jit` (a module's few numba-compiled functions), by a kernel the LLVM route
cannot translate, and by :mod:`methodgen.nbruntime` (any name not defined here is looked up
there: ``_rt.stack_buffer`` in a numba-compiled kernel, ``_rt.handle`` …).

:data:`SOURCE_SHA256` covers this file and ``nbruntime.py``: the compiled runtime reads the
configuration through the positions defined here, so a change of either is a new runtime
(its cached machine code is rebuilt, and modules generated for the old one refuse to load).

This module imports numpy and the standard library only.
"""

from __future__ import annotations

import hashlib
import os

import numpy

from . import ktypes as _t
from . import nbcache as _nbcache

__all__ = ["KERNEL_TYPES", "CFG", "FCFG", "STATUS", "SOURCE_SHA256", "MIN_BATCH", "int_config", "float_config",
           "no_kernel", "run", "use_block", "jit", "materialize", "res_rows", "jac_rows"]

_HERE = os.path.dirname(os.path.abspath(__file__))


def _digest() -> str:
    h = hashlib.sha256()
    for name in ("nbabi.py", "nbruntime.py"):
        with open(os.path.join(_HERE, name), "rb") as f:
            h.update(hashlib.sha256(f.read()).digest())
    return h.hexdigest()


#: SHA-256 over this file and ``nbruntime.py``: the stamp of the runtime's cached machine code
#: and the runtime a generated module names.
SOURCE_SHA256 = _digest()

# --- kernel types ----------------------------------------------------------------------------

_f8 = _t.float64
_i8 = _t.int64
_V = _t.float64[::1]
_M = _t.float64[:, ::1]

#: Signatures of the kernels (see :mod:`methodgen.nbruntime`), as plain data.
KERNEL_TYPES = {
    "guess": _t.void(_V, _f8, _V, _V),
    "res": _t.void(_V, _V, _V, _f8, _V, _V),
    "resjac": _t.void(_V, _V, _V, _f8, _V, _V, _M),
    "scale": _f8(_V, _f8, _V),
    "post": _t.void(_V, _V, _V, _V, _f8, _f8, _f8, _V, _V),
    "hs": _t.void(_V, _V, _V),
    "check": _t.void(_V, _V, _V),
}

# --- configuration ---------------------------------------------------------------------------

#: Positions in the int configuration array ``cfg`` of :func:`run`.
CFG = {name: i for i, name in enumerate((
    "N",            # unknowns of the step equations (0: explicit)
    "DIM",          # state length
    "STAGES",       # stages of the composition (1: the base method)
    "NF",           # first-same-as-last force components following Δy in post
    "LERR",         # local error estimate: 0 none, 1 "direct", 2 "carry"
    "KLERR",        # components of a carried estimate
    "POST_EXTRA",   # where the local-error values start in post
    "POST_DOMAIN",  # where the domain conditions start
    "NDOMAIN",      # how many domain conditions
    "POST_TT",      # where g, the level-set defect and its scale start
    "TT_GUARD",     # 1: time-transformation guard
    "POST_EJ",      # where H and its size at y1 start
    "EJUMP",        # 1: energy-jump test
    "POST_LEN",     # length of post's output
    "HAS_SCALE",    # 1: the module has a scale kernel (floor of the unknowns' size)
    "RESOLUTION",   # 0 none, 1 "full", 2 "reduced"
    "KIND",         # 0 Newton, 1 linearly implicit, 2 explicit
    "KL", "KU",     # bandwidths of the Newton matrix
))}
#: Positions in the float configuration array ``fcfg`` of :func:`run`.
FCFG = {name: i for i, name in enumerate((
    "LERR2", "LERR_SCALE", "MAX_LEVEL_DEFECT", "MAX_ENERGY_JUMP", "MAX_RESOLUTION",
    "NEWTON_FAILURE_RESOLUTION", "MAX_PREDICTOR_DISAGREEMENT", "REUSE_RATE", "AUTO_RATE",
    "AUTO_HOLD",
))}

#: Status codes (the generated module's _OK, _DIVERGED, ... have the same values).
STATUS = {name: i for i, name in enumerate((
    "OK", "DIVERGED", "NOT_CONVERGED", "UNRESOLVED", "MISPREDICTED", "LINEAR_FAILED", "NON_FINITE",
    "OUT_OF_DOMAIN", "LOCAL_ERROR", "SLOW", "UNRESOLVED_START", "TIME_SCALE", "ENERGY_JUMP"))}

_EPS = 2.220446049250313e-16
# Newton stops when the increment is at round-off level relative to the unknown, or when
# increments stop decreasing once below sqrt(eps) (the generated modules' _TOL_*).
_TOL_ROUNDOFF = 4.0 * _EPS
_TOL_PLATEAU = 1.4901161193847656e-08

#: Explicit batches of at least this many trajectories take methodgen.nbbatch's lock-step block.
MIN_BATCH = 16


def int_config(**values) -> numpy.ndarray:
    """The ``cfg`` array of :func:`run` from its entries by name (every one of :data:`CFG`)."""
    return _config(CFG, values, numpy.int64)


def float_config(**values) -> numpy.ndarray:
    """The ``fcfg`` array of :func:`run` from its entries by name (every one of :data:`FCFG`)."""
    return _config(FCFG, values, numpy.float64)


def _config(names: dict, values: dict, dtype) -> numpy.ndarray:
    if set(values) != set(names):
        missing = sorted(set(names) - set(values))
        extra = sorted(set(values) - set(names))
        raise ValueError(f"runtime configuration: missing {missing}, unknown {extra} "
                         f"(this module was generated for another methodgen.nbruntime)")
    out = numpy.zeros(len(names), dtype=dtype)
    for name, value in values.items():
        out[names[name]] = value
    return out


def use_block(cfg, batch: int) -> bool:
    """True when a batch of ``batch`` trajectories of a module with configuration ``cfg``
    takes :func:`methodgen.nbbatch.run_block`: explicit stages and at least :data:`MIN_BATCH`
    trajectories."""
    return int(cfg[CFG["KIND"]]) == 2 and batch >= MIN_BATCH


# --- kernels a module does not have --------------------------------------------------------------

class _Missing:
    """The stand-in of a kernel a module does not have, compiled only when the shared runtime's
    loop needs it (:func:`methodgen.nbruntime.handle`): a run on the fused loop, which never
    calls it, loads no numba at all."""

    __slots__ = ("kind",)

    def __init__(self, kind):
        self.kind = kind

    def compiled(self):
        from . import nbruntime
        return nbruntime.stand_in(self.kind)

    def __call__(self, *args):
        return self.compiled()(*args)

    def __repr__(self):
        return f"no_kernel({self.kind!r})"


_MISSING = {}


def no_kernel(kind: str):
    """The stand-in kernel of ``kind`` (a key of :data:`KERNEL_TYPES`), for a module without one
    (compiled, or loaded from the cache, when first passed to the compiled runtime)."""
    if kind not in KERNEL_TYPES:
        raise KeyError(f"no kernel kind {kind!r}; valid: {sorted(KERNEL_TYPES)}")
    got = _MISSING.get(kind)
    if got is None:
        got = _MISSING[kind] = _Missing(kind)
    return got


# --- numba-compiled functions of a module, compiled on first need ---------------------------------

class _Lazy:
    """A function of a generated module to be compiled by ``numba.njit(**options)`` when first
    called (or when anything else of its module is compiled by numba: :func:`materialize`).
    ``py_func`` is the Python function, as on numba's dispatcher (the LLVM route reads it)."""

    __slots__ = ("py_func", "options", "_real")

    def __init__(self, py_func, options):
        self.py_func = py_func
        self.options = options
        self._real = None

    def real(self):
        if self._real is None:
            numba = _nbcache.numba()
            self._real = numba.njit(**self.options)(self.py_func)
        return self._real

    def __call__(self, *args):
        materialize(self.py_func.__globals__)
        return self.real()(*args)

    def __repr__(self):
        return f"<lazily compiled {self.py_func.__qualname__}>"


def jit(**options):
    """Decorator: ``numba.njit(**options)`` applied when the function is first needed."""
    def deco(py_func):
        return _Lazy(py_func, options)
    return deco


def materialize(namespace: dict):
    """Before numba compiles a function of the module whose globals are ``namespace``: numba
    imported (with the module's cache guard), the runtime's types registered, and every lazily
    compiled function of the module replaced by its numba dispatcher (numba resolves a called
    global at compile time and must find a dispatcher there)."""
    numba = _nbcache.numba()
    from . import nbruntime  # noqa: F401  (registers LLVM kernels as first-class functions)
    namespace.setdefault("numba", numba)
    for name, value in list(namespace.items()):
        if isinstance(value, _Lazy):
            namespace[name] = value.real()


# --- the run ------------------------------------------------------------------------------------

def run(guess, res, resjac, scale, post_k, hs, check, cfg, fcfg, lerr_index, domain_pos, gammas, ratios,
        kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter, check_resolution, solver, use_tol, tol,
        compensated, its, fstat, fval, every, smode, slu_ok, sLU, spiv):
    """Steps ``n0 .. n1-1`` of every trajectory (see :func:`methodgen.nbruntime.run_loop` for
    the arguments): on the module's fused loop when its kernels came through LLVM IR
    (:mod:`methodgen.fused`, which hands back to the shared runtime's loop on any failure),
    else on that loop."""
    from . import fused, llvmkernels

    handed_back = None
    if isinstance(post_k, llvmkernels.LLVMKernel):
        handed_back = fused.run_fused((guess, res, resjac, post_k, hs, check, scale), cfg, fcfg, lerr_index, domain_pos,
                                      gammas, ratios, kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter,
                                      check_resolution, solver, use_tol, tol, compensated, its, fstat, every, smode)
        if handed_back is True:
            return
    from . import nbruntime
    nbruntime.run_loop(guess, res, resjac, scale, post_k, hs, check, cfg, fcfg, lerr_index, domain_pos, gammas,
                       ratios, kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter, check_resolution,
                       solver, use_tol, tol, compensated, its, fstat, fval, every, smode, slu_ok, sLU, spiv)
    if handed_back is not None and (fstat[:, 0] == STATUS["OK"]).all():
        fused.false_alarm(handed_back)


def res_rows(res, Z, Y, h, p, R):
    """The residual at each row of Z, Y (no compensation): :func:`methodgen.nbruntime.res_rows`."""
    from . import nbruntime
    nbruntime.res_rows(res, Z, Y, h, p, R)


def jac_rows(resjac, Z, Y, h, p, R, J):
    """The residual and the Jacobian at each row of Z, Y: :func:`methodgen.nbruntime.jac_rows`."""
    from . import nbruntime
    nbruntime.jac_rows(resjac, Z, Y, h, p, R, J)


def __getattr__(name):
    # the numba runtime's other names (stack_buffer in a numba-compiled kernel, handle, …)
    if name.startswith("__"):
        raise AttributeError(name)
    from . import nbruntime
    try:
        return getattr(nbruntime, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
