"""A compiled module's kernels and methodgen's runtime compiled to machine code through LLVM IR (llvmlite).

The kernels of a compiled module are float arithmetic on arrays of known shape, so this module
writes their LLVM IR directly from the kernel's tree (:mod:`methodgen.codegen.kir`, as heyoka
does from its expression graph), and from the hand-written runtime's Python source (the
stepper, the Wisdom–Holman flows, the lattice and particle step loops), and compiles it with
LLVM in milliseconds.  The result is an :class:`LLVMKernel`: machine code for the kernel type's
signature (:mod:`methodgen.codegen.ktypes`: arrays passed as pointers to a fixed structure,
:func:`packed_structs`), which the fused loop (:mod:`methodgen.runtime.fused`) inlines and which
Python calls through a C entry (ctypes).

What is translated: assignments (scalar names live in stack slots that LLVM promotes to
registers, so a value may be carried across iterations or branches), stores and ``+=``,
``-=`` … to array elements, ``for`` over ``range`` with bounds known at translation time
(a loop in the machine code) and over constant tuples (unrolled: a sum kept in its printed
order), ``while``, ``break``, ``continue``, ``if``/``else`` on run-time or translation-time
conditions, ``return``; views of
the arguments (``X[a:b]``, rows ``A[i]``), work arrays on the stack (``stack_array(shape)``)
and ``numpy.zeros`` / ``numpy.empty`` of shapes known now; the module's constant
tables (numpy arrays of indices or weights) and integer constants; calls of the module's
scalar helpers (translated once, inlined by LLVM) and of its array kernels (inlined here);
the arithmetic, comparisons and the math functions below.  For a runtime written in this
subset by hand (the Wisdom–Holman one, :mod:`methodgen.runtime.kepler_flow`) also: functions that
return tuples or integers, anywhere in their body (inlined: every ``return`` continues after
the call), unpacked into names, elements or array views (``a, b = f(…)``, ``x, y = y, x``,
``q, g = work[0], work[1]``); chained assignment; ``range`` over run-time lengths
(``x.shape[0]``, a count argument) with a constant step (``range(n - 1, -1, -1)``), the
index left as Python leaves it; ``%`` and ``//`` of integers with Python's signs; the truth
value of a number; ``math.isfinite``, ``math.floor``, numpy's ``inf``/``nan``; rows ``A[i]``
of n-D views; and a kernel returning an int64 (a C entry returns its value).  Anything else
(``for … else``, ``%`` of floats, an unknown function) raises :class:`Unsupported`, naming
the function: there is no other compiler to hand it to (the numpy backend runs any module).

The arithmetic is IEEE without fast-math (add, sub, mul, div and negation; ``x**n`` for a
constant integer n by repeated squaring from 1.0, then ``1.0/…`` for negative n; other powers
through ``llvm.pow``; ordered comparisons but ``!=``; ``max``/``min`` left to right;
``math.sqrt``, ``math.sin`` … through LLVM intrinsics or libm functions).  LLVM optimises
without fast-math flags, so it does not reassociate.  ``x**-n`` at x = 0 is inf (the modules'
error model).

What is translated is an :mod:`ast` definition: for a generated kernel, built from its kernel
IR (:func:`attach`: the tree the module holds as a table; a generated module's text is never
parsed); for the hand-written runtime, its file's executed text (:mod:`methodgen.codegen.kernelsource`),
parsed with :mod:`ast`.  Never user text.
"""

from __future__ import annotations

import ast
import ctypes
import ctypes.util
import math
import threading

from . import kir

import llvmlite.binding as llvm
import numpy as np
from llvmlite import ir
from . import kernelsource as _ks
from . import ktypes as _t
from . import llvmcache as _objcache

__all__ = ["kernel", "compile_kernel", "assembly", "Unsupported", "LLVMKernel", "packed_structs"]


class Unsupported(Exception):
    """The kernel's source uses something this translator does not know (the message names the
    function and the construct)."""


# --- LLVM set-up (once per process) ---------------------------------------------------

_DBL = ir.DoubleType()
_I64 = ir.IntType(64)
_PTR = ir.PointerType(ir.IntType(8))
_DPTR = ir.PointerType(_DBL)
_STATE: dict = {}
_LOCK = threading.RLock()


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


class _Function:
    """The state of one LLVM function being written: its builder and entry block, and the
    slots of its scalar names (allocas, which LLVM's mem2reg turns into registers)."""

    def __init__(self, fn):
        self.fn = fn
        self.entry = fn.append_basic_block("entry")
        self.builder = ir.IRBuilder(self.entry)
        self.alloca_at = None           # the last alloca in the entry block

    def alloca(self, ty, size=None, name=""):
        """A stack slot in the entry block (after the slots made before it, so that every
        slot dominates its uses, and LLVM's mem2reg promotes the scalar ones)."""
        b = self.builder
        with b.goto_block(self.entry):
            if self.alloca_at is None:
                b.position_at_start(self.entry)
            else:
                b.position_after(self.alloca_at)
            a = b.alloca(ty, size=size, name=name)
        self.alloca_at = a
        return a


class _Scope:
    """Names visible in the body being translated (a kernel, or a kernel inlined into it)."""

    def __init__(self, func: _Function, globals_: dict):
        self.func = func
        self.globals = globals_
        self.slots: dict = {}           # scalar name -> (kind "f" | "i", alloca)
        self.arrays: dict = {}          # name -> (data pointer, [extent values]) of a float view
        self.consts: dict = {}          # name -> int known at translation time
        self.fconsts: dict = {}         # name -> float known at translation time (unrolled tuple)


_CMP = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==", ast.NotEq: "!="}


