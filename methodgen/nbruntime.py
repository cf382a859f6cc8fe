"""The compiled runtime shared by every generated numba module.

Newton's method (and its simplified / fixed-point / reuse / auto variants), the
closed-form, banded and LU solves, the composition loop, the per-step checks
(finiteness, domain conditions, time-transformation guard, local error, energy
jump, resolution) and the compensated summation live here, compiled **once per
machine** with ``numba.njit(<explicit signature>, cache=True)``.  A generated
numba module contains only its small per-system kernels (residual, Jacobian,
start value, post-step values ...), compiled with fixed signatures, and passes
them to :func:`run` as first-class functions: a new system compiles its kernels
(a fraction of a second each) and loads this runtime from numba's cache,
instead of compiling one monolithic integration loop per module.

What used to be template-time constants of a module (sizes, which checks exist,
where their values sit in the post kernel's output, the composition) are the
arrays :data:`CFG` (ints), the float constants and the per-stage coefficients
passed to :func:`run`; ``methodgen.emit`` writes them into the module.

Kernel signatures (every kernel takes all of them; unused arguments get
length-1 dummy arrays):

* ``guess(y, h, p, out)``, ``res(z, y, c, h, p, r)``, ``resjac(z, y, c, h, p, r, J)``,
  ``scale(y, h, p) -> float``;
* ``post(z, y, c, g, ha, hd, hb, p, out)``: the increment of one stage and what
  the checks need at its end.  ``ha, hd, hb`` are h times the stage's
  coefficients KICK_A[k], DRIFT[k], KICK_B[k] (an explicit stage *kick by a,
  drift by d, new force, kick by b*; a composition of Störmer–Verlet with γ_k is
  (γ_k/2, γ_k, γ_k/2)).  Today's kernels are written in the stage's step h·γ_k
  and read it from ``hd``;
* ``hs(y, p, out)``, ``check(y, p, out)``.

The cache is numba's: ``__pycache__`` next to this file, or ``NUMBA_CACHE_DIR``,
or numba's per-user fallback when the package directory is not writable.  A
cached runtime is loaded only when its stamp -- the SHA-256 of this file's bytes
(:func:`methodgen.nbcache.install_stamp_guard`) -- matches, so an edited runtime is recompiled,
never loaded stale, whatever the file's mtime and size.

This module imports numpy and numba only (no SymPy: it is on the warm path).
"""

from __future__ import annotations

import math
import os
import warnings

import numba
import numpy
from llvmlite import ir as _llir
from numba import types as _t
from numba.core import cgutils as _cgutils
from numba.core import errors as _errors
from numba.core.types.function_type import WrapperAddressProtocol as _WrapperAddressProtocol
from numba.core.typing.typeof import typeof_impl as _typeof_impl
from numba.experimental.function_type import _get_wrapper_address
from numba.extending import intrinsic as _intrinsic

from . import ktypes as _kt
from . import nbabi as _abi
from .llvmkernels import LLVMKernel
from .nbcache import flush_deferred as _flush_deferred
from .nbcache import install_stamp_guard as _install_stamp_guard
from .nbcache import source_digest as _source_digest
from .progress import phase

__all__ = ["run", "handle", "KernelHandle", "res_rows", "jac_rows", "int_config", "float_config", "KERNEL_TYPES", "CFG", "FCFG", "STATUS", "SOURCE_SHA256",
           "no_kernel", "stack_buffer", "run_loop", "stand_in"]

# --- cache stamp ---------------------------------------------------------------------

#: SHA-256 over this file and nbabi.py (the configuration layout it reads): the stamp of its
#: cached machine code (:data:`methodgen.nbabi.SOURCE_SHA256`).
SOURCE_SHA256 = _abi.SOURCE_SHA256

_install_stamp_guard(os.path.abspath(__file__), SOURCE_SHA256)
_flush_deferred()   # numba is imported now: the guards generated modules deferred

# --- kernel types ------------------------------------------------------------------------

_f8 = _t.float64
_i8 = _t.int64
_V = _t.float64[::1]
_M = _t.float64[:, ::1]
_IV = _t.int64[::1]
_B = _t.boolean

#: numba signatures of the kernels (see the module docstring; methodgen.nbabi.KERNEL_TYPES as
#: numba's types).
KERNEL_TYPES = {k: _kt.to_numba(v) for k, v in _abi.KERNEL_TYPES.items()}
_F = {k: _t.FunctionType(v) for k, v in KERNEL_TYPES.items()}


