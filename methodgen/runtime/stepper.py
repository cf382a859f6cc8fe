"""The stepper: one source of a generated scheme's integration loop.

:func:`stepper` runs steps ``n0 .. n1-1`` of a batch of trajectories: each step's stages
(explicit, Newton's method with the solvers "newton", "simplified", "fixed-point" and "auto",
or the linearly implicit solve), the compensated update of the state, the first-same-as-last
force, every check (Newton's convergence, resolution and predictor, non-finite state, real
domain, time-scale guard, local error, energy jump) with the status, step, iteration count,
value and stage of a failure, and the saved rows.  It is written in the subset of Python that
:mod:`methodgen.codegen.llvmkernels` translates to LLVM IR: :mod:`methodgen.runtime.fused` binds a module's
configuration (:mod:`methodgen.codegen.abi`) as constants (``_DIM``, ``_N``, ``_PE`` …) and its kernels
(``guess``, ``res``, ``resjac``, ``post``, ``hs``, ``check``, ``scale``), compiles it with the
kernels inlined, and drives it.

A composed first-same-as-last Störmer–Verlet step whose module says so (``_MERGED``,
:attr:`methodgen.codegen.lower.ModuleIR.merged_kicks`) runs with merged kicks: the state stays
at the step's start, the compensation array holds D, the step's increment so far, each stage
adds its drift and its kick (b_{k-1} + a_k, one kick) to D, and y + D is summed once at the
step's end (Kahan's sum; the checks of the step's end follow it).

One check needs what the loop does not have: where the row-sum bound of ``J - I`` is above
the resolution threshold, the verdict is the spectral radius of ``J - I``, from its
eigenvalues.  There the stepper **stops and asks**: it leaves the matrix in ``_jout``, the
trajectory, step and stage in ``_dec`` and the state at the start of that stage in the
arrays, and returns with ``_st[0] = 1``; the driver computes ρ (LAPACK) and calls it again
from that stage with ρ in ``_dec[3]``.  The stage is then computed again from the same inputs
(the same bits: its solver state was restored), and the check takes the given ρ.

The status codes and the failure values are :data:`methodgen.codegen.abi.STATUS` (those of
the numba runtime this stepper replaced, operation for operation).

References
----------
E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed., Springer (2006),
§VIII.5 (compensated summation), §VIII.6 (the implementation of implicit methods).
"""

from __future__ import annotations

import math

__all__ = ["stepper", "lockstep", "rows", "lane_status", "project", "small_solve", "solve", "resolution", "lu", "lu_solve", "amax",
           "compensated_add", "settled"]

# The names below that this file does not define (``stack_array``: a work array on the stack,
# the upper-case constants and the kernels) are bound by methodgen.runtime.fused when it
# compiles the loop (or runs it as Python: ``stack_array`` is then numpy.zeros).
# flake8: noqa: F821