class _Translator:
    """One kernel (an ``ast.FunctionDef``) into an LLVM function of ``module``: straight-line
    arithmetic, loops over ``range`` with constant bounds (and over constant tuples, unrolled),
    branches, scalar variables of any flow (stack slots), array views, the module's constant
    tables, and calls of the module's helpers (scalar ones as functions, array kernels inlined)."""

    _CONST_OPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
                  ast.RShift: lambda a, b: a >> b, ast.LShift: lambda a, b: a << b,
                  ast.BitAnd: lambda a, b: a & b, ast.BitOr: lambda a, b: a | b,
                  ast.FloorDiv: lambda a, b: a // b, ast.Mod: lambda a, b: a % b}

    def __init__(self, module: ir.Module, fdef: ast.FunctionDef, sig, name: str, globals_: dict):
        self.module = module
        self.globals = globals_
        self.tables: dict = {}
        self.helpers: dict = {}
        self.inline_depth = 0
        self.loops: list = []           # (continue target, break target) of the enclosing loops
        self.frames: list = []          # the inlined calls being translated: their return frames
        argnames = [a.arg for a in fdef.args.args]
        if len(argnames) != len(sig.args):
            raise Unsupported("argument count differs from the signature")
        void = sig.return_type == _t.none
        if not void and sig.return_type not in (_t.float64, _t.int64):
            raise Unsupported(f"return type {sig.return_type}")
        integer = sig.return_type == _t.int64
        fnty = ir.FunctionType(_PTR if void else _I64 if integer else _DBL, [_llvm_type(t) for t in sig.args])
        fn = ir.Function(module, fnty, name=name)
        self.name = name
        self.ret = "void" if void else "i" if integer else "f"
        self.f = _Function(fn)
        self.scope = _Scope(self.f, globals_)
        self.loop_assigned = self._assigned_in_loops(fdef.body)
        for a, t, v in zip(argnames, sig.args, fn.args):
            if isinstance(t, _t.Array):
                b = self.b
                data = b.extract_value(v, 4)
                shape = [b.extract_value(v, (5, i)) for i in range(t.ndim)]
                self.scope.arrays[a] = (data, shape)
            elif t == _t.float64:
                self.store_name(a, v, "f")
            else:
                self.store_name(a, v, "i")
        self.body = fdef.body

    @property
    def b(self):
        return self.f.builder

    @staticmethod
    def _assigned_in_loops(body) -> set:
        """Names assigned anywhere inside a ``for … in range`` loop (never translation-time
        constants: their value changes from one iteration to the next)."""
        out = set()
        for node in ast.walk(ast.Module(body=list(body), type_ignores=[])):
            if isinstance(node, ast.While) or (isinstance(node, ast.For)
                                               and not isinstance(node.iter, (ast.Tuple, ast.Name))):
                out |= _Translator._assigned_names([node])
        return out

    @staticmethod
    def _assigned_names(stmts) -> set:
        """Names assigned anywhere in ``stmts``."""
        out = set()
        for node in ast.walk(ast.Module(body=list(stmts), type_ignores=[])):
            if isinstance(node, (ast.Assign, ast.AugAssign)):
                targets = list(node.targets if isinstance(node, ast.Assign) else [node.target])
                while targets:
                    t = targets.pop()
                    if isinstance(t, ast.Name):
                        out.add(t.id)
                    elif isinstance(t, (ast.Tuple, ast.List)):
                        targets.extend(t.elts)          # a, b = …: both names
            elif isinstance(node, ast.For) and isinstance(node.target, ast.Name):
                out.add(node.target.id)
        return out

    # --- names --------------------------------------------------------------------------
    def slot(self, name, kind):
        sc = self.scope
        got = sc.slots.get(name)
        if got is not None:
            if got[0] != kind:
                raise Unsupported(f"{name} holds both an integer and a float")
            return got[1]
        a = self.f.alloca(_DBL if kind == "f" else _I64, name=name)
        sc.slots[name] = (kind, a)
        return a

    def store_name(self, name, value, kind):
        sc = self.scope
        if name in sc.arrays:
            raise Unsupported(f"{name} rebound")
        sc.consts.pop(name, None)
        sc.fconsts.pop(name, None)
        self.b.store(value, self.slot(name, kind))

    # --- statements ---------------------------------------------------------------------
    def run(self):
        self.block(self.body)
        if not self.b.block.is_terminated:
            if self.ret != "void":
                raise Unsupported("no return value")
            self.b.ret(ir.Constant(_PTR, None))

    def block(self, stmts):
        for st in stmts:
            if self.b.block.is_terminated:
                return                        # after a return: not executed
            self.statement(st)

    def statement(self, st):
        b = self.b
        sc = self.scope
        if isinstance(st, ast.Expr) and isinstance(st.value, ast.Constant):
            return                                   # a docstring or a bare constant
        if isinstance(st, ast.Pass):
            return
        if isinstance(st, ast.Expr) and isinstance(st.value, ast.Call):
            self.call_values(st.value)                # its values, if any, unused
            return
        if isinstance(st, ast.Assign) and (len(st.targets) > 1 or isinstance(st.targets[0], (ast.Tuple, ast.List))):
            self.assign_many(st)
            return
        if isinstance(st, ast.Assign) and len(st.targets) == 1:
            tgt = st.targets[0]
            if isinstance(tgt, ast.Name) and self.view(tgt.id, st.value):
                return
            if isinstance(tgt, ast.Subscript) and self.is_full_slice(tgt.slice):
                if not (isinstance(st.value, ast.Constant) and st.value.value == 0.0):
                    raise Unsupported("slice assignment of a non-zero")
                self.zero(tgt.value)
                return
            if isinstance(tgt, ast.Name):
                c = self.const_eval(st.value)
                if (c is not None and tgt.id not in self.loop_assigned and self.inline_depth == 0
                        and tgt.id not in sc.slots):
                    sc.consts[tgt.id] = c
                    return
                kind, val = self.any_expr(st.value)
                self.store_name(tgt.id, val, kind)
                return
            if isinstance(tgt, ast.Subscript):
                b.store(self.expr(st.value), self.address(tgt))
                return
            raise Unsupported("assignment target")
        if isinstance(st, ast.AugAssign) and type(st.op) in (ast.Add, ast.Sub, ast.Mult, ast.Div):
            op = {ast.Add: b.fadd, ast.Sub: b.fsub, ast.Mult: b.fmul, ast.Div: b.fdiv}[type(st.op)]
            if isinstance(st.target, ast.Subscript):
                addr = self.address(st.target)
                b.store(op(b.load(addr), self.expr(st.value)), addr)
                return
            if isinstance(st.target, ast.Name) and st.target.id in sc.slots and sc.slots[st.target.id][0] == "f":
                a = sc.slots[st.target.id][1]
                b.store(op(b.load(a), self.expr(st.value)), a)
                return
            if (isinstance(st.target, ast.Name) and st.target.id in sc.slots and sc.slots[st.target.id][0] == "i"
                    and type(st.op) in (ast.Add, ast.Sub, ast.Mult)):
                a = sc.slots[st.target.id][1]
                iop = {ast.Add: b.add, ast.Sub: b.sub, ast.Mult: b.mul}[type(st.op)]
                b.store(iop(b.load(a), self.int_expr(st.value)), a)
                return
            raise Unsupported("augmented assignment")
        if isinstance(st, ast.For):
            if isinstance(st.iter, (ast.Tuple, ast.Name)):
                self.unrolled(st)
            else:
                self.loop(st)
            return
        if isinstance(st, ast.While):
            self.while_loop(st)
            return
        if isinstance(st, (ast.Break, ast.Continue)):
            if not self.loops:
                raise Unsupported(f"{type(st).__name__.lower()} outside a loop")
            cont, brk = self.loops[-1]
            b.branch(brk if isinstance(st, ast.Break) else cont)
            return
        if isinstance(st, ast.If):
            c = self.const_eval(st.test)
            if c is not None:
                self.block(st.body if c else st.orelse)
                return
            # a name folded to a constant and assigned in a branch lives in its slot from here
            # on, holding the constant on the paths that do not assign it
            for name in sorted(self._assigned_names(st.body + st.orelse)):
                if name in sc.consts:
                    b.store(ir.Constant(_I64, sc.consts.pop(name)), self.slot(name, "i"))
                elif name in sc.fconsts:
                    b.store(ir.Constant(_DBL, sc.fconsts.pop(name)), self.slot(name, "f"))
            cond = self.bool_expr(st.test)
            then = self.f.fn.append_basic_block("then")
            other = self.f.fn.append_basic_block("else")
            merge = self.f.fn.append_basic_block("endif")
            b.cbranch(cond, then, other)
            reached = False
            for blk, body in ((then, st.body), (other, st.orelse)):
                b.position_at_end(blk)
                self.block(body)
                if not b.block.is_terminated:
                    b.branch(merge)
                    reached = True
            b.position_at_end(merge)
            if not reached:                  # both branches returned
                b.unreachable()
            return
        if isinstance(st, ast.Return):
            if self.frames:
                self.inline_return(st)
                return
            if self.ret == "void":
                if st.value is not None:
                    raise Unsupported("a value returned from a void kernel")
                b.ret(ir.Constant(_PTR, None))
            elif self.ret == "i":
                kind, v = self.any_expr(st.value)
                if kind != "i":
                    raise Unsupported("a float returned from an integer kernel")
                b.ret(v)
            else:
                b.ret(self.expr(st.value))
            return
        raise Unsupported(type(st).__name__)

    def assign_many(self, st: ast.Assign):
        """``a, b = x, y`` (every value computed before any is stored, as Python), ``a, b = f(…)``
        (a function returning a tuple, inlined), and ``a = b = x`` (x computed once).  Targets
        are names (an integer or a float; an array view for ``q, g = work[0], work[1]``) or
        array elements."""
        if len(st.targets) == 1:
            targets = st.targets[0].elts
            value = st.value
            if isinstance(value, (ast.Tuple, ast.List)):
                if len(value.elts) != len(targets):
                    raise Unsupported("unpacking of another number of values")
                vals = []
                for t, e in zip(targets, value.elts):
                    arr = self.array_arg(e) if isinstance(t, ast.Name) else None
                    vals.append(("a", arr) if arr is not None else self.any_expr(e))
            elif isinstance(value, ast.Call):
                vals = self.call_values(value)
                if len(vals) != len(targets):
                    raise Unsupported("unpacking of another number of values")
            else:
                raise Unsupported("unpacking of a non-tuple")
            for t, (kind, v) in zip(targets, vals):
                if kind == "a":
                    if not isinstance(t, ast.Name) or t.id in self.scope.slots:
                        raise Unsupported("an array bound to a scalar name")
                    self.scope.arrays[t.id] = v
                else:
                    self.store_target(t, kind, v)
            return
        if any(isinstance(t, (ast.Tuple, ast.List)) for t in st.targets):
            raise Unsupported("chained unpacking")
        kind, v = self.any_expr(st.value)
        for t in st.targets:
            self.store_target(t, kind, v)

    def store_target(self, t, kind, v):
        """``v`` (of ``kind``) into a name or an array element."""
        if isinstance(t, ast.Name):
            self.store_name(t.id, v, kind)
        elif isinstance(t, ast.Subscript):
            self.b.store(v if kind == "f" else self.b.sitofp(v, _DBL), self.address(t))
        else:
            raise Unsupported("assignment target")

    def inline_return(self, st: ast.Return):
        """``return …`` in an inlined call: its values into the call's result slots (made at its
        first return, of that return's kinds), then to the code after the call."""
        frame = self.frames[-1]
        node = st.value
        if node is None:
            vals = []
        elif isinstance(node, (ast.Tuple, ast.List)):
            vals = [self.any_expr(e) for e in node.elts]
        else:
            vals = [self.any_expr(node)]
        b = self.b
        if frame["slots"] is None:
            frame["slots"] = [(k, self.f.alloca(_DBL if k == "f" else _I64, name="ret")) for k, _ in vals]
        if len(vals) != len(frame["slots"]):
            raise Unsupported("returns of different numbers of values")
        for (k, slot), (vk, v) in zip(frame["slots"], vals):
            if k != vk:
                if k == "i":
                    raise Unsupported("an integer and a float returned at one place")
                v = b.sitofp(v, _DBL)
            b.store(v, slot)
        b.branch(frame["exit"])

    # --- arrays ---------------------------------------------------------------------------
    def address(self, sub: ast.Subscript):
        if not isinstance(sub.value, ast.Name) or sub.value.id not in self.scope.arrays:
            raise Unsupported("subscript of a non-array")
        data, shape = self.scope.arrays[sub.value.id]
        idx = sub.slice
        parts = idx.elts if isinstance(idx, ast.Tuple) else [idx]
        if len(parts) != len(shape):
            raise Unsupported("index rank")
        return self.element(data, shape, [self.int_expr(p) for p in parts])

    def element(self, data, shape, ints):
        b = self.b
        # C order: ((i0 * n1) + i1) * n2 + ...  (the extents are run-time values)
        flat = ints[0]
        for n, i in zip(shape[1:], ints[1:]):
            flat = b.add(b.mul(flat, n), i)
        return b.gep(data, [flat])

    def array_arg(self, node):
        """An array argument of an inlined call: a name or a row ``A[i]`` of a 2-D view."""
        sc = self.scope
        if isinstance(node, ast.Name) and node.id in sc.arrays:
            return sc.arrays[node.id]
        if (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in sc.arrays
                and not isinstance(node.slice, (ast.Tuple, ast.Slice))):
            data, shape = sc.arrays[node.value.id]
            if len(shape) < 2:
                return None                   # an element, not a view
            # A[i] of an n-D view: the (n-1)-D view at row i (C order)
            size = shape[1]
            for e in shape[2:]:
                size = self.b.mul(size, e)
            row = self.b.mul(self.int_expr(node.slice), size)
            return self.b.gep(data, [row]), list(shape[1:])
        return None

    def int_expr(self, node):
        """An integer: a constant, a loop index or integer variable, a sum or product of those,
        or an entry of one of the module's constant integer tables."""
        b = self.b
        c = self.const_eval(node)
        if c is not None:
            return ir.Constant(_I64, c)
        sc = self.scope
        if isinstance(node, ast.Name) and node.id in sc.slots and sc.slots[node.id][0] == "i":
            return b.load(sc.slots[node.id][1])
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return b.sub(ir.Constant(_I64, 0), self.int_expr(node.operand))
        if isinstance(node, ast.BinOp) and type(node.op) in (ast.Add, ast.Sub, ast.Mult):
            x, y = self.int_expr(node.left), self.int_expr(node.right)
            return {ast.Add: b.add, ast.Sub: b.sub, ast.Mult: b.mul}[type(node.op)](x, y)
        if isinstance(node, ast.BinOp) and type(node.op) in (ast.Mod, ast.FloorDiv):
            return self.floor_div_mod(node)
        if (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Attribute)
                and node.value.attr == "shape" and isinstance(node.value.value, ast.Name)
                and node.value.value.id in sc.arrays):
            # X.shape[k] of a view: its extent (a run-time value)
            shape = sc.arrays[node.value.value.id][1]
            k = self.const_int(node.slice)
            if not -len(shape) <= k < len(shape):
                raise Unsupported("shape index out of range")
            return shape[k]
        if isinstance(node, ast.IfExp):
            # both sides integers (no side effects: a call is refused here), chosen by select
            x, y = self.int_expr(node.body), self.int_expr(node.orelse)
            return b.select(self.bool_expr(node.test), x, y)
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "int"
                and len(node.args) == 1 and not node.keywords):
            # a float holding an integer (a row permutation kept in a float64 array)
            return b.fptosi(self.expr(node.args[0]), _I64)
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("min", "max")
                and len(node.args) >= 2 and not node.keywords):
            # integer min / max, left to right as numba's do_minmax
            acc = self.int_expr(node.args[0])
            for a in node.args[1:]:
                v = self.int_expr(a)
                acc = b.select(b.icmp_signed("<" if node.func.id == "min" else ">", v, acc), v, acc)
            return acc
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name):
            if node.value.id in sc.arrays:
                raise Unsupported("a float element as an index (or an integer operator: %, //, >>, & of a float)")
            gv, shape, kind = self.table(node.value.id)
            if kind != "i":
                raise Unsupported("float table as an index")
            return b.load(self.table_address(gv, shape, node.slice))
        raise Unsupported(f"index expression {ast.unparse(node)!r}")

    def floor_div_mod(self, node):
        """``a % b`` and ``a // b`` of integers with Python's (and numba's) signs: the remainder
        has the sign of b, the quotient is rounded down.  A zero divisor gives 0 here (Python
        raises); it is never a trap."""
        b = self.b
        x, y = self.int_expr(node.left), self.int_expr(node.right)
        zero, one = ir.Constant(_I64, 0), ir.Constant(_I64, 1)
        is0 = b.icmp_signed("==", y, zero)
        ys = b.select(is0, one, y)
        q, r = b.sdiv(x, ys), b.srem(x, ys)
        # r != 0 with a sign other than y's: one step down
        fix = b.and_(b.icmp_signed("!=", r, zero), b.icmp_signed("!=", b.icmp_signed("<", r, zero),
                                                                   b.icmp_signed("<", ys, zero)))
        if isinstance(node.op, ast.Mod):
            out = b.select(fix, b.add(r, ys), r)
        else:
            out = b.select(fix, b.sub(q, one), q)
        return b.select(is0, zero, out)

    def table_address(self, gv, shape, idx):
        b = self.b
        parts = idx.elts if isinstance(idx, ast.Tuple) else [idx]
        if len(parts) != len(shape):
            raise Unsupported("table index rank")
        flat = self.int_expr(parts[0])
        for n, p in zip(shape[1:], parts[1:]):
            flat = b.add(b.mul(flat, ir.Constant(_I64, n)), self.int_expr(p))
        return b.gep(gv, [ir.Constant(_I64, 0), flat])

    def table(self, name):
        """A module-level numpy array (index tables, quadrature weights) or tuple of numbers (the
        scalar helpers' Gauss–Legendre nodes and weights) as an LLVM constant."""
        got = self.tables.get(name)
        if got is None:
            import numpy
            arr = self.scope.globals.get(name)
            if isinstance(arr, tuple) and arr and all(type(v) in (int, float) for v in arr):
                arr = numpy.array(arr, dtype=numpy.float64 if float in map(type, arr) else numpy.int64)
            if not isinstance(arr, numpy.ndarray) or arr.size == 0 or arr.dtype.kind not in "iuf":
                raise Unsupported(f"{name} is not a constant table")
            if arr.dtype.kind == "f":
                if arr.dtype != numpy.float64:
                    raise Unsupported(f"{name}: {arr.dtype}")
                kind, ety, flat = "f", _DBL, [float(v) for v in arr.ravel()]
            else:
                kind, ety, flat = "i", _I64, [int(v) for v in arr.ravel()]
            ty = ir.ArrayType(ety, len(flat))
            gv = ir.GlobalVariable(self.module, ty, name=f"{self.name}.{name}")
            gv.global_constant = True
            gv.linkage = "private"
            gv.initializer = ir.Constant(ty, flat)
            got = self.tables[name] = (gv, arr.shape, kind)
        return got

    def view(self, name, value) -> bool:
        """``name`` bound to an array: another array, ``X[a:b]`` (constant bounds), a row of a
        matrix, a work array on the stack (``stack_array(shape)``) or ``numpy.zeros``."""
        sc = self.scope
        arr = self.array_arg(value)
        if arr is not None:
            sc.arrays[name] = arr
            return True
        if (isinstance(value, ast.Subscript) and isinstance(value.value, ast.Name)
                and value.value.id in sc.arrays and isinstance(value.slice, ast.Slice)):
            data, shape = sc.arrays[value.value.id]
            sl = value.slice
            if len(shape) != 1 or sl.step is not None or sl.lower is None or sl.upper is None:
                raise Unsupported("slice")
            lo, hi = self.const_int(sl.lower), self.const_int(sl.upper)
            sc.arrays[name] = (self.b.gep(data, [ir.Constant(_I64, lo)]), [ir.Constant(_I64, hi - lo)])
            return True
        if isinstance(value, ast.Call) and isinstance(value.func, ast.Attribute) and not value.keywords:
            owner = value.func.value.id if isinstance(value.func.value, ast.Name) else None
            if self.is_numpy(owner) and value.func.attr in ("zeros", "empty") and len(value.args) == 1:
                # a work array of a shape known now (numpy.empty's: not cleared, as numpy)
                shape = self.const_shape(value.args[0])
                sc.arrays[name] = self.buffer(shape)
                if value.func.attr == "zeros":
                    self.zero(ast.Name(id=name))
                return True
        if (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "stack_array"
                and len(value.args) == 1 and not value.keywords):
            # a work array on the stack, not cleared (run as Python: numpy.zeros of the shape)
            sc.arrays[name] = self.buffer(self.const_shape(value.args[0]))
            return True
        return False

    def is_numpy(self, name) -> bool:
        """Whether ``name`` is numpy here (``numpy``, or a name the module bound to it: ``np``)."""
        if name is None:
            return False
        got = self.scope.globals.get(name)
        return name == "numpy" if got is None else got is np

    def const_shape(self, node):
        dims = node.elts if isinstance(node, ast.Tuple) else [node]
        return [self.const_int(d) for d in dims]

    def buffer(self, shape):
        """A work array on the stack (an alloca in the entry block)."""
        total = 1
        for n in shape:
            total *= n
        buf = self.f.alloca(_DBL, size=ir.Constant(_I64, max(total, 1)))
        return buf, [ir.Constant(_I64, n) for n in shape]

    @staticmethod
    def is_full_slice(idx) -> bool:
        parts = idx.elts if isinstance(idx, ast.Tuple) else [idx]
        return all(isinstance(p, ast.Slice) and p.lower is None and p.upper is None and p.step is None
                   for p in parts)

    def zero(self, node):
        if not isinstance(node, ast.Name) or node.id not in self.scope.arrays:
            raise Unsupported("clearing a non-array")
        b = self.b
        data, shape = self.scope.arrays[node.id]
        n = shape[0]
        for e in shape[1:]:
            n = b.mul(n, e)
        fn = self.module.declare_intrinsic("llvm.memset", [_PTR, _I64])
        b.call(fn, [b.bitcast(data, _PTR), ir.Constant(ir.IntType(8), 0), b.mul(n, ir.Constant(_I64, 8)),
                    ir.Constant(ir.IntType(1), 0)])

    # --- loops ----------------------------------------------------------------------------
    def const_int(self, node):
        c = self.const_eval(node)
        if c is None:
            raise Unsupported("non-constant integer")
        return c

    def const_eval(self, node):
        """The Python int value of an integer expression known at translation time (constants,
        the module's integer constants, the elements of a loop over a constant tuple), else None."""
        if isinstance(node, ast.Constant) and type(node.value) in (int, bool):
            return int(node.value)
        if isinstance(node, ast.Name):
            sc = self.scope
            if node.id in sc.consts:
                return sc.consts[node.id]
            if node.id in sc.slots or node.id in sc.arrays or node.id in sc.fconsts:
                return None
            v = sc.globals.get(node.id)
            return v if type(v) is int and node.id.startswith("_") else None
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            v = self.const_eval(node.operand)
            return None if v is None else -v
        if isinstance(node, ast.BinOp) and type(node.op) in self._CONST_OPS:
            a, b = self.const_eval(node.left), self.const_eval(node.right)
            if a is None or b is None or (type(node.op) in (ast.FloorDiv, ast.Mod) and b == 0):
                return None
            return self._CONST_OPS[type(node.op)](a, b)
        if isinstance(node, ast.BoolOp):
            # ``and`` / ``or`` of comparisons (no side effects): decided at translation time when
            # one operand decides it (False in an ``and``, True in an ``or``) or all are known
            vals = [self.const_eval(v) for v in node.values]
            decisive = 0 if isinstance(node.op, ast.And) else 1
            if any(v is not None and bool(v) == bool(decisive) for v in vals):
                return decisive
            if all(v is not None for v in vals):
                return 1 - decisive
            return None
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            v = self.const_eval(node.operand)
            return None if v is None else int(not v)
        if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _CMP:
            a, b = self.const_eval(node.left), self.const_eval(node.comparators[0])
            if a is None or b is None:
                return None
            import operator
            fn = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
                  ast.Eq: operator.eq, ast.NotEq: operator.ne}[type(node.ops[0])]
            return int(fn(a, b))
        return None

    def unrolled(self, st: ast.For):
        """``for e in (c0, c1, …)`` (a literal tuple or a module-level tuple of numbers): the
        body once per element, in order (a sum kept in its printed order)."""
        if st.orelse or not isinstance(st.target, ast.Name):
            raise Unsupported("loop (a for … else, or not over range(…) or a constant tuple)")
        if isinstance(st.iter, ast.Tuple):
            items = [self.const_eval(e) if not (isinstance(e, ast.Constant) and type(e.value) is float)
                     else e.value for e in st.iter.elts]
        else:
            items = self.scope.globals.get(st.iter.id)
            if not isinstance(items, tuple):
                raise Unsupported("loop over a non-tuple")
            items = list(items)
        if any(type(v) not in (int, float) for v in items):
            raise Unsupported("loop over a tuple of non-numbers")
        name = st.target.id
        if name in self.loop_assigned and any(type(v) is int for v in items):
            raise Unsupported("unrolled integer loop inside a run-time loop")
        sc = self.scope
        for v in items:
            if type(v) is int:
                sc.consts[name] = v
            else:
                sc.fconsts[name] = v
            self.block(st.body)
        sc.consts.pop(name, None)
        sc.fconsts.pop(name, None)

    def loop(self, st: ast.For):
        """``for i in range(a, b)`` (bounds known now) as a loop in the machine code."""
        it = st.iter
        if (st.orelse or not isinstance(st.target, ast.Name) or not isinstance(it, ast.Call)
                or not isinstance(it.func, ast.Name) or it.func.id != "range" or it.keywords
                or not 1 <= len(it.args) <= 3):
            raise Unsupported("loop (a for … else, or not over range(…) or a constant tuple)")
        step = 1
        args = list(it.args)
        if len(args) == 3:
            # a step known now (``range(n - 1, -1, -1)``: down to 0)
            step = self.const_eval(args.pop())
            if not step:
                raise Unsupported("a range step that is zero or not known at translation time")
        bounds = [self.const_eval(a) for a in args]
        name = st.target.id
        sc = self.scope
        sc.consts.pop(name, None)
        b = self.b
        cmp = "<" if step > 0 else ">"
        if all(v is not None for v in bounds):
            lo, hi = (0, bounds[0]) if len(bounds) == 1 else bounds
            if not len(range(lo, hi, step)):
                return
            lo, hi = ir.Constant(_I64, lo), ir.Constant(_I64, hi)
            known = True
        else:
            # bounds known at run time only (evaluated once, as range() does)
            vals = [self.int_expr(a) for a in args]
            lo, hi = (ir.Constant(_I64, 0), vals[0]) if len(vals) == 1 else vals
            known = False
        var = self.slot(name, "i")
        # the count in a slot of its own, the name set from it at each iteration's start (as
        # Python: an assignment to the name in the body does not change the iteration; after
        # the loop the name holds its last value, or where it broke; a loop that does not run
        # leaves it as it was)
        ctr = self.f.alloca(_I64, name=f"{name}.count")
        fn = self.f.fn
        body = fn.append_basic_block(f"loop.{name}")
        latch = fn.append_basic_block(f"next.{name}")
        after = fn.append_basic_block(f"after.{name}")
        b.store(lo, ctr)
        if known:
            b.branch(body)
        else:
            b.cbranch(b.icmp_signed(cmp, lo, hi), body, after)
        b.position_at_end(body)
        b.store(b.load(ctr), var)
        self.loop_body(body, st.body, latch, after)
        b.position_at_end(latch)
        nxt = b.add(b.load(ctr), ir.Constant(_I64, step))
        b.store(nxt, ctr)
        b.cbranch(b.icmp_signed(cmp, nxt, hi), body, after)
        b.position_at_end(after)

    def while_loop(self, st: ast.While):
        """``while <condition>:`` (no ``else``), with ``break`` and ``continue``."""
        if st.orelse:
            raise Unsupported("while … else")
        b = self.b
        fn = self.f.fn
        head = fn.append_basic_block("while")
        body = fn.append_basic_block("while.body")
        after = fn.append_basic_block("while.after")
        b.branch(head)
        b.position_at_end(head)
        b.cbranch(self.bool_expr(st.test), body, after)
        self.loop_body(body, st.body, head, after)
        b.position_at_end(after)

    def loop_body(self, block, stmts, cont, brk):
        """``stmts`` translated into ``block``, ``continue`` going to ``cont`` and ``break`` to
        ``brk``; falling off the end continues."""
        b = self.b
        b.position_at_end(block)
        self.loops.append((cont, brk))
        try:
            self.block(stmts)
        finally:
            self.loops.pop()
        if not b.block.is_terminated:
            b.branch(cont)

    # --- expressions ----------------------------------------------------------------------
    def any_expr(self, node):
        """``(kind, value)`` of an expression assigned to a name: an integer (index arithmetic)
        or a float."""
        if isinstance(node, ast.Call) and self.inlined_call(node):
            # a function of the module, inlined: its value keeps its kind (an index, a status)
            vals = self.call_values(node)
            if len(vals) != 1:
                raise Unsupported("a call returning a tuple (or nothing) used as one value")
            return vals[0]
        try:
            return "i", self.int_expr(node)
        except Unsupported:
            return "f", self.expr(node)

    def expr(self, node):
        b = self.b
        sc = self.scope
        if isinstance(node, ast.Constant):
            if type(node.value) in (int, float, bool):
                return ir.Constant(_DBL, float(node.value))
            raise Unsupported(f"constant {node.value!r}")
        if isinstance(node, ast.Name):
            if node.id in sc.fconsts:
                return ir.Constant(_DBL, sc.fconsts[node.id])
            got = sc.slots.get(node.id)
            if got is not None:
                v = b.load(got[1])
                return v if got[0] == "f" else b.sitofp(v, _DBL)
            c = self.const_eval(node)
            if c is not None:
                return ir.Constant(_DBL, float(c))
            v = sc.globals.get(node.id)
            if type(v) is float and node.id.startswith("_"):
                return ir.Constant(_DBL, v)
            raise Unsupported(f"name {node.id}")
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "math":
            if node.attr in ("inf", "nan", "pi", "e", "tau"):
                import math
                return ir.Constant(_DBL, getattr(math, node.attr))
            raise Unsupported(f"math.{node.attr}")
        if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and self.is_numpy(node.value.id)
                and node.attr in ("inf", "nan", "pi", "e")):
            return ir.Constant(_DBL, float(getattr(np, node.attr)))      # numpy's constants (np.inf)
        if isinstance(node, ast.Subscript):
            if isinstance(node.value, ast.Name) and node.value.id not in sc.arrays:
                gv, shape, kind = self.table(node.value.id)
                v = b.load(self.table_address(gv, shape, node.slice))
                return v if kind == "f" else b.sitofp(v, _DBL)
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
            c = self.const_eval(node)
            if c is not None:                     # integer arithmetic, then a float (as numba)
                return ir.Constant(_DBL, float(c))
            if type(node.op) in (ast.Mod, ast.FloorDiv):
                return b.sitofp(self.int_expr(node), _DBL)      # of integers only (a float's: refused)
            x, y = self.expr(node.left), self.expr(node.right)
            op = {ast.Add: b.fadd, ast.Sub: b.fsub, ast.Mult: b.fmul, ast.Div: b.fdiv}.get(type(node.op))
            if op is None:
                raise Unsupported("binary operator")
            return op(x, y)
        if isinstance(node, (ast.Compare, ast.BoolOp)) or (isinstance(node, ast.UnaryOp)
                                                             and isinstance(node.op, ast.Not)):
            return b.uitofp(self.bool_expr(node), _DBL)       # a truth value stored as 1.0 / 0.0
        if isinstance(node, ast.IfExp):
            cond = self.bool_expr(node.test)
            return b.select(cond, self.expr(node.body), self.expr(node.orelse))
        if isinstance(node, ast.Call):
            return self.call(node)
        raise Unsupported(type(node).__name__)

    def bool_expr(self, node):
        b = self.b
        c = self.const_eval(node)
        if c is not None:
            return ir.Constant(ir.IntType(1), int(bool(c)))
        if isinstance(node, ast.Constant) and type(node.value) is bool:
            return ir.Constant(ir.IntType(1), int(node.value))
        if isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _CMP:
            op = _CMP[type(node.ops[0])]
            try:
                x, y = self.int_expr(node.left), self.int_expr(node.comparators[0])
                return b.icmp_signed(op, x, y)
            except Unsupported:
                pass
            x, y = self.expr(node.left), self.expr(node.comparators[0])
            # numba: ordered comparisons, except != (unordered: NaN != x)
            return b.fcmp_unordered(op, x, y) if op == "!=" else b.fcmp_ordered(op, x, y)
        if isinstance(node, ast.BoolOp):
            # short-circuit, as Python and numba: a later operand is evaluated only when the
            # earlier ones do not decide (``i < n and a[i] > 0`` never reads a[n])
            is_and = isinstance(node.op, ast.And)
            fn = self.f.fn
            merge = fn.append_basic_block("bool.end")
            incoming = []
            for i, v in enumerate(node.values):
                val = self.bool_expr(v)
                here = b.block
                if i == len(node.values) - 1:
                    b.branch(merge)
                    incoming.append((val, here))
                else:
                    nxt = fn.append_basic_block("bool.next")
                    if is_and:
                        b.cbranch(val, nxt, merge)
                    else:
                        b.cbranch(val, merge, nxt)
                    incoming.append((ir.Constant(ir.IntType(1), 0 if is_and else 1), here))
                    b.position_at_end(nxt)
            b.position_at_end(merge)
            phi = b.phi(ir.IntType(1))
            for val, blk in incoming:
                phi.add_incoming(val, blk)
            return phi
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return b.not_(self.bool_expr(node.operand))
        if self.is_math_call(node, "isfinite"):
            # |x| ordered and not equal to inf: false for NaN and ±inf (numba's isfinite)
            x = self.expr(node.args[0])
            fabs = self.module.declare_intrinsic("llvm.fabs", [_DBL], ir.FunctionType(_DBL, [_DBL]))
            return b.fcmp_ordered("!=", b.call(fabs, [x]), ir.Constant(_DBL, math.inf))
        if isinstance(node, (ast.Name, ast.Call, ast.Subscript, ast.BinOp, ast.IfExp)):
            # the truth value of a number, as Python's: not zero (NaN is true)
            kind, v = self.any_expr(node)
            if kind == "i":
                return b.icmp_signed("!=", v, ir.Constant(_I64, 0))
            return b.fcmp_unordered("!=", v, ir.Constant(_DBL, 0.0))
        raise Unsupported("condition")

    def is_math_call(self, node, name) -> bool:
        """Whether ``node`` is ``math.<name>(x)``."""
        f = getattr(node, "func", None)
        return (isinstance(node, ast.Call) and isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name)
                and f.value.id == "math" and f.attr == name and len(node.args) == 1 and not node.keywords)

    def power(self, node):
        b = self.b
        n = self.const_eval(node.right)
        if n is not None and self.const_eval(node.left) is not None:
            raise Unsupported("integer power of an integer")
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
        b = self.b
        f = node.func
        if isinstance(f, ast.Name) and f.id in ("max", "min") and len(node.args) >= 2:
            # numba's do_minmax, left to right: v replaces the accumulator where v > acc (max)
            # / v < acc (min)
            acc = self.expr(node.args[0])
            for a in node.args[1:]:
                v = self.expr(a)
                acc = b.select(b.fcmp_ordered(">" if f.id == "max" else "<", v, acc), v, acc)
            return acc
        if self.is_math_call(node, "floor"):
            # llvm.floor; numba's math.floor is this value as an int64, converted back where a
            # float is wanted: the same value for |x| < 2**63
            fn = self.module.declare_intrinsic("llvm.floor", [_DBL], ir.FunctionType(_DBL, [_DBL]))
            return b.call(fn, [self.expr(node.args[0])])
        if self.is_math_call(node, "isfinite"):
            return b.uitofp(self.bool_expr(node), _DBL)
        if isinstance(f, ast.Name) and f.id == "int" and len(node.args) == 1:
            return b.sitofp(self.int_expr(node), _DBL)      # int(x) where a float is wanted
        if isinstance(f, ast.Name) and f.id == "abs" and len(node.args) == 1:
            name, table = "fabs", _UNARY
        elif (isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name) and f.value.id == "math"
              and (f.attr in _UNARY or f.attr in _BINARY)):
            name, table = f.attr, (_UNARY if f.attr in _UNARY else _BINARY)
        elif isinstance(f, ast.Name):
            if self.inlined_call(node):
                kind, v = self.any_expr(node)       # an array kernel (or a helper) inlined
                return v if kind == "f" else b.sitofp(v, _DBL)
            return self.call_helper(node)
        else:
            raise Unsupported(f"call of {ast.unparse(f)}")
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
        return b.call(fn, args)

    def _py_function(self, name):
        obj = self.scope.globals.get(name)
        py = getattr(obj, "py_func", obj)
        if not callable(py) or not hasattr(py, "__code__"):
            raise Unsupported(f"call of {name}")
        return py

    def call_helper(self, node):
        """A call of one of the module's scalar helpers (floats in, a float out): the helper
        translated once into a function of this module, called."""
        name = node.func.id
        fn = self.helpers.get(name)
        if fn is None:
            py = self._py_function(name)
            fdef = _function_def(py)
            n = len(fdef.args.args)
            sig = _t.float64(*([_t.float64] * n))
            sub = _Translator(self.module, fdef, sig, f"{self.name}.{name}", _names_of(py))
            sub.tables = self.tables
            sub.helpers = self.helpers
            with _naming(name):
                sub.run()
            fn = self.helpers[name] = sub.f.fn
            fn.linkage = "private"
            fn.attributes.add("alwaysinline")
        if len(node.args) != len(fn.args):
            raise Unsupported("argument count of a helper")
        return self.b.call(fn, [self.expr(a) for a in node.args])

    #: builtins the translator knows (not functions of the module)
    _BUILTINS = frozenset({"max", "min", "abs", "int", "range"})
    #: calls inlined into one another at most this deep
    _MAX_INLINE = 16

    def inlined_call(self, node) -> bool:
        """Whether the call ``node`` is of a function of the module to inline (:meth:`call_values`):
        one taking an array, returning a tuple or an integer constant somewhere, or called with
        fewer arguments than it has (its defaults); other scalar helpers are translated once and
        called (:meth:`call_helper`)."""
        f = node.func
        if not isinstance(f, ast.Name) or f.id in self._BUILTINS or node.keywords:
            return False
        py = self._py_function(f.id)
        if any(self.is_array(a) for a in node.args):
            return True
        fdef = _function_def(py)
        if len(node.args) != len(fdef.args.args):
            return True
        for n in ast.walk(fdef):
            if isinstance(n, ast.Return) and (isinstance(n.value, (ast.Tuple, ast.List)) or (
                    isinstance(n.value, ast.Constant) and type(n.value.value) in (int, bool))):
                return True
        return False

    def is_array(self, node) -> bool:
        """Whether ``node`` is an array view (a name bound to one, or a row ``A[i]`` of one);
        nothing is emitted."""
        sc = self.scope
        if isinstance(node, ast.Name):
            return node.id in sc.arrays
        return (isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id in sc.arrays
                and not isinstance(node.slice, (ast.Tuple, ast.Slice)) and len(sc.arrays[node.value.id][1]) >= 2)

    def call_values(self, node):
        """A call of one of the module's functions, inlined: its body translated here with its
        parameters bound to the arguments (array views, or integer or float values, computed
        first in the caller's scope; omitted trailing ones take the definition's constant
        defaults).  Every ``return`` stores its values and continues after the call.  Returns
        ``[(kind, value), …]``: what it returned (empty for nothing)."""
        if node.keywords or not isinstance(node.func, ast.Name):
            raise Unsupported("call statement")
        py = self._py_function(node.func.id)
        fdef = _function_def(py)
        params = [a.arg for a in fdef.args.args]
        argnodes = list(node.args)
        defaults = fdef.args.defaults
        missing = len(params) - len(argnodes)
        if 0 < missing <= len(defaults):
            extra = defaults[len(defaults) - missing:]
            if not all(isinstance(d, ast.Constant) and type(d.value) in (int, float, bool) for d in extra):
                raise Unsupported("a default that is not a number")
            argnodes += extra
        if (len(params) != len(argnodes) or self.inline_depth >= self._MAX_INLINE or fdef.args.vararg
                or fdef.args.kwarg or fdef.args.kwonlyargs):
            raise Unsupported("call statement")
        # the arguments, evaluated in the caller's scope: array views or integer / float values
        args = []
        for a in argnodes:
            arr = self.array_arg(a)
            args.append(("a", arr) if arr is not None else self.any_expr(a))
        outer = self.scope
        saved_assigned = self.loop_assigned
        self.scope = _Scope(self.f, _names_of(py))
        for p, (kind, v) in zip(params, args):
            if kind == "a":
                self.scope.arrays[p] = v
            else:
                self.store_name(p, v, kind)     # an integer (a count) stays one
        frame = {"exit": self.f.fn.append_basic_block(f"ret.{node.func.id}"), "slots": None}
        self.frames.append(frame)
        self.inline_depth += 1
        self.loop_assigned = self._assigned_in_loops(fdef.body)
        try:
            with _naming(py.__name__):
                self.block(fdef.body)
            b = self.b
            if not b.block.is_terminated:
                b.branch(frame["exit"])         # off the end: returns None
            b.position_at_end(frame["exit"])
            return [(k, b.load(slot)) for k, slot in (frame["slots"] or ())]
        finally:
            self.scope = outer
            self.frames.pop()
            self.inline_depth -= 1
            self.loop_assigned = saved_assigned


