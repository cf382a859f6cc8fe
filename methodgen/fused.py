"""A module's integration loop compiled with its kernels inlined (LLVM IR).

On the shared runtime (:func:`methodgen.nbruntime.run`) every stage is a call through a
function pointer, and an implicit stage's Newton iteration calls its residual and Jacobian
kernels the same way: about 13 ns a call, a third of an explicit step of Kepler's
Störmer–Verlet composed to order 10 (35 stages) and half of a Hénon–Heiles energy-momentum
step of order 8 (80 calls).  When a module's kernels were compiled through LLVM IR
(:mod:`methodgen.llvmkernels`), this module compiles, once per module (milliseconds, or loaded
from the machine-code cache), the loop of :func:`_stage_loop` with the kernels inlined: the same stages,
Newton iterations (solvers "newton", "simplified", "fixed-point", "auto"; the linearly
implicit solve), compensated update, first-same-as-last force and checks, operation for
operation, so the same bits, iterations and solver state.

It is an accelerator, never the judge: it runs only while every check passes.  When any
check the runtime makes would fail (Newton's convergence, resolution, predictor, non-finite
state, domain, time-scale guard, local error, energy jump) it stops and says so, and
:func:`run_fused` restores the inputs and lets the shared runtime run the same call from
the start, which records the failure exactly as before.  One check it can only bound: where
the runtime takes the spectral radius of a Newton matrix from its eigenvalues, this loop
uses a bound of it (:func:`_resolution_f`) and hands back what the bound cannot decide.
Modules it does not apply to (a kernel numba compiled, solver "reuse", arrays that are not
C-contiguous float64) take the shared runtime directly; explicit batches of at least
``nbbatch.MIN_BATCH`` take the lock-step block of :mod:`methodgen.nbbatch` before this.

The loop's source below is translated by :mod:`methodgen.llvmkernels` with the module's
configuration bound as constants (``_DIM``, ``_STAGES``, ``_N`` …) and its kernels as
``guess``, ``res``, ``resjac``, ``post``, ``hs``, ``check``, ``scale``; it is called through its C
entry point with ctypes (:func:`_drive`), so a run on this path does not import numba.
"""

from __future__ import annotations

import ctypes
import math
import os
import types

import numpy

from . import ktypes as _t
from . import llvmkernels as _lk
from . import nbabi as _rt

__all__ = ["run_fused", "enabled", "false_alarm"]

_f8, _i8, _V, _M = _t.float64, _t.int64, _t.float64[::1], _t.float64[:, ::1]
_T3 = _t.float64[:, :, ::1]

#: signature of the compiled loop: Y, C, G (B, ·), traj (rows, B, DIM), p, kick_a, drift,
#: kick_b, h, n0, n1, every, nxt0, row0, check_resolution, compensated, status (1; 1.0 = stopped),
#: iterations (B, n1 - n0; implicit), solver modes (B, STAGES; "auto"), maxiter, solver, use_tol, tol,
#: the number of trajectories B
LOOP_SIG = _t.void(_M, _M, _M, _T3, _V, _V, _V, _V, _f8, _i8, _i8, _i8, _i8, _i8, _i8, _i8, _V,
                   _M, _M, _i8, _i8, _i8, _f8, _i8)


def enabled() -> bool:
    """The fused loop is used unless ``METHODGEN_FUSED=0`` (or the kernels take numba)."""
    return os.environ.get("METHODGEN_FUSED", "1").strip() != "0" and _lk.enabled()


