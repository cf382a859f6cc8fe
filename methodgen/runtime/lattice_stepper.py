"""The step loop of a lattice module (:mod:`methodgen.codegen.lattice_emit`), one source run two ways.

:func:`lattice_run` takes ``steps`` steps of ``y1 = y0 + h J ∇̄H(y0, y1)`` on a lattice of n
sites: the predictor, Newton's method ("newton" or "simplified") with the Newton matrix
``I - h J ∂∇̄H/∂y1`` block tridiagonal and cyclic (2 × 2 blocks per site), factored by block
Gaussian elimination with a border (the periodic corner couples every row to the last site, and
the last row to every site: both carried as one extra block column and row, O(n) operations),
the convergence, non-finite and resolution checks, and the saved rows.  Like
:mod:`methodgen.runtime.stepper`, it is written in the subset of Python that
:mod:`methodgen.codegen.llvmkernels` translates: the module's kernel ``grad`` (∇̄H and its derivative,
a loop over the sites of each term, printed by the module) is bound as a global and inlined,
the whole compiled to machine code with the size n a run-time argument -- or run as plain Python
(the reference the compiled loop is tested against, and the fallback without llvmlite).

Work array ``_W`` (``W_ROWS``, n): ``G`` (2 rows: ∇̄H), ``D`` (12: the derivative's three block
diagonals, entries 00 01 10 11 of site j to j-1, j, j+1), ``Z``, ``ZP`` (2 each: the iterate and
the predictor), ``R`` (2: the residual, then the update), ``UI`` (4: the eliminated diagonal
blocks' inverses), ``LL`` (4: the multipliers of the rows), ``E`` (4: the border column), ``ML``
(4: the last row's multipliers), ``Y`` (2: the forward-substituted right-hand side), ``DY``, ``DY2``
(2 each: the last two steps' increments).

The predictor extrapolates the last two increments, ``z = y + 2 Δ₁ - Δ₂`` (error O(h³): fewer
Newton iterations than from the explicit Euler step, and no evaluation of ∇H of its own); the
second step takes ``y + Δ₁``, the first the explicit Euler step.

References
----------
G. H. Golub, C. F. Van Loan, *Matrix Computations*, 4th ed. (2013), §4.5 (block tridiagonal
systems), §2.1.4 (bordered systems).
"""

from __future__ import annotations

import math

__all__ = ["lattice_run", "W_ROWS", "STATUS"]

# flake8: noqa: F821  (``grad`` and the constants below are bound by the driver)

#: rows of the work array
_IG, _ID, _IZ, _IZP, _IR, _IUI, _ILL, _IE, _IML, _IY, _IDY, _IDY2 = 0, 2, 14, 16, 18, 20, 24, 28, 32, 36, 38, 40
W_ROWS = 42
# (named _I…: the translator reads a global integer constant only under a private name)
#: failure status of a run (``_fst[0]``)
STATUS = {"OK": 0, "CONVERGENCE": 1, "NONFINITE": 2, "RESOLUTION": 3, "SINGULAR": 4}


