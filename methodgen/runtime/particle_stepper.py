"""The step loops of a particle module (:mod:`methodgen.codegen.particle_emit`), one source run two ways.

:func:`sv_run` takes ``steps`` steps of a Störmer–Verlet composition (kicks and drifts with the
module's coefficients, adjacent half kicks merged, the force at the step's end kept for the next
step's first kick); :func:`em_run` ``steps`` steps of the energy-momentum method, the increment
``Δq = h ∇T(p0 - (h/2) A(q0, q0 + Δq))`` by fixed-point iteration from the Störmer–Verlet
predictor (``A(q0, q0) = ∇V(q0)``), in stages of size ``γ_k h`` where the method is composed to
a higher order.  Forces and discrete gradients are pair loops ``a < b`` over the module's pair
kernel (``fpair``, ``gpair``) plus, with an external potential, a loop over the particles
(``fext``, ``gext``): O(N²) + O(N) per sweep; the velocities a loop over the particles (``vel``).  Like :mod:`methodgen.runtime.lattice_stepper` this is written in the subset of
Python that :mod:`methodgen.codegen.llvmkernels` translates: the module's kernels are bound as
globals and inlined, the whole compiled with N a run-time argument -- or run as plain Python,
the reference the compiled loops are tested against bit for bit.

Why fixed-point iteration and not Newton: the iteration's contraction factor is about
``(h ω)²`` for the fastest pair frequency ω the step resolves, so a resolved step takes a few
iterations of one O(N²) pair sweep each, while Newton's dense matrix (assembled pair by pair,
d × d blocks) costs O(N² d²) to assemble and O((N d)³) to factor: beyond N ≈ 10 the factorisation
alone outweighs several sweeps (measured in ``benchmarks/nbody_pairloop.py``).

The state's sums are compensated (Kahan) across steps: each ``y += c x`` carries the rounding
error of the last one (``_CQ``, ``_CP``), at one O(N) pass per update beside the O(N²) sweeps.

References
----------
W. Kahan, "Further remarks on reducing truncation errors", Comm. ACM 8 (1965) 40; E. Hairer,
C. Lubich, G. Wanner, *GNI* (2006) VIII.5 (compensated summation in geometric integration).
"""

from __future__ import annotations

import math

__all__ = ["sv_run", "em_run", "STATUS"]

# flake8: noqa: F821  (``vel``, ``fpair``, ``fext``, ``gpair``, ``gext``, ``compensated_add``, ``settled`` are bound
# by the driver)

#: failure status of a run (``_fst[0]``)
STATUS = {"OK": 0, "CONVERGENCE": 1, "NONFINITE": 2}


def add(_Y, _C, _X, c, n, d):
    """``_Y += c _X`` elementwise with the compensation ``_C``: the stepper's compensated (Kahan)
    add, :func:`methodgen.runtime.stepper.compensated_add` (bound by the driver)."""
    for a in range(n):
        for k in range(d):
            t, _C[a, k] = compensated_add(_Y[a, k], _C[a, k], c * _X[a, k])
            _Y[a, k] = t


def forces(_Q, _F, _M, _p, n, d, hx):
    """``_F`` = the force at every particle: the pair kernel over the pairs a < b, then the
    external force (``hx`` 1)."""
    for a in range(n):
        for k in range(d):
            _F[a, k] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            fpair(_Q, _F, a, b, _M, _p)
    if hx != 0:
        for a in range(n):
            fext(_Q, _F, a, _M, _p)


def dg(_Q, _D, _A, _M, _p, n, d, hx):
    """``_A`` = the sum over the pairs of ±g (r0 + r1), r1 = r0 + D_a - D_b, then (``hx`` 1) the
    external potential's discrete gradient G(q0_a, q0_a + D_a) of every particle."""
    for a in range(n):
        for k in range(d):
            _A[a, k] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            gpair(_Q, _D, _A, a, b, _M, _p)
    if hx != 0:
        for a in range(n):
            gext(_Q, _D, _A, a, _M, _p)


def half_kick_velocity(_P, _A, _PT, _V, _M, _p, h, n, d):
    """``_V`` = ∇T(p - (h/2) A) at every particle (``_PT`` the kicked momenta): the energy-momentum
    step's velocity, for its predictor and for each fixed-point iterate."""
    for a in range(n):
        for k in range(d):
            _PT[a, k] = _P[a, k] - (0.5 * h) * _A[a, k]
    for a in range(n):
        vel(_PT, _V, a, _M, _p)


def finite(_Q, _P, n, d):
    """1 when every entry of the state is finite."""
    ok = 1
    for a in range(n):
        for k in range(d):
            if not (abs(_Q[a, k]) < math.inf and abs(_P[a, k]) < math.inf):
                ok = 0
    return ok


