"""numba's side of the compiled backend: what numba-compiled code of a generated module needs.

The integration loop, the lock-step loop and the rows of ``residual()`` / ``jacobian()`` are
:mod:`methodgen.runtime.stepper`, compiled with a module's kernels inlined (:mod:`methodgen.runtime.fused`, no
numba).  numba compiles only a kernel the LLVM translator refuses (or every kernel under
``METHODGEN_KERNELS=numba``); then the stepper runs as Python with it.  For such kernels this
module provides

* :func:`stack_buffer`: scratch arrays on the stack of numba-compiled kernels;
* the kernels' numba signatures (:data:`KERNEL_TYPES`, from :mod:`methodgen.codegen.abi`);
* a kernel compiled through LLVM IR as a numba first-class function (numba's public
  wrapper-address protocol), should numba-compiled code call one.

The cache is numba's: ``__pycache__`` next to this file, or ``NUMBA_CACHE_DIR``, or numba's
per-user fallback when the package directory is not writable.  A cached function is loaded only
when its stamp -- the SHA-256 of the runtime's files (:data:`methodgen.runtime.nbabi.SOURCE_SHA256`,
:func:`methodgen.codegen.nbcache.install_stamp_guard`) -- matches, so an edited file is recompiled,
never loaded stale, whatever its mtime and size.

This module imports numpy, numba and llvmlite only (no SymPy), and only numba's public API.
"""

from __future__ import annotations

import os

from llvmlite import ir as _llir
from numba import types as _t
from numba.core.errors import RequireLiteralValue
from numba.core.types import WrapperAddressProtocol as _WrapperAddressProtocol
from numba.extending import intrinsic as _intrinsic
from numba.extending import typeof_impl as _typeof_impl

from ..codegen import ktypes as _kt
from ..codegen import abi as _abi
from ..codegen.llvmkernels import LLVMKernel
from ..codegen.nbcache import flush_deferred as _flush_deferred
from ..codegen.nbcache import install_stamp_guard as _install_stamp_guard

__all__ = ["KERNEL_TYPES", "CFG", "FCFG", "STATUS", "SOURCE_SHA256", "stack_buffer"]

# --- cache stamp ---------------------------------------------------------------------

#: SHA-256 over this file, nbabi.py and abi.py: the stamp of numba's cached machine code of
#: generated modules (:data:`methodgen.runtime.nbabi.SOURCE_SHA256`).
SOURCE_SHA256 = _abi.RUNTIME_SHA256

_install_stamp_guard(os.path.abspath(__file__), SOURCE_SHA256)
_flush_deferred()   # numba is imported now: the guards generated modules deferred

# --- kernel types ------------------------------------------------------------------------

#: numba signatures of the kernels (methodgen.codegen.abi.KERNEL_TYPES as numba's types).
KERNEL_TYPES = {k: _kt.to_numba(v) for k, v in _abi.KERNEL_TYPES.items()}

# A kernel compiled through LLVM IR (methodgen.codegen.llvmkernels) is a first-class function as it
# is: its address is numba's C-ABI wrapper's, resolved once.  Registered here, where numba is
# imported, so that llvmkernels stays free of numba.
_WrapperAddressProtocol.register(LLVMKernel)


@_typeof_impl.register(LLVMKernel)
def _typeof_llvm_kernel(val, c):
    return val.numba_type()


@_intrinsic
def stack_buffer(typingctx, size):
    """A pointer to ``size`` float64 on the stack of the compiled function that calls it
    (``size`` a literal int); view it as an array with ``numba.carray(ptr, shape)``.

    Work arrays of a kernel without a heap allocation per call (``numpy.empty`` costs about
    20 ns, more than a small stage kernel's arithmetic).  The buffer lives in the caller's
    entry block, so it is valid until the caller returns, and is not initialised.
    """
    if not isinstance(size, _t.IntegerLiteral):
        raise RequireLiteralValue(size)
    n = size.literal_value

    def codegen(context, builder, signature, args):
        # in the entry block (once per call of the function, not per loop iteration)
        with builder.goto_entry_block():
            buf = builder.alloca(_llir.ArrayType(_llir.DoubleType(), n))
        return builder.bitcast(buf, _llir.DoubleType().as_pointer())

    return _t.CPointer(_t.float64)(size), codegen


# --- configuration -------------------------------------------------------------------------

# The contract (methodgen.codegen.abi, re-exported by methodgen.runtime.nbabi), for the generated modules' _rt.
CFG = _abi.CFG
FCFG = _abi.FCFG
STATUS = _abi.STATUS
