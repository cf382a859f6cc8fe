"""Straight-line kernels compiled to machine code through LLVM IR (llvmlite), not numba.

numba spends seconds typing and lowering a kernel of a few hundred straight-line
statements (the outer solar system's energy-momentum Newton matrix: 3.4 s of a 9.5 s
first use; most of it is numba's type inference trying overloads per operation, not
LLVM).  The kernels of a numba module are straight-line float arithmetic on arrays
whose shape is known, so this module writes their LLVM IR directly from the kernel's
Python source -- as heyoka does from its expression graph -- and compiles it with LLVM
in milliseconds.  The result is a :class:`methodgen.nbruntime.KernelHandle` (numba's
wrapper-address protocol) with the signature of numba's C-ABI wrapper for the same
kernel type, so the shared runtime calls it exactly as it calls a numba kernel.

Same arithmetic, same bits: every operation is the one numba emits for the same source
without fastmath (IEEE add, sub, mul, div and negation; ``x**n`` for a constant integer
n by repeated squaring from 1.0, then ``1.0/…`` for negative n, as
``numba.cpython.numbers.static_power_impl``; other powers through ``llvm.pow``;
``math.sqrt``, ``math.sin`` … through the same intrinsics or libm functions).  LLVM
optimises without fast-math flags, so it does not reassociate.

Only what this module knows is translated: assignments to names, stores to array
elements at constant indices, ``return``, the arithmetic above, the math functions in
:data:`_UNARY` / :data:`_BINARY`, ``abs``.  Anything else (loops, branches, helper
calls, stack buffers) raises :class:`Unsupported`, and :func:`kernel` then compiles the
kernel with numba as before.  ``METHODGEN_KERNELS=numba`` forces numba for every kernel
(the control the tests use).

The kernels' source is the generated module's own text (``inspect.getsource``), parsed
with :mod:`ast` -- generated code, never user text.
"""

from __future__ import annotations

import ast
import ctypes
import ctypes.util
import inspect
import os
import textwrap

import llvmlite.binding as llvm
from llvmlite import ir
from numba import types as _t

from . import nbruntime as _rt

__all__ = ["kernel", "compile_kernel", "Unsupported", "LLVMKernel", "enabled"]


class Unsupported(Exception):
    """The kernel's source uses something this translator does not know."""


def enabled() -> bool:
    """Whether straight-line kernels take this route (``METHODGEN_KERNELS`` is not ``numba``)."""
    return os.environ.get("METHODGEN_KERNELS", "llvm").strip().lower() != "numba"


# --- LLVM set-up (once per process) ---------------------------------------------------

_DBL = ir.DoubleType()
_I64 = ir.IntType(64)
_PTR = ir.PointerType(ir.IntType(8))
_DPTR = ir.PointerType(_DBL)
_STATE: dict = {}


def _target_machine():
    """A new target machine for the host (the pass builder's; the engine owns its own)."""
    if "triple" not in _STATE:
        llvm.initialize_native_target()
        llvm.initialize_native_asmprinter()
        libm = ctypes.util.find_library("m")
        if libm:
            llvm.load_library_permanently(libm)   # tan, asin, … resolved at link time
        _STATE["triple"] = llvm.get_process_triple()
        _STATE["cpu"] = llvm.get_host_cpu_name()
        _STATE["features"] = llvm.get_host_cpu_features().flatten()
    target = llvm.Target.from_triple(_STATE["triple"])
    return target.create_target_machine(cpu=_STATE["cpu"], features=_STATE["features"], opt=2,
                                        codemodel="jitdefault")


def _engine():
    """The process's one execution engine: every kernel's module is added to it and lives
    as long as the process (an engine owns its target machine and modules; freeing it under
    a kernel still in use would free that kernel's code)."""
    eng = _STATE.get("engine")
    if eng is None:
        tm = _target_machine()
        eng = _STATE["engine"] = llvm.create_mcjit_compiler(llvm.parse_assembly(""), tm)
        _STATE["count"] = 0
    return eng


def _array_type(ndim: int) -> ir.LiteralStructType:
    # numba's value type of array(float64, ndim, 'C'): meminfo, parent, nitems, itemsize,
    # data, shape, strides (passed by value to its C-ABI wrappers)
    return ir.LiteralStructType([_PTR, _PTR, _I64, _I64, _DPTR, ir.ArrayType(_I64, ndim),
                                 ir.ArrayType(_I64, ndim)])


