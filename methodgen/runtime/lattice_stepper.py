"""The step loop of a lattice module (:mod:`methodgen.codegen.lattice_emit`), one source run two ways.

:func:`lattice_run` takes ``steps`` steps of ``y1 = y0 + h K ∇̄H(y0, y1)`` on a lattice of n
sites (K the canonical J, or a skew stencil S): the predictor, Newton's method ("newton" or
"simplified") with the Newton matrix ``I - h K ∂∇̄H/∂y1``, the convergence, non-finite and
resolution checks, and the saved rows.  Like :mod:`methodgen.runtime.stepper`, it is written in the
subset of Python that :mod:`methodgen.codegen.llvmkernels` translates: the module's kernel ``grad``
(∇̄H and its derivative, a loop over the sites of each term, printed by the module) is bound as
a global and inlined, the whole compiled to machine code with the size n a run-time argument
-- or run as plain Python (the reference the compiled loop is tested against, and the
fallback without llvmlite).

The Newton matrix.  With ``nf`` fields per site (2: q, p; 1: a skew lattice's u) and every
site coupled to the sites at most w away (cyclically; w the lattice's
:attr:`~methodgen.problem.lattice.Lattice.half_width`), the matrix is banded.  The sites are grouped
into blocks of g = max(w, 1) consecutive sites -- q = n // g groups, the last one taking the
remainder r = n - q g too (g + r sites) -- so that a group couples only to the groups before
and after it: the matrix is block tridiagonal and cyclic, interior blocks m × m (m = nf g), the
last group's mB × mB (mB = nf (g + r)).  It is factored by block Gaussian elimination with
the last group as a border (the periodic corners couple group 0 to the last group, and the
last group to group 0: both carried as one block column and row; O(n nf³ g²) operations).
A half-width-1 canonical lattice is the case g = 1, m = mB = 2: the 2 × 2 blocks per site of
before, the same arithmetic.  A non-periodic lattice is the case of zero corners.

Arrays: ``_Y`` (nf, n) the state; ``_W`` (``W_ROWS``, n): ``G`` (∇̄H), ``Z``, ``ZP`` (the iterate
and the predictor), ``R`` (the residual, then the update), ``Y`` (the forward-substituted
right-hand side), nf rows each at the offsets below; ``_DH`` (2 s nf, n): per stage k (of s) its
increments at the last step and the one before, rows ``2 k nf`` and ``(2 k + 1) nf``; ``_D`` ((2 wH + 1) nf², n): the kernel's ∂∇̄H, row ``(e + wH) nf² + f nf + f'`` the entry
∂∇̄H_(f, j)/∂z_(f', j + e) at column j (wH the Jacobian's half-width); ``_P`` ((2 w + 1) nf², n):
the Newton matrix in the same layout; ``_F`` (:func:`factor_size`): the blocks and the factors.
The shape (nf, g, m, mB, the structure, the half-widths) is bound as translation-time constants
``_NF``, ``_GS``, ``_BM``, ``_BB``, ``_SK``, ``_SW``, ``_WH``, ``_W2`` per compiled loop
(:func:`methodgen.runtime.lattice_driver.shape_constants`): a module compiles at most g loops, one per
N mod g.

A skew lattice (``_SK = 1``, one field, ``u1 = u0 + h S ∇̄H(u0, u1)``, ``(S g)_i = Σ_k c_k g_(i+k)``,
k = -sw … sw, ``_cs`` the c_k at this n) has the Newton matrix ``P_e(s) = δ_e0 - Σ_k (h c_k)
D_(e-k)(s + k)`` (half-width wH + sw); a canonical one ``P_e = δ_e0 I - h J D_e``.

The predictor extrapolates the last two increments, ``z = y + 2 Δ₁ - Δ₂`` (error O(h³): fewer
Newton iterations than from the explicit Euler step, and no evaluation of ∇H of its own); the
second step takes ``y + Δ₁``, the first the explicit Euler step.  The increments (``_DH``) and the
count of steps behind them (``_s0``) come in and go out, so that a run continued in chunks
(``integrate(..., info=...)``) is bitwise the run in one piece.

Order 4, 6, 8: a step is s stages, the order-2 step of sizes ``γ_k h`` (``_gam``; a symmetric
composition, Σ γ = 1, negative γ included [Yos90, Suz90; HLW06 §II.4, §V.3]).  Stage k's
predictor extrapolates stage k's own increments Δ₁, Δ₂ of the last two steps: the same map at
points one step h apart along the solution, so O(h³) off as at order 2 (the previous stage's
increment scaled by γ_k/γ_(k-1) would be O(h²) off: it is taken at another point, and a
negative γ reverses it).  With s = 1, γ = (1,) this is the order-2 loop, the same arithmetic.

References
----------
G. H. Golub, C. F. Van Loan, *Matrix Computations*, 4th ed. (2013), §4.3 (banded systems),
§4.5 (block tridiagonal systems), §2.1.4 (bordered systems).
[Yos90] H. Yoshida, Phys. Lett. A 150 (1990) 262-268; [Suz90] M. Suzuki, Phys. Lett. A 146
(1990) 319-323; [HLW06] E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*,
2nd ed. (2006), §II.4, §V.3 (symmetric compositions).
"""