def stepper(_Y, _C, _G, _K, _PRJ, _T, _p, _ka, _kd, _kb, _h, _n0, _n1, _every, _nxt0, _row0, _st, _its, _smode,
            _sluok, _sLU, _spiv, _fst, _fval, _dec, _jout, _maxiter, _tol, _nbt, _b0, _nr, _k0, _nxtr, _rowr):
    """Steps ``_n0 .. _n1-1`` of trajectories ``_b0 .. _nbt-1``.

    ``_Y``, ``_C``, ``_G`` (B, ·): state, compensation, carried force, updated in place;
    ``_K`` (B, NK + 2): the carried estimate's b and H with its size, left for a resumed call;
    ``_PRJ`` (B, 2 PM): a projected step's levels g(y_start), then its multipliers λ (updated);
    ``_T`` (rows, B, DIM): saved rows (row ``n // every`` after step ``n - 1``); ``_its``
    (B, n1 - n0): Newton iterations per step; ``_smode`` (B, STAGES): "auto" Newton steps
    left; ``_sluok`` (B, STAGES), ``_sLU`` (B·STAGES, N·N), ``_spiv`` (B·STAGES, N): solver
    "reuse"'s kept LU factors per trajectory and stage, whether they are valid, and their row
    permutation; ``_fst`` (B, 4): status, step, iteration, stage of a failure, ``_fval`` (B,) its
    value; ``_st``: 1 when the loop stopped to ask for a spectral radius (``_dec``: trajectory,
    step, stage; ``_jout``: the Newton matrix), else 0.  A resumed call (``_nr >= 0``) starts
    trajectory ``_b0`` at step ``_nr``, stage ``_k0``, with ρ = ``_dec[3]`` for that stage.
    ``_nxt0``, ``_nxtr``: the first step after ``_n0`` (``_nr``) whose state is kept, a multiple
    of ``_every``; ``_row0``, ``_rowr``: its row, ``_nxt0 // _every``.

    The run's options that select code -- ``_solver`` (0 newton, 1 simplified, 2 fixed point,
    3 reuse, 4 auto), ``_usetol``, ``_chk`` (check_resolution), ``_comp`` (compensated) -- are
    constants of the compiled loop, like the configuration: each combination is its own
    machine code, compiled when first used, holding only the branches it takes.
    """
    _z = stack_array((_NZ,))
    _zp = stack_array((_NZ,))
    _dz = stack_array((_NZ,))
    _r = stack_array((_NZ,))
    _J = stack_array((_NZ, _NZ))
    _wa = stack_array((_NZ, _NZ))
    _wb = stack_array((_NZ,))
    _out = stack_array((_PL,))
    _ejs = stack_array((2,))
    _rr = stack_array((2,))
    _ck = stack_array((1 + _DIM,))
    _LU0 = stack_array((_NZ * _NZ,))   # "reuse": the factors at the stage's start
    _pv0 = stack_array((_NZ,))         # (a stage asked again)
    _okb = stack_array((1,))
    _ejn = stack_array((2,))      # H and its size at a composed step's end
    _g0 = stack_array((_NK,))
    # the trajectory's state, compensation and carried force in stack buffers while it runs:
    # LLVM keeps them in registers across the stages (the caller's rows it must reload after
    # every store, not knowing that _Y, _C and _G do not overlap); written back at its end
    # a projected step's work (methodgen.symbolic.projection; PM = 1 where there is none)
    _pres = stack_array((3,))
    _py1 = stack_array((_DIM,))
    _pc1 = stack_array((_DIM,))
    _pyt = stack_array((_DIM,))
    _pct = stack_array((_DIM,))
    _plag = stack_array((_DIM,))
    _pgv = stack_array((_PGV,))
    _pgv1 = stack_array((_PGV,))
    _pD0 = stack_array((_PM, _DIM))
    _pD1 = stack_array((_PM, _DIM))
    _pA = stack_array((_PM, _PM))
    _pW = stack_array((_PM, _PM))
    _pv = stack_array((7, _PM))    # r, r_old, λ_old, size, rhs, c, x
    _plam = stack_array((_PM,))
    _yl = stack_array((_DIM,))
    _cl = stack_array((_DIM,))
    _gl = stack_array((_NG,))
    _cst = stack_array((_DIM,))   # the compensation as it came (merged, plain)
    _hh = 0.5 * _h * _GAMMA0
    _limit = _n1
    _st[0] = 0.0
    for _b in range(_b0, _nbt):
        _resume = 0
        if _nr >= 0 and _b == _b0:
            _resume = 1
        for _i in range(_DIM):
            _yl[_i] = _Y[_b, _i]
            _cl[_i] = _C[_b, _i]
            _cst[_i] = _cl[_i]
        for _i in range(_NG):
            _gl[_i] = _G[_b, _i]
        if _PROJ != 0:
            for _j in range(_PM):
                _plam[_j] = _PRJ[_b, _PM + _j]
        if _resume != 0:
            # the carried values as they were at the start of the stage asked about
            for _j in range(_KLERR):
                _g0[_j] = _K[_b, _j]
            _ejs[0] = _K[_b, _NK]
            _ejs[1] = _K[_b, _NK + 1]
            _nstart = _nr
            _nxt = _nxtr
            _row = _rowr
        else:
            _fst[_b, 0] = _S_OK
            if _EJUMP and _PROJ == 0:
                hs(_yl, _p, _ejs)
            if _LERR == 2 and _PROJ == 0:
                # a carried estimate: (h/2) f at the start of the first step
                check(_yl, _p, _ck)
                for _j in range(_KLERR):
                    _g0[_j] = _hh * _ck[1 + _LIDX[_j]]
            _nstart = _n0
            _nxt = _nxt0
            _row = _row0
        _e0 = _ejs[0]
        _e1 = _ejs[1]
        _failed = 0
        _stop = 0
        for _n in range(_nstart, _limit):
            _k = 0
            if _resume != 0 and _n == _nr:
                _k = _k0
            if _PROJ != 0:
                # a projected step (a stage kind of its own: the base step's stages inside its
                # iteration on the multipliers)
                project(_yl, _cl, _plam, _PRJ[_b], _p, _h, _ka, _kd, _kb, _maxiter, _z, _gl, _out, _py1, _pc1,
                        _pyt, _pct, _plag, _pgv, _pgv1, _pD0, _pD1, _pA, _pW, _pv, _pres)
                _it = int(_pres[2])
                _its[_b, _n - _n0] += _it
                if _pres[0] != _S_OK:
                    _fst[_b, 0] = _pres[0]
                    _fst[_b, 1] = _n
                    _fst[_b, 2] = _it
                    _fval[_b] = _pres[1]
                    _failed = 1
                else:
                    for _i in range(_DIM):
                        _yl[_i] = _py1[_i]
                        if _comp != 0:
                            _cl[_i] = _pc1[_i]
                        else:
                            _cl[_i] = 0.0
                _k = _STAGES     # (the stage loop below does not run)
            while _k < _STAGES:
                _hs = _h * _kd[_k]
                _status = _S_OK
                _it = 0
                _val = 0.0
                _asked = 0       # the spectral radius this stage needs: 1 asked for, 2 given
                _rho = 0.0
                if _resume != 0 and _n == _nr and _k == _k0:
                    _rho = _dec[3]
                    _asked = 2
                if _KIND == 1:
                    # linearly implicit: one solve from z = 0 (the equations are linear in z)
                    for _i in range(_N):
                        _z[_i] = 0.0
                    resjac(_z, _yl, _cl, _hs, _p, _r, _J)
                    solve(_J, _r, _dz, _wa, _wb)
                    for _i in range(_N):
                        _z[_i] = -_dz[_i]
                    _it = 1
                    if _RESOL != 0 and _chk != 0:
                        if _asked != 2:
                            resolution(_J, _rr, _MAXRES)
                            _rho = _rr[0]
                            if _rr[1] != 0.0:
                                _asked = 1
                        if _asked != 1 and not _rho <= _MAXRES:
                            _status = _S_UNRESOLVED
                            _val = _rho
                    if _asked != 1 and _status == _S_OK:
                        for _i in range(_N):
                            if not (_z[_i] - _z[_i] == 0.0):
                                _status = _S_LINEAR_FAILED
                                _val = math.nan
                elif _KIND == 0:
                    # Newton's method (solvers 0 newton, 1 simplified, 2 fixed point, 3 reuse,
                    # 4 auto); this stage's solver state, for a stage asked again
                    _mode0 = _smode[_b, _k]
                    _bk = _b * _STAGES + _k
                    _luok0 = 0.0
                    if _solver == 3:
                        _luok0 = _sluok[_b, _k]
                    _snap = 0
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
                    # One call site per kernel (each is inlined where it is called): the
                    # iterations (phase 0), then for a failure R at the last iterate (phase 2,
                    # maxiter reached) and the Newton matrix at the start value (phase 1, is the
                    # step resolved there at all?) through the same sites.
                    _phase = 0
                    while True:
                        if _phase == 0:
                            if _it >= _maxiter:
                                _phase = 2
                                if _solver == 3:
                                    _sluok[_b, _k] = 0.0
                            else:
                                _it += 1
                        _fp = 0
                        _jac = 0
                        if _phase == 1:
                            _jac = 1
                        elif _phase == 0:
                            if _solver == 2 or (_solver == 4 and _newton == 0):
                                _fp = 1
                            elif _solver == 3:
                                if _sluok[_b, _k] == 0.0:
                                    _jac = 1
                            elif _solver == 0 or _solver == 4 or _have == 0:
                                _jac = 1
                        if _jac != 0:
                            resjac(_z, _yl, _cl, _hs, _p, _r, _J)
                            if _phase == 0:
                                _have = 1
                        else:
                            res(_z, _yl, _cl, _hs, _p, _r)
                        if _phase == 1:
                            # the failure's verdict: unresolved at the start value (ρ above the
                            # threshold of a Newton failure), else the failure as it was
                            if _asked != 2:
                                resolution(_J, _rr, _NFR)
                                _rho = _rr[0]
                                if _rr[1] != 0.0:
                                    _asked = 1
                            if _asked != 1 and _rho > _NFR:
                                _status = _S_UNRESOLVED_START
                                _val = _rho
                            elif _status == _S_DIVERGED:
                                _val = amax(_r)    # the residual's size at the start value
                            break
                        if _phase == 2:
                            # maxiter reached: slow (the residual already near round-off), not
                            # resolved at the start value, or not converged
                            _rn = amax(_r)
                            _zn = amax(_z)
                            _yn = 0.0
                            for _i in range(_DIM):
                                _v = abs(_yl[_i])
                                if _v > _yn or _v != _v:
                                    _yn = _v
                            _it = _maxiter
                            _val = _rn
                            if _usetol == 0 and (_rn <= _TOL_PLATEAU * max(_zn, _floor) or _rn <= _TOL_ROUNDOFF * _yn):
                                _status = _S_SLOW
                                break
                            _status = _S_NOT_CONVERGED
                            if _RESOL != 0 and _chk != 0:
                                for _i in range(_N):
                                    _z[_i] = _zp[_i]    # (z is not used after a failure)
                                _phase = 1
                                continue
                            break
                        if _fp != 0:
                            # fixed point z <- F(z) for R(z) = z - F(z): the increment is R
                            for _i in range(_N):
                                _dz[_i] = _r[_i]
                        elif _solver == 3:
                            # simplified Newton whose LU factors are kept over steps: refreshed
                            # at the current iterate when an iteration contracts by less than
                            # REUSE_RATE, and from the predictor when an iterate diverges
                            _okb[0] = 1.0
                            if _jac != 0:
                                if _snap == 0:
                                    for _i in range(_N * _N):
                                        _LU0[_i] = _sLU[_bk, _i]
                                    for _i in range(_N):
                                        _pv0[_i] = _spiv[_bk, _i]
                                    _snap = 1
                                lu(_J, _sLU[_bk], _spiv[_bk], _okb)
                                if _okb[0] != 0.0:
                                    _sluok[_b, _k] = 1.0
                            if _okb[0] != 0.0:
                                lu_solve(_sLU[_bk], _spiv[_bk], _r, _dz)
                            else:
                                for _i in range(_N):
                                    _dz[_i] = math.nan
                        else:
                            solve(_J, _r, _dz, _wa, _wb)
                        for _i in range(_N):
                            _z[_i] -= _dz[_i]
                        _nd = amax(_dz)
                        _nz = amax(_z)
                        _nz = max(_nz, _floor)
                        if _solver == 4 and _newton == 0 and (not _nd <= 1e300 or (_it >= 2 and _nd > _AUTO_RATE * _prev)):
                            # the fixed point diverges or contracts slowly: Newton's method from
                            # this iterate (from the predictor after a non-finite one) for this
                            # step and the next AUTO_HOLD
                            _newton = 1
                            _smode[_b, _k] = _AUTO_HOLD1
                            if not _nd <= 1e300:
                                for _i in range(_N):
                                    _z[_i] = _zp[_i]
                            _prev = math.inf
                            continue
                        if not _nd <= 1e300:
                            if _solver == 3 and _have == 0:
                                # factors kept from earlier steps led astray: start again from
                                # the predictor with fresh ones
                                _sluok[_b, _k] = 0.0
                                for _i in range(_N):
                                    _z[_i] = _zp[_i]
                                _prev = math.inf
                                continue
                            if _solver == 3:
                                _sluok[_b, _k] = 0.0
                            # diverged: unresolved at the start value, or diverged
                            _status = _S_DIVERGED
                            if _RESOL != 0 and _chk != 0:
                                for _i in range(_N):
                                    _z[_i] = _zp[_i]    # (z is not used after a failure)
                                _phase = 1
                                continue
                            _val = amax(_r)    # the residual's size at the last iterate
                            break
                        _conv = 0
                        if _usetol != 0:
                            if _nd <= _tol:
                                _conv = 1
                        elif _nd <= _TOL_ROUNDOFF * _nz or (_nd >= _prev and _prev <= _TOL_PLATEAU * _nz):
                            _conv = 1
                        if _conv != 0:
                            if _RESOL != 0 and _chk != 0:
                                if _have != 0:
                                    if _asked != 2:
                                        resolution(_J, _rr, _MAXRES)
                                        _rho = _rr[0]
                                        if _rr[1] != 0.0:
                                            _asked = 1
                                    if _asked != 1 and not _rho <= _MAXRES:
                                        _status = _S_UNRESOLVED
                                        _val = _rho
                                if _asked != 1 and _status == _S_OK:
                                    # the predictor disagrees with the converged step by more
                                    # than the step itself: h does not resolve the dynamics
                                    _dis = 0.0
                                    if _nz > 0.0:
                                        for _i in range(_N):
                                            _v = abs(_z[_i] - _zp[_i])
                                            if _v > _dis or _v != _v:
                                                _dis = _v
                                        _dis = _dis / _nz
                                    if not _dis <= _MAXDIS:
                                        _status = _S_MISPREDICTED
                                        _val = _dis
                            if _asked != 1 and _status == _S_OK and _newton != 0:
                                _smode[_b, _k] -= 1.0
                            break
                        if _solver == 3 and _nd > _REUSE_RATE * _prev:
                            _sluok[_b, _k] = 0.0     # contracting too slowly: factor at this iterate
                        _prev = _nd
                    if _asked == 1:
                        _smode[_b, _k] = _mode0
                        if _solver == 3:
                            _sluok[_b, _k] = _luok0
                        if _snap != 0:
                            for _i in range(_N * _N):
                                _sLU[_bk, _i] = _LU0[_i]
                            for _i in range(_N):
                                _spiv[_bk, _i] = _pv0[_i]
                if _asked == 1:
                    # ask the driver for the spectral radius of J - I; this stage is computed
                    # again, from the state below, when it calls back
                    for _i in range(_N):
                        for _j in range(_N):
                            _jout[_i, _j] = _J[_i, _j]
                    _dec[0] = _b
                    _dec[1] = _n
                    _dec[2] = _k
                    _dec[3] = _limit
                    for _j in range(_KLERR):
                        _K[_b, _j] = _g0[_j]
                    _K[_b, _NK] = _e0
                    _K[_b, _NK + 1] = _e1
                    _st[0] = 1.0
                    _stop = 1
                    break
                if _KIND != 2:
                    _its[_b, _n - _n0] += _it
                    if _status != _S_OK:
                        _fst[_b, 0] = _status
                        _fst[_b, 1] = _n
                        _fst[_b, 2] = _it
                        _fval[_b] = _val
                        _failed = 1
                        break
                _bad = 0.0
                if _MERGED != 0:
                    # a composed Störmer–Verlet step with merged kicks: y stays (q0, p0) through
                    # the step and _cl holds D, the step's increment so far (from the carried
                    # compensation); the stage is called at y + D with the kick the last stage's
                    # closing one and its own merged (b_{k-1} + a_k), and no closing kick (_hb 0:
                    # the next stage's, or the step's end, makes it).  D_q takes the drift, D_p
                    # the kick here (the kernel's own sum p + (D_p - kick), which LLVM shares);
                    # the stage's unread Δp is dropped.  From one force to the next: the kick, the
                    # drift, q0 + D_q and the force (about 10 dependent operations on
                    # Hénon–Heiles, 15 with Kahan's sum at every stage).
                    if _k == 0:
                        _hk = _h * _ka[0]
                    else:
                        _hk = _h * (_kb[_k - 1] + _ka[_k])
                    post(_z, _yl, _cl, _gl, _hk, _hs, 0.0, _p, _out)
                    for _i in range(_NF):
                        _cl[_i] = _cl[_i] + _out[_i]
                        _cl[_NF + _i] = _cl[_NF + _i] - _hk * _gl[_i]
                else:
                    # the increment, then what the checks need at y1
                    post(_z, _yl, _cl, _gl, _h * _ka[_k], _hs, _h * _kb[_k], _p, _out)
                for _i in range(_DIM):
                    if _MERGED != 0:
                        continue
                    if _comp != 0:
                        # compensated (Kahan) summation: the rounding error of y + Δy is
                        # carried to the next stage
                        _s, _cl[_i] = compensated_add(_yl[_i], _cl[_i], _out[_i])
                        _yl[_i] = _s
                    else:
                        _s = _yl[_i] + _out[_i]
                        _yl[_i] = _s
                    if _FINITE_EVERY_STAGE or _k == _STAGES - 1:
                        if not (_s - _s == 0.0):
                            _bad = 1.0
                # first-same-as-last: the force at this stage's end starts the next stage
                for _i in range(_NF):
                    _gl[_i] = _out[_DIM + _i]
                # the checks at the stage's end: a failure is recorded (status, step, iteration
                # or condition, value) and ends the trajectory's run
                if _bad != 0.0:
                    _fst[_b, 0] = _S_NON_FINITE
                    _fst[_b, 1] = _n
                    _fst[_b, 2] = 0
                    _fval[_b] = math.nan
                    _failed = 1
                    break
                _jbad = -1
                for _j in range(_NDOMAIN):
                    _v = _out[_PD + _j]
                    if (_DPOS[_j] != 0 and not (_v > 0.0)) or (_DPOS[_j] == 0 and not (_v >= 0.0)):
                        _jbad = _j
                        break
                if _jbad >= 0:
                    _fst[_b, 0] = _S_OUT_OF_DOMAIN
                    _fst[_b, 1] = _n
                    _fst[_b, 2] = _jbad
                    _fval[_b] = _out[_PD + _jbad]
                    _failed = 1
                    break
                if _TT_GUARD:
                    if not (_out[_PT] > 0.0) or (_chk != 0 and abs(_out[_PT + 1]) > _MLD * _out[_PT + 2]):
                        _fst[_b, 0] = _S_TIME_SCALE
                        _fst[_b, 1] = _n
                        _fst[_b, 2] = 0
                        _fval[_b] = _out[_PT]
                        _failed = 1
                        break
                if _LERR != 0 and _chk != 0:
                    if _LERR == 1:
                        _ne2 = _out[_PE]
                        _nd2 = _out[_PE + 1]
                    else:
                        _ne2 = 0.0
                        for _j in range(_KLERR):
                            _e = _out[_PE + 1 + _j] - _RATIOS[_k] * _g0[_j]
                            _g0[_j] = _out[_PE + 1 + _KLERR + _j]
                            _ne2 += _e * _e
                        _nd2 = _out[_PE]
                    if _ne2 > _LERR2 * _nd2:
                        _fst[_b, 0] = _S_LOCAL_ERROR
                        _fst[_b, 1] = _n
                        _fst[_b, 2] = 0
                        _fval[_b] = _LERR_SCALE * math.sqrt(_ne2 / _nd2)
                        _failed = 1
                        break
                if _EJUMP == 1:
                    if _chk != 0 and abs(_out[_PJ] - _e0) > _MEJ * _e1:
                        _fst[_b, 0] = _S_ENERGY_JUMP
                        _fst[_b, 1] = _n
                        _fst[_b, 2] = 0
                        _fval[_b] = abs(_out[_PJ] - _e0) / _e1
                        _failed = 1
                        break
                    _e0 = _out[_PJ]
                    _e1 = _out[_PJ + 1]
                _k += 1
            if _MERGED != 0 and _stop == 0:
                # the composed step's end (or a failed stage's): its closing kick, then y + D in
                # one sum, compensated (Kahan: the new compensation is its rounding error) or
                # plain (the compensation left as it came, as every stage leaves it then)
                if _failed == 0:
                    _hk = _h * _kb[_STAGES - 1]
                    for _i in range(_NF):
                        _cl[_NF + _i] = _cl[_NF + _i] - _hk * _gl[_i]
                for _i in range(_DIM):
                    _a = _cl[_i]
                    if _comp != 0:
                        _s = _yl[_i] + _a
                        _cl[_i] = _a - (_s - _yl[_i])
                    else:
                        _s = _yl[_i] + (_a - _cst[_i])
                        _cl[_i] = _cst[_i]
                    _yl[_i] = _s
                    if not (_s - _s == 0.0):
                        _bad = 1.0
                if _bad != 0.0 and _failed == 0:
                    _fst[_b, 0] = _S_NON_FINITE
                    _fst[_b, 1] = _n
                    _fst[_b, 2] = 0
                    _fval[_b] = math.nan
                    _failed = 1
                    _k = _STAGES - 1
            if _EJUMP == 2 and _failed == 0 and _stop == 0 and _PROJ == 0:
                # a composition: the energy jump of the composed step, H at its end against its
                # start (stage -1 in the record: the composed step, no stage of it)
                hs(_yl, _p, _ejn)
                if _chk != 0 and abs(_ejn[0] - _e0) > _MEJ * _e1:
                    _fst[_b, 0] = _S_ENERGY_JUMP
                    _fst[_b, 1] = _n
                    _fst[_b, 2] = 0
                    _fval[_b] = abs(_ejn[0] - _e0) / _e1
                    _failed = 1
                    _k = -1
                _e0 = _ejn[0]
                _e1 = _ejn[1]
            if _stop != 0:
                break
            if _failed != 0:
                _fst[_b, 3] = _k    # the stage that failed (for the message)
                _limit = _n + 1
                break
            if _n + 1 == _nxt:
                for _i in range(_DIM):
                    _T[_row, _b, _i] = _yl[_i]
                _row = _row + 1
                _nxt = _nxt + _every
        for _i in range(_DIM):
            _Y[_b, _i] = _yl[_i]
            _C[_b, _i] = _cl[_i]
        for _i in range(_NG):
            _G[_b, _i] = _gl[_i]
        if _PROJ != 0:
            for _j in range(_PM):
                _PRJ[_b, _PM + _j] = _plam[_j]
        if _stop != 0:
            return