class _naming:
    """Context: an :class:`Unsupported` raised inside prefixed with the function it was raised
    in (``in stepper: in _nb_res: binary operator``), so a refusal names the kernel."""

    def __init__(self, name):
        self.name = name

    def __enter__(self):
        return self

    def __exit__(self, kind, exc, tb):
        if isinstance(exc, Unsupported) and not getattr(exc, "_named", None) == self.name:
            new = Unsupported(f"in {self.name}: {exc}")
            new._named = self.name
            raise new from None
        return False


def _function_def(py_func) -> ast.FunctionDef:
    """The definition a function is translated from: a generated kernel's tree
    (:func:`attach`: built from the module's kernel IR, never from its text), else the executed
    text of a hand-written function's file (:mod:`methodgen.codegen.kernelsource`, which refuses
    generated modules)."""
    tree = getattr(py_func, KIR_ATTR, None)
    if tree is not None:
        got = _KIR_DEFS.get(py_func.__kir_digest__)
        if got is None:
            got = _KIR_DEFS[py_func.__kir_digest__] = kir.function_def(tree)
        return got
    try:
        return _ks.function_def(py_func)
    except _ks.StaleSource as exc:
        raise Unsupported(f"no source ({exc})") from None


#: digest -> the FunctionDef built from that tree (shared, read-only)
_KIR_DEFS: dict = {}
KIR_ATTR = kir.KIR_ATTR


