"""The stepper compiled for one module, with its kernels inlined (LLVM IR), and its driver.

A call through a function pointer per stage (and per Newton iteration of an implicit stage)
cost about 13 ns, a third of an explicit step of Kepler's Störmer–Verlet composed to order 10
(35 stages).  So this module compiles, once per module (milliseconds, or loaded from the
machine-code cache), :func:`methodgen.runtime.stepper.stepper` with the module's kernels inlined
(their kernel IR, :mod:`methodgen.codegen.llvmkernels`) and its configuration
(:mod:`methodgen.codegen.abi`) bound as constants, and runs it.

The stepper records every failure itself (status, step, iteration, value, stage).  Where a
resolution verdict needs the spectral radius of a Newton matrix, it stops and asks;
:func:`run_fused` computes ρ from the eigenvalues (LAPACK) and calls it again from that stage.
Explicit batches of at least ``nbabi.MIN_BATCH`` take :func:`run_lockstep`
(:func:`methodgen.runtime.stepper.lockstep`, the module's block kernel inlined).  The same stepper
runs as Python with ``python=True`` (``METHODGEN_STEPPER=python``): the reference the compiled
loop is tested against, bit for bit.

The loop is called through its C entry point with ctypes (:func:`_drive`).
"""

from __future__ import annotations

import math
import os
import threading
import types

import numpy

from ..codegen import ktypes as _t
from ..codegen import llvmkernels as _lk
from . import stepper as _stepper
from ..codegen import abi as _abi
from ..codegen.abi import STATUS as _STATUS

__all__ = ["run_fused", "run_lockstep", "run_rows"]

_f8, _i8, _V, _M = _t.float64, _t.int64, _t.float64[::1], _t.float64[:, ::1]
_T3 = _t.float64[:, :, ::1]

#: signature of the compiled stepper (:func:`methodgen.runtime.stepper.stepper`): Y, C, G, K, PJ (B, ·),
#: traj (rows, B, DIM), p, kick_a, drift, kick_b, h, n0, n1, every, nxt0, row0, stop (2), iterations (B, n1 - n0), solver modes (B, STAGES),
#: "reuse"'s valid flags (B, STAGES), factors (B·STAGES, N·N) and permutations (B·STAGES, N),
#: failures (B, 4), failure values (B), the question (4), the Newton matrix asked about,
#: maxiter, tol, B, b0, nr, k0, nxtr, rowr (solver, use_tol, check_resolution and compensated are
#: constants of each compiled loop)
LOOP_SIG = _t.void(_M, _M, _M, _M, _M, _T3, _V, _V, _V, _V, _f8, _i8, _i8, _i8, _i8, _i8, _V,
                   _M, _M, _M, _M, _M, _M, _V, _V, _M, _i8, _f8, _i8, _i8, _i8, _i8, _i8, _i8)


def _drive(loop, *args):
    """Run the compiled stepper through its C entry (ctypes); arrays by reference, their
    structures packed into one buffer (:func:`methodgen.codegen.llvmkernels.packed_structs`), which
    lives until the call returns."""
    arrays = [a for a in args if isinstance(a, numpy.ndarray)]
    buf, addrs = _lk.packed_structs(arrays)
    it = iter(addrs)
    loop.c_call(*[next(it) if isinstance(a, numpy.ndarray) else a for a in args])
    del buf


class _Addr(int):
    """The address of an array structure packed already (:func:`_scratch`, :func:`_constant`):
    :func:`_drive` passes it as it is.  Whoever made it keeps the array and the buffer alive."""


_LOCAL = threading.local()
_KEEP = 64
#: Batches up to this size keep their work arrays between calls (:func:`_scratch`); a larger
#: one allocates its own (the per-call cost is then small beside the run's, and a cache must
#: not hold a large batch's arrays).
_SCRATCH_B = 64