def factor(_W, _n, _h):
    """Build the Newton matrix from ``D`` and factor it into UI, LL, E, ML (rows of _W; the last
    site's eliminated block's inverse in column n-1 of UI).  Returns 0, or 1 for a singular block."""
    n = _n
    h = _h
    bad = 0
    # block j of M: row q is -h (row p of D), row p is +h (row q of D); identity on the diagonal
    # blocks A_j = M[0] (to j-1), B_j = M[1], C_j = M[2]; D rows: 2 + 4 r + (2 f + g)
    # forward elimination over j = 0 .. n-2 with the border x_{n-1}
    for j in range(n - 1):
        # B_j
        b00 = 1.0 - h * _W[_ID + 4 + 2, j]
        b01 = -h * _W[_ID + 4 + 3, j]
        b10 = h * _W[_ID + 4 + 0, j]
        b11 = 1.0 + h * _W[_ID + 4 + 1, j]
        # border entry of row j: A_0 (j = 0) + C_{n-2} (j = n-2)
        e00 = 0.0
        e01 = 0.0
        e10 = 0.0
        e11 = 0.0
        if j == 0:
            e00 += -h * _W[_ID + 2, 0]
            e01 += -h * _W[_ID + 3, 0]
            e10 += h * _W[_ID + 0, 0]
            e11 += h * _W[_ID + 1, 0]
        if j == n - 2:
            e00 += -h * _W[_ID + 8 + 2, j]
            e01 += -h * _W[_ID + 8 + 3, j]
            e10 += h * _W[_ID + 8 + 0, j]
            e11 += h * _W[_ID + 8 + 1, j]
        if j > 0:
            # L_j = A_j U_{j-1}^{-1}; U_j = B_j - L_j S_{j-1}; E_j -= L_j E_{j-1}
            a00 = -h * _W[_ID + 2, j]
            a01 = -h * _W[_ID + 3, j]
            a10 = h * _W[_ID + 0, j]
            a11 = h * _W[_ID + 1, j]
            u00 = _W[_IUI + 0, j - 1]
            u01 = _W[_IUI + 1, j - 1]
            u10 = _W[_IUI + 2, j - 1]
            u11 = _W[_IUI + 3, j - 1]
            l00 = a00 * u00 + a01 * u10
            l01 = a00 * u01 + a01 * u11
            l10 = a10 * u00 + a11 * u10
            l11 = a10 * u01 + a11 * u11
            _W[_ILL + 0, j] = l00
            _W[_ILL + 1, j] = l01
            _W[_ILL + 2, j] = l10
            _W[_ILL + 3, j] = l11
            if j - 1 < n - 2:     # S_{j-1} = C_{j-1} (the super-diagonal, not the border)
                s00 = -h * _W[_ID + 8 + 2, j - 1]
                s01 = -h * _W[_ID + 8 + 3, j - 1]
                s10 = h * _W[_ID + 8 + 0, j - 1]
                s11 = h * _W[_ID + 8 + 1, j - 1]
                b00 -= l00 * s00 + l01 * s10
                b01 -= l00 * s01 + l01 * s11
                b10 -= l10 * s00 + l11 * s10
                b11 -= l10 * s01 + l11 * s11
            p00 = _W[_IE + 0, j - 1]
            p01 = _W[_IE + 1, j - 1]
            p10 = _W[_IE + 2, j - 1]
            p11 = _W[_IE + 3, j - 1]
            e00 -= l00 * p00 + l01 * p10
            e01 -= l00 * p01 + l01 * p11
            e10 -= l10 * p00 + l11 * p10
            e11 -= l10 * p01 + l11 * p11
        det = b00 * b11 - b01 * b10
        if not (det != 0.0 and abs(det) < math.inf):
            bad = 1           # (one return, at the end: the translator inlines this function)
            det = 1.0
        _W[_IUI + 0, j] = b11 / det
        _W[_IUI + 1, j] = -b01 / det
        _W[_IUI + 2, j] = -b10 / det
        _W[_IUI + 3, j] = b00 / det
        _W[_IE + 0, j] = e00
        _W[_IE + 1, j] = e01
        _W[_IE + 2, j] = e10
        _W[_IE + 3, j] = e11
    # the last row: W_j (its coefficient on x_j) from C_{n-1} (j = 0) and A_{n-1} (j = n-2)
    last = n - 1
    c00 = 1.0 - h * _W[_ID + 4 + 2, last]
    c01 = -h * _W[_ID + 4 + 3, last]
    c10 = h * _W[_ID + 4 + 0, last]
    c11 = 1.0 + h * _W[_ID + 4 + 1, last]
    w00 = -h * _W[_ID + 8 + 2, last]
    w01 = -h * _W[_ID + 8 + 3, last]
    w10 = h * _W[_ID + 8 + 0, last]
    w11 = h * _W[_ID + 8 + 1, last]
    for j in range(n - 1):
        if j == n - 2:
            w00 += -h * _W[_ID + 2, last]
            w01 += -h * _W[_ID + 3, last]
            w10 += h * _W[_ID + 0, last]
            w11 += h * _W[_ID + 1, last]
        # M_j = W_j U_j^{-1}
        u00 = _W[_IUI + 0, j]
        u01 = _W[_IUI + 1, j]
        u10 = _W[_IUI + 2, j]
        u11 = _W[_IUI + 3, j]
        m00 = w00 * u00 + w01 * u10
        m01 = w00 * u01 + w01 * u11
        m10 = w10 * u00 + w11 * u10
        m11 = w10 * u01 + w11 * u11
        _W[_IML + 0, j] = m00
        _W[_IML + 1, j] = m01
        _W[_IML + 2, j] = m10
        _W[_IML + 3, j] = m11
        p00 = _W[_IE + 0, j]
        p01 = _W[_IE + 1, j]
        p10 = _W[_IE + 2, j]
        p11 = _W[_IE + 3, j]
        c00 -= m00 * p00 + m01 * p10
        c01 -= m00 * p01 + m01 * p11
        c10 -= m10 * p00 + m11 * p10
        c11 -= m10 * p01 + m11 * p11
        # W_{j+1} = -M_j S_j (S_j = C_j for j < n-2; the border otherwise)
        if j < n - 2:
            s00 = -h * _W[_ID + 8 + 2, j]
            s01 = -h * _W[_ID + 8 + 3, j]
            s10 = h * _W[_ID + 8 + 0, j]
            s11 = h * _W[_ID + 8 + 1, j]
            w00 = -(m00 * s00 + m01 * s10)
            w01 = -(m00 * s01 + m01 * s11)
            w10 = -(m10 * s00 + m11 * s10)
            w11 = -(m10 * s01 + m11 * s11)
    det = c00 * c11 - c01 * c10
    if not (det != 0.0 and abs(det) < math.inf):
        bad = 1
        det = 1.0
    _W[_IUI + 0, last] = c11 / det
    _W[_IUI + 1, last] = -c01 / det
    _W[_IUI + 2, last] = -c10 / det
    _W[_IUI + 3, last] = c00 / det
    return bad