from __future__ import annotations

import math

__all__ = ["lattice_run", "W_ROWS", "STATUS", "layout", "factor_size"]

# flake8: noqa: F821  (``grad``, ``settled`` and the constants below are bound by the driver)

#: rows of the work array _W (nf ≤ 2 rows each; the module's kernel reads Z at _IZ, writes G at _IG)
_IG, _IZ, _IZP, _IR, _IY = 0, 2, 4, 6, 8
W_ROWS = 10
# (named _I…: the translator reads a global integer constant only under a private name)
#: the factor array _F: per group _NMAT blocks of mB × mB slots (row stride mB): the matrix's
#: blocks A (to the group before), B, C (to the group after), the eliminated diagonal block's
#: inverse UI, the multiplier LL, the border column E, the border row's multiplier ML; then
#: _NSCR scratch blocks.  (The block t of the group k is at (k _NMAT + t) mB², the scratch block t
#: at (q _NMAT + t) mB²; written out where used: the translator inlines a function returning an
#: integer only when it returns a tuple.)
_MA, _MB, _MC, _MUI, _MLL, _ME, _MML = 0, 1, 2, 3, 4, 5, 6
_NMAT = 7
_NSCR = 7
#: failure status of a run (``_fst[0]``)
STATUS = {"OK": 0, "CONVERGENCE": 1, "NONFINITE": 2, "RESOLUTION": 3, "SINGULAR": 4}

# The shape of the problem, bound per compiled loop by methodgen.runtime.lattice_driver (constants at
# translation time, so that every loop over a block's entries has a known trip count and LLVM
# unrolls the small ones: the 2 × 2 blocks of a nearest-neighbour lattice cost what the explicit
# formulas did).  The values here are a canonical nearest-neighbour lattice's.
#: fields per site; sites per group g; interior block size m = nf g; the last group's mB = nf (g + r)
_NF, _GS, _BM, _BB = 2, 1, 2, 2
#: skew (1) or canonical (0); the stencil's half-width sw; ∂∇̄H's half-width wH; the Newton matrix's
#: 2 w + 1 diagonals (w = wH + sw)
_SK, _SW, _WH, _W2 = 0, 0, 1, 3


def layout(n, nf, g):
    """``(q, m, mb)``: the number of groups of g sites, the interior blocks' size m = nf g and the
    last group's mb = nf (g + n - q g)."""
    q = n // g
    return q, nf * g, nf * (g + n - q * g)


def factor_size(n, nf, g):
    """The length of the factor array ``_F`` for n sites, nf fields, groups of g sites."""
    q, m, mb = layout(n, nf, g)
    return (_NMAT * q + _NSCR) * mb * mb


def newton(_D, _P, n, h, _cs):
    """The Newton matrix ``I - h K ∂∇̄H`` into _P from ∂∇̄H in _D (module docstring); ``_cs`` the
    skew stencil's c_(-sw) … c_sw."""
    w = (_W2 - 1) // 2
    for e in range(_W2):
        for f in range(_NF):
            for f2 in range(_NF):
                d = 0.0
                if e == w and f == f2:
                    d = 1.0
                row = e * _NF * _NF + f * _NF + f2
                if _SK == 0:
                    # canonical (w = wH): row q takes -h (row p of D), row p +h (row q of D)
                    if f == 0:
                        for s in range(n):
                            _P[row, s] = d - h * _D[e * _NF * _NF + _NF + f2, s]
                    else:
                        for s in range(n):
                            _P[row, s] = d + h * _D[e * _NF * _NF + f2, s]
                else:
                    for s in range(n):
                        acc = 0.0
                        for kk in range(2 * _SW + 1):
                            ed = e - w - (kk - _SW)         # D_(e - k) at the site s + k
                            if ed >= -_WH and ed <= _WH:
                                t = s + kk - _SW            # the site s + k, cyclically (no division)
                                if t < 0:
                                    t += n
                                elif t >= n:
                                    t -= n
                                acc += (h * _cs[kk]) * _D[(ed + _WH) * _NF * _NF, t]
                        _P[row, s] = d - acc


