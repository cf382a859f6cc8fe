"""Lock-step batched integration for explicit methods (numba backend).

:func:`methodgen.nbabi.run` integrates a batch one trajectory after the
other, calling the module's ``post`` kernel (a first-class function: an opaque
call) once per stage per trajectory.  For explicit stages (``KIND == 2``:
Störmer–Verlet, its compositions, the splitting families) every trajectory
takes the same fixed steps, so a batch can instead be stepped in lock-step:
:func:`run_block` copies ``lanes`` trajectories at a time into a
structure-of-arrays block (component-major, lanes innermost, unit stride) and
calls the module's *block* kernel ``post_block`` once per stage for the whole
block.  That kernel is the module's straight-line ``post`` code inside a loop
over the lanes, with no branch and no reduction across lanes, which LLVM
vectorises; the state update and the checks are lane loops here.

The arithmetic of every lane is that of the one-trajectory path, operation for
operation (no fastmath, no contraction into fused multiply-adds), so both paths
give bitwise the same rows; ``tests/test_ensemble.py`` checks it.

The checks are the same (finiteness, domain conditions, time-transformation
guard, local error, energy jump), evaluated for every lane after every stage:
a branch-free count of failing lanes, and only when it is not zero a scalar pass
that records each failing lane as :func:`methodgen.nbabi.run` would
(``fstat[b] = (status, step, index/0, stage)``, ``fval[b]``).  A lane that
fails stops there (its state is the one after the failing stage, as on the
one-trajectory path); the other lanes of its block finish that step, and every
later block runs up to that step, so rows ``0 .. step`` are complete for all
trajectories and the first failing step and its trajectories are those of the
one-trajectory path.  (Trajectories of *earlier* blocks may have run further,
as earlier trajectories do there.)

The block kernel's type is :data:`KERNEL_TYPES` ``["post_block"]``:
``post_block(Y, C, G, ha, hd, hb, p, OUT, nl, compensated) -> int`` with ``Y``,
``C`` (DIM rows), ``G`` (NF rows; one dummy row without first-same-as-last
force) and ``OUT`` (POST_LEN rows) flat, row-major with rows of ``lanes``
(component i of lane l at ``i * lanes + l``; ``lanes`` is the module's constant
``_BLOCK_LANES``, compiled into its kernel: a constant stride is what lets LLVM
prove that the rows do not overlap and vectorise).  For lanes ``0 .. nl-1`` it
takes the stage: ``Y`` (and ``C`` when compensated) updated as the one-trajectory
path updates them from the post kernel's Δy, ``G`` the new force, ``OUT`` the
check values (its rows of Δy and force are left alone); it returns how many of
the updated components are not finite (0 when all are).

This module imports numpy and numba only, and is compiled once per machine
(numba's cache, stamped with this file's SHA-256 as the shared runtime is).
"""

from __future__ import annotations

import hashlib
import math
import os

import numba
import numpy
from numba import types as _t

from methodgen import nbabi as _abi
from methodgen import nbruntime as _rt

__all__ = ["run_block", "KERNEL_TYPES", "SOURCE_SHA256", "use_block"]

#: SHA-256 of this file and of the runtime's interface it reads (the configuration layout,
#: methodgen.nbabi): the stamp of its cached machine code.
SOURCE_SHA256 = hashlib.sha256((_rt._source_digest(os.path.abspath(__file__)) + _abi.SOURCE_SHA256).encode()).hexdigest()
_rt._install_stamp_guard(os.path.abspath(__file__), SOURCE_SHA256)

_f8 = _t.float64
_i8 = _t.int64
_V = _t.float64[::1]
_M = _t.float64[:, ::1]
_IV = _t.int64[::1]
_B = _t.boolean

#: numba signature of the block kernel (see the module docstring).
KERNEL_TYPES = {"post_block": _i8(_V, _V, _V, _f8, _f8, _f8, _V, _V, _i8, _B)}
_F = {k: _t.FunctionType(v) for k, v in KERNEL_TYPES.items()}
_RF = {k: _t.FunctionType(v) for k, v in _rt.KERNEL_TYPES.items()}

_OPTS = dict(cache=True, error_model="numpy")