def project(y, c, lam, tgt, p, h, ka, kd, kb, maxiter, z, frc, out, y1, c1, yt, ct, lag, gv, gv1, D0, D1, A, W,
            v, res):
    """One projected step from ``(y, c)`` (state and compensation) onto the level set ``g = tgt``
    (:mod:`methodgen.symbolic.projection`: the iteration on the multipliers ``lam``, updated in place):
    ``y1``, ``c1`` the new state and its compensation; ``res`` = status, value, iterations.

    Symmetric projection (PSYM 1): ỹ0 = y0 + D(y0)λ, ŷ1 = Φ_h(ỹ0), y1 = ŷ1 + D(y1)λ with
    g(y1) = tgt, D = diag(w) Gᵀ; Φ_h (every stage of the base composition, ``post`` with the
    first-same-as-last ``force`` at its start) is evaluated again at every iterate.  Standard
    projection (PSYM 0): ŷ1 = Φ_h(y0) once.  The first matrix is G(y1)(D(y0) + D(y1)) (G(y1)
    D(y1)), later ones Broyden's update; converged when every residual is within PTOL of the
    size of g's first-order terms, or stopped decreasing at or below PPLAT of it.  Statuses:
    NON_FINITE, NOT_CONVERGED, DIVERGED (a non-finite residual or multiplier), LOCAL_ERROR (the
    base step's direct estimate at the first iterate, with check_resolution).  Every sum is
    compensated.  The kernels' output ``proj``: g (PM), G row by row (PM·DIM), w (DIM)."""
    wo = _PM + _PM * _DIM        # where w starts in proj's output
    if _PSYM != 0:
        proj(y, p, gv)
        for a in range(_PM):
            for i in range(_DIM):
                D0[a, i] = gv[wo + i] * gv[_PM + a * _DIM + i]
    prev = math.inf
    status = _S_NOT_CONVERGED
    rn = 0.0
    it = 0
    while it < maxiter:
        it += 1
        if it == 1 or _PSYM != 0:
            # the base step from ỹ0 (symmetric: at every iterate; standard: from y0 once,
            # yt and ct keep ŷ1 for the later iterates)
            for i in range(_DIM):
                d = 0.0
                if _PSYM != 0:
                    for a in range(_PM):
                        d += D0[a, i] * lam[a]
                d += c[i]
                s = y[i] + d
                ct[i] = d - (s - y[i])
                yt[i] = s
            if _NF > 0:
                force(yt, ct, p, frc)
            ne2 = 0.0
            nd2 = 1.0
            for k in range(_STAGES):
                post(z, yt, ct, frc, h * ka[k], h * kd[k], h * kb[k], p, out)
                for i in range(_DIM):
                    yt[i], ct[i] = compensated_add(yt[i], ct[i], out[i])
                for i in range(_NF):
                    frc[i] = out[_DIM + i]
                if _LERR == 1:
                    # the largest local error estimate of the stages (|E|², |Δy|²)
                    if out[_PE] * nd2 > ne2 * out[_PE + 1] or out[_PE] != out[_PE]:
                        ne2 = out[_PE]
                        nd2 = out[_PE + 1]
            if _LERR == 1 and _chk != 0 and it == 1 and ne2 > _LERR2 * nd2:
                # the base step does not resolve the dynamics here
                status = _S_LOCAL_ERROR
                rn = _LERR_SCALE * math.sqrt(ne2 / nd2)
                break
        if it == 1:
            # D at ŷ1 for the first y1: y1 = ŷ1 + D(y1)λ then holds to O(|λ|²)
            proj(yt, p, gv1)
            if _PSYM == 0:
                for i in range(_DIM):
                    gv[wo + i] = gv1[wo + i]   # the metric w
            for a in range(_PM):
                for i in range(_DIM):
                    D1[a, i] = gv[wo + i] * gv1[_PM + a * _DIM + i]
        finite = 1
        for i in range(_DIM):
            d = ct[i]
            for a in range(_PM):
                d += D1[a, i] * lam[a]
            s = yt[i] + d
            c1[i] = d - (s - yt[i])
            y1[i] = s
            if not (s - s == 0.0):
                finite = 0
        if finite == 0:
            status = _S_NON_FINITE
            rn = math.nan
            break
        proj(y1, p, gv1)
        # the lag of the D(y1) that y1 was built with, and the residual at the consistent
        # y1 = ŷ1 + D(y1)λ to first order in it
        for i in range(_DIM):
            s = 0.0
            wi = gv[wo + i]
            for a in range(_PM):
                s += (wi * gv1[_PM + a * _DIM + i] - D1[a, i]) * lam[a]
            lag[i] = s
        # each residual against its round-off: the size of g's first-order terms (v[3])
        rn = 0.0
        rel = 0.0
        for a in range(_PM):
            s = gv1[a] - tgt[a]
            zz = 0.0
            for i in range(_DIM):
                s += gv1[_PM + a * _DIM + i] * lag[i]
                zz += abs(gv1[_PM + a * _DIM + i]) * max(abs(y[i]), abs(y1[i]))
            v[0, a] = s
            v[3, a] = zz
            rn = max(rn, abs(s))
            if zz > 0.0:
                rel = max(rel, abs(s) / zz)
            elif s != 0.0:
                rel = math.inf
        if not (rel - rel == 0.0):
            status = _S_DIVERGED
            break
        if rel <= _PTOL or (rel >= prev and prev <= _PPLAT):
            status = _S_OK
            # y1 rebuilt with D(y1) itself (the lag, already in the residual, leaves y1)
            for i in range(_DIM):
                y1[i], c1[i] = compensated_add(y1[i], c1[i], lag[i])
            break
        prev = rel
        if it == 1:
            # ∂g(y1)/∂λ with Φ_h' replaced by I (relative error O(h)); the standard
            # projection does not move the start: G(y1) D(y1) alone
            for a in range(_PM):
                for e in range(_PM):
                    s = 0.0
                    for i in range(_DIM):
                        dn = gv[wo + i] * gv1[_PM + e * _DIM + i]
                        if _PSYM != 0:
                            s += gv1[_PM + a * _DIM + i] * (D0[e, i] + dn)
                        else:
                            s += gv1[_PM + a * _DIM + i] * dn
                    A[a, e] = s
        else:
            # Broyden's update from the last two iterates, unless the residual's change is
            # round-off (PNOISE of the size of g's first-order terms)
            dd = 0.0
            for e in range(_PM):
                dl = lam[e] - v[2, e]
                dd += dl * dl
            big = 0
            for a in range(_PM):
                if abs(v[0, a] - v[1, a]) > _PNOISE * v[3, a]:
                    big = 1
            if dd > 0.0 and big != 0:
                for a in range(_PM):
                    u = v[0, a] - v[1, a]
                    for e in range(_PM):
                        u -= A[a, e] * (lam[e] - v[2, e])
                    u = u / dd
                    for e in range(_PM):
                        A[a, e] += u * (lam[e] - v[2, e])
        for a in range(_PM):
            v[4, a] = -v[0, a]
        small_solve(A, v[4], v[6], W, v[5])
        ok = 1
        for a in range(_PM):
            v[2, a] = lam[a]
            v[1, a] = v[0, a]
            lam[a] += v[6, a]
            if not (lam[a] - lam[a] == 0.0):
                ok = 0
            for i in range(_DIM):
                D1[a, i] = gv[wo + i] * gv1[_PM + a * _DIM + i]
        if ok == 0:
            status = _S_DIVERGED
            break
    res[0] = status
    res[1] = rn
    res[2] = it