def _stage_loop(_Y, _C, _G, _T, _p, _ka, _kd, _kb, _h, _n0, _n1, _every, _nxt0, _row0, _chk, _comp, _st,
                _its, _smode, _maxiter, _solver, _usetol, _tol, _nbt):
    # (translated by methodgen.llvmkernels with the module's constants and kernels bound)
    _z = numba.carray(_rt.stack_buffer(_NZ), (_NZ,))
    _zp = numba.carray(_rt.stack_buffer(_NZ), (_NZ,))
    _dz = numba.carray(_rt.stack_buffer(_NZ), (_NZ,))
    _r = numba.carray(_rt.stack_buffer(_NZ), (_NZ,))
    _J = numba.carray(_rt.stack_buffer(_NZ * _NZ), (_NZ, _NZ))
    _wa = numba.carray(_rt.stack_buffer(_NZ * _NZ), (_NZ, _NZ))
    _wb = numba.carray(_rt.stack_buffer(_NZ), (_NZ,))
    _out = numba.carray(_rt.stack_buffer(_PL), (_PL,))
    _ejs = numba.carray(_rt.stack_buffer(2), (2,))
    _rr = numba.carray(_rt.stack_buffer(1), (1,))
    _ck = numba.carray(_rt.stack_buffer(1 + _DIM), (1 + _DIM,))
    _g0 = numba.carray(_rt.stack_buffer(_NK), (_NK,))
    # the trajectory's state, compensation and carried force in stack buffers while it runs:
    # LLVM keeps them in registers across the stages (the caller's rows it must reload after
    # every store, not knowing that _Y, _C and _G do not overlap); written back at its end (a
    # failure returns without: the caller restores its copies)
    _yl = numba.carray(_rt.stack_buffer(_DIM), (_DIM,))
    _cl = numba.carray(_rt.stack_buffer(_DIM), (_DIM,))
    _gl = numba.carray(_rt.stack_buffer(_NG), (_NG,))
    _hh = 0.5 * _h * _GAMMA0
    for _b in range(_nbt):
        if _EJUMP:
            hs(_Y[_b], _p, _ejs)
        _e0 = _ejs[0]
        _e1 = _ejs[1]
        if _LERR == 2:
            # a carried estimate: (h/2) f at the start of the first step
            check(_Y[_b], _p, _ck)
            for _j in range(_KLERR):
                _g0[_j] = _hh * _ck[1 + _LIDX[_j]]
        _nxt = _nxt0
        _row = _row0
        for _i in range(_DIM):
            _yl[_i] = _Y[_b, _i]
            _cl[_i] = _C[_b, _i]
        for _i in range(_NG):
            _gl[_i] = _G[_b, _i]
        for _n in range(_n0, _n1):
            for _k in range(_STAGES):
                _hs = _h * _kd[_k]
                if _KIND == 1:
                    # linearly implicit: one solve from z = 0 (nbruntime._solve_linear)
                    for _i in range(_N):
                        _z[_i] = 0.0
                    resjac(_z, _yl, _cl, _hs, _p, _r, _J)
                    _solve_f(_J, _r, _dz, _wa, _wb)
                    for _i in range(_N):
                        _z[_i] = -_dz[_i]
                    if _RESOL != 0 and _chk != 0:
                        _resolution_f(_J, _rr)
                        _rho = _rr[0]
                        if not _rho <= _MAXRES:
                            _st[0] = 1
                            return
                    for _i in range(_N):
                        if not (_z[_i] - _z[_i] == 0.0):
                            _st[0] = 1
                            return
                    _its[_b, _n - _n0] += 1.0
                elif _KIND == 0:
                    # Newton's method (nbruntime._solve_newton, solvers 0, 1, 2 and 4)
                    guess(_yl, _hs, _p, _z)
                    for _i in range(_N):
                        _zp[_i] = _z[_i]
                    if _HAS_SCALE:
                        _floor = scale(_yl, _hs, _p)
                    else:
                        _floor = 0.0
                    _prev = math.inf
                    _have = 0
                    _newton = 0
                    if _solver == 4 and _smode[_b, _k] > 0.0:
                        _newton = 1
                    _it = 0
                    _ok = 0
                    while _it < _maxiter:
                        _it += 1
                        if _solver == 2 or (_solver == 4 and _newton == 0):
                            res(_z, _yl, _cl, _hs, _p, _r)
                            for _i in range(_N):
                                _dz[_i] = _r[_i]
                        else:
                            if _solver == 0 or _solver == 4 or _have == 0:
                                resjac(_z, _yl, _cl, _hs, _p, _r, _J)
                                _have = 1
                            else:
                                res(_z, _yl, _cl, _hs, _p, _r)
                            _solve_f(_J, _r, _dz, _wa, _wb)
                        for _i in range(_N):
                            _z[_i] -= _dz[_i]
                        _nd = 0.0
                        for _i in range(_N):
                            _v = abs(_dz[_i])
                            if _v > _nd or _v != _v:
                                _nd = _v
                        _nz = 0.0
                        for _i in range(_N):
                            _v = abs(_z[_i])
                            if _v > _nz or _v != _v:
                                _nz = _v
                        _nz = max(_nz, _floor)
                        if _solver == 4 and _newton == 0 and (not _nd <= 1e300 or (_it >= 2 and _nd > _AUTO_RATE * _prev)):
                            _newton = 1
                            _smode[_b, _k] = _AUTO_HOLD1
                            if not _nd <= 1e300:
                                for _i in range(_N):
                                    _z[_i] = _zp[_i]
                            _prev = math.inf
                            continue
                        if not _nd <= 1e300:
                            _st[0] = 1
                            return
                        _done = 0
                        if _usetol != 0:
                            if _nd <= _tol:
                                _done = 1
                        elif _nd <= _TOL_ROUNDOFF * _nz or (_nd >= _prev and _prev <= _TOL_PLATEAU * _nz):
                            _done = 1
                        if _done != 0:
                            if _RESOL != 0 and _chk != 0:
                                if _have != 0:
                                    _resolution_f(_J, _rr)
                                    _rho = _rr[0]
                                    if not _rho <= _MAXRES:
                                        _st[0] = 1
                                        return
                                _dis = 0.0
                                if _nz > 0.0:
                                    for _i in range(_N):
                                        _v = abs(_z[_i] - _zp[_i])
                                        if _v > _dis or _v != _v:
                                            _dis = _v
                                    _dis = _dis / _nz
                                if not _dis <= _MAXDIS:
                                    _st[0] = 1
                                    return
                            if _newton != 0:
                                _smode[_b, _k] -= 1.0
                            _ok = 1
                            break
                        _prev = _nd
                    if _ok == 0:
                        _st[0] = 1
                        return
                    _its[_b, _n - _n0] += _it
                post(_z, _yl, _cl, _gl, _h * _ka[_k], _hs, _h * _kb[_k], _p, _out)
                _bad = 0.0
                for _i in range(_DIM):
                    if _comp != 0:
                        _a = _out[_i] + _cl[_i]
                        _s = _yl[_i] + _a
                        _cl[_i] = _a - (_s - _yl[_i])
                        _yl[_i] = _s
                    else:
                        _s = _yl[_i] + _out[_i]
                        _yl[_i] = _s
                    if not (_s - _s == 0.0):
                        _bad = 1.0
                for _i in range(_NF):
                    _gl[_i] = _out[_DIM + _i]
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
                if _LERR == 1:
                    if _chk != 0 and _out[_PE] > _LERR2 * _out[_PE + 1]:
                        _st[0] = 1
                        return
                elif _LERR == 2:
                    if _chk != 0:
                        _ne2 = 0.0
                        for _j in range(_KLERR):
                            _e = _out[_PE + 1 + _j] - _RATIOS[_k] * _g0[_j]
                            _g0[_j] = _out[_PE + 1 + _KLERR + _j]
                            _ne2 += _e * _e
                        if _ne2 > _LERR2 * _out[_PE]:
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
                    _T[_row, _b, _i] = _yl[_i]
                _nxt = _nxt + _every
        for _i in range(_DIM):
            _Y[_b, _i] = _yl[_i]
            _C[_b, _i] = _cl[_i]
        for _i in range(_NG):
            _G[_b, _i] = _gl[_i]



