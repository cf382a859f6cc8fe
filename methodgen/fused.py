"""An explicit module's integration loop compiled with its post kernel inlined (LLVM IR).

On the shared runtime (:func:`methodgen.nbruntime.run`) every stage of an explicit
composition is a call through a function pointer: about 13 ns a stage on Kepler's
Störmer–Verlet composed to order 10 (35 stages), a third of its step.  When a module's
post kernel was compiled through LLVM IR (:mod:`methodgen.llvmkernels`), this module
compiles, once per module and process (milliseconds), the loop of :func:`_explicit_loop`
with that kernel inlined: the same stages, the same compensated update, the same checks,
operation for operation, so the same bits.

It is an accelerator, never the judge: it runs only while every check passes.  When any
check the runtime makes would fail (non-finite state, domain, time-scale guard, local
error, energy jump) it stops and says so, and :func:`run_fused` restores the inputs and
lets the shared runtime run the same call from the start, which records the failure
exactly as before.  Modules it does not apply to (implicit stages, a post kernel numba
compiled, a carried local-error estimate, a trajectory array that is not C-contiguous)
take the shared runtime directly.

The loop's source below is translated by :mod:`methodgen.llvmkernels` with the module's
configuration bound as constants (``_DIM``, ``_STAGES``, …) and its kernels as ``post``
and ``hs``; the numba driver :func:`_drive` (compiled once per machine) calls it.
"""

from __future__ import annotations

import os

import numba
import numpy
from numba import types as _t

from . import llvmkernels as _lk
from . import nbruntime as _rt

__all__ = ["run_fused", "enabled", "SOURCE_SHA256"]

#: SHA-256 of this file: the stamp of the cached driver (as the shared runtime's).
SOURCE_SHA256 = _rt._source_digest(os.path.abspath(__file__))
_rt._install_stamp_guard(os.path.abspath(__file__), SOURCE_SHA256)

_f8, _i8, _V, _M = _rt._f8, _rt._i8, _rt._V, _rt._M
_T3 = _t.float64[:, :, ::1]

#: signature of the compiled loop: Y, C, G (B, ·), traj (rows, B, DIM), p, kick_a, drift,
#: kick_b, h, n0, n1, every, nxt0, row0, check_resolution, compensated, status (1; 1.0 = stopped)
LOOP_SIG = _t.void(_M, _M, _M, _T3, _V, _V, _V, _V, _f8, _i8, _i8, _i8, _i8, _i8, _i8, _i8, _V)


def enabled() -> bool:
    """The fused loop is used unless ``METHODGEN_FUSED=0`` (or the kernels take numba)."""
    return os.environ.get("METHODGEN_FUSED", "1").strip() != "0" and _lk.enabled()


def _explicit_loop(_Y, _C, _G, _T, _p, _ka, _kd, _kb, _h, _n0, _n1, _every, _nxt0, _row0, _chk, _comp, _st):
    # (translated by methodgen.llvmkernels with the module's constants and kernels bound)
    _z = numba.carray(_rt.stack_buffer(1), (1,))
    _out = numba.carray(_rt.stack_buffer(_PL), (_PL,))
    _ejs = numba.carray(_rt.stack_buffer(2), (2,))
    for _b in range(_NB):
        if _EJUMP:
            hs(_Y[_b], _p, _ejs)
        _e0 = _ejs[0]
        _e1 = _ejs[1]
        _nxt = _nxt0
        _row = _row0
        for _n in range(_n0, _n1):
            for _k in range(_STAGES):
                post(_z, _Y[_b], _C[_b], _G[_b], _h * _ka[_k], _h * _kd[_k], _h * _kb[_k], _p, _out)
                _bad = 0.0
                for _i in range(_DIM):
                    if _comp != 0:
                        _a = _out[_i] + _C[_b, _i]
                        _s = _Y[_b, _i] + _a
                        _C[_b, _i] = _a - (_s - _Y[_b, _i])
                        _Y[_b, _i] = _s
                    else:
                        _s = _Y[_b, _i] + _out[_i]
                        _Y[_b, _i] = _s
                    if not (_s - _s == 0.0):
                        _bad = 1.0
                for _i in range(_NF):
                    _G[_b, _i] = _out[_DIM + _i]
                if _bad != 0.0:
                    _st[0] = 1
                    return
                for _j in range(_NDOMAIN):
                    if _DPOS[_j] != 0:
                        if not (_out[_PD + _j] > 0.0):
                            _st[0] = 1
                            return
                    else:
                        if not (_out[_PD + _j] >= 0.0):
                            _st[0] = 1
                            return
                if _TT_GUARD:
                    if not (_out[_PT] > 0.0):
                        _st[0] = 1
                        return
                    if _chk != 0 and abs(_out[_PT + 1]) > _MLD * _out[_PT + 2]:
                        _st[0] = 1
                        return
                if _LERR:
                    if _chk != 0 and _out[_PE] > _LERR2 * _out[_PE + 1]:
                        _st[0] = 1
                        return
                if _EJUMP:
                    if _chk != 0 and abs(_out[_PJ] - _e0) > _MEJ * _e1:
                        _st[0] = 1
                        return
                    _e0 = _out[_PJ]
                    _e1 = _out[_PJ + 1]
            if _n + 1 == _nxt:
                _row = _row + 1
                for _i in range(_DIM):
                    _T[_row, _b, _i] = _Y[_b, _i]
                _nxt = _nxt + _every