def compensated_add(y, c, x):
    """Compensated (Kahan) ``y + x`` with the compensation ``c`` of ``y`` (the true value is
    about ``y + c``): ``(s, c')`` with ``s = y + (x + c)`` and ``c' = (x + c) - (s - y)``, the
    rounding error of that sum, carried to the next.  The one implementation of the
    compensated add: the stepper's state updates and the Wisdom–Holman runtime's
    (:mod:`methodgen.runtime.kepler_flow`, whose compensations have the other sign) call it."""
    a = x + c
    s = y + a
    return s, a - (s - y)


def settled(size, scale, last, tol):
    """1 where an iteration has converged, else 0: its update ``size`` (max-norm) is at ``tol``
    times the iterate's ``scale``, or at round-off (1000 ulps of it) and no longer halving from the
    ``last`` one.  The rule of the lattice and particle step loops
    (:mod:`methodgen.runtime.lattice_stepper`, :mod:`methodgen.runtime.particle_stepper`), which
    bind it as this module's."""
    if size <= tol * scale or (size <= 1e3 * 2.220446049250313e-16 * scale and size > 0.5 * last):
        return 1
    return 0


def small_solve(A, b, x, W, c):
    """``x`` with ``A x = b`` (PM × PM) by Gaussian elimination with partial pivoting on the
    copies ``W``, ``c``; NaN where A is singular."""
    for i in range(_PM):
        c[i] = b[i]
        for j in range(_PM):
            W[i, j] = A[i, j]
    singular = 0
    for k in range(_PM):
        if singular == 0:
            piv = k
            for i in range(k + 1, _PM):
                if abs(W[i, k]) > abs(W[piv, k]):
                    piv = i
            if not W[piv, k] != 0.0:
                for i in range(_PM):
                    x[i] = math.nan
                singular = 1
            else:
                if piv != k:
                    for j in range(_PM):
                        t = W[k, j]
                        W[k, j] = W[piv, j]
                        W[piv, j] = t
                    t = c[k]
                    c[k] = c[piv]
                    c[piv] = t
                for i in range(k + 1, _PM):
                    f = W[i, k] / W[k, k]
                    for j in range(k, _PM):
                        W[i, j] -= f * W[k, j]
                    c[i] -= f * c[k]
    if singular == 0:
        for kk in range(_PM):
            k = _PM - 1 - kk
            s = c[k]
            for j in range(k + 1, _PM):
                s -= W[k, j] * x[j]
            x[k] = s / W[k, k]