def _solve_f(_a0, _r0, _x, _wa, _wb):
    # nbruntime._solve with N, KL, KU constants: the closed form for N <= 3, else elimination
    # with partial pivoting within the band; a singular matrix gives NaN
    if _N == 1:
        _x[0] = _r0[0] / _a0[0, 0]
    elif _N == 2:
        a00 = _a0[0, 0]
        a01 = _a0[0, 1]
        a10 = _a0[1, 0]
        a11 = _a0[1, 1]
        b0 = _r0[0]
        b1 = _r0[1]
        det = a00 * a11 - a01 * a10
        _x[0] = (b0 * a11 - a01 * b1) / det
        _x[1] = (a00 * b1 - b0 * a10) / det
    elif _N == 3:
        a00 = _a0[0, 0]
        a01 = _a0[0, 1]
        a02 = _a0[0, 2]
        a10 = _a0[1, 0]
        a11 = _a0[1, 1]
        a12 = _a0[1, 2]
        a20 = _a0[2, 0]
        a21 = _a0[2, 1]
        a22 = _a0[2, 2]
        b0 = _r0[0]
        b1 = _r0[1]
        b2 = _r0[2]
        c00 = a11 * a22 - a12 * a21
        c01 = a12 * a20 - a10 * a22
        c02 = a10 * a21 - a11 * a20
        det = a00 * c00 + a01 * c01 + a02 * c02
        _x[0] = (b0 * c00 + b1 * (a02 * a21 - a01 * a22) + b2 * (a01 * a12 - a02 * a11)) / det
        _x[1] = (b0 * c01 + b1 * (a00 * a22 - a02 * a20) + b2 * (a02 * a10 - a00 * a12)) / det
        _x[2] = (b0 * c02 + b1 * (a01 * a20 - a00 * a21) + b2 * (a00 * a11 - a01 * a10)) / det
    else:
        for r in range(_N):
            _wb[r] = _r0[r]
            for c in range(_N):
                _wa[r, c] = _a0[r, c]
        singular = 0
        for col in range(_N):
            low = min(_N, col + _KL + 1)         # rows that can hold a nonzero in this column
            high = min(_N, col + _KL + _KU + 1)  # columns a pivot row can reach
            piv = col
            best = abs(_wa[col, col])
            for r in range(col + 1, low):
                v = abs(_wa[r, col])
                if v > best:
                    piv = r
                    best = v
            if best == 0.0:
                for r in range(_N):
                    _x[r] = math.nan
                singular = 1
                break
            if piv != col:
                for c in range(col, high):
                    t = _wa[col, c]
                    _wa[col, c] = _wa[piv, c]
                    _wa[piv, c] = t
                t = _wb[col]
                _wb[col] = _wb[piv]
                _wb[piv] = t
            inv = 1.0 / _wa[col, col]
            for r in range(col + 1, low):
                f = _wa[r, col] * inv
                if f != 0.0:
                    for c in range(col + 1, high):
                        _wa[r, c] -= f * _wa[col, c]
                    _wb[r] -= f * _wb[col]
        if singular == 0:
            for rr in range(_N):
                r = _N - 1 - rr
                s = _wb[r]
                for c in range(r + 1, min(_N, r + _KL + _KU + 1)):
                    s -= _wa[r, c] * _x[c]
                _x[r] = s / _wa[r, r]