def _names_of(py_func) -> dict:
    """The names a function's body is translated in: a kernel-IR function's own (math, the
    package's scalar helpers, the kernels it inlines: :func:`attach`), else its module's."""
    names = getattr(py_func, "__kir_names__", None)
    return names if names is not None else getattr(py_func, "__globals__", {})


#: (the attaching itself is llvmlite-free: a module without llvmlite still carries its trees)
attach = kir.attach


def compile_kernel(py_func, sig, globals_=None, c_entry=False, *, unroll=True, vectorize=True,
                   lazy=False) -> "LLVMKernel":
    """``py_func`` (a kernel of a generated module) compiled through LLVM IR for the
    signature ``sig`` (:mod:`methodgen.codegen.ktypes`), its names resolved in ``globals_`` (default: its module's).  Raises
    :class:`Unsupported` when its source uses anything the translator does not know.

    ``c_entry``: also a C entry point taking each array argument as a pointer to its
    array structure (:func:`packed_structs`), callable from Python through ctypes
    (:meth:`LLVMKernel.c_call`; its result is the kernel's float64 or int64 value, if it
    returns one).

    ``unroll``, ``vectorize``: LLVM's loop unrolling and loop / SLP vectorisation in the -O2
    pipeline (both by default).  Code of many short loops over run-time lengths (a few bodies
    of an N-body loop) gains nothing from either and pays for them in compile time: the
    Wisdom–Holman runtime turns them off.  They never change the bits (no fast-math: LLVM
    does not reassociate).

    ``lazy``: return the kernel named (its symbol, from the cache key) without compiling it.  A
    generated module's kernels are made so: the fused loop inlines their kernel IR and never
    calls their own machine code, so compiling each at import was a second compilation of the
    same code (0.42 s of the outer solar system's cold first use); a call from Python compiles
    its C entry (:meth:`LLVMKernel.__call__`)."""
    sig = _t.plain(sig)
    options = (bool(unroll), bool(vectorize))
    with _LOCK:     # one engine per process: modules are added to it one at a time
        if lazy and not c_entry:
            key, name = _symbol(py_func, sig, globals_, c_entry, options)
            if name not in _LOADED:
                out = LLVMKernel(py_func, sig, None, _engine(), name)
                out._globals = globals_
                return out
        return _compile_kernel(py_func, sig, globals_, c_entry, options)