def solve(_W, _n, _h):
    """Solve the factored system for the right-hand side -R (rows _IR), in place: _IR becomes
    the update."""
    n = _n
    h = _h
    last = n - 1
    # forward: y_j = r_j - L_j y_{j-1}; the last row y_last -= M_j y_j
    yl0 = -_W[_IR + 0, last]
    yl1 = -_W[_IR + 1, last]
    y0 = 0.0
    y1 = 0.0
    for j in range(n - 1):
        r0 = -_W[_IR + 0, j]
        r1 = -_W[_IR + 1, j]
        if j > 0:
            r0 -= _W[_ILL + 0, j] * y0 + _W[_ILL + 1, j] * y1
            r1 -= _W[_ILL + 2, j] * y0 + _W[_ILL + 3, j] * y1
        y0 = r0
        y1 = r1
        _W[_IY + 0, j] = y0
        _W[_IY + 1, j] = y1
        yl0 -= _W[_IML + 0, j] * y0 + _W[_IML + 1, j] * y1
        yl1 -= _W[_IML + 2, j] * y0 + _W[_IML + 3, j] * y1
    xl0 = _W[_IUI + 0, last] * yl0 + _W[_IUI + 1, last] * yl1
    xl1 = _W[_IUI + 2, last] * yl0 + _W[_IUI + 3, last] * yl1
    _W[_IR + 0, last] = xl0
    _W[_IR + 1, last] = xl1
    # back: x_j = U_j^{-1} (y_j - S_j x_{j+1} - E_j x_last)
    x0 = xl0
    x1 = xl1
    for k in range(n - 1):
        j = n - 2 - k
        t0 = _W[_IY + 0, j] - (_W[_IE + 0, j] * xl0 + _W[_IE + 1, j] * xl1)
        t1 = _W[_IY + 1, j] - (_W[_IE + 2, j] * xl0 + _W[_IE + 3, j] * xl1)
        if j < n - 2:
            s00 = -h * _W[_ID + 8 + 2, j]
            s01 = -h * _W[_ID + 8 + 3, j]
            s10 = h * _W[_ID + 8 + 0, j]
            s11 = h * _W[_ID + 8 + 1, j]
            t0 -= s00 * x0 + s01 * x1
            t1 -= s10 * x0 + s11 * x1
        x0 = _W[_IUI + 0, j] * t0 + _W[_IUI + 1, j] * t1
        x1 = _W[_IUI + 2, j] * t0 + _W[_IUI + 3, j] * t1
        _W[_IR + 0, j] = x0
        _W[_IR + 1, j] = x1