class KernelHandle(_WrapperAddressProtocol):
    """A compiled kernel as a first-class function value whose address is resolved once.

    numba unboxes a dispatcher passed for a ``FunctionType`` argument by looking up its
    compiled overload and two machine-code addresses on *every* call (about 35 µs per
    kernel: 0.45 ms for the seven kernels of :func:`run`, measured; a time-transformed run
    that lands on T makes ~15 calls).  A handle implements numba's wrapper-address protocol
    with the address looked up here, once: unboxing it is an attribute read.  Calls then go
    through the kernel's C-ABI wrapper, which forwards to the same compiled body (same
    machine code for the arithmetic: bitwise the same results).

    Parameters
    ----------
    kernel : numba dispatcher
        The kernel, compiled for ``sig`` (it is kept alive by the handle).
    sig : numba signature
        Its signature, e.g. ``KERNEL_TYPES["post"]``.
    """

    __slots__ = ("kernel", "_sig", "_addr", "_type")

    def __init__(self, kernel, sig):
        self.kernel = kernel
        self._sig = sig
        self._addr = _get_wrapper_address(kernel, sig)
        self._type = _t.FunctionType(sig)

    def __wrapper_address__(self):
        return self._addr

    def signature(self):
        return self._sig


@_typeof_impl.register(KernelHandle)
def _typeof_handle(val, c):
    # numba's generic typeof of a wrapper-address object builds a new FunctionType per call
    return val._type


_HANDLES: dict = {}


# A kernel compiled through LLVM IR (methodgen.llvmkernels) is a first-class function as it
# is: its address is numba's C-ABI wrapper's, resolved once.  Registered here, where numba is
# imported, so that llvmkernels stays free of numba.
_WrapperAddressProtocol.register(LLVMKernel)


@_typeof_impl.register(LLVMKernel)
def _typeof_llvm_kernel(val, c):
    return val.numba_type()


def handle(kernel, sig):
    """The :class:`KernelHandle` of ``kernel`` for ``sig``, made on first use and then reused
    (a handle or an LLVM kernel passed is returned as it is)."""
    if isinstance(kernel, (KernelHandle, LLVMKernel)):
        return kernel
    if isinstance(kernel, _abi._Missing):
        kernel = kernel.compiled()
    key = (id(kernel), id(sig))   # (hashing a numba signature costs microseconds)
    h = _HANDLES.get(key)
    if h is None:   # (the handle keeps its kernel alive: the id is not reused)
        h = _HANDLES[key] = KernelHandle(kernel, sig)
    return h

# error_model="numpy": a division by zero gives inf/nan (reported by the finiteness checks
# with the step) instead of an exception that would abort the loop.  No fastmath:
# reassociation would destroy compensated summation and the round-off stopping rule.
_OPTS = dict(cache=True, error_model="numpy")


def _kernel(sig):
    return numba.njit(sig, **_OPTS)


# Stand-ins for the kernels a module does not have (an explicit method has no Newton
# kernels, a method that keeps H no energy-jump kernel); never called.  Compiled (or loaded
# from the cache) on first request, so a module loads only those it needs.
def _no_guess(y, h, p, out):
    pass


def _no_res(z, y, c, h, p, r):
    pass


def _no_resjac(z, y, c, h, p, r, J):
    pass


def _no_scale(y, h, p):
    return 0.0


def _no_hs(y, p, out):
    pass


def _no_check(y, p, out):
    pass


_NO = {"guess": _no_guess, "res": _no_res, "resjac": _no_resjac, "scale": _no_scale, "hs": _no_hs,
       "check": _no_check}
_compiled = {}


def _once(key, sig, py_func):
    """``py_func`` compiled for ``sig`` (cached on disk), the first time it is asked for."""
    f = _compiled.get(key)
    if f is None:
        f = _compiled[key] = numba.njit(sig, **_OPTS)(py_func)
    return f


def stand_in(kind: str):
    """The compiled stand-in kernel of ``kind`` (see :func:`methodgen.nbabi.no_kernel`)."""
    return _once("no_" + kind, KERNEL_TYPES[kind], _NO[kind])


no_kernel = _abi.no_kernel
_Missing = _abi._Missing


@_intrinsic
def stack_buffer(typingctx, size):
    """A pointer to ``size`` float64 on the stack of the compiled function that calls it
    (``size`` a literal int); view it as an array with ``numba.carray(ptr, shape)``.

    Work arrays of a kernel without a heap allocation per call (``numpy.empty`` costs about
    20 ns, more than a small stage kernel's arithmetic).  The buffer lives in the caller's
    entry block, so it is valid until the caller returns, and is not initialised.
    """
    if not isinstance(size, _t.IntegerLiteral):
        raise _errors.RequireLiteralValue(size)
    n = size.literal_value

    def codegen(context, builder, signature, args):
        buf = _cgutils.alloca_once(builder, _llir.ArrayType(_llir.DoubleType(), n))
        return builder.bitcast(buf, _llir.DoubleType().as_pointer())

    return _t.CPointer(_t.float64)(size), codegen


# --- configuration -------------------------------------------------------------------------