def _resolution_f(_Jr, _rr):
    # nbruntime._resolution's verdict: h·ω from the max row sum of |J - I|; where that bound is
    # above the threshold, the runtime takes the spectral radius ρ of J - I from its eigenvalues
    # (LAPACK), and this loop, which has no eigenvalue solver, a bound u >= ρ: the closed form
    # for N = 2, else the smaller of the column-sum and Frobenius norms.  Each is widened by more
    # than the rounding of either computation (LAPACK's computed |λ| is the exact one of a matrix
    # within c·eps·|A| of J - I: below |A|·(1 + 1e-10) for any norm |A|; a defective 2×2 block
    # moves its eigenvalues by up to sqrt(eps)·|A| ~ 1.5e-8·|A|), so a step it passes the runtime
    # passes too; otherwise NaN: the call is handed back to the runtime, which decides.
    norm = 0.0
    for i in range(_N):
        s = 0.0
        for j in range(_N):
            if i == j:
                s += abs(_Jr[i, j] - 1.0)
            else:
                s += abs(_Jr[i, j])
        if s > norm or s != s:
            norm = s
    if _N > 1 and norm > _RTHRESH:
        if _N == 2:
            a = _Jr[0, 0] - 1.0
            bb = _Jr[0, 1]
            c = _Jr[1, 0]
            d = _Jr[1, 1] - 1.0
            t = 0.5 * (a + d)
            det = a * d - bb * c
            disc = t * t - det
            if disc >= 0.0:
                u = abs(t) + math.sqrt(disc)
            else:
                u = math.sqrt(det)
            u = u + 1e-7 * math.sqrt(a * a + bb * bb + c * c + d * d)
        else:
            cn = 0.0
            fr = 0.0
            for j in range(_N):
                s = 0.0
                for i in range(_N):
                    if i == j:
                        v = abs(_Jr[i, j] - 1.0)
                    else:
                        v = abs(_Jr[i, j])
                    s += v
                    fr += v * v
                if s > cn or s != s:
                    cn = s
            u = min(cn, math.sqrt(fr)) * (1.0 + 1e-10)
        if _RESOL == 1:
            v = 2.0 * u
        else:
            v = 2.0 * math.sqrt(u)
        if v <= _MAXRES:
            _rr[0] = v
        else:
            _rr[0] = math.nan
    elif _RESOL == 1:
        _rr[0] = 2.0 * norm
    else:
        _rr[0] = 2.0 * math.sqrt(norm)