(_C_N, _C_DIM, _C_STAGES, _C_NF, _C_LERR, _C_KLERR, _C_POST_EXTRA, _C_POST_DOMAIN, _C_NDOMAIN,
 _C_POST_TT, _C_TT_GUARD, _C_POST_EJ, _C_EJUMP, _C_POST_LEN, _C_HAS_SCALE, _C_RESOLUTION, _C_KIND,
 _C_KL, _C_KU) = (_rt.CFG[k] for k in (
     "N", "DIM", "STAGES", "NF", "LERR", "KLERR", "POST_EXTRA", "POST_DOMAIN", "NDOMAIN", "POST_TT",
     "TT_GUARD", "POST_EJ", "EJUMP", "POST_LEN", "HAS_SCALE", "RESOLUTION", "KIND", "KL", "KU"))
_F_LERR2 = _rt.FCFG["LERR2"]
_F_LERR_SCALE = _rt.FCFG["LERR_SCALE"]
_F_MAX_LEVEL_DEFECT = _rt.FCFG["MAX_LEVEL_DEFECT"]
_F_MAX_ENERGY_JUMP = _rt.FCFG["MAX_ENERGY_JUMP"]

_OK = _rt.STATUS["OK"]
_NON_FINITE = _rt.STATUS["NON_FINITE"]
_OUT_OF_DOMAIN = _rt.STATUS["OUT_OF_DOMAIN"]
_LOCAL_ERROR = _rt.STATUS["LOCAL_ERROR"]
_TIME_SCALE = _rt.STATUS["TIME_SCALE"]
_ENERGY_JUMP = _rt.STATUS["ENERGY_JUMP"]


# Which batches take run_block (explicit stages, at least nbabi.MIN_BATCH trajectories: below
# that the block is mostly empty and the one-trajectory path is as fast).  Decided in
# methodgen.nbabi, so that a module asks without importing this module.
use_block = _abi.use_block


@numba.njit(**_OPTS)
def _lane_status(PS, YS, NE2, ND2, EJS, l, L, DIM, NDOMAIN, PD, domain_pos, TT_GUARD, PT, MLD, LERR, LERR2,
                 LERR_SCALE, PJ, EJUMP, MEJ, check_resolution):
    """(status, index, value) of lane ``l`` after a stage: the first failing check in the
    order of :func:`methodgen.nbabi.run`, or ``_OK``."""
    for i in range(DIM):
        if not math.isfinite(YS[i * L + l]):
            return _NON_FINITE, 0, math.nan
    for j in range(NDOMAIN):
        v = PS[(PD + j) * L + l]
        if not (v > 0.0 if domain_pos[j] else v >= 0.0):
            return _OUT_OF_DOMAIN, j, v
    if TT_GUARD:
        if not PS[PT * L + l] > 0.0 or (check_resolution and abs(PS[(PT + 1) * L + l]) > MLD * PS[(PT + 2) * L + l]):
            return _TIME_SCALE, 0, PS[PT * L + l]
    if LERR and check_resolution:
        if NE2[l] > LERR2 * ND2[l]:
            return _LOCAL_ERROR, 0, LERR_SCALE * math.sqrt(NE2[l] / ND2[l])
    if EJUMP and check_resolution:
        d = abs(PS[PJ * L + l] - EJS[0 * L + l])
        if d > MEJ * EJS[1 * L + l]:
            return _ENERGY_JUMP, 0, d / EJS[1 * L + l]
    return _OK, 0, 0.0


_BLOCK_SIG = _t.void(
    _F["post_block"], _RF["hs"], _RF["check"],
    _IV, _V, _IV, _IV, _V, _V, _V, _V, _V,          # cfg, fcfg, lerr_index, domain_pos, gammas, ratios, a, d, b
    _t.float64[:, :, :], _i8, _i8, _M, _M, _M,      # traj (any layout), n0, n1, Y, C, FRC
    _f8, _V, _B, _B,                                # h, p, check_resolution, compensated
    _t.int64[:, ::1], _V, _i8, _i8,                 # fstat, fval, every, lanes
)


