"""numba's side of the compiled backend: what numba-compiled code needs to call the kernels.

The integration loop is :mod:`methodgen.stepper`, compiled with a module's kernels inlined
(:mod:`methodgen.fused`, no numba).  Three kinds of code are still compiled by numba and call
kernels through this module: the lock-step block of explicit batches (:mod:`methodgen.nbbatch`),
the loop of a projected method (``templates/numba_projection.py.j2``), and a kernel the LLVM
translator refuses (or every kernel under ``METHODGEN_KERNELS=numba``).  For them it provides

* :func:`handle`: a kernel compiled through LLVM IR as a numba first-class function
  (:class:`KernelHandle`, numba's wrapper-address protocol) of its signature
  (:data:`KERNEL_TYPES`, from :mod:`methodgen.abi`);
* :func:`stand_in`: numba-compiled stand-ins of kernels a module does not have;
* :func:`stack_buffer`: scratch arrays on the stack of numba-compiled kernels;
* :func:`res_rows`, :func:`jac_rows`: the residual and Newton matrix at many states.

The cache is numba's: ``__pycache__`` next to this file, or ``NUMBA_CACHE_DIR``, or numba's
per-user fallback when the package directory is not writable.  A cached function is loaded only
when its stamp -- the SHA-256 of the runtime's files (:data:`methodgen.nbabi.SOURCE_SHA256`,
:func:`methodgen.nbcache.install_stamp_guard`) -- matches, so an edited file is recompiled,
never loaded stale, whatever its mtime and size.

This module imports numpy and numba only (no SymPy).
"""

from __future__ import annotations

import os

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
from . import abi as _abi
from .llvmkernels import LLVMKernel
from .nbcache import flush_deferred as _flush_deferred
from .nbcache import install_stamp_guard as _install_stamp_guard
from .nbcache import source_digest as _source_digest

__all__ = ["handle", "KernelHandle", "res_rows", "jac_rows", "KERNEL_TYPES", "CFG", "FCFG", "STATUS",
           "SOURCE_SHA256", "stack_buffer", "stand_in"]

# --- cache stamp ---------------------------------------------------------------------

#: SHA-256 over this file and nbabi.py (the configuration layout it reads): the stamp of its
#: cached machine code (:data:`methodgen.nbabi.SOURCE_SHA256`).
SOURCE_SHA256 = _abi.RUNTIME_SHA256

_install_stamp_guard(os.path.abspath(__file__), SOURCE_SHA256)
_flush_deferred()   # numba is imported now: the guards generated modules deferred

# --- kernel types ------------------------------------------------------------------------

_f8 = _t.float64
_V = _t.float64[::1]
_M = _t.float64[:, ::1]

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
    if hasattr(kernel, "kind") and hasattr(kernel, "compiled"):   # nbabi.no_kernel's stand-in marker
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

# The contract (methodgen.abi, re-exported by methodgen.nbabi), for the generated modules' _rt.
CFG = _abi.CFG
FCFG = _abi.FCFG
STATUS = _abi.STATUS




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