def _scratch(key, shapes):
    """Zeroed float64 work arrays of ``shapes`` for one run of a loop, and their packed
    structures' addresses (:class:`_Addr`): made once per thread and key, zeroed again at each
    later call (the arrays and their structures cost more to make than to clear)."""
    store = getattr(_LOCAL, "scratch", None)
    if store is None:
        store = _LOCAL.scratch = {}
    got = store.get(key)
    if got is None:
        arrays = [numpy.zeros(sh) for sh in shapes]
        buf, addrs = _lk.packed_structs(arrays)
        got = (arrays, [_Addr(x) for x in addrs], buf)
        store[key] = got
        while len(store) > _KEEP:
            del store[next(iter(store))]
    else:
        for arr in got[0]:
            arr.fill(0.0)
    return got[0], got[1]


_CONSTANTS: dict = {}


def _constant(a):
    """:class:`_Addr` of a module's constant array (the same object at every call: its stage
    coefficients), packed once and kept with the array (so its id is not reused while the entry
    lives); any other array as it is."""
    got = _CONSTANTS.get(id(a))
    if got is None or got[0] is not a:
        buf, (addr,) = _lk.packed_structs([a])
        got = _CONSTANTS[id(a)] = (a, _Addr(addr), buf)
        while len(_CONSTANTS) > 4 * _KEEP:
            del _CONSTANTS[next(iter(_CONSTANTS))]
    return got[1]


_LOOPS: dict = {}

#: The kernels of a module, in the order run_fused takes them (methodgen.codegen.abi.KERNEL_TYPES).
KERNEL_NAMES = ("guess", "res", "resjac", "post", "hs", "check", "scale", "force", "proj")


def spectral_h_omega(J, resol: int) -> float:
    """h·ω from the spectral radius ρ of ``J - I`` (its eigenvalues, LAPACK, complex input): 2ρ for ``resol`` 1 ("full"), 2ρ^(1/2) for 2 ("reduced"); ∞ for a
    non-finite matrix."""
    A = numpy.array(J, dtype=numpy.complex128) - numpy.eye(J.shape[0])
    if not numpy.isfinite(A).all():
        rho = math.inf
    else:
        rho = float(numpy.max(numpy.abs(numpy.linalg.eigvals(A))))
    return 2.0 * rho if resol == 1 else 2.0 * math.sqrt(rho)


#: signature of the compiled lock-step loop (:func:`methodgen.runtime.stepper.lockstep`): Y, C, G (B, ·),
#: traj (rows, B, DIM), p, kick_a, drift, kick_b, h, n0, n1, every, nxt0, row0, failures (B, 4), failure
#: values (B), B
LOCKSTEP_SIG = _t.void(_M, _M, _M, _T3, _V, _V, _V, _V, _f8, _i8, _i8, _i8, _i8, _i8, _M, _V, _i8)


def _compiled_loop(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block=None):
    """The loop for this module's kernels and configuration, compiled on first use (or loaded
    from the machine-code cache).  ``block``: ``(post_block, lanes)`` for the lock-step loop
    (:func:`methodgen.runtime.stepper.lockstep`).

    Raises
    ------
    methodgen.codegen.llvmkernels.Unsupported
        The translator refuses the loop with these kernels (the message names the kernel)."""
    # keyed by what the loop is compiled from: the kernels' machine code (their symbols name
    # the text they were translated from; an id() is reused once a regenerated module's old
    # kernels are freed) and the constants bound into it
    kernels = tuple(kernels) + ((block[0],) if block else ())
    key = (tuple(getattr(k, "symbol", None) or ("id", id(k)) for k in kernels),
           cfg.tobytes(), fcfg.tobytes(), tuple(lerr_index), tuple(map(bool, domain_pos)),
           tuple(map(float, gammas)), tuple(map(float, ratios)), options, block[1] if block else 0)
    got = _LOOPS.get(key)
    if got is None:
        fn, sig = loop_function(kernels[:len(KERNEL_NAMES)], cfg, fcfg, lerr_index, domain_pos, gammas, ratios,
                                options, block)
        got = _lk.compile_kernel(fn, sig, globals_=fn.__globals__, c_entry=True)
        # (the kernels are kept with the loop: an id() in the key is not reused while it lives)
        _LOOPS[key] = got = (got, kernels)
    return got[0], key