def _drive(loop, Y, C, G, T, p, ka, kd, kb, h, n0, n1, every, nxt0, row0, chk, comp, st, its, smode, maxiter,
           solver, usetol, tol):
    """Run the compiled loop through its C entry (ctypes: no numba dispatcher is loaded, so a
    warm start does not pay for numba's target initialisation)."""
    arrays = [_lk.array_struct(a) for a in (Y, C, G, T, p, ka, kd, kb)]
    tail = [_lk.array_struct(a) for a in (st, its, smode)]
    loop.c_call(*[ctypes.byref(a) for a in arrays], h, n0, n1, every, nxt0, row0, chk, comp,
                *[ctypes.byref(a) for a in tail], maxiter, solver, usetol, tol, Y.shape[0])


_LOOPS: dict = {}
#: calls handed back that the runtime then ran to the end, by loop (a resolution bound this
#: loop could not decide, where the eigenvalues pass): after _MAX_FALSE_ALARMS such calls a
#: module's runs go to the runtime directly, rather than twice
_FALSE_ALARMS: dict = {}
_MAX_FALSE_ALARMS = 3


def false_alarm(key):
    """The runtime ran to the end a call this loop (``key``) handed back."""
    _FALSE_ALARMS[key] = _FALSE_ALARMS.get(key, 0) + 1


def _compiled_loop(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios):
    """The loop for this module's kernels and configuration, compiled on first use (or loaded
    from the machine-code cache); None where it does not apply."""
    # keyed by what the loop is compiled from: the kernels' machine code (their symbols name
    # the text they were translated from; an id() is reused once a regenerated module's old
    # kernels are freed) and the constants bound into it
    key = (tuple(getattr(k, "symbol", None) or ("id", id(k)) for k in kernels),
           cfg.tobytes(), fcfg.tobytes(), tuple(lerr_index), tuple(map(bool, domain_pos)),
           tuple(map(float, gammas)), tuple(map(float, ratios)))
    got = _LOOPS.get(key)
    if got is None:
        C = _rt.CFG
        F = _rt.FCFG
        n = int(cfg[C["N"]])
        fr = float(fcfg[F["NEWTON_FAILURE_RESOLUTION"]])
        resol = int(cfg[C["RESOLUTION"]])
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
                  # the threshold of nbruntime._resolution (x**2 there is x*x: numba's static power)
                  "_RTHRESH": 0.5 * fr if resol == 1 else (0.5 * fr) * (0.5 * fr),
                  "_TOL_ROUNDOFF": _rt._TOL_ROUNDOFF, "_TOL_PLATEAU": _rt._TOL_PLATEAU,
                  "_KLERR": int(cfg[C["KLERR"]]), "_NK": max(int(cfg[C["KLERR"]]), 1),
                  "_LIDX": numpy.array(list(lerr_index) or [0], dtype=numpy.int64),
                  "_RATIOS": numpy.array(ratios, dtype=numpy.float64), "_GAMMA0": float(gammas[0]),
                  "_DPOS": numpy.array([int(bool(v)) for v in domain_pos] or [0], dtype=numpy.int64),
                  "_rt": _rt, "math": math}
        for name, k in zip(("guess", "res", "resjac", "post", "hs", "check", "scale"), kernels):
            consts[name] = getattr(k, "py_func", None)
        # the helpers, with their constants resolved in this loop's configuration
        for f in (_solve_f, _resolution_f):
            consts[f.__name__] = types.FunctionType(f.__code__, consts, f.__name__)
        try:
            got = _lk.compile_kernel(_stage_loop, LOOP_SIG, globals_=consts, c_entry=True)
        except _lk.Unsupported:
            got = False
        # (the kernels are kept with the loop: an id() in the key is not reused while it lives)
        _LOOPS[key] = got = (got, kernels)
    return (got[0] or None), key