def lattice_run(_Y, _T, _its, _fst, _p, _n, _h, _steps, _every, _maxiter, _tol, _chk, _simpl, _maxdis, _W):
    """Steps 0 .. _steps-1 from the state ``_Y`` (2, n), updated in place.

    ``_T`` (rows, 2n): row k + 1 is the state after step (k + 1)·_every - 1 (and the last row the
    last state); ``_its`` (_steps,): Newton iterations; ``_fst`` (4,): status (STATUS), step,
    iterations, and the failing value (the residual, or the predictor ratio) of a failure.
    ``_chk``: the resolution check (predictor disagreement ≤ ``_maxdis``); ``_simpl``:
    simplified Newton (the matrix at the predictor only).
    """
    n = _n
    h = _h
    row = 1
    for s in range(_steps):
        if s == 0:
            # the first step: the explicit Euler predictor Z = Y + h J ∇H(Y)
            for j in range(n):
                _W[_IG + 0, j] = 0.0
                _W[_IG + 1, j] = 0.0
                _W[_IZ + 0, j] = _Y[0, j]
                _W[_IZ + 1, j] = _Y[1, j]
            grad(_Y, _W, _n, _p, 0)
            for j in range(n):
                _W[_IDY + 0, j] = h * _W[_IG + 1, j]
                _W[_IDY + 1, j] = -h * _W[_IG + 0, j]
        for j in range(n):
            z0 = _Y[0, j] + _W[_IDY + 0, j]
            z1 = _Y[1, j] + _W[_IDY + 1, j]
            if s >= 2:
                z0 = _Y[0, j] + (2.0 * _W[_IDY + 0, j] - _W[_IDY2 + 0, j])
                z1 = _Y[1, j] + (2.0 * _W[_IDY + 1, j] - _W[_IDY2 + 1, j])
            _W[_IZ + 0, j] = z0
            _W[_IZ + 1, j] = z1
            _W[_IZP + 0, j] = z0
            _W[_IZP + 1, j] = z1
        last = math.inf
        refac = 0
        done = 0
        it = 0
        size = 0.0
        while it < _maxiter:
            it += 1
            jac = 1 if (it == 1 or _simpl == 0 or refac == 1) else 0
            for j in range(n):
                _W[_IG + 0, j] = 0.0
                _W[_IG + 1, j] = 0.0
            if jac == 1:
                for k in range(12):
                    for j in range(n):
                        _W[_ID + k, j] = 0.0
            grad(_Y, _W, _n, _p, jac)
            for j in range(n):
                _W[_IR + 0, j] = _W[_IZ + 0, j] - _Y[0, j] - h * _W[_IG + 1, j]
                _W[_IR + 1, j] = _W[_IZ + 1, j] - _Y[1, j] + h * _W[_IG + 0, j]
            if jac == 1:
                if factor(_W, _n, _h) != 0:
                    _fst[0] = 4.0
                    _fst[1] = s
                    _fst[2] = it
                    return
            solve(_W, _n, _h)
            size = 0.0
            scale = 1.0
            for j in range(n):
                for c in range(2):
                    d = _W[_IR + c, j]
                    z = _W[_IZ + c, j] + d
                    _W[_IZ + c, j] = z
                    size = max(size, abs(d))
                    scale = max(scale, abs(z))
            if not (size < math.inf):
                _fst[0] = 2.0
                _fst[1] = s
                _fst[2] = it
                return
            if size <= _tol * scale or (size <= 1e3 * 2.220446049250313e-16 * scale and size > 0.5 * last):
                done = 1
                break
            # simplified Newton converging slowly (the matrix at the predictor too far off): the
            # matrix at the iterate from now on, for this step
            if size > 0.25 * last:
                refac = 1
            last = size
        if done == 0:
            # the residual at the last iterate, for the message
            for j in range(n):
                _W[_IG + 0, j] = 0.0
                _W[_IG + 1, j] = 0.0
            grad(_Y, _W, _n, _p, 0)
            res = 0.0
            for j in range(n):
                res = max(res, abs(_W[_IZ + 0, j] - _Y[0, j] - h * _W[_IG + 1, j]))
                res = max(res, abs(_W[_IZ + 1, j] - _Y[1, j] + h * _W[_IG + 0, j]))
            _fst[0] = 1.0
            _fst[1] = s
            _fst[2] = it
            _fst[3] = res
            return
        if _chk != 0:
            moved = 0.0
            off = 0.0
            for j in range(n):
                for c in range(2):
                    moved = max(moved, abs(_W[_IZ + c, j] - _Y[c, j]))
                    off = max(off, abs(_W[_IZ + c, j] - _W[_IZP + c, j]))
            ratio = 0.0
            if moved > 0.0:
                ratio = off / moved
            if ratio > _maxdis:
                _fst[0] = 3.0
                _fst[1] = s
                _fst[2] = it
                _fst[3] = ratio
                return
        for j in range(n):
            _W[_IDY2 + 0, j] = _W[_IDY + 0, j]
            _W[_IDY2 + 1, j] = _W[_IDY + 1, j]
            _W[_IDY + 0, j] = _W[_IZ + 0, j] - _Y[0, j]
            _W[_IDY + 1, j] = _W[_IZ + 1, j] - _Y[1, j]
            _Y[0, j] = _W[_IZ + 0, j]
            _Y[1, j] = _W[_IZ + 1, j]
        _its[s] = it
        if (s + 1) % _every == 0 or s + 1 == _steps:
            for j in range(n):
                _T[row, j] = _Y[0, j]
                _T[row, n + j] = _Y[1, j]
            row += 1