def loop_function(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block=None):
    """``(function, signature)``: :func:`methodgen.runtime.stepper.stepper` (with ``block``:
    :func:`methodgen.runtime.stepper.lockstep`) with a module's configuration and kernels bound as its
    globals, what :func:`_compiled_loop` compiles (and :func:`methodgen.codegen.llvmkernels.assembly`
    shows)."""
    consts = _bound(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block)
    entry, sig = (_stepper.lockstep, LOCKSTEP_SIG) if block else (_stepper.stepper, LOOP_SIG)
    return types.FunctionType(entry.__code__, consts, entry.__name__), sig


def python_stepper(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block=None):
    """:func:`methodgen.runtime.stepper.stepper` (with ``block``: :func:`methodgen.runtime.stepper.lockstep`) bound
    to a module's kernels (their Python functions) and configuration, to run as plain Python: the
    same source as the compiled loop, the reference it is tested against (slow: an
    interpreter's loop)."""
    consts = _bound(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block)
    # the stepper's work arrays (on the stack when compiled: the translator knows the name, and a
    # function bound here would make the loop's machine code uncacheable)
    consts["stack_array"] = numpy.zeros
    # the kernels as callables: their machine code (an LLVM kernel called from Python goes
    # through a C entry of the same translation), so that a comparison with the compiled loop
    # tests the stepper alone
    consts.update(zip(KERNEL_NAMES, kernels))
    if block:
        consts["post_block"] = block[0]
    entry = _stepper.lockstep if block else _stepper.stepper
    return types.FunctionType(entry.__code__, consts, entry.__name__)


#: The stepper's helpers (:mod:`methodgen.runtime.stepper`), bound with each loop's constants.
_HELPERS = ("lane_status", "project", "small_solve", "solve", "resolution", "lu", "lu_solve", "amax",
            "compensated_add")


def _bound(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block=None) -> dict:
    """The stepper's globals for a module: its configuration as constants (:mod:`methodgen.codegen.abi`),
    the run's options that select code (``options``: solver code, use_tol, check_resolution,
    compensated, as ints), the status codes, its kernels' Python functions and the helpers
    bound to the same."""
    C = _abi.CFG
    F = _abi.FCFG
    n = int(cfg[C["N"]])
    fr = float(fcfg[F["NEWTON_FAILURE_RESOLUTION"]])
    resol = int(cfg[C["RESOLUTION"]])
    pm = int(cfg[C["PROJ"]])
    consts = {"_PL": max(int(cfg[C["POST_LEN"]]), 1), "_STAGES": int(cfg[C["STAGES"]]),
              "_DIM": int(cfg[C["DIM"]]), "_NF": int(cfg[C["NF"]]), "_NDOMAIN": int(cfg[C["NDOMAIN"]]),
              "_PD": int(cfg[C["POST_DOMAIN"]]), "_TT_GUARD": int(cfg[C["TT_GUARD"]]),
              "_PT": int(cfg[C["POST_TT"]]), "_LERR": int(cfg[C["LERR"]]), "_PE": int(cfg[C["POST_EXTRA"]]),
              "_EJUMP": int(cfg[C["EJUMP"]]), "_PJ": int(cfg[C["POST_EJ"]]),
              "_KIND": int(cfg[C["KIND"]]), "_N": n, "_NG": max(int(cfg[C["NF"]]), 1), "_NZ": max(n, 1), "_KL": int(cfg[C["KL"]]),
              "_KU": int(cfg[C["KU"]]), "_RESOL": resol, "_HAS_SCALE": int(cfg[C["HAS_SCALE"]]),
              "_LERR2": float(fcfg[F["LERR2"]]), "_MLD": float(fcfg[F["MAX_LEVEL_DEFECT"]]),
              "_MEJ": float(fcfg[F["MAX_ENERGY_JUMP"]]), "_MAXRES": float(fcfg[F["MAX_RESOLUTION"]]),
              "_MAXDIS": float(fcfg[F["MAX_PREDICTOR_DISAGREEMENT"]]),
              "_AUTO_RATE": float(fcfg[F["AUTO_RATE"]]), "_AUTO_HOLD1": int(fcfg[F["AUTO_HOLD"]]) + 1,
              # the threshold of the resolution check, squared for "reduced" (x*x, as the stepper)
              "_RTHRESH": 0.5 * fr if resol == 1 else (0.5 * fr) * (0.5 * fr),
              "_TOL_ROUNDOFF": _abi.TOL_ROUNDOFF, "_TOL_PLATEAU": _abi.TOL_PLATEAU,
              "_KLERR": int(cfg[C["KLERR"]]), "_NK": max(int(cfg[C["KLERR"]]), 1),
              "_LIDX": numpy.array(list(lerr_index) or [0], dtype=numpy.int64),
              "_RATIOS": numpy.array(ratios, dtype=numpy.float64), "_GAMMA0": float(gammas[0]),
              "_NFR": fr, "_LERR_SCALE": float(fcfg[F["LERR_SCALE"]]), "_REUSE_RATE": float(fcfg[F["REUSE_RATE"]]),
              "_DPOS": numpy.array([int(bool(v)) for v in domain_pos] or [0], dtype=numpy.int64),
              "_MERGED": int(cfg[C["MERGED"]]),
              "_PROJ": pm, "_PM": max(pm, 1), "_PSYM": int(cfg[C["PROJ_SYM"]]),
              "_PGV": max(pm, 1) * (1 + int(cfg[C["DIM"]])) + int(cfg[C["DIM"]]),
              "_PTOL": float(fcfg[F["PROJ_TOL"]]), "_PPLAT": float(fcfg[F["PROJ_PLATEAU"]]),
              "_PNOISE": float(fcfg[F["PROJ_NOISE"]]),
              "math": math}
    # The non-finite state check of an explicit stage is made at the composed step's end: a stage
    # adds its increment to the state, so a component that became inf or NaN stays so (inf + x is
    # inf or NaN, NaN + x is NaN) and the step's end shows it; checking every component at every
    # stage was 10 % of a Störmer–Verlet o10 stage.  Where a domain or time-scale check reads the
    # stage's end, a NaN there must be reported as non-finite first: every stage.
    consts["_FINITE_EVERY_STAGE"] = int(consts["_KIND"] != 2 or consts["_NDOMAIN"] != 0 or consts["_TT_GUARD"] != 0)
    consts.update({"_S_" + name: code for name, code in _STATUS.items()})
    consts.update(zip(("_solver", "_usetol", "_chk", "_comp"), options))
    for name, k in zip(KERNEL_NAMES, kernels):
        consts[name] = getattr(k, "py_func", None)
    if block:
        consts["post_block"] = getattr(block[0], "py_func", None)
        consts["_L"] = int(block[1])
    # the helpers, with their constants resolved in this loop's configuration
    for name in _HELPERS:
        consts[name] = types.FunctionType(getattr(_stepper, name).__code__, consts, name)
    return consts