def save(_T, row, _Q, _P, n, d):
    for a in range(n):
        for k in range(d):
            _T[row, a * d + k] = _Q[a, k]
            _T[row, n * d + a * d + k] = _P[a, k]


def sv_run(_Q, _P, _CQ, _CP, _F, _V, _M, _p, _n, _d, _h, _steps, _every, _T, _kick, _drift, _ns, _hx, _fst):
    """Steps 0 … _steps-1 of the composition from ``_Q``, ``_P`` (n, d), updated in place.

    ``_T`` (rows, 2nd): row k + 1 the state after step (k + 1)·_every - 1 (and the last row the
    last state); ``_kick`` (_ns + 1,), ``_drift`` (_ns,): the coefficients (times h here);
    ``_hx``: 1 when there is an external force; ``_fst`` (4,): status (STATUS) and step of a failure.
    """
    n = _n
    d = _d
    h = _h
    forces(_Q, _F, _M, _p, n, d, _hx)
    row = 1
    for s in range(_steps):
        for k in range(_ns):
            add(_P, _CP, _F, _kick[k] * h, n, d)
            for a in range(n):
                vel(_P, _V, a, _M, _p)
            add(_Q, _CQ, _V, _drift[k] * h, n, d)
            forces(_Q, _F, _M, _p, n, d, _hx)
        add(_P, _CP, _F, _kick[_ns] * h, n, d)
        if finite(_Q, _P, n, d) == 0:
            _fst[0] = 2.0
            _fst[1] = s
            return
        if (s + 1) % _every == 0 or s + 1 == _steps:
            save(_T, row, _Q, _P, n, d)
            row += 1


def em_run(_Q, _P, _CQ, _CP, _A, _D, _PT, _V, _M, _p, _n, _d, _h, _steps, _every, _T, _its, _maxiter, _tol,
           _gam, _ns, _hx, _fst):
    """Steps 0 … _steps-1 of the energy-momentum method from ``_Q``, ``_P`` (n, d), in place.

    ``_A``, ``_D``, ``_PT``, ``_V`` (n, d): work (the discrete gradient, the increment, the mean
    momentum, the velocity); ``_gam`` (_ns,): the composition's stage coefficients (each stage a
    step of size ``_gam[k] h``; ``(1.0,)`` at order 2); ``_hx``: 1 when there is an external
    potential; ``_its`` (_steps,): iterations per step (summed over the stages); ``_fst`` (5,):
    status, step, iterations, the last update and the stage of a failure.  Converged: the update
    at ``_tol`` times the scale ``max |q| + max |Δq|``, or at round-off and no longer halving.
    """
    n = _n
    d = _d
    row = 1
    for s in range(_steps):
        _its[s] = 0.0
        for st in range(_ns):
            h = _gam[st] * _h
            for a in range(n):
                for k in range(d):
                    _D[a, k] = 0.0
            dg(_Q, _D, _A, _M, _p, n, d, _hx)
            half_kick_velocity(_P, _A, _PT, _V, _M, _p, h, n, d)
            for a in range(n):
                for k in range(d):
                    _D[a, k] = h * _V[a, k]
            last = math.inf
            done = 0
            it = 0
            size = 0.0
            while it < _maxiter:
                it += 1
                dg(_Q, _D, _A, _M, _p, n, d, _hx)
                half_kick_velocity(_P, _A, _PT, _V, _M, _p, h, n, d)
                size = 0.0
                qmax = 0.0
                dmax = 0.0
                for a in range(n):
                    for k in range(d):
                        dn = h * _V[a, k]
                        size = max(size, abs(dn - _D[a, k]))
                        _D[a, k] = dn
                        qmax = max(qmax, abs(_Q[a, k]))
                        dmax = max(dmax, abs(dn))
                scale = qmax + dmax
                if scale == 0.0:
                    scale = 1.0
                if not (size < math.inf):
                    _fst[0] = 2.0
                    _fst[1] = s
                    _fst[2] = it
                    _fst[4] = st
                    return
                if settled(size, scale, last, _tol) != 0:
                    done = 1
                    break
                last = size
            if done == 0:
                _fst[0] = 1.0
                _fst[1] = s
                _fst[2] = it
                _fst[3] = size
                _fst[4] = st
                return
            _its[s] += it
            add(_Q, _CQ, _D, 1.0, n, d)
            add(_P, _CP, _A, -h, n, d)
        if finite(_Q, _P, n, d) == 0:
            _fst[0] = 2.0
            _fst[1] = s
            return
        if (s + 1) % _every == 0 or s + 1 == _steps:
            save(_T, row, _Q, _P, n, d)
            row += 1