def _llvm_type(nbtype):
    if isinstance(nbtype, _t.Array):
        if nbtype.dtype != _t.float64 or nbtype.layout != "C":
            raise Unsupported(f"array argument {nbtype}")
        return _array_type(nbtype.ndim)
    if nbtype == _t.float64:
        return _DBL
    if nbtype == _t.int64:
        return _I64
    raise Unsupported(f"argument type {nbtype}")


# --- translation ----------------------------------------------------------------------

#: math functions of one argument: LLVM intrinsic (as numba's mathimpl) or libm symbol
_UNARY = {"sqrt": ("intr", "llvm.sqrt"), "fabs": ("intr", "llvm.fabs"), "exp": ("intr", "llvm.exp"),
          "log": ("intr", "llvm.log"), "log10": ("intr", "llvm.log10"), "sin": ("intr", "llvm.sin"),
          "cos": ("intr", "llvm.cos"), "tan": ("extern", "tan"), "asin": ("extern", "asin"),
          "acos": ("extern", "acos"), "atan": ("extern", "atan"), "sinh": ("extern", "sinh"),
          "cosh": ("extern", "cosh"), "tanh": ("extern", "tanh"), "asinh": ("extern", "asinh"),
          "acosh": ("extern", "acosh"), "atanh": ("extern", "atanh"), "log1p": ("extern", "log1p"),
          "expm1": ("extern", "expm1"), "erf": ("extern", "erf"), "erfc": ("extern", "erfc")}
#: math functions of two arguments
_BINARY = {"atan2": ("extern", "atan2"), "copysign": ("intr", "llvm.copysign")}