def assemble(_P, _F, n):
    """The blocks A, B, C of every group into _F from the site diagonals _P (added: a coupling
    the wrap makes to the same group twice, at q = 2, sums)."""
    q = n // _GS
    w = (_W2 - 1) // 2
    for k in range(q):
        for x in range(3 * _BB * _BB):
            _F[k * _NMAT * _BB * _BB + x] = 0.0
    for s in range(n):
        k = s // _GS
        if k > q - 1:
            k = q - 1                   # the last group holds the remainder
        kn = k + 1                      # the group after k, cyclically
        if kn == q:
            kn = 0
        for e in range(_W2):
            t = s + e - w               # the site s + e - w, cyclically (no division: w < n)
            if t < 0:
                t += n
            elif t >= n:
                t -= n
            kt = t // _GS
            if kt > q - 1:
                kt = q - 1
            slot = _MA
            if kt == k:
                slot = _MB
            elif kt == kn:
                slot = _MC
            b0 = (k * _NMAT + slot) * _BB * _BB
            for f in range(_NF):
                i = (s - k * _GS) * _NF + f
                for f2 in range(_NF):
                    j = (t - kt * _GS) * _NF + f2
                    _F[b0 + i * _BB + j] += _P[e * _NF * _NF + f * _NF + f2, s]


# Block operations on _F (row stride _BB), r × c blocks: the callers pass the shape as the
# constants _BM, _BB (m × m, m × mB, mB × m, mB × mB), so that after inlining every loop's trip
# count is known and LLVM unrolls the small ones.

def copy(_F, dst, src, r, c):
    for i in range(r):
        for j in range(c):
            _F[dst + i * _BB + j] = _F[src + i * _BB + j]


def add(_F, dst, src, r, c):
    for i in range(r):
        for j in range(c):
            _F[dst + i * _BB + j] = _F[dst + i * _BB + j] + _F[src + i * _BB + j]


def mul(_F, dst, a, b, r, c, k, mode):
    """The product a (r × k) b (k × c) into dst (r × c): set (mode 0), subtracted (1) or negated
    (2); each entry's sum formed first, in the order of its terms (for 2 × 2 blocks the
    arithmetic of the explicit a00 b00 + a01 b10 …)."""
    for i in range(r):
        for j in range(c):
            s = 0.0
            for l in range(k):
                s += _F[a + i * _BB + l] * _F[b + l * _BB + j]
            if mode == 0:
                _F[dst + i * _BB + j] = s
            elif mode == 1:
                _F[dst + i * _BB + j] = _F[dst + i * _BB + j] - s
            else:
                _F[dst + i * _BB + j] = -s


def invert(_F, dst, src, d, tmp):
    """The inverse of the d × d block at src into dst: 2 × 2 by its adjugate over the determinant,
    larger by Gauss-Jordan elimination with partial pivoting (in tmp, a scratch block).
    Returns 1 where it is singular (a zero or non-finite pivot; then taken as 1), else 0."""
    bad = 0
    if d == 2:
        b00 = _F[src]
        b01 = _F[src + 1]
        b10 = _F[src + _BB]
        b11 = _F[src + _BB + 1]
        det = b00 * b11 - b01 * b10
        if not (det != 0.0 and abs(det) < math.inf):
            bad = 1
            det = 1.0
        _F[dst] = b11 / det
        _F[dst + 1] = -b01 / det
        _F[dst + _BB] = -b10 / det
        _F[dst + _BB + 1] = b00 / det
        return bad
    for i in range(d):
        for j in range(d):
            _F[tmp + i * _BB + j] = _F[src + i * _BB + j]
            _F[dst + i * _BB + j] = 0.0
        _F[dst + i * _BB + i] = 1.0
    for c in range(d):
        piv = c
        big = abs(_F[tmp + c * _BB + c])
        for i in range(c + 1, d):
            a = abs(_F[tmp + i * _BB + c])
            if a > big:
                big = a
                piv = i
        if piv != c:
            for j in range(d):
                x = _F[tmp + c * _BB + j]
                _F[tmp + c * _BB + j] = _F[tmp + piv * _BB + j]
                _F[tmp + piv * _BB + j] = x
                x = _F[dst + c * _BB + j]
                _F[dst + c * _BB + j] = _F[dst + piv * _BB + j]
                _F[dst + piv * _BB + j] = x
        pv = _F[tmp + c * _BB + c]
        if not (pv != 0.0 and abs(pv) < math.inf):
            bad = 1
            pv = 1.0
        for j in range(d):
            _F[tmp + c * _BB + j] = _F[tmp + c * _BB + j] / pv
            _F[dst + c * _BB + j] = _F[dst + c * _BB + j] / pv
        for i in range(d):
            if i != c:
                fac = _F[tmp + i * _BB + c]
                if fac != 0.0:
                    for j in range(d):
                        _F[tmp + i * _BB + j] = _F[tmp + i * _BB + j] - fac * _F[tmp + c * _BB + j]
                        _F[dst + i * _BB + j] = _F[dst + i * _BB + j] - fac * _F[dst + c * _BB + j]
    return bad