# The layout of the configuration arrays and the status codes: methodgen.nbabi's (plain
# data a module reads without importing numba), as constants of the compiled code.
CFG = _abi.CFG
FCFG = _abi.FCFG
(_C_N, _C_DIM, _C_STAGES, _C_NF, _C_LERR, _C_KLERR, _C_POST_EXTRA, _C_POST_DOMAIN, _C_NDOMAIN,
 _C_POST_TT, _C_TT_GUARD, _C_POST_EJ, _C_EJUMP, _C_POST_LEN, _C_HAS_SCALE, _C_RESOLUTION, _C_KIND,
 _C_KL, _C_KU) = range(len(CFG))
(_F_LERR2, _F_LERR_SCALE, _F_MAX_LEVEL_DEFECT, _F_MAX_ENERGY_JUMP, _F_MAX_RESOLUTION,
 _F_NEWTON_FAILURE_RESOLUTION, _F_MAX_PREDICTOR_DISAGREEMENT, _F_REUSE_RATE, _F_AUTO_RATE,
 _F_AUTO_HOLD) = range(len(FCFG))

STATUS = _abi.STATUS
(_OK, _DIVERGED, _NOT_CONVERGED, _UNRESOLVED, _MISPREDICTED, _LINEAR_FAILED, _NON_FINITE, _OUT_OF_DOMAIN,
 _LOCAL_ERROR, _SLOW, _UNRESOLVED_START, _TIME_SCALE, _ENERGY_JUMP) = range(len(STATUS))

_EPS = _abi._EPS
_TOL_ROUNDOFF = _abi._TOL_ROUNDOFF
_TOL_PLATEAU = _abi._TOL_PLATEAU

# Newton's method and the checks are inlined (numba IR) into run: one function for LLVM,
# about 1.3x faster per step on a cheap 2-DOF system than calls (compiled once, so free).
_inline = numba.njit(inline="always", **_OPTS)
_jit = numba.njit(**_OPTS)


# --- linear algebra --------------------------------------------------------------------------

@_inline
def _maxabs(v, n):
    # Max-norm of v[:n] that propagates NaN (a NaN entry must fail every later test).
    m = 0.0
    for i in range(n):
        a = abs(v[i])
        if a > m or a != a:
            m = a
    return m


@_inline
def _solve(a, b, x, _a, _b, n, kl, ku):
    """Solve a x = b: closed form for n <= 3 (the numpy backend's formulas), else Gaussian
    elimination with partial pivoting within the band (``kl`` below, ``ku`` above the
    diagonal).  A singular matrix gives NaN (reported as divergence)."""
    if n == 1:
        x[0] = b[0] / a[0, 0]
        return
    if n == 2:
        a00 = a[0, 0]
        a01 = a[0, 1]
        a10 = a[1, 0]
        a11 = a[1, 1]
        b0 = b[0]
        b1 = b[1]
        det = a00 * a11 - a01 * a10
        x[0] = (b0 * a11 - a01 * b1) / det
        x[1] = (a00 * b1 - b0 * a10) / det
        return
    if n == 3:
        a00 = a[0, 0]
        a01 = a[0, 1]
        a02 = a[0, 2]
        a10 = a[1, 0]
        a11 = a[1, 1]
        a12 = a[1, 2]
        a20 = a[2, 0]
        a21 = a[2, 1]
        a22 = a[2, 2]
        b0 = b[0]
        b1 = b[1]
        b2 = b[2]
        c00 = a11 * a22 - a12 * a21
        c01 = a12 * a20 - a10 * a22
        c02 = a10 * a21 - a11 * a20
        det = a00 * c00 + a01 * c01 + a02 * c02
        x[0] = (b0 * c00 + b1 * (a02 * a21 - a01 * a22) + b2 * (a01 * a12 - a02 * a11)) / det
        x[1] = (b0 * c01 + b1 * (a00 * a22 - a02 * a20) + b2 * (a02 * a10 - a00 * a12)) / det
        x[2] = (b0 * c02 + b1 * (a01 * a20 - a00 * a21) + b2 * (a00 * a11 - a01 * a10)) / det
        return
    for r in range(n):
        _b[r] = b[r]
        for c in range(n):
            _a[r, c] = a[r, c]
    for col in range(n):
        low = min(n, col + kl + 1)        # rows that can hold a nonzero in this column
        high = min(n, col + kl + ku + 1)  # columns a pivot row can reach
        piv = col
        best = abs(_a[col, col])
        for r in range(col + 1, low):
            v = abs(_a[r, col])
            if v > best:
                piv = r
                best = v
        if best == 0.0:
            for r in range(n):
                x[r] = math.nan
            return
        if piv != col:
            for c in range(col, high):
                t = _a[col, c]
                _a[col, c] = _a[piv, c]
                _a[piv, c] = t
            t = _b[col]
            _b[col] = _b[piv]
            _b[piv] = t
        inv = 1.0 / _a[col, col]
        for r in range(col + 1, low):
            f = _a[r, col] * inv
            if f != 0.0:
                for c in range(col + 1, high):
                    _a[r, c] -= f * _a[col, c]
                _b[r] -= f * _b[col]
    for r in range(n - 1, -1, -1):
        s = _b[r]
        for c in range(r + 1, min(n, r + kl + ku + 1)):
            s -= _a[r, c] * x[c]
        x[r] = s / _a[r, r]


