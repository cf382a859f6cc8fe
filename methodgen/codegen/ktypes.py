"""The kernel types of the compiled backend as plain data.

:mod:`methodgen.codegen.llvmkernels` derives the LLVM types of a kernel from its signature.
They are written in a small type vocabulary -- ``float64``, ``int64``, ``none``/``void``,
C-contiguous ``float64[::1]``, ``float64[:, ::1]`` … and signatures
``void(float64[::1], float64)`` (numba's spellings, which the kernels were first written in)
-- with the attributes the translator reads (``Array.ndim``, ``.dtype``, ``.layout``;
``Signature.return_type``, ``.args``).

This module imports the standard library only.
"""

from __future__ import annotations

__all__ = ["Scalar", "Array", "Signature", "float64", "int64", "boolean", "none", "void", "plain"]


class Signature:
    """``return_type(*args)``: a kernel's signature."""

    __slots__ = ("return_type", "args")

    def __init__(self, return_type, args):
        self.return_type = return_type
        self.args = tuple(args)

    def __eq__(self, other):
        return isinstance(other, Signature) and (self.return_type, self.args) == (other.return_type, other.args)

    def __hash__(self):
        return hash((self.return_type, self.args))

    def __repr__(self):
        return f"{self.return_type}({', '.join(map(str, self.args))})"

    __str__ = __repr__


class Scalar:
    """A scalar type by numba's name; calling it makes a signature with it as return type,
    indexing it with slices an :class:`Array` of it (``float64[:, ::1]``: 2-D, C order)."""

    __slots__ = ("name",)

    def __init__(self, name):
        self.name = name

    def __eq__(self, other):
        return isinstance(other, Scalar) and other.name == self.name

    def __hash__(self):
        return hash(("scalar", self.name))

    def __repr__(self):
        return self.name

    __str__ = __repr__

    def __call__(self, *args):
        return Signature(self, args)

    def __getitem__(self, index):
        index = index if isinstance(index, tuple) else (index,)
        if not all(isinstance(s, slice) and s.start is None and s.stop is None for s in index):
            raise TypeError(f"array types are written with slices only, got {index!r}")
        last = index[-1].step
        layout = "C" if last == 1 and all(s.step is None for s in index[:-1]) else "A"
        return Array(self, len(index), layout)


class Array:
    """An array type: ``dtype``, ``ndim`` and ``layout`` ("C" contiguous, "A" any)."""

    __slots__ = ("dtype", "ndim", "layout")

    def __init__(self, dtype, ndim, layout):
        self.dtype, self.ndim, self.layout = dtype, int(ndim), layout

    def __eq__(self, other):
        return isinstance(other, Array) and (self.dtype, self.ndim, self.layout) == (other.dtype, other.ndim,
                                                                                      other.layout)

    def __hash__(self):
        return hash(("array", self.dtype, self.ndim, self.layout))

    def __repr__(self):
        return f"array({self.dtype}, {self.ndim}d, {self.layout})"

    __str__ = __repr__


float64 = Scalar("float64")
int64 = Scalar("int64")
boolean = Scalar("boolean")
none = Scalar("none")
void = none


def plain(sig) -> Signature:
    """``sig``, checked to be a :class:`Signature` of this module's types."""
    if not isinstance(sig, Signature) or not all(isinstance(t, (Scalar, Array)) for t in (sig.return_type, *sig.args)):
        raise TypeError(f"not a kernel signature of methodgen.codegen.ktypes: {sig!r}")
    return sig