def factor(_P, _F, _n):
    """Factor the Newton matrix (site diagonals in _P) into _F.  Returns 0, or 1 for a singular
    block.

    Forward elimination over the groups j = 0 … q-2, the last group x_(q-1) a border: row j is
    U_j x_j + S_j x_(j+1) + E_j x_(q-1) (S_j = C_j for j < q-2; the border collects A_0 at j = 0
    and C_(q-2) at j = q-2); L_j = A_j U_(j-1)⁻¹, U_j = B_j - L_j S_(j-1), E_j = E⁰_j - L_j E_(j-1).
    The last row's coefficient W_j on x_j (C_(q-1) at j = 0, A_(q-1) joining at j = q-2) is
    eliminated alongside: M_j = W_j U_j⁻¹, its diagonal block less M_j E_j, W_(j+1) = -M_j S_j.
    """
    n = _n
    assemble(_P, _F, n)
    q = n // _GS
    z = _BB * _BB
    ub = (q * _NMAT + 0) * z        # U_j being formed
    eb = (q * _NMAT + 1) * z        # E_j being formed
    cb = (q * _NMAT + 2) * z        # the border's diagonal block being formed
    wb = (q * _NMAT + 3) * z        # the border row's coefficient W_j
    tb = (q * _NMAT + 4) * z        # the inverse's scratch
    bad = 0
    for j in range(q - 1):
        copy(_F, ub, (j * _NMAT + _MB) * z, _BM, _BM)
        for i in range(_BM):
            for c in range(_BB):
                _F[eb + i * _BB + c] = 0.0
        if j == 0:
            add(_F, eb, _MA * z, _BM, _BB)
        if j == q - 2:
            add(_F, eb, (j * _NMAT + _MC) * z, _BM, _BB)
        if j > 0:
            lb = (j * _NMAT + _MLL) * z
            mul(_F, lb, (j * _NMAT + _MA) * z, ((j - 1) * _NMAT + _MUI) * z, _BM, _BM, _BM, 0)
            mul(_F, ub, lb, ((j - 1) * _NMAT + _MC) * z, _BM, _BM, _BM, 1)
            mul(_F, eb, lb, ((j - 1) * _NMAT + _ME) * z, _BM, _BB, _BM, 1)
        if invert(_F, (j * _NMAT + _MUI) * z, ub, _BM, tb) != 0:
            bad = 1
        copy(_F, (j * _NMAT + _ME) * z, eb, _BM, _BB)
    last = q - 1
    copy(_F, cb, (last * _NMAT + _MB) * z, _BB, _BB)
    copy(_F, wb, (last * _NMAT + _MC) * z, _BB, _BM)
    for j in range(q - 1):
        if j == q - 2:
            add(_F, wb, (last * _NMAT + _MA) * z, _BB, _BM)
        mb = (j * _NMAT + _MML) * z
        mul(_F, mb, wb, (j * _NMAT + _MUI) * z, _BB, _BM, _BM, 0)
        mul(_F, cb, mb, (j * _NMAT + _ME) * z, _BB, _BB, _BM, 1)
        if j < q - 2:
            mul(_F, wb, mb, (j * _NMAT + _MC) * z, _BB, _BM, _BM, 2)
    if invert(_F, (last * _NMAT + _MUI) * z, cb, _BB, tb) != 0:
        bad = 1
    return bad