@_jit
def _lu(J, LU, piv, n, kl, ku):
    """LU factorisation with partial pivoting of J into LU (row permutation in ``piv``);
    False for an exactly singular J (solver "reuse")."""
    for i in range(n):
        piv[i] = i
        for j in range(n):
            LU[i, j] = J[i, j]
    for col in range(n):
        best = abs(LU[col, col])
        pr = col
        for i in range(col + 1, min(n, col + kl + 1)):
            v = abs(LU[i, col])
            if v > best:
                best = v
                pr = i
        if not best > 0.0:
            return False
        if pr != col:
            for j in range(n):
                t = LU[col, j]
                LU[col, j] = LU[pr, j]
                LU[pr, j] = t
            t = piv[col]
            piv[col] = piv[pr]
            piv[pr] = t
        inv = 1.0 / LU[col, col]
        high = min(n, col + kl + ku + 1)  # columns a pivot row can reach (the band)
        for i in range(col + 1, min(n, col + kl + 1)):
            f = LU[i, col] * inv
            LU[i, col] = f
            if f != 0.0:
                for j in range(col + 1, high):
                    LU[i, j] -= f * LU[col, j]
    return True


@_jit
def _lu_solve(LU, piv, b, x, n, kl, ku):
    """Solve J x = b from the factors of _lu (forward, then back substitution)."""
    for i in range(n):
        s = b[piv[i]]
        for j in range(i):
            s -= LU[i, j] * x[j]
        x[i] = s
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(i + 1, min(n, i + kl + ku + 1)):
            s -= LU[i, j] * x[j]
        x[i] = s / LU[i, i]


@_inline
def _resolution(J, n, kind, failure_resolution):
    """h·ω from the Newton Jacobian: the max row sum of |J - I|, or where that bound is
    large the spectral radius of J - I (``kind`` 1 "full": h·ω ≈ 2ρ, 2 "reduced":
    h·ω ≈ 2ρ^(1/2))."""
    norm = 0.0
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += abs(J[i, j] - 1.0) if i == j else abs(J[i, j])
        if s > norm or s != s:
            norm = s
    threshold = 0.5 * failure_resolution if kind == 1 else (0.5 * failure_resolution) ** 2
    if n > 1 and norm > threshold:
        # The row-sum norm only bounds the spectral radius and changes with the units; the
        # eigenvalues of J - I decide where the bound could change a verdict.  Complex
        # input: numba's eigvals keeps the domain.
        A = numpy.empty((n, n), dtype=numpy.complex128)
        fin = True
        for i in range(n):
            for j in range(n):
                v = J[i, j] - 1.0 if i == j else J[i, j]
                fin = fin and math.isfinite(v)
                A[i, j] = v
        norm = numpy.max(numpy.abs(numpy.linalg.eigvals(A))) if fin else math.inf
    if kind == 1:
        return 2.0 * norm
    return 2.0 * math.sqrt(norm)


# --- one implicit stage -----------------------------------------------------------------------

@_inline
def _solve_linear(resjac, y, c, h, p, check_resolution, cfg, fcfg, z, dz, r, J, _a, _b):
    """Linearly implicit step: the equations are linear in z, so one solve is exact.
    Returns (status, iterations, value); ``z`` holds the solution."""
    n = cfg[_C_N]
    for i in range(n):
        z[i] = 0.0
    resjac(z, y, c, h, p, r, J)
    _solve(J, r, dz, _a, _b, n, cfg[_C_KL], cfg[_C_KU])
    for i in range(n):
        z[i] = -dz[i]
    if cfg[_C_RESOLUTION] and check_resolution:
        rho = _resolution(J, n, cfg[_C_RESOLUTION], fcfg[_F_NEWTON_FAILURE_RESOLUTION])
        if not rho <= fcfg[_F_MAX_RESOLUTION]:
            return _UNRESOLVED, 1, rho
    for i in range(n):
        if not math.isfinite(z[i]):
            return _LINEAR_FAILED, 1, math.nan
    return _OK, 1, 0.0