def solve(_a0, _r0, _x, _wa, _wb):
    """Solve ``_a0 x = _r0`` (N unknowns, bandwidths KL, KU: constants): the closed form for
    N <= 3, else Gaussian elimination with partial pivoting within the band; a singular
    matrix gives NaN (reported as divergence)."""
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


def resolution(_Jr, _rr, _lim):
    """h·ω from the Newton matrix, for a verdict ``h·ω <= _lim``: ``_rr[0]`` = 2·(max row sum
    of |J - I|) (RESOL 1, "full"; 2·sqrt(·) for 2, "reduced") where that bound is at most the
    threshold RTHRESH (or N = 1).  Above it the value is the spectral radius ρ of J - I, from
    its eigenvalues, which this loop does not compute: where a bound u >= ρ (the closed form
    for N = 2, else the smaller of the column-sum and Frobenius norms, each widened by more than
    the rounding of either computation: LAPACK's computed |λ| is the exact one of a matrix
    within c·eps·|A| of J - I, below |A|·(1 + 1e-10) for any norm |A|; a defective 2×2 block
    moves its eigenvalues by up to sqrt(eps)·|A|) already passes ``_lim``, ``_rr[0]`` is that
    bound (the verdict is the same; the value of a passed check is not reported); otherwise
    ``_rr[1] = 1``: the stepper asks its driver.  A NaN entry gives a NaN norm, which no
    threshold passes."""
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
    _rr[1] = 0.0
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
        _rr[0] = v
        if not v <= _lim:
            _rr[1] = 1.0
    elif _RESOL == 1:
        _rr[0] = 2.0 * norm
    else:
        _rr[0] = 2.0 * math.sqrt(norm)