def _add_c_entry(module, fn, sig, name):
    """``name``(arrays by pointer, scalars by value): loads each structure and calls ``fn``."""
    args = [ir.PointerType(_llvm_type(t)) if isinstance(t, _t.Array) else _llvm_type(t) for t in sig.args]
    void = sig.return_type == _t.none
    ret = ir.VoidType() if void else _I64 if sig.return_type == _t.int64 else _DBL
    entry = ir.Function(module, ir.FunctionType(ret, args), name=name)
    b = ir.IRBuilder(entry.append_basic_block("entry"))
    vals = [b.load(a) if isinstance(t, _t.Array) else a for a, t in zip(entry.args, sig.args)]
    got = b.call(fn, vals)
    if void:
        b.ret_void()
    else:
        b.ret(got)                  # the kernel's value (float64 or int64)


def _symbol(py_func, sig, globals_, c_entry, options):
    """``(cache key or None, symbol)`` of a compilation: named by the key, the same in every
    process (a cached object's), or unique in this process's engine where it cannot be cached."""
    _engine()
    key = _objcache.key(py_func, sig, globals_, c_entry, _STATE,
                        options="" if options == (True, True) else f"unroll={options[0]},vectorize={options[1]}")
    if key is not None:
        return key, f"mg_{key[:24]}_{py_func.__name__}"
    _STATE["count"] += 1
    return None, f"mg{_STATE['count']}_{py_func.__name__}"