def solve(_W, _F, _n):
    """Solve the factored system for the right-hand side -R (rows _IR), in place: _IR becomes
    the update.  Forward: y_j = r_j - L_j y_(j-1), the border's row less M_j y_j; the border;
    back: x_j = U_j⁻¹ (y_j - E_j x_(q-1) - S_j x_(j+1)).  The entry i of a group k is the field
    i % nf at the site k g + i // nf."""
    n = _n
    q = n // _GS
    z = _BB * _BB
    yb = (q * _NMAT + 5) * z        # the border's right-hand side
    tb = (q * _NMAT + 6) * z        # a group's back-substituted right-hand side
    s0 = (q - 1) * _GS
    for i in range(_BB):
        _F[yb + i] = -_W[_IR + i % _NF, s0 + i // _NF]
    for j in range(q - 1):
        sj = j * _GS
        lb = (j * _NMAT + _MLL) * z
        for i in range(_BM):
            r = -_W[_IR + i % _NF, sj + i // _NF]
            if j > 0:
                a = 0.0
                for l in range(_BM):
                    a += _F[lb + i * _BB + l] * _W[_IY + l % _NF, sj - _GS + l // _NF]
                r -= a
            _W[_IY + i % _NF, sj + i // _NF] = r
        mb = (j * _NMAT + _MML) * z
        for i in range(_BB):
            a = 0.0
            for l in range(_BM):
                a += _F[mb + i * _BB + l] * _W[_IY + l % _NF, sj + l // _NF]
            _F[yb + i] = _F[yb + i] - a
    ul = ((q - 1) * _NMAT + _MUI) * z
    for i in range(_BB):
        a = 0.0
        for l in range(_BB):
            a += _F[ul + i * _BB + l] * _F[yb + l]
        _W[_IR + i % _NF, s0 + i // _NF] = a
    for k in range(q - 1):
        j = q - 2 - k
        sj = j * _GS
        e0 = (j * _NMAT + _ME) * z
        c0 = (j * _NMAT + _MC) * z
        for i in range(_BM):
            a = 0.0
            for l in range(_BB):
                a += _F[e0 + i * _BB + l] * _W[_IR + l % _NF, s0 + l // _NF]
            t = _W[_IY + i % _NF, sj + i // _NF] - a
            if j < q - 2:
                a = 0.0
                for l in range(_BM):
                    a += _F[c0 + i * _BB + l] * _W[_IR + l % _NF, sj + _GS + l // _NF]
                t -= a
            _F[tb + i] = t
        u0 = (j * _NMAT + _MUI) * z
        for i in range(_BM):
            a = 0.0
            for l in range(_BM):
                a += _F[u0 + i * _BB + l] * _F[tb + l]
            _W[_IR + i % _NF, sj + i // _NF] = a


def flow(_W, j, f, n, h, _cs):
    """h K ∇̄H at the site j, field f, from G: canonical (h G_p, -h G_q); skew Σ_k (h c_k) G_(j+k),
    k ascending."""
    if _SK == 0:
        if f == 0:
            return h * _W[_IG + 1, j]
        return -h * _W[_IG + 0, j]
    acc = 0.0
    for kk in range(2 * _SW + 1):
        t = j + kk - _SW
        if t < 0:
            t += n
        elif t >= n:
            t -= n
        acc += (h * _cs[kk]) * _W[_IG, t]
    return acc


def lattice_run(_Y, _T, _its, _fst, _p, _n, _h, _steps, _every, _maxiter, _tol, _chk, _simpl, _maxdis, _W,
                _D, _P, _F, _cs, _gam, _ns, _DH, _s0):
    """Steps 0 .. _steps-1 from the state ``_Y`` (nf, n), updated in place.

    ``_T`` (rows, nf n): row k + 1 is the state after step (k + 1)·_every - 1 (and the last row
    the last state); ``_its`` (_steps,): Newton iterations (summed over the stages); ``_fst`` (5,):
    status (STATUS), step, iterations, the failing value (the residual, or the predictor ratio)
    and the stage (0-based) of a failure.  ``_chk``: the resolution check (predictor disagreement
    ≤ ``_maxdis``); ``_simpl``: simplified Newton (the matrix at the predictor only); ``_cs`` a skew
    lattice's stencil coefficients c_(-sw) … c_sw at this n.  ``_gam`` (``_ns``,): the stage sizes
    in units of _h (a symmetric composition; (1.0,) at order 2); ``_DH`` (2 _ns nf, n): each stage's
    last two increments (module docstring), on entry those of the run this call continues;
    ``_s0``: the steps that run took (0 for a new run; 1: ``_DH`` holds the last increments only;
    2: both), so that a run continued in chunks takes the predictors of the run in one piece.
    The lattice's shape (nf, g, …) is bound as constants (module docstring).
    """
    n = _n
    nf = _NF
    nd = (2 * _WH + 1) * _NF * _NF
    row = 1
    for s in range(_steps):
        nits = 0
        for k in range(_ns):
            h = _h * _gam[k]            # (order 2: _gam[0] = 1, h = _h exactly)
            idy = 2 * k * nf            # this stage's increments in _DH: the last step's, the one before
            idy2 = idy + nf
            if s + _s0 == 0:
                # a run's first step: the explicit Euler predictor Z = Y + h K ∇H(Y)
                for j in range(n):
                    for c in range(nf):
                        _W[_IG + c, j] = 0.0
                        _W[_IZ + c, j] = _Y[c, j]
                grad(_Y, _W, _D, _n, _p, 0)
                for j in range(n):
                    for c in range(nf):
                        _DH[idy + c, j] = flow(_W, j, c, n, h, _cs)
            for j in range(n):
                for c in range(nf):
                    z = _Y[c, j] + _DH[idy + c, j]
                    if s + _s0 >= 2:
                        z = _Y[c, j] + (2.0 * _DH[idy + c, j] - _DH[idy2 + c, j])
                    _W[_IZ + c, j] = z
                    _W[_IZP + c, j] = z
            last = math.inf
            refac = 0
            done = 0
            it = 0
            size = 0.0
            while it < _maxiter:
                it += 1
                jac = 1 if (it == 1 or _simpl == 0 or refac == 1) else 0
                for j in range(n):
                    for c in range(nf):
                        _W[_IG + c, j] = 0.0
                if jac == 1:
                    for kd in range(nd):
                        for j in range(n):
                            _D[kd, j] = 0.0
                grad(_Y, _W, _D, _n, _p, jac)
                for j in range(n):
                    for c in range(nf):
                        _W[_IR + c, j] = _W[_IZ + c, j] - _Y[c, j] - flow(_W, j, c, n, h, _cs)
                if jac == 1:
                    newton(_D, _P, n, h, _cs)
                    if factor(_P, _F, n) != 0:
                        _fst[0] = 4.0
                        _fst[1] = s
                        _fst[2] = it
                        _fst[4] = k
                        return
                solve(_W, _F, n)
                size = 0.0
                scale = 1.0
                for j in range(n):
                    for c in range(nf):
                        d = _W[_IR + c, j]
                        z = _W[_IZ + c, j] + d
                        _W[_IZ + c, j] = z
                        size = max(size, abs(d))
                        scale = max(scale, abs(z))
                if not (size < math.inf):
                    _fst[0] = 2.0
                    _fst[1] = s
                    _fst[2] = it
                    _fst[4] = k
                    return
                if settled(size, scale, last, _tol) != 0:
                    done = 1
                    break
                # simplified Newton converging slowly (the matrix at the predictor too far off): the
                # matrix at the iterate from now on, for this stage
                if size > 0.25 * last:
                    refac = 1
                last = size
            if done == 0:
                # the residual at the last iterate, for the message
                for j in range(n):
                    for c in range(nf):
                        _W[_IG + c, j] = 0.0
                grad(_Y, _W, _D, _n, _p, 0)
                res = 0.0
                for j in range(n):
                    for c in range(nf):
                        res = max(res, abs(_W[_IZ + c, j] - _Y[c, j] - flow(_W, j, c, n, h, _cs)))
                _fst[0] = 1.0
                _fst[1] = s
                _fst[2] = it
                _fst[3] = res
                _fst[4] = k
                return
            if _chk != 0:
                moved = 0.0
                off = 0.0
                for j in range(n):
                    for c in range(nf):
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
                    _fst[4] = k
                    return
            for j in range(n):
                for c in range(nf):
                    _DH[idy2 + c, j] = _DH[idy + c, j]
                    _DH[idy + c, j] = _W[_IZ + c, j] - _Y[c, j]
                    _Y[c, j] = _W[_IZ + c, j]
            nits += it
        _its[s] = nits
        if (s + 1) % _every == 0 or s + 1 == _steps:
            for c in range(nf):
                for j in range(n):
                    _T[row, c * n + j] = _Y[c, j]
            row += 1