@_inline
def _solve_newton(guess, res, resjac, scale, y, c, h, p, maxiter, check_resolution, solver, use_tol, tol,
                  cfg, fcfg, z, z_pred, dz, r, J, _a, _b, LU, piv, lu_ok, mode, n):
    """Solve R(z) = 0 for one state; returns (status, iterations, value), ``z`` the solution.

    ``solver``: 0 Newton (Jacobian every iteration), 1 simplified Newton (Jacobian
    frozen at the start value), 2 fixed point (``dz = R``), 3 reuse (simplified Newton
    whose LU factors ``LU``, ``piv`` are kept over steps while ``lu_ok[0]`` is 1:
    refreshed at the current iterate when an iteration contracts by less than
    REUSE_RATE, and from the predictor when an iterate diverges), 4 auto (fixed point
    while it contracts by AUTO_RATE or better, else Newton from the current iterate,
    and Newton for the next ``mode[0]`` steps).  The start value, stopping rule and
    resolution checks are those of the numpy backend; ``value`` is the residual norm,
    h·ω or the predictor disagreement of a failure.  ``n`` is cfg[N] (a compile-time constant
    in the fused loop's copy of this iteration, methodgen.fused).
    """
    kl = cfg[_C_KL]
    ku = cfg[_C_KU]
    resol = cfg[_C_RESOLUTION]
    guess(y, h, p, z)
    for i in range(n):
        z_pred[i] = z[i]
    floor = scale(y, h, p) if cfg[_C_HAS_SCALE] else 0.0
    prev = math.inf
    have_jac = False  # J holds the Jacobian at an iterate of this step
    newton = solver == 4 and mode[0] > 0  # (auto) Newton's method in this step
    it = 0
    while it < maxiter:
        it += 1
        if solver == 2 or (solver == 4 and not newton):
            # Fixed point z <- F(z) for R(z) = z - F(z): the increment is R itself.
            res(z, y, c, h, p, r)
            for i in range(n):
                dz[i] = r[i]
        elif solver == 3:
            if lu_ok[0] == 0:
                resjac(z, y, c, h, p, r, J)
                have_jac = True
                if _lu(J, LU, piv, n, kl, ku):
                    lu_ok[0] = 1
                    _lu_solve(LU, piv, r, dz, n, kl, ku)
                else:
                    for i in range(n):
                        dz[i] = math.nan
            else:
                res(z, y, c, h, p, r)
                _lu_solve(LU, piv, r, dz, n, kl, ku)
        else:
            if solver == 0 or solver == 4 or not have_jac:
                resjac(z, y, c, h, p, r, J)
                have_jac = True
            else:
                res(z, y, c, h, p, r)
            _solve(J, r, dz, _a, _b, n, kl, ku)
        for i in range(n):
            z[i] -= dz[i]
        nd = _maxabs(dz, n)
        nz = max(_maxabs(z, n), floor)
        if solver == 4 and not newton and (not nd <= 1e300 or (it >= 2 and nd > fcfg[_F_AUTO_RATE] * prev)):
            # The fixed point diverges or contracts slowly (h·ω not small): Newton's method
            # from the current iterate (from the predictor after a non-finite one) for this
            # step and the next AUTO_HOLD.
            newton = True
            mode[0] = int(fcfg[_F_AUTO_HOLD]) + 1
            if not nd <= 1e300:
                for i in range(n):
                    z[i] = z_pred[i]
            prev = math.inf
            continue
        if not nd <= 1e300:
            if solver == 3 and not have_jac:
                # Factors kept from earlier steps led astray: start again from the
                # predictor with fresh ones.
                lu_ok[0] = 0
                for i in range(n):
                    z[i] = z_pred[i]
                prev = math.inf
                continue
            lu_ok[0] = 0
            if resol and check_resolution:
                resjac(z_pred, y, c, h, p, r, J)
                rho = _resolution(J, n, resol, fcfg[_F_NEWTON_FAILURE_RESOLUTION])
                if rho > fcfg[_F_NEWTON_FAILURE_RESOLUTION]:
                    return _UNRESOLVED_START, it, rho
            return _DIVERGED, it, _maxabs(r, n)
        if use_tol:
            done = nd <= tol
        else:
            done = nd <= _TOL_ROUNDOFF * nz or (nd >= prev and prev <= _TOL_PLATEAU * nz)
        if done:
            if resol and check_resolution:
                if have_jac:
                    rho = _resolution(J, n, resol, fcfg[_F_NEWTON_FAILURE_RESOLUTION])
                    if not rho <= fcfg[_F_MAX_RESOLUTION]:
                        return _UNRESOLVED, it, rho
                # The start value is an explicit predictor of the step; when it disagrees
                # with the converged step by more than the step itself, h does not resolve
                # the dynamics there.
                dis = 0.0
                if nz > 0.0:
                    for i in range(n):
                        e = abs(z[i] - z_pred[i])
                        if e > dis or e != e:
                            dis = e
                    dis = dis / nz
                if not dis <= fcfg[_F_MAX_PREDICTOR_DISAGREEMENT]:
                    return _MISPREDICTED, it, dis
            if newton:
                mode[0] -= 1
            return _OK, it, 0.0
        if solver == 3 and nd > fcfg[_F_REUSE_RATE] * prev:
            lu_ok[0] = 0  # contracting too slowly: factor the Jacobian at this iterate
        prev = nd
    lu_ok[0] = 0
    res(z, y, c, h, p, r)
    rnorm = _maxabs(r, n)
    if not use_tol and (rnorm <= _TOL_PLATEAU * max(_maxabs(z, n), floor) or rnorm <= _TOL_ROUNDOFF * _maxabs(y, y.shape[0])):
        # Still converging, the residual already near round-off (of the unknowns, or of the
        # state where the increments are far smaller than it): maxiter was too small.
        return _SLOW, maxiter, rnorm
    if resol and check_resolution:
        resjac(z_pred, y, c, h, p, r, J)
        rho = _resolution(J, n, resol, fcfg[_F_NEWTON_FAILURE_RESOLUTION])
        if rho > fcfg[_F_NEWTON_FAILURE_RESOLUTION]:
            return _UNRESOLVED_START, maxiter, rho
    return _NOT_CONVERGED, maxiter, rnorm


