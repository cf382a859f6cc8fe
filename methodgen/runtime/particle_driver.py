"""Run a compiled particle module's steps: :mod:`methodgen.runtime.particle_stepper` with the module's
kernels bound, compiled through LLVM once per module (machine code cached on disk, keyed by the
kernels' text), or run as plain Python where llvmlite is missing or ``python=True``."""

from __future__ import annotations

import math
import types

import numpy

from ..codegen import ktypes as _t
from . import particle_stepper as _ps
from . import stepper as _stepper
from .lattice_driver import _compiled

__all__ = ["run_sv", "run_em"]

_f8, _i8, _V, _M = _t.float64, _t.int64, _t.float64[::1], _t.float64[:, ::1]
#: Q, P, CQ, CP, F, V (n, d), M, p, n, d, h, steps, every, T, kick, drift, ns, hx, fst
SIG_SV = _t.void(_M, _M, _M, _M, _M, _M, _M, _V, _i8, _i8, _f8, _i8, _i8, _M, _V, _V, _i8, _i8, _V)
#: Q, P, CQ, CP, A, D, PT, V (n, d), M, p, n, d, h, steps, every, T, its, maxiter, tol, gammas, ns, hx, fst
SIG_EM = _t.void(_M, _M, _M, _M, _M, _M, _M, _M, _M, _V, _i8, _i8, _f8, _i8, _i8, _M, _V, _i8, _f8, _V, _i8, _i8,
                 _V)
_HELPERS = ("add", "forces", "dg", "half_kick_velocity", "finite", "save")
_LOOPS_SV: dict = {}
_LOOPS_EM: dict = {}


def _loop(entry: str, kernels: dict, key, cache: dict, sig, python: bool):
    consts = {"math": math, **kernels}
    for name in ("compensated_add", "settled"):      # the stepper's own helpers
        consts[name] = types.FunctionType(getattr(_stepper, name).__code__, consts, name)
    for name in _HELPERS:
        consts[name] = types.FunctionType(getattr(_ps, name).__code__, consts, name)
    fn = types.FunctionType(getattr(_ps, entry).__code__, consts, entry)
    if python:
        return fn, False
    return _compiled(cache, key, fn, sig, consts, f"the particle step loop ({entry})"), True


def _call(loop, compiled, args):
    if compiled:
        from .fused import _drive
        _drive(loop, *args)
    else:
        loop(*args)


def _rows(steps, every, n, d, Q, P):
    nrows = steps // every + (1 if steps % every else 0) + 1
    T = numpy.zeros((nrows, 2 * n * d))
    T[0, :n * d], T[0, n * d:] = Q.reshape(-1), P.reshape(-1)
    return T


def _finish(T, fst, steps, every, its):
    code = int(fst[0])
    done = int(fst[1]) if code else steps
    kept = done // every + 1 + (1 if code == 0 and steps % every else 0)
    return T[:kept], its[:steps].astype(numpy.int64), (code, int(fst[1]), int(fst[2]), float(fst[3]), int(fst[4]))


def _prepare(Q, P, M, p):
    Q = numpy.ascontiguousarray(Q, dtype=numpy.float64)
    P = numpy.ascontiguousarray(P, dtype=numpy.float64)
    M = numpy.ascontiguousarray(M, dtype=numpy.float64)
    p = numpy.ascontiguousarray(p, dtype=numpy.float64)
    return Q, P, M, p if p.size else numpy.zeros(1)


def _compensation(comp, n, d):
    """The compensations CQ, CP (n, d) a run starts from: ``comp`` (2, n, d), the run's it
    continues (copied; :func:`_keep` writes the end's back), or zeros for a new run."""
    if comp is None:
        return [numpy.zeros((n, d)), numpy.zeros((n, d))]
    if comp.shape != (2, n, d):
        raise ValueError(f"comp must have shape {(2, n, d)} (the compensations of q and p), got {comp.shape}")
    return [numpy.array(comp[0], dtype=numpy.float64), numpy.array(comp[1], dtype=numpy.float64)]


def _keep(comp, CQ, CP, fst):
    """The end's compensations into ``comp`` (where given) after a run that did not fail."""
    if comp is not None and int(fst[0]) == 0:
        comp[0], comp[1] = CQ, CP


def run_sv(vel, fpair, fext, Q, P, M, p, h, steps, every, kicks, drifts, has_external, *, python=False, comp=None):
    """Störmer–Verlet composition steps from ``Q``, ``P`` (n, d), updated in place: ``(rows, its,
    (code, step, iterations, value, stage))`` with rows (steps // every + 1 + …, 2nd), row 0 the start.

    ``comp``: None (a new run: no compensation), or the compensations of q and p, (2, n, d), of
    the run this call continues, overwritten with the end's (on success): a run continued in
    chunks is then bitwise the run in one piece."""
    Q, P, M, p = _prepare(Q, P, M, p)
    n, d = Q.shape
    T = _rows(steps, every, n, d, Q, P)
    fst = numpy.zeros(5)
    work = _compensation(comp, n, d) + [numpy.zeros((n, d)) for _ in range(2)]     # CQ, CP, F, V
    kick = numpy.ascontiguousarray(kicks, dtype=numpy.float64)
    drift = numpy.ascontiguousarray(drifts, dtype=numpy.float64)
    loop, compiled = _loop("sv_run", {"vel": vel, "fpair": fpair, "fext": fext}, fpair, _LOOPS_SV, SIG_SV, python)
    _call(loop, compiled, (Q, P, *work, M, p, int(n), int(d), float(h), int(steps), int(every), T, kick, drift,
                           int(len(drift)), int(has_external), fst))
    _keep(comp, work[0], work[1], fst)
    return _finish(T, fst, steps, every, numpy.zeros(max(steps, 1)))


def run_em(vel, gpair, gext, Q, P, M, p, h, steps, every, maxiter, tol, gammas=(1.0,), has_external=0, *,
           python=False, comp=None):
    """Energy-momentum steps from ``Q``, ``P`` (n, d), updated in place (as :func:`run_sv`; ``its``
    the fixed-point iterations per step, summed over the stages; ``comp`` as there): each step the
    stages of size ``γ_k h`` (``gammas``, the composition's coefficients); ``has_external``: 1 to
    add the external potential's discrete gradient (``gext``) per particle."""
    Q, P, M, p = _prepare(Q, P, M, p)
    n, d = Q.shape
    T = _rows(steps, every, n, d, Q, P)
    fst = numpy.zeros(5)
    its = numpy.zeros(max(steps, 1))
    work = _compensation(comp, n, d) + [numpy.zeros((n, d)) for _ in range(4)]     # CQ, CP, A, D, PT, V
    gam = numpy.ascontiguousarray(gammas, dtype=numpy.float64)
    loop, compiled = _loop("em_run", {"vel": vel, "gpair": gpair, "gext": gext}, gpair, _LOOPS_EM, SIG_EM, python)
    _call(loop, compiled, (Q, P, *work, M, p, int(n), int(d), float(h), int(steps), int(every), T, its,
                           int(maxiter), float(tol), gam, int(gam.size), int(has_external), fst))
    _keep(comp, work[0], work[1], fst)
    return _finish(T, fst, steps, every, its)