def _compile_kernel(py_func, sig, globals_=None, c_entry=False, options=(True, True), named=None):
    engine = _engine()
    key, name = named if named is not None else _symbol(py_func, sig, globals_, c_entry, options)
    got = _LOADED.get(name)
    if got is None:
        obj = _objcache.load(key, name) if key is not None else None
        if obj is None:
            obj = _translate_and_compile(py_func, sig, globals_, c_entry, name, options)
            if key is not None:
                _objcache.store(key, name, obj)
        engine.add_object_file(llvm.ObjectFileRef.from_data(obj))
        engine.finalize_object()
        addr = engine.get_function_address(name)
        if not addr:
            raise Unsupported("no address after compilation")
        got = _LOADED[name] = (addr, engine.get_function_address(name + "_c") if c_entry else 0)
    addr, c_addr = got
    out = LLVMKernel(py_func, sig, addr, engine, name)
    out._globals = globals_
    if c_entry:
        argtypes = [ctypes.c_void_p if isinstance(t, _t.Array) else
                    ctypes.c_double if t == _t.float64 else ctypes.c_int64 for t in sig.args]
        restype = (None if sig.return_type == _t.none else ctypes.c_int64 if sig.return_type == _t.int64
                   else ctypes.c_double)
        out.c_call = ctypes.CFUNCTYPE(restype, *argtypes)(c_addr)
    return out