def lu(_Jm, _LU, _pv, _okb):
    """LU factorisation with partial pivoting (within the band KL, KU) of ``_Jm`` into ``_LU``
    (N·N, row-major; the row permutation in ``_pv``, as floats); ``_okb[0]`` = 0 for an exactly
    singular matrix (solver "reuse")."""
    for i in range(_N):
        _pv[i] = i
        for j in range(_N):
            _LU[i * _N + j] = _Jm[i, j]
    _okb[0] = 1.0
    for col in range(_N):
        if _okb[0] != 0.0:
            best = abs(_LU[col * _N + col])
            pr = col
            for i in range(col + 1, min(_N, col + _KL + 1)):
                v = abs(_LU[i * _N + col])
                if v > best:
                    best = v
                    pr = i
            if not best > 0.0:
                _okb[0] = 0.0
            else:
                if pr != col:
                    for j in range(_N):
                        t = _LU[col * _N + j]
                        _LU[col * _N + j] = _LU[pr * _N + j]
                        _LU[pr * _N + j] = t
                    t = _pv[col]
                    _pv[col] = _pv[pr]
                    _pv[pr] = t
                inv = 1.0 / _LU[col * _N + col]
                high = min(_N, col + _KL + _KU + 1)   # columns a pivot row can reach (the band)
                for i in range(col + 1, min(_N, col + _KL + 1)):
                    f = _LU[i * _N + col] * inv
                    _LU[i * _N + col] = f
                    if f != 0.0:
                        for j in range(col + 1, high):
                            _LU[i * _N + j] -= f * _LU[col * _N + j]


def lu_solve(_LU, _pv, _b, _x):
    """Solve J x = b from the factors of :func:`lu` (forward, then back substitution)."""
    for i in range(_N):
        s = _b[int(_pv[i])]
        for j in range(i):
            s -= _LU[i * _N + j] * _x[j]
        _x[i] = s
    for ii in range(_N):
        i = _N - 1 - ii
        s = _x[i]
        for j in range(i + 1, min(_N, i + _KL + _KU + 1)):
            s -= _LU[i * _N + j] * _x[j]
        _x[i] = s / _LU[i * _N + i]


def amax(_v):
    """Max-norm of ``_v[:N]`` that propagates NaN (a NaN entry must fail every later test)."""
    m = 0.0
    for i in range(_N):
        a = abs(_v[i])
        if a > m or a != a:
            m = a
    return m