def run_fused(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p,
              maxiter, check_resolution, solver, use_tol, tol, compensated, its, fstat, fval, every, smode, slu_ok,
              sLU, spiv, PJ=None, *, python=False):
    """Steps ``n0 .. n1-1`` on the module's compiled stepper (the arguments of
    :func:`methodgen.runtime.nbabi.run`; ``kernels`` as :data:`KERNEL_NAMES`; ``PJ`` (B, 2 PM) a projected
    module's levels and multipliers, updated):
    ``Y``, ``C``, ``FRC``, ``traj``, ``its``, ``smode``, ``fstat``, ``fval`` updated, failures
    included.  ``python``: run the same stepper as plain Python (:func:`python_stepper`)
    instead."""
    CFG = _abi.CFG
    kind = int(cfg[CFG["KIND"]])
    pm = int(cfg[CFG["PROJ"]])
    if n1 <= n0:
        fstat[:, 0] = _STATUS["OK"]
        return
    options = (int(solver), int(bool(use_tol)), int(bool(check_resolution)), int(bool(compensated)))
    if python:
        loop = python_stepper(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options)
        drive = _call
    else:
        loop, _ = _compiled_loop(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options)
        drive = _drive
    # the stepper's arrays are C-contiguous float64: inputs of another layout are copied (the
    # state, compensation and force back at the end)
    p, kick_a, drift, kick_b = (numpy.ascontiguousarray(a, dtype=numpy.float64) for a in (p, kick_a, drift, kick_b))
    state = (Y, C, FRC)
    Y, C, FRC = (numpy.ascontiguousarray(a, dtype=numpy.float64) for a in state)
    nxt0 = (n0 // every + 1) * every
    r0 = 0                     # the row the stepper's traj starts at
    user_rows = None
    if not (traj.dtype.char == "d" and traj.flags.c_contiguous):
        # a caller's ``out`` of another layout: the stepper writes a contiguous copy of the
        # rows this call can reach
        r0 = nxt0 // every
        user_rows = traj[r0:n1 // every + 1]
        traj = numpy.ascontiguousarray(user_rows, dtype=numpy.float64)
    B = Y.shape[0]
    n = int(cfg[CFG["N"]])
    nk = max(int(cfg[CFG["KLERR"]]), 1)
    resol = int(cfg[CFG["RESOLUTION"]])
    m1 = max(n, 1)
    # the work arrays, then the placeholders of arrays this run does not use (one element)
    shapes = ((2,), (B, nk + 2), (B, 4), (B,), (4,), (m1, m1), (1, 2), (1, 1), (1, 1), (1, 1), (1, 1), (1, 1))
    if python or B > _SCRATCH_B:
        work = [numpy.zeros(sh) for sh in shapes]
        refs = work
    else:
        # made once per loop and size, with the structures the C entry takes
        work, refs = _scratch((id(loop), B, nk, m1), shapes)
        kick_a, drift, kick_b = (_constant(a) for a in (kick_a, drift, kick_b))
    st, K, fst, fvl, dec, jout = work[:6]
    # the iterations: counted as floats (the translated code's arrays are float64) in place of
    # its, when its is zeros (its usual state: 0 has the same bits as 0.0), else in a copy
    counted = kind != 2 or pm          # (an explicit step has no iterations; a projected one has)
    in_place = counted and its.flags.c_contiguous and not its.any()
    itsf = its.view(numpy.float64) if in_place else numpy.zeros((B, n1 - n0)) if counted else refs[7]
    PJ = refs[6] if PJ is None else PJ
    smf = smode.astype(numpy.float64) if kind == 0 else refs[8]
    reuse = kind == 0 and solver == 3
    if reuse:
        S = smode.shape[1]
        m = max(n, 1)
        okf = slu_ok.astype(numpy.float64)
        luf = numpy.ascontiguousarray(sLU, dtype=numpy.float64).reshape(B * S, m * m)
        pvf = spiv.astype(numpy.float64).reshape(B * S, m)
    else:
        okf, luf, pvf = refs[9:12]
    b0, nr, k0, limit = 0, -1, 0, n1
    while True:
        nxtr = (max(nr, 0) // every + 1) * every
        drive(loop, Y, C, FRC, refs[1], PJ, traj, p, kick_a, drift, kick_b, float(h), int(n0), int(limit),
              int(every), nxt0, nxt0 // every - r0, refs[0], itsf, smf, okf, luf, pvf, refs[2], refs[3], refs[4],
              refs[5], int(maxiter), float(tol), B, b0, nr, k0, nxtr, nxtr // every - r0)
        if not st[0]:
            break
        # the stepper asks for the spectral radius of J - I at trajectory b, step n, stage k:
        # computed here, then that stage again with it
        asked = (b0, nr, k0)
        b0, nr, k0, limit = (int(v) for v in dec)
        if (b0, nr, k0) == asked:
            # a stage given its answer must not ask again: a defect of the stepper, not of the run
            raise RuntimeError(f"methodgen.runtime.stepper asked twice at trajectory {b0}, step {nr}, stage {k0}")
        dec[3] = spectral_h_omega(jout[:n, :n], resol)
    if in_place:
        its[...] = itsf        # (numpy copies overlapping operands first)
    elif counted:
        its += itsf.astype(numpy.int64)
    if kind == 0:
        smode[...] = smf.astype(numpy.int64)
    if reuse:
        slu_ok[...] = okf.astype(numpy.int64)
        sLU[...] = luf.reshape(sLU.shape)
        spiv[...] = pvf.reshape(spiv.shape).astype(numpy.int64)
    fstat[...] = fst.astype(numpy.int64)
    fval[...] = fvl
    if user_rows is not None:
        user_rows[...] = traj
    for mine, theirs in zip((Y, C, FRC), state):
        if mine is not theirs:
            theirs[...] = mine


def _call(loop, *args):
    """Run the stepper as Python (:func:`python_stepper`)."""
    loop(*args)


def run_lockstep(block, kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, kick_a, drift, kick_b, traj,
                 n0, n1, Y, C, FRC, h, p, check_resolution, compensated, fstat, fval, every, *, python=False):
    """Steps ``n0 .. n1-1`` of an explicit module's batch in lock-step
    (:func:`methodgen.runtime.stepper.lockstep`; ``block`` = the module's block kernel and its lanes, the
    other arguments :func:`run_fused`'s).  ``python``: the same loop as plain Python."""
    if n1 <= n0:
        fstat[:, 0] = _STATUS["OK"]
        return
    options = (0, 0, int(bool(check_resolution)), int(bool(compensated)))
    if python:
        loop, drive = python_stepper(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block), _call
    else:
        loop, _ = _compiled_loop(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, options, block)
        drive = _drive
    p, kick_a, drift, kick_b = (numpy.ascontiguousarray(a, dtype=numpy.float64) for a in (p, kick_a, drift, kick_b))
    state = (Y, C, FRC)
    Y, C, FRC = (numpy.ascontiguousarray(a, dtype=numpy.float64) for a in state)
    rows = traj
    if not (traj.dtype.char == "d" and traj.flags.c_contiguous):
        rows = numpy.ascontiguousarray(traj, dtype=numpy.float64)
    B = Y.shape[0]
    fst = numpy.zeros((B, 4))
    fvl = numpy.zeros(B)
    nxt0 = (n0 // every + 1) * every
    drive(loop, Y, C, FRC, rows, p, kick_a, drift, kick_b, float(h), int(n0), int(n1), int(every), nxt0,
          nxt0 // every, fst, fvl, B)
    if rows is not traj:
        traj[...] = rows
    fstat[...] = fst.astype(numpy.int64)
    fval[...] = fvl
    for mine, theirs in zip((Y, C, FRC), state):
        if mine is not theirs:
            theirs[...] = mine


#: signature of the compiled rows loop (:func:`methodgen.runtime.stepper.rows`): Z, Y, h, p, R, J, B
ROWS_SIG = _t.void(_M, _M, _f8, _V, _M, _M, _i8)


def run_rows(kernel, jac, cfg, Z, Y, h, p, R, J=None):
    """The residual (``jac`` False: ``kernel`` is the module's ``res``) or the residual and the
    Newton matrix (True: its ``resjac``) at each row of ``Z``, ``Y`` (B, ·), into ``R`` (B, N)
    and ``J`` (B, N, N): :func:`methodgen.runtime.stepper.rows`, compiled with the kernel inlined."""
    n = int(cfg[_abi.CFG["N"]])
    kernels = [_Absent()] * len(KERNEL_NAMES)
    kernels[KERNEL_NAMES.index("resjac" if jac else "res")] = kernel
    fcfg = numpy.zeros(len(_abi.FCFG))
    opts = (0, 0, 0, 0)
    B = Z.shape[0]
    # (copies: writable C-contiguous rows, as a kernel's signature takes them)
    Z, Y, p = (numpy.array(a, dtype=numpy.float64, order="C") for a in (Z, Y, p))
    R2 = numpy.zeros((B, max(n, 1)))
    J2 = numpy.zeros((B * max(n, 1), max(n, 1))) if jac else numpy.zeros((1, 1))
    key = ("rows", kernel.symbol, bool(jac), cfg.tobytes())
    got = _LOOPS.get(key)
    if got is None:
        consts = _bound(kernels, cfg, fcfg, (), (), (1.0,), (1.0,), opts)
        consts["_JAC"] = int(bool(jac))
        got = _lk.compile_kernel(types.FunctionType(_stepper.rows.__code__, consts, "rows"), ROWS_SIG,
                                 globals_=consts, c_entry=True)
        _LOOPS[key] = got = (got, kernel)
    _drive(got[0], Z, Y, float(h), p, R2, J2, B)
    R[...] = R2[:, :n]
    if jac:
        J[...] = J2.reshape(B, max(n, 1), max(n, 1))[:, :n, :n]


class _Absent:
    """A kernel the rows loop does not call."""
    py_func = None
