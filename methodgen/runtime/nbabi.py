"""The shared compiled runtime's interface, without numba: what a numba module needs to load
and run on its fused loop.

A generated numba module imports this module as ``_rt``.
It re-exports the runtime's contract (:mod:`methodgen.codegen.abi`: the kernels' signatures
:data:`KERNEL_TYPES`, the configuration arrays' names :data:`CFG`, :data:`FCFG`, the status
codes) and holds :func:`run`, which runs a call on the
module's fused loop (:mod:`methodgen.runtime.fused`: machine code from llvmlite, called through
ctypes) and imports the numba runtime only when that loop does not apply or hands the call
back.  So a cached module that runs fused never imports numba (0.18 s of a 0.3 s warm start).

numba is imported, on first need, through :func:`methodgen.codegen.nbcache.numba`: by the lazy
decorators :func:`jit` (a module's few numba-compiled functions), by a kernel the LLVM route
cannot translate, and by :mod:`methodgen.runtime.nbruntime` (any name not defined here is looked up
there: ``_rt.stack_buffer`` in a numba-compiled kernel).

:data:`SOURCE_SHA256` covers this file, ``abi.py`` and ``nbruntime.py``: the compiled runtime reads the
configuration through the positions defined in :mod:`methodgen.codegen.abi`, so a change of any is a new runtime
(its cached machine code is rebuilt, and modules generated for the old one refuse to load).

This module imports numpy and the standard library only.
"""

from __future__ import annotations

import hashlib
import os

import numpy

from ..codegen import abi as _abi
from ..codegen import nbcache as _nbcache

__all__ = ["KERNEL_TYPES", "CFG", "FCFG", "STATUS", "SOURCE_SHA256", "MIN_BATCH", "int_config", "float_config",
           "no_kernel", "run", "use_block", "jit", "materialize", "res_rows", "jac_rows"]



#: The runtime's stamp (:data:`methodgen.codegen.abi.RUNTIME_SHA256`): the stamp of its cached machine
#: code and the runtime a generated module names.
SOURCE_SHA256 = _abi.RUNTIME_SHA256

# --- the contract (methodgen.codegen.abi), re-exported for the generated modules' ``_rt.`` -------------

KERNEL_TYPES = _abi.KERNEL_TYPES
CFG = _abi.CFG
FCFG = _abi.FCFG
STATUS = _abi.STATUS
_EPS = _abi.EPS
_TOL_ROUNDOFF = _abi.TOL_ROUNDOFF
_TOL_PLATEAU = _abi.TOL_PLATEAU

#: Explicit batches of at least this many trajectories run in lock-step (methodgen.runtime.stepper.lockstep).
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
                         f"(this module was generated for another methodgen.runtime.nbruntime)")
    out = numpy.zeros(len(names), dtype=dtype)
    for name, value in values.items():
        out[names[name]] = value
    return out


def use_block(cfg, batch: int) -> bool:
    """True when a batch of ``batch`` trajectories of a module with configuration ``cfg``
    runs in lock-step (:func:`methodgen.runtime.stepper.lockstep`): explicit stages (not projected) and
    at least :data:`MIN_BATCH` trajectories."""
    return int(cfg[CFG["KIND"]]) == 2 and not int(cfg[CFG["PROJ"]]) and batch >= MIN_BATCH


# --- kernels a module does not have --------------------------------------------------------------

class _Missing:
    """The stand-in of a kernel a module does not have: the stepper's constants select code
    that never calls it (an explicit step has no Newton kernels).  ``py_func`` is None (nothing
    to inline)."""

    __slots__ = ("kind",)
    py_func = None

    def __init__(self, kind):
        self.kind = kind

    def __call__(self, *args):
        raise RuntimeError(f"methodgen: the {self.kind!r} kernel of a module that has none was called "
                           "(a defect of the stepper's configuration)")

    def __repr__(self):
        return f"no_kernel({self.kind!r})"


_MISSING = {}