def lockstep(_Y, _C, _G, _T, _p, _ka, _kd, _kb, _h, _n0, _n1, _every, _nxt0, _row0, _fst, _fval, _nbt):
    """Steps ``_n0 .. _n1-1`` of trajectories ``0 .. _nbt-1`` of an explicit method (KIND 2,
    no projection), ``_L`` trajectories at a time in lock-step: the lanes of a block.

    The block is component-major, lanes innermost (component i of lane l at ``i * _L + l``),
    so that the module's block kernel ``post_block`` -- its straight-line ``post`` code in a
    loop over the lanes, with the state's update (compensated or not) and the carried force
    -- and the checks' lane loops have unit stride and no branch across lanes, and LLVM
    vectorises them.  Every lane's arithmetic is :func:`stepper`'s, operation for operation,
    so the rows are bitwise those of the one-trajectory loop.

    The checks (non-finite state, domain, time-scale guard, local error, energy jump) are a
    count of failing lanes after every stage (a composition's energy jump: after every composed
    step, lane by lane); only where it is not zero a scalar pass
    (:func:`lane_status`) records each failing lane as :func:`stepper` does (status, step,
    index, stage; value).  A failed lane keeps its state after the failing stage; the other
    lanes of its block finish that step, and every later block runs only up to it, so rows
    ``0 .. step`` are complete and the first failing step and its trajectories are those of
    the one-trajectory loop.  The arguments are :func:`stepper`'s (``_Y``, ``_C``, ``_G``
    updated in place, ``_T`` the saved rows, ``_nxt0`` / ``_row0`` the first kept step and its
    row, ``_fst`` / ``_fval`` the failures)."""
    _YS = stack_array((_DIM * _L,))
    _CS = stack_array((_DIM * _L,))
    _CST = stack_array((_DIM * _L,))   # the compensation as it came (merged, plain)
    _FS = stack_array((_NG * _L,))
    _PS = stack_array((_PL * _L,))
    _G0 = stack_array((_NK * _L,))     # (h_prev/2) f per lane ("carry")
    _EJS = stack_array((2 * _L,))        # H and its size at the step's start
    _NE2 = stack_array((_L,))
    _ND2 = stack_array((_L,))
    _DEAD = stack_array((_L,))     # lane failed in this step (at stage DEAD - 1)
    _SAVE = stack_array(((2 * _DIM + _NG) * _L,))
    _ck = stack_array((1 + _DIM,))
    _ejs = stack_array((2,))
    _yq = stack_array((_DIM,))          # one lane's state (EJUMP 2)
    _ls = stack_array((3,))
    for _i in range(_L):
        _NE2[_i] = 0.0
        _ND2[_i] = 0.0
    _hh = 0.5 * _h * _GAMMA0
    _limit = _n1
    _b0 = 0
    while _b0 < _nbt:
        _nl = min(_L, _nbt - _b0)
        for _l in range(_nl):
            _b = _b0 + _l
            _fst[_b, 0] = _S_OK
            _DEAD[_l] = 0.0
            for _i in range(_DIM):
                _YS[_i * _L + _l] = _Y[_b, _i]
                _CS[_i * _L + _l] = _C[_b, _i]
                _CST[_i * _L + _l] = _C[_b, _i]
            for _i in range(_NF):
                _FS[_i * _L + _l] = _G[_b, _i]
            if _EJUMP:
                hs(_Y[_b], _p, _ejs)
                _EJS[_l] = _ejs[0]
                _EJS[_L + _l] = _ejs[1]
            if _LERR == 2:
                check(_Y[_b], _p, _ck)
                for _j in range(_KLERR):
                    _G0[_j * _L + _l] = _hh * _ck[1 + _LIDX[_j]]
        _nxt = _nxt0
        _row = _row0
        _failed = 0
        for _n in range(_n0, _limit):
            for _k in range(_STAGES):
                # the stage for the whole block: y (compensated or not) and the carried force
                # updated in place, the check values in _PS, the count of non-finite components
                if _MERGED != 0:
                    # merged kicks (the stepper's stage): _CS holds D, _YS stays
                    if _k == 0:
                        _hk = _h * _ka[0]
                    else:
                        _hk = _h * (_kb[_k - 1] + _ka[_k])
                    _nbad = post_block(_YS, _CS, _FS, _hk, _h * _kd[_k], 0.0, _p, _PS, _nl, 2)
                else:
                    _nbad = post_block(_YS, _CS, _FS, _h * _ka[_k], _h * _kd[_k], _h * _kb[_k], _p, _PS, _nl, _comp)
                _rk = _RATIOS[_k]
                # the other checks: a count of failing lanes, one row of lanes at a time (an
                # integer count: LLVM vectorises the lane loops; a float sum it may not reorder)
                _cnt = 0
                for _j in range(_NDOMAIN):
                    _o = (_PD + _j) * _L
                    if _DPOS[_j] != 0:
                        for _l in range(_nl):
                            if not (_PS[_o + _l] > 0.0):
                                _cnt += 1
                    else:
                        for _l in range(_nl):
                            if not (_PS[_o + _l] >= 0.0):
                                _cnt += 1
                if _TT_GUARD:
                    for _l in range(_nl):
                        if not (_PS[_PT * _L + _l] > 0.0):
                            _cnt += 1
                    if _chk != 0:
                        for _l in range(_nl):
                            if abs(_PS[(_PT + 1) * _L + _l]) > _MLD * _PS[(_PT + 2) * _L + _l]:
                                _cnt += 1
                if _LERR != 0 and _chk != 0:
                    if _LERR == 1:
                        for _l in range(_nl):
                            _NE2[_l] = _PS[_PE * _L + _l]
                            _ND2[_l] = _PS[(_PE + 1) * _L + _l]
                    else:
                        for _l in range(_nl):
                            _NE2[_l] = 0.0
                            _ND2[_l] = _PS[_PE * _L + _l]
                        for _j in range(_KLERR):
                            for _l in range(_nl):
                                _e = _PS[(_PE + 1 + _j) * _L + _l] - _rk * _G0[_j * _L + _l]
                                _NE2[_l] += _e * _e
                    for _l in range(_nl):
                        if _NE2[_l] > _LERR2 * _ND2[_l]:
                            _cnt += 1
                if _EJUMP == 1 and _chk != 0:
                    for _l in range(_nl):
                        if abs(_PS[_PJ * _L + _l] - _EJS[_l]) > _MEJ * _EJS[_L + _l]:
                            _cnt += 1
                if _nbad != 0.0 or _cnt != 0:
                    # which lanes failed, and how: the checks in the one-trajectory loop's order
                    for _l in range(_nl):
                        if _DEAD[_l] == 0.0:
                            lane_status(_PS, _YS, _NE2, _ND2, _EJS, _l, _ls)
                            if _ls[0] != _S_OK:
                                _b = _b0 + _l
                                _fst[_b, 0] = _ls[0]
                                _fst[_b, 1] = _n
                                _fst[_b, 2] = _ls[1]
                                _fst[_b, 3] = _k
                                _fval[_b] = _ls[2]
                                _DEAD[_l] = _k + 1
                                for _i in range(_DIM):
                                    _SAVE[_i * _L + _l] = _YS[_i * _L + _l]
                                    _SAVE[(_DIM + _i) * _L + _l] = _CS[_i * _L + _l]
                                for _i in range(_NF):
                                    _SAVE[(2 * _DIM + _i) * _L + _l] = _FS[_i * _L + _l]
                                _failed = 1
                # what the next stage's checks start from
                if _LERR == 2:
                    for _j in range(_KLERR):
                        for _l in range(_nl):
                            _G0[_j * _L + _l] = _PS[(_PE + 1 + _KLERR + _j) * _L + _l]
                if _EJUMP == 1:
                    for _l in range(2 * _L):
                        _EJS[_l] = _PS[_PJ * _L + _l]    # H and its size: two consecutive rows
            if _MERGED != 0:
                # the composed step's end, lane by lane as in the stepper: a lane that failed at a
                # stage from its state then (no closing kick), the others after the closing
                # kick; then y + D (Kahan, or plain with the compensation as it came)
                _hk = _h * _kb[_STAGES - 1]
                for _l in range(_nl):
                    if _DEAD[_l] != 0.0:
                        for _i in range(_DIM):
                            _YS[_i * _L + _l] = _SAVE[_i * _L + _l]
                            _CS[_i * _L + _l] = _SAVE[(_DIM + _i) * _L + _l]
                        for _i in range(_NF):
                            _FS[_i * _L + _l] = _SAVE[(2 * _DIM + _i) * _L + _l]
                    else:
                        for _i in range(_NF):
                            _CS[(_NF + _i) * _L + _l] = _CS[(_NF + _i) * _L + _l] - _hk * _FS[_i * _L + _l]
                    _lbad = 0
                    for _i in range(_DIM):
                        _a = _CS[_i * _L + _l]
                        _y0 = _YS[_i * _L + _l]
                        if _comp != 0:
                            _s = _y0 + _a
                            _CS[_i * _L + _l] = _a - (_s - _y0)
                        else:
                            _s = _y0 + (_a - _CST[_i * _L + _l])
                            _CS[_i * _L + _l] = _CST[_i * _L + _l]
                        _YS[_i * _L + _l] = _s
                        if not (_s - _s == 0.0):
                            _lbad = 1
                    if _DEAD[_l] != 0.0:
                        _DEAD[_l] = _STAGES      # (its state is that of the failing stage, folded)
                    elif _lbad != 0:
                        _b = _b0 + _l
                        _fst[_b, 0] = _S_NON_FINITE
                        _fst[_b, 1] = _n
                        _fst[_b, 2] = 0
                        _fst[_b, 3] = _STAGES - 1
                        _fval[_b] = math.nan
                        _DEAD[_l] = _STAGES
                        _failed = 1
            if _EJUMP == 2:
                # a composition: each live lane's energy jump over the composed step (stepper's
                # test, on the same values)
                for _l in range(_nl):
                    if _DEAD[_l] == 0.0:
                        for _i in range(_DIM):
                            _yq[_i] = _YS[_i * _L + _l]
                        hs(_yq, _p, _ejs)
                        if _chk != 0 and abs(_ejs[0] - _EJS[_l]) > _MEJ * _EJS[_L + _l]:
                            _b = _b0 + _l
                            _fst[_b, 0] = _S_ENERGY_JUMP
                            _fst[_b, 1] = _n
                            _fst[_b, 2] = 0
                            _fst[_b, 3] = -1
                            _fval[_b] = abs(_ejs[0] - _EJS[_l]) / _EJS[_L + _l]
                            _DEAD[_l] = _STAGES      # (its state is the step's end: kept as it is)
                            _failed = 1
                        _EJS[_l] = _ejs[0]
                        _EJS[_L + _l] = _ejs[1]
            if _failed != 0:
                # the failed lanes keep their state after the failing stage; the others
                # completed this step (a lane that failed at the last stage, or at the composed
                # step's end, ran no stage after it: its state is that already)
                for _l in range(_nl):
                    if _DEAD[_l] != 0.0 and _DEAD[_l] < _STAGES:
                        for _i in range(_DIM):
                            _YS[_i * _L + _l] = _SAVE[_i * _L + _l]
                            _CS[_i * _L + _l] = _SAVE[(_DIM + _i) * _L + _l]
                        for _i in range(_NF):
                            _FS[_i * _L + _l] = _SAVE[(2 * _DIM + _i) * _L + _l]
                _limit = _n + 1
            if _n + 1 == _nxt:
                for _l in range(_nl):
                    if _DEAD[_l] == 0.0:
                        for _i in range(_DIM):
                            _T[_row, _b0 + _l, _i] = _YS[_i * _L + _l]
                _row = _row + 1
                _nxt = _nxt + _every
            if _failed != 0:
                break
        for _l in range(_nl):
            _b = _b0 + _l
            for _i in range(_DIM):
                _Y[_b, _i] = _YS[_i * _L + _l]
                _C[_b, _i] = _CS[_i * _L + _l]
            for _i in range(_NF):
                _G[_b, _i] = _FS[_i * _L + _l]
        _b0 = _b0 + _L