# --- the integration loop -----------------------------------------------------------------------

@_inline
def _fail(fstat, fval, b, status, n, it, val):
    fstat[b, 0] = status
    fstat[b, 1] = n
    fstat[b, 2] = it
    fval[b] = val


_RUN_SIG = _t.void(
    _F["guess"], _F["res"], _F["resjac"], _F["scale"], _F["post"], _F["hs"], _F["check"],
    _IV, _V, _IV, _IV, _V, _V, _V, _V, _V,          # cfg, fcfg, lerr_index, domain_pos, gammas, ratios, a, d, b
    _t.float64[:, :, :], _i8, _i8, _M, _M, _M,      # traj (any layout: a user's out), n0, n1, Y, C, FRC
    _f8, _V, _i8, _B, _i8, _B, _f8, _B,             # h, p, maxiter, check_resolution, solver, use_tol, tol, compensated
    _t.int64[:, ::1], _t.int64[:, ::1], _V, _i8,    # its, fstat, fval, every
    _t.int64[:, ::1], _t.int64[:, ::1], _t.float64[:, :, :, ::1], _t.int64[:, :, ::1],  # smode, slu_ok, sLU, spiv
)


@_inline
def _loop(kernels, cfg, fcfg, lerr_index, domain_pos, coefs, traj, n0, n1, Y, C, FRC, h, p, options, its, fstat,
          fval, every, smode, slu_ok, sLU, spiv, N):
    # The body of run_loop, with the number of unknowns N passed in; run_loop's other
    # arguments come in tuples: Python compiles a call of more than 30 arguments
    # to a call with *args, which numba does not inline.
    guess, res, resjac, scale, post_k, hs, check = kernels
    gammas, ratios, kick_a, drift, kick_b = coefs
    maxiter, check_resolution, solver, use_tol, tol, compensated = options
    DIM = cfg[_C_DIM]
    STAGES = cfg[_C_STAGES]
    NF = cfg[_C_NF]
    LERR = cfg[_C_LERR]
    KLERR = cfg[_C_KLERR]
    POST_EXTRA = cfg[_C_POST_EXTRA]
    POST_DOMAIN = cfg[_C_POST_DOMAIN]
    NDOMAIN = cfg[_C_NDOMAIN]
    POST_TT = cfg[_C_POST_TT]
    TT_GUARD = cfg[_C_TT_GUARD]
    POST_EJ = cfg[_C_POST_EJ]
    EJUMP = cfg[_C_EJUMP]
    KIND = cfg[_C_KIND]
    LERR2 = fcfg[_F_LERR2]
    LERR_SCALE = fcfg[_F_LERR_SCALE]
    m = max(N, 1)
    z = numpy.zeros(m)
    z_pred = numpy.zeros(m)
    dz = numpy.zeros(m)
    r = numpy.zeros(m)
    J = numpy.zeros((m, m))
    _a = numpy.zeros((m, m))
    _b = numpy.zeros(m)
    post = numpy.zeros(max(cfg[_C_POST_LEN], 1))
    chk = numpy.zeros(1 + DIM)
    g0 = numpy.zeros(max(KLERR, 1))  # b = (h/2) f(y0) of the step (E = a - b, see the post kernel)
    hh = 0.5 * h * gammas[0]
    ejs = numpy.zeros(2)  # H and its size at the start of the step (carried from post)
    limit = n1
    for b in range(Y.shape[0]):
        y = Y[b]
        c = C[b]
        frc = FRC[b]  # ∇U at the start of the step (first-same-as-last), updated in place
        if EJUMP:
            hs(y, p, ejs)
        fstat[b, 0] = _OK
        if LERR == 2:
            # f at the start of the first step (the initial state was checked in Python)
            check(y, p, chk)
            for j in range(KLERR):
                g0[j] = hh * chk[1 + lerr_index[j]]
        nxt = (n0 // every + 1) * every  # the next step whose state is kept
        for n in range(n0, limit):
            k = 0
            while k < STAGES:
                hs_ = h * drift[k]
                rk = ratios[k]  # g0 holds (h_prev/2) f: rescale to this stage's step
                if KIND != 2:
                    # the solver state of this stage of trajectory b, kept over steps and
                    # calls: "auto": Newton steps left; "reuse": LU factors and their validity
                    if KIND == 1:
                        status, it, val = _solve_linear(resjac, y, c, hs_, p, check_resolution, cfg, fcfg,
                                                        z, dz, r, J, _a, _b)
                    else:
                        status, it, val = _solve_newton(guess, res, resjac, scale, y, c, hs_, p, maxiter,
                                                        check_resolution, solver, use_tol, tol, cfg, fcfg,
                                                        z, z_pred, dz, r, J, _a, _b, sLU[b, k], spiv[b, k],
                                                        slu_ok[b, k:k + 1], smode[b, k:k + 1], N)
                    its[b, n - n0] += it
                    if status != _OK:
                        _fail(fstat, fval, b, status, n, it, val)
                        break
                # the increment, then what the checks need at y1 (the error estimate's
                # field values or E, the domain conditions ...)
                post_k(z, y, c, frc, h * kick_a[k], hs_, h * kick_b[k], p, post)
                finite = True
                if compensated:
                    # Compensated (Kahan) summation of the update: the rounding error of
                    # y + dy is carried to the next step.
                    for i in range(DIM):
                        a = post[i] + c[i]
                        s = y[i] + a
                        c[i] = a - (s - y[i])
                        y[i] = s
                        finite = finite and math.isfinite(s)
                else:
                    for i in range(DIM):
                        y[i] += post[i]
                        finite = finite and math.isfinite(y[i])
                # first-same-as-last: the force at this stage's end starts the next stage
                for i in range(NF):
                    frc[i] = post[DIM + i]
                if not finite:
                    _fail(fstat, fval, b, _NON_FINITE, n, 0, math.nan)
                    break
                bad = -1
                for j in range(NDOMAIN):
                    v = post[POST_DOMAIN + j]
                    if not (v > 0.0 if domain_pos[j] else v >= 0.0):
                        bad = j
                        break
                if bad >= 0:
                    _fail(fstat, fval, b, _OUT_OF_DOMAIN, n, bad, post[POST_DOMAIN + bad])
                    break
                if TT_GUARD:
                    if not post[POST_TT] > 0.0 or (check_resolution and abs(post[POST_TT + 1])
                                                   > fcfg[_F_MAX_LEVEL_DEFECT] * post[POST_TT + 2]):
                        _fail(fstat, fval, b, _TIME_SCALE, n, 0, post[POST_TT])
                        break
                if LERR and check_resolution:
                    if LERR == 1:
                        ne2 = post[POST_EXTRA]
                        nd2 = post[POST_EXTRA + 1]
                    else:
                        ne2 = 0.0
                        for j in range(KLERR):
                            e = post[POST_EXTRA + 1 + j] - rk * g0[j]
                            g0[j] = post[POST_EXTRA + 1 + KLERR + j]
                            ne2 += e * e
                        nd2 = post[POST_EXTRA]
                    if ne2 > LERR2 * nd2:
                        _fail(fstat, fval, b, _LOCAL_ERROR, n, 0, LERR_SCALE * math.sqrt(ne2 / nd2))
                        break
                if EJUMP:
                    if check_resolution and abs(post[POST_EJ] - ejs[0]) > fcfg[_F_MAX_ENERGY_JUMP] * ejs[1]:
                        _fail(fstat, fval, b, _ENERGY_JUMP, n, 0, abs(post[POST_EJ] - ejs[0]) / ejs[1])
                        break
                    ejs[0] = post[POST_EJ]
                    ejs[1] = post[POST_EJ + 1]
                k += 1
            if fstat[b, 0] != _OK:
                fstat[b, 3] = k  # the stage that failed (for the message)
                limit = n + 1
                break
            if n + 1 == nxt:
                row = nxt // every
                for i in range(DIM):
                    traj[row, b, i] = y[i]
                nxt += every


def _run(guess, res, resjac, scale, post_k, hs, check, cfg, fcfg, lerr_index, domain_pos, gammas, ratios,
         kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter, check_resolution, solver, use_tol, tol,
         compensated, its, fstat, fval, every, smode, slu_ok, sLU, spiv):
    # run_loop's compiled body (see there)
    _loop((guess, res, resjac, scale, post_k, hs, check), cfg, fcfg, lerr_index, domain_pos,
          (gammas, ratios, kick_a, drift, kick_b), traj, n0, n1, Y, C, FRC, h, p,
          (maxiter, check_resolution, solver, use_tol, tol, compensated), its, fstat, fval, every, smode, slu_ok,
          sLU, spiv, cfg[_C_N])


_COMPILED: dict = {}


def loop_for(n=None):
    """The compiled integration loop (any number of unknowns; ``n`` is accepted and ignored),
    compiled on first use with the fixed signature and cached by numba: once per machine.

    There were four copies, three with N = 1, 2, 3 a constant (unrolled Newton loops, the
    closed-form solve folded: a fifth of a 2-unknown step faster), 21-25 s of compilation
    each.  Since a module's fused loop (methodgen.fused) runs almost every call with N a
    constant of its own, this loop only takes what that one does not apply to (solver "reuse",
    kernels numba compiled, ``METHODGEN_FUSED=0``): one copy, compiled once."""
    f = _COMPILED.get(None)
    if f is None:
        # minutes and ~1 GB on a loaded machine the first time (then numba's cache): reported as
        # a phase like every other (a line on the CLI's stderr past 2 s; progress.install for
        # the API), never silent
        with phase("compile runtime (once per machine)"), warnings.catch_warnings():
            # numba calls first-class function types experimental; the runtime is built on them
            # and tested, and the warning would reach users once per machine
            warnings.simplefilter("ignore", numba.core.errors.NumbaExperimentalFeatureWarning)
            f = _COMPILED[None] = numba.njit(_RUN_SIG, **_OPTS)(_run)
    return f


def run_loop(guess, res, resjac, scale, post_k, hs, check, cfg, fcfg, lerr_index, domain_pos, gammas, ratios,
             kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter, check_resolution, solver, use_tol, tol,
             compensated, its, fstat, fval, every, smode, slu_ok, sLU, spiv):
    """Steps ``n0 .. n1-1`` of every trajectory: the states after the steps that are multiples
    of ``every`` go to their rows ``(n+1) // every`` of ``traj`` (rows, B, DIM).

    ``Y`` (B, DIM), the compensation ``C`` and the first-same-as-last force ``FRC``
    (B, NF; a (B, 1) dummy without) are updated in place; ``its`` (B, n1-n0)
    receives the iterations per step.  A failure of trajectory b is recorded as
    ``fstat[b] = (status, step, iterations, stage)``, ``fval[b]`` (for
    _OUT_OF_DOMAIN the iterations slot holds the index of the violated domain
    condition and ``fval`` its value, for _LOCAL_ERROR ``fval`` is the estimate
    relative to the step); later trajectories then only run up to that step (they
    cannot change which step fails first, only which trajectories fail there), so
    rows ``0 .. step`` are complete for all trajectories.

    One compiled copy for any number of unknowns (:func:`loop_for`; 21-25 s to compile,
    once per machine, then loaded from numba's cache).

    :func:`run` (:func:`methodgen.nbabi.run`) is a module's entry: it tries the module's fused
    loop first (:mod:`methodgen.fused`) and calls this loop where that does not apply.
    """
    kt = KERNEL_TYPES
    guess, res, resjac, scale = (handle(guess, kt["guess"]), handle(res, kt["res"]), handle(resjac, kt["resjac"]),
                                 handle(scale, kt["scale"]))
    post_k, hs, check = handle(post_k, kt["post"]), handle(hs, kt["hs"]), handle(check, kt["check"])
    loop_for()(guess, res, resjac, scale, post_k, hs, check, cfg, fcfg, lerr_index, domain_pos,
                              gammas, ratios, kick_a, drift, kick_b, traj, n0, n1, Y, C, FRC, h, p, maxiter,
                              check_resolution, solver, use_tol, tol, compensated, its, fstat, fval, every, smode,
                              slu_ok, sLU, spiv)


run = _abi.run


def _res_rows(res, Z, Y, h, p, R):
    c = numpy.zeros(Y.shape[1])
    for b in range(Z.shape[0]):
        res(Z[b], Y[b], c, h, p, R[b])


def _jac_rows(resjac, Z, Y, h, p, R, J):
    c = numpy.zeros(Y.shape[1])
    for b in range(Z.shape[0]):
        resjac(Z[b], Y[b], c, h, p, R[b], J[b])


def _writable(a):
    # The explicit signatures take writable arrays (the kernels' types); a module's rows of
    # one z and one y0 are read-only views of numpy.broadcast_to, refused by numba's dispatch.
    return a if a.flags.writeable else a.copy()


def res_rows(res, Z, Y, h, p, R):
    """The residual at each row of Z, Y (no compensation); compiled on first use."""
    _once("res_rows", _t.void(_F["res"], _M, _M, _f8, _V, _M), _res_rows)(
        handle(res, KERNEL_TYPES["res"]), _writable(Z), _writable(Y), h, p, R)


def jac_rows(resjac, Z, Y, h, p, R, J):
    """The residual and the Jacobian at each row of Z, Y (no compensation); compiled on first use."""
    _once("jac_rows", _t.void(_F["resjac"], _M, _M, _f8, _V, _M, _t.float64[:, :, ::1]), _jac_rows)(
        handle(resjac, KERNEL_TYPES["resjac"]), _writable(Z), _writable(Y), h, p, R, J)


# --- configuration arrays (Python) ----------------------------------------------------------

int_config = _abi.int_config
float_config = _abi.float_config
