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

A skew lattice (one field u, ``u1 = u0 + h S ∇̄H(u0, u1)``, ``(S g)_i = c (g_{i+1} - g_{i-1})``,
``_sk = 1``) runs in the same layout over the pairs of sites: column k holds ``u_{2k}, u_{2k+1}``
(0-based) as the rows "q" and "p" (the module's kernel writes ∇̄H and its derivative there), and
``h S`` is the block tridiagonal constant ``[[0, -c], [0, 0]]`` (to the pair k - 1), ``[[0, c],
[-c, 0]]``, ``[[0, 0], [c, 0]]`` (to k + 1) -- the canonical J scaled by c plus two corner terms
(:func:`flow`, :func:`block`).  The Newton matrix I - h S ∂∇̄H/∂u1 is pentadiagonal in u, so
block tridiagonal in the pairs: the same factorisation solves it.  A canonical lattice runs
with ``_sk = 0`` and c = 1 (``h * 1.0`` is h: the same bits as without the skew terms).

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


def block(_W, r, j, h, n, sk):
    """The Newton matrix's 2 × 2 block of site j to j + r - 1 (r = 0, 1, 2), from ∂∇̄H in D: row q
    is -h (row p of D), row p is +h (row q of D), the identity added on the diagonal (r = 1); h is
    the step times the structure's coefficient.

    A skew lattice (``sk`` 1, pairs of sites) adds the stencil's corner terms: the row q of the
    pair j (u_2j, whose flow is c (g_2j+1 - g_2j-1)) takes +h (row p of D_(r+1) at j - 1), the
    row p (u_2j+1: c (g_2j+2 - g_2j)) takes -h (row q of D_(r-1) at j + 1); D_3 = D_(-1) = 0."""
    d = 1.0 if r == 1 else 0.0
    b00 = d - h * _W[_ID + 4 * r + 2, j]
    b01 = -h * _W[_ID + 4 * r + 3, j]
    b10 = h * _W[_ID + 4 * r + 0, j]
    b11 = d + h * _W[_ID + 4 * r + 1, j]
    if sk != 0:
        if r < 2:
            jm = n - 1 if j == 0 else j - 1
            b00 += h * _W[_ID + 4 * (r + 1) + 2, jm]
            b01 += h * _W[_ID + 4 * (r + 1) + 3, jm]
        if r > 0:
            jp = 0 if j == n - 1 else j + 1
            b10 -= h * _W[_ID + 4 * (r - 1) + 0, jp]
            b11 -= h * _W[_ID + 4 * (r - 1) + 1, jp]
    return b00, b01, b10, b11


def flow(_W, j, n, h, sk):
    """h K ∇̄H at the site (or pair) j from G: canonical (h G_p, -h G_q); skew (pairs of sites)
    (h (G_p[j] - G_p[j - 1]), h (G_q[j + 1] - G_q[j])), h the step times c."""
    if sk == 0:
        return h * _W[_IG + 1, j], -h * _W[_IG + 0, j]
    jm = n - 1 if j == 0 else j - 1
    jp = 0 if j == n - 1 else j + 1
    return h * (_W[_IG + 1, j] - _W[_IG + 1, jm]), h * (_W[_IG + 0, jp] - _W[_IG + 0, j])


def mm(a00, a01, a10, a11, b00, b01, b10, b11):
    """The product of two 2 × 2 matrices, entries row by row."""
    return (a00 * b00 + a01 * b10, a00 * b01 + a01 * b11, a10 * b00 + a11 * b10, a10 * b01 + a11 * b11)


def mv(a00, a01, a10, a11, v0, v1):
    """A 2 × 2 matrix (entries row by row) times a vector."""
    return a00 * v0 + a01 * v1, a10 * v0 + a11 * v1


def load4(_W, row, j):
    return _W[row + 0, j], _W[row + 1, j], _W[row + 2, j], _W[row + 3, j]


def store4(_W, row, j, x00, x01, x10, x11):
    _W[row + 0, j] = x00
    _W[row + 1, j] = x01
    _W[row + 2, j] = x10
    _W[row + 3, j] = x11


def store_inverse(_W, j, b00, b01, b10, b11):
    """The inverse of the block into UI at j; 1 where it is singular (stored as if det were 1)."""
    det = b00 * b11 - b01 * b10
    bad = 0
    if not (det != 0.0 and abs(det) < math.inf):
        bad = 1
        det = 1.0
    store4(_W, _IUI, j, b11 / det, -b01 / det, -b10 / det, b00 / det)
    return bad


def factor(_W, _n, _h, _sk):
    """Factor the Newton matrix (blocks from ``D``) into UI, LL, E, ML (rows of _W; the last
    site's eliminated block's inverse in column n-1 of UI).  Returns 0, or 1 for a singular block.

    Forward elimination over the sites j = 0 … n-2, the last site x_{n-1} a border: row j is
    U_j x_j + S_j x_{j+1} + E_j x_{n-1} (S_j = C_j for j < n-2; the border collects A_0 at j = 0
    and C_{n-2} at j = n-2); L_j = A_j U_{j-1}⁻¹, U_j = B_j - L_j S_{j-1}, E_j = E⁰_j - L_j E_{j-1}.
    The last row's coefficient W_j on x_j (C_{n-1} at j = 0, A_{n-1} joining at j = n-2) is
    eliminated alongside: M_j = W_j U_j⁻¹, its diagonal block less M_j E_j, W_{j+1} = -M_j S_j.
    """
    n = _n
    h = _h
    sk = _sk
    bad = 0
    for j in range(n - 1):
        b00, b01, b10, b11 = block(_W, 1, j, h, n, sk)
        e00, e01, e10, e11 = 0.0, 0.0, 0.0, 0.0
        if j == 0:
            c00, c01, c10, c11 = block(_W, 0, 0, h, n, sk)
            e00, e01, e10, e11 = e00 + c00, e01 + c01, e10 + c10, e11 + c11
        if j == n - 2:
            c00, c01, c10, c11 = block(_W, 2, j, h, n, sk)
            e00, e01, e10, e11 = e00 + c00, e01 + c01, e10 + c10, e11 + c11
        if j > 0:
            a00, a01, a10, a11 = block(_W, 0, j, h, n, sk)
            u00, u01, u10, u11 = load4(_W, _IUI, j - 1)
            l00, l01, l10, l11 = mm(a00, a01, a10, a11, u00, u01, u10, u11)
            store4(_W, _ILL, j, l00, l01, l10, l11)
            if j - 1 < n - 2:     # S_{j-1} = C_{j-1} (the super-diagonal, not the border)
                s00, s01, s10, s11 = block(_W, 2, j - 1, h, n, sk)
                t00, t01, t10, t11 = mm(l00, l01, l10, l11, s00, s01, s10, s11)
                b00, b01, b10, b11 = b00 - t00, b01 - t01, b10 - t10, b11 - t11
            p00, p01, p10, p11 = load4(_W, _IE, j - 1)
            t00, t01, t10, t11 = mm(l00, l01, l10, l11, p00, p01, p10, p11)
            e00, e01, e10, e11 = e00 - t00, e01 - t01, e10 - t10, e11 - t11
        if store_inverse(_W, j, b00, b01, b10, b11) != 0:
            bad = 1
        store4(_W, _IE, j, e00, e01, e10, e11)
    last = n - 1
    c00, c01, c10, c11 = block(_W, 1, last, h, n, sk)
    w00, w01, w10, w11 = block(_W, 2, last, h, n, sk)
    for j in range(n - 1):
        if j == n - 2:
            a00, a01, a10, a11 = block(_W, 0, last, h, n, sk)
            w00, w01, w10, w11 = w00 + a00, w01 + a01, w10 + a10, w11 + a11
        u00, u01, u10, u11 = load4(_W, _IUI, j)
        m00, m01, m10, m11 = mm(w00, w01, w10, w11, u00, u01, u10, u11)
        store4(_W, _IML, j, m00, m01, m10, m11)
        p00, p01, p10, p11 = load4(_W, _IE, j)
        t00, t01, t10, t11 = mm(m00, m01, m10, m11, p00, p01, p10, p11)
        c00, c01, c10, c11 = c00 - t00, c01 - t01, c10 - t10, c11 - t11
        if j < n - 2:
            s00, s01, s10, s11 = block(_W, 2, j, h, n, sk)
            t00, t01, t10, t11 = mm(m00, m01, m10, m11, s00, s01, s10, s11)
            w00, w01, w10, w11 = -t00, -t01, -t10, -t11
    if store_inverse(_W, last, c00, c01, c10, c11) != 0:
        bad = 1
    return bad


def solve(_W, _n, _h, _sk):
    """Solve the factored system for the right-hand side -R (rows _IR), in place: _IR becomes
    the update.  Forward: y_j = r_j - L_j y_{j-1}, the last row less M_j y_j; the last site;
    back: x_j = U_j⁻¹ (y_j - S_j x_{j+1} - E_j x_{n-1})."""
    n = _n
    h = _h
    sk = _sk
    last = n - 1
    yl0 = -_W[_IR + 0, last]
    yl1 = -_W[_IR + 1, last]
    y0 = 0.0
    y1 = 0.0
    for j in range(n - 1):
        r0 = -_W[_IR + 0, j]
        r1 = -_W[_IR + 1, j]
        if j > 0:
            l00, l01, l10, l11 = load4(_W, _ILL, j)
            a0, a1 = mv(l00, l01, l10, l11, y0, y1)
            r0 -= a0
            r1 -= a1
        y0 = r0
        y1 = r1
        _W[_IY + 0, j] = y0
        _W[_IY + 1, j] = y1
        m00, m01, m10, m11 = load4(_W, _IML, j)
        a0, a1 = mv(m00, m01, m10, m11, y0, y1)
        yl0 -= a0
        yl1 -= a1
    u00, u01, u10, u11 = load4(_W, _IUI, last)
    xl0, xl1 = mv(u00, u01, u10, u11, yl0, yl1)
    _W[_IR + 0, last] = xl0
    _W[_IR + 1, last] = xl1
    x0 = xl0
    x1 = xl1
    for k in range(n - 1):
        j = n - 2 - k
        e00, e01, e10, e11 = load4(_W, _IE, j)
        a0, a1 = mv(e00, e01, e10, e11, xl0, xl1)
        t0 = _W[_IY + 0, j] - a0
        t1 = _W[_IY + 1, j] - a1
        if j < n - 2:
            s00, s01, s10, s11 = block(_W, 2, j, h, n, sk)
            a0, a1 = mv(s00, s01, s10, s11, x0, x1)
            t0 -= a0
            t1 -= a1
        u00, u01, u10, u11 = load4(_W, _IUI, j)
        x0, x1 = mv(u00, u01, u10, u11, t0, t1)
        _W[_IR + 0, j] = x0
        _W[_IR + 1, j] = x1

def lattice_run(_Y, _T, _its, _fst, _p, _n, _h, _steps, _every, _maxiter, _tol, _chk, _simpl, _maxdis, _W,
                _sk, _c):
    """Steps 0 .. _steps-1 from the state ``_Y`` (2, n), updated in place.

    ``_T`` (rows, 2n): row k + 1 is the state after step (k + 1)·_every - 1 (and the last row the
    last state); ``_its`` (_steps,): Newton iterations; ``_fst`` (4,): status (STATUS), step,
    iterations, and the failing value (the residual, or the predictor ratio) of a failure.
    ``_chk``: the resolution check (predictor disagreement ≤ ``_maxdis``); ``_simpl``:
    simplified Newton (the matrix at the predictor only); ``_sk``: 1 for a skew lattice (``_Y`` the
    pairs of sites), with ``_c`` the stencil's coefficient (1.0 for a canonical lattice).
    """
    n = _n
    h = _h * _c
    sk = _sk
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
                f0, f1 = flow(_W, j, n, h, sk)
                _W[_IDY + 0, j] = f0
                _W[_IDY + 1, j] = f1
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
                f0, f1 = flow(_W, j, n, h, sk)
                _W[_IR + 0, j] = _W[_IZ + 0, j] - _Y[0, j] - f0
                _W[_IR + 1, j] = _W[_IZ + 1, j] - _Y[1, j] - f1
            if jac == 1:
                if factor(_W, _n, h, sk) != 0:
                    _fst[0] = 4.0
                    _fst[1] = s
                    _fst[2] = it
                    return
            solve(_W, _n, h, sk)
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
                f0, f1 = flow(_W, j, n, h, sk)
                res = max(res, abs(_W[_IZ + 0, j] - _Y[0, j] - f0))
                res = max(res, abs(_W[_IZ + 1, j] - _Y[1, j] - f1))
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