#: machine code in this process's engine, by symbol (a kernel asked for twice is added once)
_LOADED: dict = {}


def _translate_and_compile(py_func, sig, globals_, c_entry, name, options=(True, True)) -> bytes:
    """The kernel's object code: translated to LLVM IR, optimised (-O2), emitted for the host."""
    return _target_machine().emit_object(_optimised(py_func, sig, globals_, c_entry, name, options))


def assembly(py_func, sig, globals_=None, *, unroll=True, vectorize=True) -> str:
    """The host assembly of ``py_func`` translated and optimised as :func:`compile_kernel` does
    (for inspection: which loops LLVM vectorised, that no multiply-add was contracted)."""
    with _LOCK:
        _engine()
        return _target_machine().emit_assembly(_optimised(py_func, _t.plain(sig), globals_, False, py_func.__name__,
                                                          (bool(unroll), bool(vectorize))))


def _optimised(py_func, sig, globals_, c_entry, name, options=(True, True)):
    """The kernel translated to LLVM IR and optimised (-O2): an llvmlite module."""
    module = ir.Module(name=py_func.__name__)
    module.triple = _STATE["triple"]
    with _naming(py_func.__name__):
        fdef = _function_def(py_func)
        tr = _Translator(module, fdef, sig, name, _names_of(py_func) if globals_ is None else globals_)
        tr.run()
    if c_entry:
        _add_c_entry(module, tr.f.fn, sig, name + "_c")
    mod = llvm.parse_assembly(str(module))
    mod.verify()
    tm = _target_machine()
    pto = llvm.create_pipeline_tuning_options(speed_level=2)
    if not options[0]:
        pto.loop_unrolling = False
    if not options[1]:
        pto.loop_vectorization = False
        pto.slp_vectorization = False
    pb = llvm.create_pass_builder(tm, pto)
    pb.getModulePassManager().run(mod, pb)
    return mod