@numba.njit(_t.void(_t.FunctionType(LOOP_SIG), *LOOP_SIG.args), cache=True, error_model="numpy")
def _drive(loop, Y, C, G, T, p, ka, kd, kb, h, n0, n1, every, nxt0, row0, chk, comp, st):
    loop(Y, C, G, T, p, ka, kd, kb, h, n0, n1, every, nxt0, row0, chk, comp, st)


_LOOPS: dict = {}


def _compiled_loop(post_k, hs, cfg, fcfg, domain_pos, batch):
    """The loop for this module's kernels and configuration (and batch size: the number of
    trajectories is a constant of the loop), compiled on first use; None where it does not apply."""
    key = (id(post_k), id(hs), batch)
    got = _LOOPS.get(key)
    if got is None:
        C = _rt.CFG
        consts = {"_PL": max(int(cfg[C["POST_LEN"]]), 1), "_NB": int(batch), "_STAGES": int(cfg[C["STAGES"]]),
                  "_DIM": int(cfg[C["DIM"]]), "_NF": int(cfg[C["NF"]]), "_NDOMAIN": int(cfg[C["NDOMAIN"]]),
                  "_PD": int(cfg[C["POST_DOMAIN"]]), "_TT_GUARD": int(cfg[C["TT_GUARD"]]),
                  "_PT": int(cfg[C["POST_TT"]]), "_LERR": int(cfg[C["LERR"]]), "_PE": int(cfg[C["POST_EXTRA"]]),
                  "_EJUMP": int(cfg[C["EJUMP"]]), "_PJ": int(cfg[C["POST_EJ"]]),
                  "_LERR2": float(fcfg[_rt.FCFG["LERR2"]]), "_MLD": float(fcfg[_rt.FCFG["MAX_LEVEL_DEFECT"]]),
                  "_MEJ": float(fcfg[_rt.FCFG["MAX_ENERGY_JUMP"]]),
                  "_DPOS": numpy.array([int(bool(v)) for v in domain_pos] or [0], dtype=numpy.int64),
                  "post": post_k.py_func, "hs": getattr(hs, "py_func", None), "numba": numba, "_rt": _rt}
        try:
            got = _lk.compile_kernel(_explicit_loop, LOOP_SIG, globals_=consts)
        except _lk.Unsupported:
            got = False
        _LOOPS[key] = got
    return got or None


def run_fused(post_k, hs, cfg, fcfg, domain_pos, kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p,
              check_resolution, compensated, fstat, every) -> bool:
    """Steps ``n0 .. n1-1`` of an explicit module through its fused loop (the arguments of
    :func:`methodgen.nbruntime.run`).  True when it ran them all (every check passed: the
    results are those of the shared runtime); False when it does not apply or a check would
    fail -- then ``Y``, ``C``, ``FRC`` are as they were and the caller runs the shared runtime."""
    CFG = _rt.CFG
    if (not enabled() or int(cfg[CFG["KIND"]]) != 2 or int(cfg[CFG["LERR"]]) == 2
            or not isinstance(post_k, _lk.LLVMKernel)
            or (int(cfg[CFG["EJUMP"]]) and not isinstance(hs, _lk.LLVMKernel))
            or not traj.flags.c_contiguous or Y.shape[0] > 8 or n1 <= n0):
        return False
    loop = _compiled_loop(post_k, hs, cfg, fcfg, domain_pos, Y.shape[0])
    if loop is None:
        return False
    Y0, C0, G0 = Y.copy(), C.copy(), FRC.copy()
    st = numpy.zeros(1)
    nxt0 = (n0 // every + 1) * every
    _drive(loop, Y, C, FRC, traj, p, kick_a, drift, kick_b, float(h), int(n0), int(n1), int(every), nxt0,
           nxt0 // every - 1, int(bool(check_resolution)), int(bool(compensated)), st)
    if st[0]:
        Y[...] = Y0
        C[...] = C0
        FRC[...] = G0
        return False
    fstat[:, 0] = _rt.STATUS["OK"]
    return True