def lane_status(PS, YS, NE2, ND2, EJS, l, out):
    """``out`` = (status, index, value) of lane ``l`` of a :func:`lockstep` block after a stage:
    its first failing check in :func:`stepper`'s order, or OK."""
    st = _S_OK
    ix = 0
    val = 0.0
    for i in range(_DIM):
        if st == _S_OK and not (YS[i * _L + l] - YS[i * _L + l] == 0.0):
            st = _S_NON_FINITE
            val = math.nan
    for j in range(_NDOMAIN):
        v = PS[(_PD + j) * _L + l]
        if st == _S_OK and ((_DPOS[j] != 0 and not (v > 0.0)) or (_DPOS[j] == 0 and not (v >= 0.0))):
            st = _S_OUT_OF_DOMAIN
            ix = j
            val = v
    if _TT_GUARD and st == _S_OK:
        if not (PS[_PT * _L + l] > 0.0) or (_chk != 0 and abs(PS[(_PT + 1) * _L + l]) > _MLD * PS[(_PT + 2) * _L + l]):
            st = _S_TIME_SCALE
            val = PS[_PT * _L + l]
    if _LERR != 0 and _chk != 0 and st == _S_OK:
        if NE2[l] > _LERR2 * ND2[l]:
            st = _S_LOCAL_ERROR
            val = _LERR_SCALE * math.sqrt(NE2[l] / ND2[l])
    if _EJUMP == 1 and _chk != 0 and st == _S_OK:
        d = abs(PS[_PJ * _L + l] - EJS[l])
        if d > _MEJ * EJS[_L + l]:
            st = _S_ENERGY_JUMP
            val = d / EJS[_L + l]
    out[0] = st
    out[1] = ix
    out[2] = val


def rows(_Z, _Y, _h, _p, _R, _J, _nb):
    """The step equations' residual (``_JAC`` 0), or residual and Newton matrix (``_JAC`` 1), at
    each of the ``_nb`` rows of ``_Z`` (B, N) and ``_Y`` (B, DIM), without compensation: ``_R``
    (B, N), ``_J`` (B·N, N), the matrix of row b in rows ``b·N .. b·N + N - 1`` (a module's
    ``residual()`` and ``jacobian()``)."""
    _c = stack_array((_DIM,))
    _Jb = stack_array((_NZ, _NZ))
    for _i in range(_DIM):
        _c[_i] = 0.0
    for _b in range(_nb):
        if _JAC != 0:
            for _i in range(_N):
                for _j in range(_N):
                    _Jb[_i, _j] = 0.0
            resjac(_Z[_b], _Y[_b], _c, _h, _p, _R[_b], _Jb)
            for _i in range(_N):
                for _j in range(_N):
                    _J[_b * _N + _i, _j] = _Jb[_i, _j]
        else:
            res(_Z[_b], _Y[_b], _c, _h, _p, _R[_b])