def run_block(post_block, hs, check, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, kick_a, drift, kick_b,
              traj, n0, n1, Y, C, FRC, h, p, check_resolution, compensated, fstat, fval, every, lanes):
    """Steps ``n0 .. n1-1`` of every trajectory of an explicit method in lock-step (see
    :func:`_run_block`); the kernels are passed as :func:`methodgen.nbruntime.handle` s, their
    addresses resolved once per process rather than at every call."""
    _run_block(_rt.handle(post_block, KERNEL_TYPES["post_block"]), _rt.handle(hs, _rt.KERNEL_TYPES["hs"]),
               _rt.handle(check, _rt.KERNEL_TYPES["check"]), cfg, fcfg, lerr_index, domain_pos, gammas, ratios,
               kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, check_resolution, compensated, fstat, fval,
               every, lanes)


@numba.njit(_BLOCK_SIG, **_OPTS)
def _run_block(post_block, hs, check, cfg, fcfg, lerr_index, domain_pos, gammas, ratios, kick_a, drift, kick_b,
               traj, n0, n1, Y, C, FRC, h, p, check_resolution, compensated, fstat, fval, every, lanes):
    """Steps ``n0 .. n1-1`` of every trajectory of an explicit method, ``lanes`` trajectories
    in lock-step: the arguments and their meaning are those of
    :func:`methodgen.nbabi.run` (without the Newton solver's), ``Y``, ``C``, ``FRC``
    (B, ·) updated in place, the failures recorded in ``fstat``, ``fval``."""
    DIM = cfg[_C_DIM]
    STAGES = cfg[_C_STAGES]
    NF = cfg[_C_NF]
    LERR = cfg[_C_LERR]
    KLERR = cfg[_C_KLERR]
    PE = cfg[_C_POST_EXTRA]
    PD = cfg[_C_POST_DOMAIN]
    NDOMAIN = cfg[_C_NDOMAIN]
    PT = cfg[_C_POST_TT]
    TT_GUARD = cfg[_C_TT_GUARD]
    PJ = cfg[_C_POST_EJ]
    EJUMP = cfg[_C_EJUMP]
    LERR2 = fcfg[_F_LERR2]
    LERR_SCALE = fcfg[_F_LERR_SCALE]
    MLD = fcfg[_F_MAX_LEVEL_DEFECT]
    MEJ = fcfg[_F_MAX_ENERGY_JUMP]
    B = Y.shape[0]
    L = lanes
    # the block, component-major (lanes innermost)
    YS = numpy.zeros(DIM * L)
    CS = numpy.zeros(DIM * L)
    FS = numpy.zeros(max(NF, 1) * L)
    PS = numpy.zeros(max(cfg[_C_POST_LEN], 1) * L)
    G0 = numpy.zeros(max(KLERR, 1) * L)   # (h_prev/2) f per lane ("carry" local error)
    EJS = numpy.zeros(2 * L)               # H and its size at the start of the step, per lane
    NE2 = numpy.zeros(L)
    ND2 = numpy.zeros(L)
    DEAD = numpy.zeros(L, dtype=numpy.int64)  # lane failed in this step (at stage DEAD - 1)
    SAVE = numpy.zeros((2 * DIM + max(NF, 1)) * L)  # a failed lane's y, c, frc after its failing stage
    chk = numpy.zeros(1 + DIM)
    ejs = numpy.zeros(2)
    hh = 0.5 * h * gammas[0]
    limit = n1
    for b0 in range(0, B, L):
        nl = min(L, B - b0)
        for l in range(nl):
            b = b0 + l
            fstat[b, 0] = _OK
            DEAD[l] = 0
            for i in range(DIM):
                YS[i * L + l] = Y[b, i]
                CS[i * L + l] = C[b, i]
            for i in range(NF):
                FS[i * L + l] = FRC[b, i]
            if EJUMP:
                hs(Y[b], p, ejs)
                EJS[0 * L + l] = ejs[0]
                EJS[1 * L + l] = ejs[1]
            if LERR == 2:
                check(Y[b], p, chk)
                for j in range(KLERR):
                    G0[j * L + l] = hh * chk[1 + lerr_index[j]]
        nxt = (n0 // every + 1) * every
        failed = False
        for n in range(n0, limit):
            for k in range(STAGES):
                # the stage for the whole block: the update of y (compensated or not) and the
                # carried force in place, the check values in PS, the non-finite count back
                nbad = post_block(YS, CS, FS, h * kick_a[k], h * drift[k], h * kick_b[k], p, PS, nl, compensated)
                rk = ratios[k]
                # The other checks: a count of failing lanes.  Each loop runs over the lanes of
                # one row, taken as a view: a unit-stride index that LLVM knows is not
                # negative, so it vectorises (an index i * L + l with L unknown defeats it).
                for j in range(NDOMAIN):
                    d = PS[(PD + j) * L:(PD + j) * L + L]
                    if domain_pos[j]:
                        for l in range(nl):
                            nbad += not (d[l] > 0.0)
                    else:
                        for l in range(nl):
                            nbad += not (d[l] >= 0.0)
                if TT_GUARD:
                    g = PS[PT * L:PT * L + L]
                    for l in range(nl):
                        nbad += not (g[l] > 0.0)
                    if check_resolution:
                        dd = PS[(PT + 1) * L:(PT + 1) * L + L]
                        ds = PS[(PT + 2) * L:(PT + 2) * L + L]
                        for l in range(nl):
                            nbad += abs(dd[l]) > MLD * ds[l]
                if LERR and check_resolution:
                    if LERR == 1:
                        ne = PS[PE * L:PE * L + L]
                        nd = PS[(PE + 1) * L:(PE + 1) * L + L]
                        for l in range(nl):
                            NE2[l] = ne[l]
                            ND2[l] = nd[l]
                    else:
                        nd = PS[PE * L:PE * L + L]
                        for l in range(nl):
                            NE2[l] = 0.0
                            ND2[l] = nd[l]
                        for j in range(KLERR):
                            pa = PS[(PE + 1 + j) * L:(PE + 1 + j) * L + L]
                            g0 = G0[j * L:j * L + L]
                            for l in range(nl):
                                e = pa[l] - rk * g0[l]
                                NE2[l] += e * e
                    for l in range(nl):
                        nbad += NE2[l] > LERR2 * ND2[l]
                if EJUMP and check_resolution:
                    hj = PS[PJ * L:PJ * L + L]
                    for l in range(nl):
                        nbad += abs(hj[l] - EJS[l]) > MEJ * EJS[L + l]
                if nbad:
                    # which lanes failed, and how: the checks in the one-trajectory path's order
                    for l in range(nl):
                        if DEAD[l]:
                            continue
                        st, ix, val = _lane_status(PS, YS, NE2, ND2, EJS, l, L, DIM, NDOMAIN, PD, domain_pos, TT_GUARD,
                                                   PT, MLD, LERR, LERR2, LERR_SCALE, PJ, EJUMP, MEJ,
                                                   check_resolution)
                        if st != _OK:
                            b = b0 + l
                            fstat[b, 0] = st
                            fstat[b, 1] = n
                            fstat[b, 2] = ix
                            fstat[b, 3] = k
                            fval[b] = val
                            DEAD[l] = k + 1
                            for i in range(DIM):
                                SAVE[i * L + l] = YS[i * L + l]
                                SAVE[(DIM + i) * L + l] = CS[i * L + l]
                            for i in range(NF):
                                SAVE[(2 * DIM + i) * L + l] = FS[i * L + l]
                            failed = True
                # what the next stage's checks start from
                if LERR == 2:
                    for j in range(KLERR):
                        g0 = G0[j * L:j * L + L]
                        pb = PS[(PE + 1 + KLERR + j) * L:(PE + 1 + KLERR + j) * L + L]
                        for l in range(nl):
                            g0[l] = pb[l]
                if EJUMP:
                    for l in range(2 * L):
                        EJS[l] = PS[PJ * L + l]  # H and its size: two consecutive rows
            if failed:
                # the failed lanes keep their state after the failing stage; the others
                # completed this step
                for l in range(nl):
                    if DEAD[l]:
                        for i in range(DIM):
                            YS[i * L + l] = SAVE[i * L + l]
                            CS[i * L + l] = SAVE[(DIM + i) * L + l]
                        for i in range(NF):
                            FS[i * L + l] = SAVE[(2 * DIM + i) * L + l]
                limit = n + 1
            if n + 1 == nxt:
                row = nxt // every
                for l in range(nl):
                    if DEAD[l] == 0:
                        for i in range(DIM):
                            traj[row, b0 + l, i] = YS[i * L + l]
                nxt += every
            if failed:
                break
        for l in range(nl):
            b = b0 + l
            for i in range(DIM):
                Y[b, i] = YS[i * L + l]
                C[b, i] = CS[i * L + l]
            for i in range(NF):
                FRC[b, i] = FS[i * L + l]