class _Translator:
    """One kernel function (an ``ast.FunctionDef``) into an LLVM function of ``module``."""

    def __init__(self, module: ir.Module, fdef: ast.FunctionDef, sig, name: str, globals_: dict):
        self.module = module
        argnames = [a.arg for a in fdef.args.args]
        if len(argnames) != len(sig.args):
            raise Unsupported("argument count differs from the signature")
        self.void = sig.return_type == _t.none
        if not self.void and sig.return_type != _t.float64:
            raise Unsupported(f"return type {sig.return_type}")
        fnty = ir.FunctionType(_PTR if self.void else _DBL, [_llvm_type(t) for t in sig.args])
        self.fn = ir.Function(module, fnty, name=name)
        self.values: dict = {}          # name -> double (or i64 loop index) value
        self.arrays: dict = {}          # name -> (data pointer, [extent values]) of a float view
        self.tables: dict = {}          # name -> (LLVM global, shape) of a constant int table
        self.globals = globals_
        self.entry = self.fn.append_basic_block("entry")
        self.builder = ir.IRBuilder(self.entry)
        for a, t, v in zip(argnames, sig.args, self.fn.args):
            if isinstance(t, _t.Array):
                data = self.builder.extract_value(v, 4)
                shape = [self.builder.extract_value(v, (5, i)) for i in range(t.ndim)]
                self.arrays[a] = (data, shape)
            else:
                self.values[a] = v
        self.body = fdef.body
        self.returned = False
        self.loop_vars: dict = {}       # loop index name -> i64 value
        self.loop_defs = None           # names assigned in the innermost loop body
        self.consts: dict = {}          # name -> Python int (an unrolled loop's element, …)

    # statements
    def run(self):
        for st in self.body:
            if self.returned:
                raise Unsupported("statement after return")
            self.statement(st)
        if not self.returned:
            if not self.void:
                raise Unsupported("no return value")
            self.builder.ret(ir.Constant(_PTR, None))

    def statement(self, st):
        b = self.builder
        if isinstance(st, ast.Expr) and isinstance(st.value, ast.Constant):
            return                                   # a docstring or a bare constant
        if isinstance(st, ast.Pass):
            return
        if isinstance(st, ast.Assign) and len(st.targets) == 1:
            tgt = st.targets[0]
            if isinstance(tgt, ast.Name) and self.view(tgt.id, st.value):
                return
            if isinstance(tgt, ast.Subscript) and self.is_full_slice(tgt.slice):
                # X[:] = 0.0 / X[:, :] = 0.0 (an accumulator cleared)
                if not (isinstance(st.value, ast.Constant) and st.value.value == 0.0):
                    raise Unsupported("slice assignment of a non-zero")
                self.zero(tgt.value)
                return
            if isinstance(tgt, ast.Name):
                c = self.const_eval(st.value)
                if c is not None:                    # an integer known now (_k = _e >> 3)
                    if self.loop_defs is not None or tgt.id in self.values:
                        raise Unsupported(f"{tgt.id}: an integer assigned in a loop")
                    self.consts[tgt.id] = c
                    return
                self.consts.pop(tgt.id, None)
            val = self.expr(st.value)
            if isinstance(tgt, ast.Name):
                if tgt.id in self.arrays or tgt.id in self.loop_vars:
                    raise Unsupported(f"{tgt.id} rebound")
                if self.loop_defs is not None:
                    if tgt.id in self.values and tgt.id not in self.loop_defs:
                        raise Unsupported(f"{tgt.id}: a value carried across iterations")
                    self.loop_defs.add(tgt.id)
                self.values[tgt.id] = val
            elif isinstance(tgt, ast.Subscript):
                b.store(val, self.address(tgt))
            else:
                raise Unsupported("assignment target")
            return
        if isinstance(st, ast.For) and isinstance(st.iter, ast.Tuple):
            self.unrolled(st)
            return
        if isinstance(st, ast.For):
            self.loop(st)
            return
        if isinstance(st, ast.If):
            c = self.const_eval(st.test)
            if c is None:
                raise Unsupported("a branch on a run-time value")
            for s in (st.body if c else st.orelse):
                self.statement(s)
            return
        if isinstance(st, ast.AugAssign) and isinstance(st.target, ast.Subscript) and isinstance(st.op, ast.Add):
            addr = self.address(st.target)
            b.store(b.fadd(b.load(addr), self.expr(st.value)), addr)
            return
        if isinstance(st, ast.Return):
            if self.void:
                if st.value is not None:
                    raise Unsupported("a value returned from a void kernel")
                b.ret(ir.Constant(_PTR, None))
            else:
                b.ret(self.expr(st.value))
            self.returned = True
            return
        raise Unsupported(type(st).__name__)

    def address(self, sub: ast.Subscript):
        if not isinstance(sub.value, ast.Name) or sub.value.id not in self.arrays:
            raise Unsupported("subscript of a non-argument")
        data, shape = self.arrays[sub.value.id]
        idx = sub.slice
        parts = idx.elts if isinstance(idx, ast.Tuple) else [idx]
        if len(parts) != len(shape):
            raise Unsupported("index rank")
        ints = [self.int_expr(p) for p in parts]
        b = self.builder
        # C order: ((i0 * n1) + i1) * n2 + ...  (the extents are run-time values)
        flat = ints[0]
        for n, i in zip(shape[1:], ints[1:]):
            flat = b.add(b.mul(flat, n), i)
        return b.gep(data, [flat])

    _CONST_OPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
                  ast.RShift: lambda a, b: a >> b, ast.LShift: lambda a, b: a << b,
                  ast.BitAnd: lambda a, b: a & b, ast.BitOr: lambda a, b: a | b}

    def const_eval(self, node):
        """The Python int value of an integer expression known at translation time (constants
        and the elements of a loop over a constant tuple), else None."""
        if isinstance(node, ast.Constant) and type(node.value) is int:
            return node.value
        if isinstance(node, ast.Name):
            return self.consts.get(node.id)
        if isinstance(node, ast.BinOp) and type(node.op) in self._CONST_OPS:
            a, b = self.const_eval(node.left), self.const_eval(node.right)
            return None if a is None or b is None else self._CONST_OPS[type(node.op)](a, b)
        if (isinstance(node, ast.Compare) and len(node.ops) == 1 and len(node.comparators) == 1
                and type(node.ops[0]) in (ast.Eq, ast.NotEq)):
            a, b = self.const_eval(node.left), self.const_eval(node.comparators[0])
            if a is None or b is None:
                return None
            return int((a == b) if isinstance(node.ops[0], ast.Eq) else (a != b))
        return None

    def unrolled(self, st: ast.For):
        """``for e in (c0, c1, …)``: the body once per constant, in order (a sum kept in its
        printed order; its branches on e are decided here)."""
        if st.orelse or not isinstance(st.target, ast.Name):
            raise Unsupported("loop")
        items = [self.const_eval(e) for e in st.iter.elts]
        if any(v is None for v in items) or self.loop_defs is not None:
            raise Unsupported("loop over a tuple")
        name = st.target.id
        for v in items:
            self.consts[name] = v
            for s in st.body:
                self.statement(s)
        self.consts.pop(name, None)

    def int_expr(self, node):
        """An index: an integer constant, a loop index, a sum or product of those, or an
        entry of one of the module's constant integer tables."""
        b = self.builder
        if isinstance(node, ast.Constant) and type(node.value) is int:
            return ir.Constant(_I64, node.value)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return b.sub(ir.Constant(_I64, 0), self.int_expr(node.operand))
        if isinstance(node, ast.Name) and node.id in self.loop_vars:
            return self.loop_vars[node.id]
        c = self.const_eval(node)
        if c is not None:
            return ir.Constant(_I64, c)
        if isinstance(node, ast.BinOp) and type(node.op) in (ast.Add, ast.Sub, ast.Mult):
            x, y = self.int_expr(node.left), self.int_expr(node.right)
            return {ast.Add: b.add, ast.Sub: b.sub, ast.Mult: b.mul}[type(node.op)](x, y)
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name):
            gv, shape = self.table(node.value.id)
            idx = node.slice
            parts = idx.elts if isinstance(idx, ast.Tuple) else [idx]
            if len(parts) != len(shape):
                raise Unsupported("table index rank")
            flat = self.int_expr(parts[0])
            for n, p in zip(shape[1:], parts[1:]):
                flat = b.add(b.mul(flat, ir.Constant(_I64, n)), self.int_expr(p))
            return b.load(b.gep(gv, [ir.Constant(_I64, 0), flat]))
        raise Unsupported("index expression")

    def table(self, name):
        """A module-level integer array (the loops' index tables) as an LLVM constant."""
        got = self.tables.get(name)
        if got is None:
            import numpy
            arr = self.globals.get(name)
            if not isinstance(arr, numpy.ndarray) or arr.dtype.kind not in "iu" or arr.size == 0:
                raise Unsupported(f"{name} is not an integer table")
            flat = [int(v) for v in arr.ravel()]
            ty = ir.ArrayType(_I64, len(flat))
            gv = ir.GlobalVariable(self.module, ty, name=f"{self.fn.name}.{name}")
            gv.global_constant = True
            gv.linkage = "private"
            gv.initializer = ir.Constant(ty, flat)
            got = self.tables[name] = (gv, arr.shape)
        return got

    def view(self, name, value) -> bool:
        """``name = X`` or ``name = X[a:b]`` (constant bounds) of an array argument: a view."""
        if isinstance(value, ast.Name) and value.id in self.arrays:
            self.arrays[name] = self.arrays[value.id]
            return True
        if (isinstance(value, ast.Subscript) and isinstance(value.value, ast.Name)
                and value.value.id in self.arrays and isinstance(value.slice, ast.Slice)):
            data, shape = self.arrays[value.value.id]
            sl = value.slice
            if len(shape) != 1 or sl.step is not None or sl.lower is None or sl.upper is None:
                raise Unsupported("slice")
            lo, hi = self.const_int(sl.lower), self.const_int(sl.upper)
            self.arrays[name] = (self.builder.gep(data, [ir.Constant(_I64, lo)]), [ir.Constant(_I64, hi - lo)])
            return True
        if (isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute)
                and isinstance(value.func.value, ast.Name) and value.func.value.id == "numpy"
                and value.func.attr == "zeros" and len(value.args) == 1 and not value.keywords):
            dims = value.args[0].elts if isinstance(value.args[0], ast.Tuple) else [value.args[0]]
            shape = [self.const_int(d) for d in dims]
            total = 1
            for n in shape:
                total *= n
            # a work array on the stack (alloca in the entry block), cleared
            with self.builder.goto_block(self.entry):
                self.builder.position_at_start(self.entry)
                buf = self.builder.alloca(_DBL, size=ir.Constant(_I64, max(total, 1)))
            self.arrays[name] = (buf, [ir.Constant(_I64, n) for n in shape])
            self.zero(ast.Name(id=name))
            return True
        return False

    @staticmethod
    def is_full_slice(idx) -> bool:
        parts = idx.elts if isinstance(idx, ast.Tuple) else [idx]
        return all(isinstance(p, ast.Slice) and p.lower is None and p.upper is None and p.step is None
                   for p in parts)

    def zero(self, node):
        if not isinstance(node, ast.Name) or node.id not in self.arrays:
            raise Unsupported("clearing a non-array")
        b = self.builder
        data, shape = self.arrays[node.id]
        n = shape[0]
        for e in shape[1:]:
            n = b.mul(n, e)
        fn = self.module.declare_intrinsic("llvm.memset", [_PTR, _I64])
        b.call(fn, [b.bitcast(data, _PTR), ir.Constant(ir.IntType(8), 0), b.mul(n, ir.Constant(_I64, 8)),
                    ir.Constant(ir.IntType(1), 0)])

    def loop(self, st: ast.For):
        """``for i in range(a, b)`` (constant bounds) over straight-line statements."""
        it = st.iter
        if (st.orelse or not isinstance(st.target, ast.Name) or not isinstance(it, ast.Call)
                or not isinstance(it.func, ast.Name) or it.func.id != "range" or it.keywords
                or not 1 <= len(it.args) <= 2):
            raise Unsupported("loop")
        bounds = [self.const_int(a) for a in it.args]
        lo, hi = (0, bounds[0]) if len(bounds) == 1 else bounds
        if hi <= lo:
            return
        name = st.target.id
        if name in self.values or name in self.loop_vars or name in self.consts:
            raise Unsupported("loop index reused")
        b = self.builder
        pre = b.block
        body = self.fn.append_basic_block(f"loop.{name}")
        after = self.fn.append_basic_block(f"after.{name}")
        b.branch(body)
        b.position_at_end(body)
        phi = b.phi(_I64, name=name)
        phi.add_incoming(ir.Constant(_I64, lo), pre)
        saved = dict(self.values)
        outer_defs = self.loop_defs
        self.loop_vars[name] = phi
        self.loop_defs = set()
        for s in st.body:
            self.statement(s)
        nxt = b.add(phi, ir.Constant(_I64, 1))
        phi.add_incoming(nxt, b.block)
        b.cbranch(b.icmp_signed("<", nxt, ir.Constant(_I64, hi)), body, after)
        b.position_at_end(after)
        # the body's names are its own: after the loop only what was defined before
        self.values = saved
        del self.loop_vars[name]
        self.loop_defs = outer_defs

    @staticmethod
    def const_int(node):
        neg = False
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            neg, node = True, node.operand
        if isinstance(node, ast.Constant) and type(node.value) is int:
            return -node.value if neg else node.value
        raise Unsupported("non-constant index")

    # expressions
    def expr(self, node):
        b = self.builder
        if isinstance(node, ast.Constant):
            if type(node.value) in (int, float):
                return ir.Constant(_DBL, float(node.value))
            raise Unsupported(f"constant {node.value!r}")
        if isinstance(node, ast.Name):
            v = self.values.get(node.id)
            if v is None:
                raise Unsupported(f"name {node.id}")
            return v
        if isinstance(node, ast.Subscript):
            return b.load(self.address(node))
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.USub):
                return b.fneg(self.expr(node.operand))
            if isinstance(node.op, ast.UAdd):
                return self.expr(node.operand)
            raise Unsupported("unary operator")
        if isinstance(node, ast.BinOp):
            if isinstance(node.op, ast.Pow):
                return self.power(node)
            x, y = self.expr(node.left), self.expr(node.right)
            op = {ast.Add: b.fadd, ast.Sub: b.fsub, ast.Mult: b.fmul, ast.Div: b.fdiv}.get(type(node.op))
            if op is None:
                raise Unsupported("binary operator")
            return op(x, y)
        if isinstance(node, ast.Call):
            return self.call(node)
        raise Unsupported(type(node).__name__)

    def power(self, node):
        b = self.builder
        try:
            n = self.const_int(node.right)
        except Unsupported:
            n = None
        x = self.expr(node.left)
        if n is None or abs(n) > 0x10000:
            fn = self.module.declare_intrinsic("llvm.pow", [_DBL])
            return b.call(fn, [x, self.expr(node.right)])
        # numba's static_power_impl: exponentiation by squaring, unrolled, from 1.0
        res, val, e = ir.Constant(_DBL, 1.0), x, abs(n)
        while e:
            if e & 1:
                res = b.fmul(res, val)
            e >>= 1
            val = b.fmul(val, val)
        return b.fdiv(ir.Constant(_DBL, 1.0), res) if n < 0 else res

    def call(self, node):
        if node.keywords:
            raise Unsupported("keyword arguments")
        f = node.func
        if isinstance(f, ast.Name) and f.id == "abs" and len(node.args) == 1:
            name, table = "fabs", _UNARY
        elif (isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id == "math"
              and (f.attr in _UNARY or f.attr in _BINARY)):
            name, table = f.attr, (_UNARY if f.attr in _UNARY else _BINARY)
        else:
            raise Unsupported("call")
        args = [self.expr(a) for a in node.args]
        if len(args) != (1 if table is _UNARY else 2):
            raise Unsupported("argument count of a math function")
        kind, sym = table[name]
        if kind == "intr":
            fn = self.module.declare_intrinsic(sym, [_DBL], ir.FunctionType(_DBL, [_DBL] * len(args)))
        else:
            fn = self.module.globals.get(sym)
            if fn is None:
                fn = ir.Function(self.module, ir.FunctionType(_DBL, [_DBL] * len(args)), name=sym)
        return self.builder.call(fn, args)