def packed_structs(arrays):
    """``(buffer, addresses)``: the array structures of ``arrays`` (meminfo, parent, nitems,
    itemsize, data, shape, strides: what a C entry point takes for each array argument) back to
    back in one int64 buffer, and the address of each; pass the addresses, and keep the buffer
    and the arrays alive while they are used.  One allocation for all of them (a ctypes
    structure per array cost about 2.4 µs each, a tenth of a one-step call).  ValueError for an
    array that is not C-contiguous float64 of 1-3 dimensions: the translated code indexes C
    order from the shape alone."""
    vals = []
    offs = []
    for a in arrays:
        if a.dtype.char != "d" or not a.flags.c_contiguous or not 1 <= a.ndim <= 3:
            raise ValueError(f"a C-contiguous float64 array of 1-3 dimensions is needed, got {a.dtype} {a.shape}")
        try:
            # the data pointer through the buffer protocol: a sixth of a.ctypes.data's cost
            # (which builds numpy's ctypes helper object); read-only or empty arrays take the
            # array interface
            ptr = ctypes.addressof(ctypes.c_char.from_buffer(a))
        except (TypeError, ValueError):
            ptr = a.__array_interface__["data"][0]
        offs.append(len(vals))
        vals += (0, 0, a.size, 8, ptr)
        vals += a.shape
        vals += a.strides
    buf = np.array(vals, dtype=np.int64)
    base = buf.__array_interface__["data"][0]
    return buf, [base + 8 * o for o in offs]


class LLVMKernel:
    """A kernel compiled by :func:`compile_kernel`.

    The fused loop (:mod:`methodgen.runtime.fused`) inlines its kernel IR (a lazy kernel's own
    machine code is never compiled: ``compile_kernel(lazy=True)``).  Callable from Python: the same
    translation with a C entry (:func:`compile_kernel` with ``c_entry``, made on the first such
    call, its machine code cached as any other) called through ctypes -- the kernel's own
    arithmetic (the Python stepper, tests and diagnostics; the runtime never does)."""

    __slots__ = ("py_func", "engine", "_py", "c_call", "_sig", "_addr", "symbol", "_globals")

    def __init__(self, py_func, sig, addr, engine, symbol=""):
        self._sig = sig               # methodgen.codegen.ktypes.Signature
        self._addr = addr
        self.py_func = py_func
        self.engine = engine          # owns the machine code
        self._py = None               # the C entry, for calls from Python (made on the first)
        self.c_call = None            # the C entry through ctypes (compile_kernel(c_entry=True))
        self._globals = None          # the names it was translated in (compile_kernel's globals_)
        # the machine code's symbol: named by the cache key of the text it was translated
        # from (or unique in the process), so it identifies the code, as an id() cannot
        self.symbol = symbol

    def __call__(self, *args):
        """Call the machine code from Python: arrays (C-contiguous, of the signature's dtype) by
        reference, so the kernel writes into the caller's arrays; ValueError for others."""
        entry = self.c_call or self._py
        if entry is None:
            entry = self._py = compile_kernel(self.py_func, self._sig, globals_=self._globals, c_entry=True).c_call
        if len(args) != len(self._sig.args):
            raise TypeError(f"{self.py_func.__name__}() takes {len(self._sig.args)} arguments, got {len(args)}")
        keep, vals = [], []
        for a, t in zip(args, self._sig.args):
            if isinstance(t, _t.Array):
                want = np.dtype(str(t.dtype))
                if not (isinstance(a, np.ndarray) and a.dtype == want and a.ndim == t.ndim
                        and a.flags.c_contiguous):
                    got = (f"{a.dtype} {a.shape} {'C-contiguous' if a.flags.c_contiguous else 'strided'}"
                           if isinstance(a, np.ndarray) else type(a).__name__)
                    raise ValueError(f"{self.py_func.__name__}(): a C-contiguous {t.ndim}-d {want} array is "
                                     f"needed, got {got}")
                buf, (addr,) = _packed(a)
                keep.append(buf)
                vals.append(addr)
            else:
                vals.append(int(a) if t == _t.int64 else float(a))
        out = entry(*vals)
        del keep
        return out


def _packed(a):
    """:func:`packed_structs` of one array of any dtype of 8-byte items (a kernel's index
    tables are int64)."""
    ptr = a.__array_interface__["data"][0]
    buf = np.array([0, 0, a.size, a.itemsize, ptr, *a.shape, *a.strides], dtype=np.int64)
    return buf, [buf.__array_interface__["data"][0]]


def kernel(sig, table):
    """Decorator: a generated kernel compiled through LLVM IR from its kernel IR ``table``
    (:func:`attach`: the tree, never the module's text; its machine code keyed by the tree's
    digest), named now and compiled on first use (the fused loop inlines the tree instead).

    Raises
    ------
    Unsupported
        ``table`` is None: a module printed without the kernel's tree (there is no other
        compiler to hand its text to).
    """
    def deco(py_func):
        if table is None:
            raise Unsupported(f"{py_func.__name__}: no kernel-IR table (the compiled backend compiles a "
                              "kernel from its tree only; regenerate the module, or use backend=\"numpy\")")
        attach(py_func, table)
        return compile_kernel(py_func, sig, globals_=getattr(py_func, "__kir_names__", None), lazy=True)

    return deco