def run_fused(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p,
              maxiter, check_resolution, solver, use_tol, tol, compensated, its, fstat, every, smode):
    """Steps ``n0 .. n1-1`` through the module's fused loop (the arguments of
    :func:`methodgen.nbruntime.run`; ``kernels`` = guess, res, resjac, post, hs, check, scale).  True when it
    ran them all (every check passed: the results are those of the shared runtime); None when
    it does not apply; the loop's key when a check would fail or could not be decided here --
    then ``Y``, ``C``, ``FRC``, ``its`` and ``smode`` are as they were, and the caller runs the
    shared runtime (and reports :func:`false_alarm` if that runs to the end)."""
    CFG = _rt.CFG
    kind = int(cfg[CFG["KIND"]])
    guess, res, resjac, post_k, hs, check, scale = kernels
    needed = [post_k] + ([hs] if int(cfg[CFG["EJUMP"]]) else []) + \
        ([check] if int(cfg[CFG["LERR"]]) == 2 else []) + \
        ([scale] if kind == 0 and int(cfg[CFG["HAS_SCALE"]]) else []) + \
        ([resjac] if kind == 1 else [guess, res, resjac] if kind == 0 else [])
    if (not enabled() or (kind == 0 and solver == 3)
            or not all(isinstance(k, _lk.LLVMKernel) for k in needed)
            or n1 <= n0
            or not all(a.dtype.char == "d" and a.flags.c_contiguous
                       for a in (Y, C, FRC, traj, p, kick_a, drift, kick_b))):
        return None
    loop, key = _compiled_loop(kernels, cfg, fcfg, lerr_index, domain_pos, gammas, ratios)
    if loop is None or _FALSE_ALARMS.get(key, 0) >= _MAX_FALSE_ALARMS:
        return None
    Y0, C0, G0 = Y.copy(), C.copy(), FRC.copy()
    st = numpy.zeros(1)
    # the iterations: counted as floats (the translated code's arrays are float64) in place of
    # its, when its is zeros (its usual state: 0 has the same bits as 0.0), else in a copy
    in_place = kind != 2 and its.flags.c_contiguous and not its.any()
    itsf = its.view(numpy.float64) if in_place else numpy.zeros((Y.shape[0], n1 - n0) if kind != 2 else (1, 1))
    smf = smode.astype(numpy.float64) if kind == 0 else numpy.zeros((1, 1))
    nxt0 = (n0 // every + 1) * every
    _drive(loop, Y, C, FRC, traj, p, kick_a, drift, kick_b, float(h), int(n0), int(n1), int(every), nxt0,
           nxt0 // every - 1, int(bool(check_resolution)), int(bool(compensated)), st, itsf, smf,
           int(maxiter), int(solver), int(bool(use_tol)), float(tol))
    if st[0]:
        Y[...] = Y0
        C[...] = C0
        FRC[...] = G0
        if in_place:
            its[...] = 0
        return key
    if in_place:
        its[...] = itsf        # (numpy copies overlapping operands first)
    elif kind != 2:
        its += itsf.astype(numpy.int64)
    if kind == 0:
        smode[...] = smf.astype(numpy.int64)
    fstat[:, 0] = _rt.STATUS["OK"]
    return True