def _function_def(py_func) -> ast.FunctionDef:
    try:
        src = textwrap.dedent(inspect.getsource(py_func))
    except (OSError, TypeError) as exc:
        raise Unsupported(f"no source ({exc})") from None
    tree = ast.parse(src)
    if len(tree.body) != 1 or not isinstance(tree.body[0], ast.FunctionDef):
        raise Unsupported("not one function definition")
    return tree.body[0]


def compile_kernel(py_func, sig) -> "LLVMKernel":
    """``py_func`` (a straight-line kernel of a generated module) compiled through LLVM IR
    for the numba signature ``sig``.  Raises :class:`Unsupported` when its source uses
    anything the translator does not know."""
    engine = _engine()
    fdef = _function_def(py_func)
    module = ir.Module(name=py_func.__name__)
    module.triple = _STATE["triple"]
    _STATE["count"] += 1
    name = f"mg{_STATE['count']}_{py_func.__name__}"   # unique in the engine
    tr = _Translator(module, fdef, sig, name, getattr(py_func, "__globals__", {}))
    tr.run()
    mod = llvm.parse_assembly(str(module))
    mod.verify()
    tm = _target_machine()
    pto = llvm.create_pipeline_tuning_options(speed_level=2)
    pb = llvm.create_pass_builder(tm, pto)
    pb.getModulePassManager().run(mod, pb)
    engine.add_module(mod)
    engine.finalize_object()
    addr = engine.get_function_address(name)
    if not addr:
        raise Unsupported("no address after compilation")
    return LLVMKernel(py_func, sig, addr, engine)


class LLVMKernel(_rt.KernelHandle):
    """A kernel compiled by :func:`compile_kernel`: a first-class function for the shared
    runtime (numba's wrapper-address protocol), callable from Python too (through numba,
    compiled on the first such call: tests and diagnostics; the runtime never does)."""

    __slots__ = ("py_func", "engine", "_nb")

    def __init__(self, py_func, sig, addr, engine):
        self.kernel = None
        self._sig = sig
        self._addr = addr
        self._type = _t.FunctionType(sig)
        self.py_func = py_func
        self.engine = engine          # owns the machine code
        self._nb = None

    def __call__(self, *args):
        if self._nb is None:
            import numba
            self._nb = numba.njit(self._sig, cache=True, error_model="numpy")(self.py_func)
        return self._nb(*args)


def kernel(sig):
    """Decorator: the kernel compiled through LLVM IR when it is straight-line code this
    module translates (and the route is :func:`enabled`), else with numba for ``sig`` (cached
    on disk) as every kernel was before."""
    import numba

    def deco(py_func):
        if enabled():
            try:
                return compile_kernel(py_func, sig)
            except Unsupported:
                pass
        return numba.njit(sig, cache=True, error_model="numpy")(py_func)

    return deco