def no_kernel(kind: str):
    """The stand-in kernel of ``kind`` (a key of :data:`KERNEL_TYPES`), for a module without one."""
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
        compensated, its, fstat, fval, every, smode, slu_ok, sLU, spiv, *, force_k=None, proj_k=None, PJ=None,
        block=None):
    """Steps ``n0 .. n1-1`` of every trajectory on the module's stepper (:mod:`methodgen.runtime.stepper`),
    compiled with its kernels inlined (:mod:`methodgen.runtime.fused`).

    The arguments: the kernels; the configuration (:mod:`methodgen.codegen.abi`); the stage
    coefficients; ``traj`` (rows, B, DIM): row ``n // every`` gets the state after step
    ``n - 1``; ``Y``, ``C``, ``FRC`` (B, ·): state, compensation, carried force, updated in
    place; ``h``, ``p``; Newton's ``maxiter``, ``check_resolution``, ``solver`` code, ``use_tol``,
    ``tol``; ``compensated``; ``its`` (B, n1 - n0) iterations per step; ``fstat`` (B, 4) status,
    step, iteration, stage and ``fval`` (B) value of a failure; ``every``; the solver state
    ``smode``, ``slu_ok``, ``sLU``, ``spiv``; for a projected module (:mod:`methodgen.symbolic.projection`)
    its ``force_k`` (first-same-as-last, where the base step has it) and ``proj_k`` kernels and
    ``PJ`` (B, 2 PM): the levels to keep, then the multipliers (updated).  ``block``: an explicit
    module's ``(block kernel factory, lanes)``; a batch of at least :data:`MIN_BATCH` then runs
    in lock-step (:func:`methodgen.runtime.stepper.lockstep`, bitwise the same rows).

    Where the stepper cannot be compiled with these kernels (a kernel the LLVM translator
    refused, compiled by numba instead, or ``METHODGEN_KERNELS=numba``) it runs as plain Python
    with them: the same source and results, about a hundred times slower, said once per module
    in a warning.  ``METHODGEN_STEPPER=python`` runs it so always (the reference)."""
    from . import fused

    args = ((guess, res, resjac, post_k, hs, check, scale, force_k or no_kernel("force"), proj_k or no_kernel("proj")), cfg, fcfg, lerr_index, domain_pos, gammas, ratios,
            kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter, check_resolution, solver, use_tol, tol,
            compensated, its, fstat, fval, every, smode, slu_ok, sLU, spiv, PJ)
    python = os.environ.get("METHODGEN_STEPPER", "").strip() == "python"
    if block is not None and use_block(cfg, Y.shape[0]):
        largs = ((block[0](), block[1]),) + args[:13] + (Y, C, FRC, h, p, check_resolution, compensated, fstat,
                                                          fval, every)
        if not python:
            if fused.run_lockstep(*largs):
                return
            _warn_python(post_k)
        fused.run_lockstep(*largs, python=True)
        return
    if not python:
        if fused.run_fused(*args):
            return
        _warn_python(post_k)
    fused.run_fused(*args, python=True)


_WARNED: set = set()


def _warn_python(post_k) -> None:
    """Say once per module that its stepper runs as Python (a kernel numba compiled)."""
    import warnings

    where = getattr(getattr(post_k, "py_func", post_k), "__module__", None) or "a module"
    if where not in _WARNED:
        _WARNED.add(where)
        warnings.warn(f"{where}: the integration loop runs as Python (its kernels were compiled by numba, "
                      "not through LLVM IR: METHODGEN_KERNELS=numba, or a construct the translator refuses): "
                      "the same results, about a hundred times slower", RuntimeWarning, stacklevel=3)


def res_rows(res, cfg, Z, Y, h, p, R):
    """The residual at each row of Z, Y (no compensation): :func:`methodgen.runtime.fused.run_rows`."""
    from . import fused
    fused.run_rows(res, False, cfg, Z, Y, h, p, R)


def jac_rows(resjac, cfg, Z, Y, h, p, R, J):
    """The residual and the Jacobian at each row of Z, Y: :func:`methodgen.runtime.fused.run_rows`."""
    from . import fused
    fused.run_rows(resjac, True, cfg, Z, Y, h, p, R, J)


def __getattr__(name):
    # the numba runtime's other names (stack_buffer in a numba-compiled kernel, handle, …)
    if name.startswith("__"):
        raise AttributeError(name)
    from . import nbruntime
    try:
        return getattr(nbruntime, name)
    except AttributeError:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
