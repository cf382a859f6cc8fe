"""The compiled runtime's interface: what a compiled module (``backend="numba"``) needs to load
and run.

A generated compiled module imports this module as ``_rt``.  It re-exports the runtime's
contract (:mod:`methodgen.codegen.abi`: the kernels' signatures :data:`KERNEL_TYPES`, the
configuration arrays' names :data:`CFG`, :data:`FCFG`, the status codes) and holds :func:`run`,
which runs a call on the module's fused loop (:mod:`methodgen.runtime.fused`: machine code from
llvmlite, called through ctypes), or on the same stepper as Python under
``METHODGEN_STEPPER=python``.  (The name is historical: the kernels' array ABI was numba's.)

:data:`SOURCE_SHA256` covers this file and ``abi.py``: the compiled runtime reads the
configuration through the positions defined in :mod:`methodgen.codegen.abi`, so a change of
either is a new runtime (modules generated for the old one refuse to load).

This module imports numpy and the standard library only.
"""

from __future__ import annotations

import os

import numpy

from ..codegen import abi as _abi

__all__ = ["KERNEL_TYPES", "CFG", "FCFG", "STATUS", "SOURCE_SHA256", "MIN_BATCH", "int_config", "float_config",
           "no_kernel", "run", "use_block", "res_rows", "jac_rows"]


#: The runtime's stamp (:data:`methodgen.codegen.abi.RUNTIME_SHA256`): the runtime a generated
#: module names.
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
                         f"(this module was generated for another methodgen runtime)")
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

    ``METHODGEN_STEPPER=python`` runs the same stepper as plain Python (the reference the
    compiled loop is tested against: the same bits, about a hundred times slower)."""
    from . import fused

    args = ((guess, res, resjac, post_k, hs, check, scale, force_k or no_kernel("force"), proj_k or no_kernel("proj")), cfg, fcfg, lerr_index, domain_pos, gammas, ratios,
            kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter, check_resolution, solver, use_tol, tol,
            compensated, its, fstat, fval, every, smode, slu_ok, sLU, spiv, PJ)
    python = os.environ.get("METHODGEN_STEPPER", "").strip() == "python"
    if block is not None and use_block(cfg, Y.shape[0]):
        largs = ((block[0](), block[1]),) + args[:13] + (Y, C, FRC, h, p, check_resolution, compensated, fstat,
                                                          fval, every)
        fused.run_lockstep(*largs, python=python)
        return
    fused.run_fused(*args, python=python)


def res_rows(res, cfg, Z, Y, h, p, R):
    """The residual at each row of Z, Y (no compensation): :func:`methodgen.runtime.fused.run_rows`."""
    from . import fused
    fused.run_rows(res, False, cfg, Z, Y, h, p, R)


def jac_rows(resjac, cfg, Z, Y, h, p, R, J):
    """The residual and the Jacobian at each row of Z, Y: :func:`methodgen.runtime.fused.run_rows`."""
    from . import fused
    fused.run_rows(resjac, True, cfg, Z, Y, h, p, R, J)
