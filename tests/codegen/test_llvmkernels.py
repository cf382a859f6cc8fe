"""Kernels and the runtime compiled through LLVM IR (methodgen.codegen.llvmkernels).

A compiled module's kernels (from their kernel IR) and methodgen's hand-written runtime (from
its source) are translated to LLVM IR and compiled by LLVM.  They must compute bitwise what
their source means -- the source run as Python with the translator's documented arithmetic
(IEEE operations, libm's functions, integer powers by squaring: :func:`_reference`) -- refuse,
naming the function, anything the translator does not know, and never translate a construct
wrongly.
"""

from __future__ import annotations

import ast
import ctypes
import ctypes.util
import importlib.util
import math
import os
import textwrap

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen.emit import module_filename
from methodgen.codegen.lower import uses_loops

pytest.importorskip("llvmlite")

from methodgen.codegen import abi  # noqa: E402
from methodgen.codegen import llvmkernels as lk  # noqa: E402
from methodgen.codegen import ktypes as kt  # noqa: E402

RES = abi.KERNEL_TYPES["res"]


def _load(tmp_path, name, source):
    """A module of kernels written to a file (the translator reads a kernel's source)."""
    path = tmp_path / f"{name}.py"
    path.write_text("import math\nimport numpy\n\n" + textwrap.dedent(source))
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _rows(kernel, Y, n_out):
    """The kernel (signature ``res``) at each row of Y: an LLVM kernel through its C entry, or a
    Python function (:func:`_reference`)."""
    R = np.zeros((Y.shape[0], n_out))
    Y = np.ascontiguousarray(Y)
    p = np.array([2.0, -3.0])
    for b in range(Y.shape[0]):
        kernel(np.zeros(Y.shape[1]), Y[b].copy(), np.zeros(Y.shape[1]), 0.1, p, R[b])
    return R


# --- the reference: the source run as Python, with the translator's arithmetic ----------------

_LIBM = ctypes.CDLL(ctypes.util.find_library("m"))


def _libm(name, nargs):
    f = getattr(_LIBM, name)
    f.restype, f.argtypes = ctypes.c_double, [ctypes.c_double] * nargs
    return f


class _Math:
    """``math`` as compiled code computes it: libm's functions (IEEE values, no exceptions)."""

    def __getattr__(self, name):
        if name == "isfinite" or not callable(getattr(math, name)):
            return getattr(math, name)       # (and the constants inf, nan, pi, e)
        return _libm(name, 2 if name in ("atan2", "copysign", "pow", "hypot") else 1)


def _div(a, b):
    with np.errstate(all="ignore"):
        out = np.float64(a) / np.float64(b)
    return float(out)


def _pow(x, n):
    """``x**n`` as translated: a constant integer power by squaring from 1.0 (then 1/… for n < 0);
    other powers by libm's pow."""
    if type(n) is int and abs(n) <= 0x10000:
        res, val, e = 1.0, float(x), abs(n)
        while e:
            if e & 1:
                res = res * val
            e >>= 1
            val = val * val
        return _div(1.0, res) if n < 0 else res
    return _libm("pow", 2)(float(x), float(n))


class _Ops(ast.NodeTransformer):
    def visit_BinOp(self, node):
        self.generic_visit(node)
        if isinstance(node.op, (ast.Pow, ast.Div)):
            fn = "_pow" if isinstance(node.op, ast.Pow) else "_div"
            return ast.copy_location(ast.Call(ast.Name(fn, ast.Load()), [node.left, node.right], []), node)
        return node


def _reference(mod, name):
    """``name`` of the kernel module ``mod`` (:func:`_load`), its whole source run as Python with
    ``**`` and ``/`` as the translator computes them and ``math`` as libm."""
    tree = _Ops().visit(ast.parse(open(mod.__file__).read()))
    ast.fix_missing_locations(tree)
    ns = {"_pow": _pow, "_div": _div, "stack_array": np.zeros}
    exec(compile(tree, mod.__file__, "exec"), ns)
    ns["math"] = _Math()
    return ns[name]


ARITH = """
def arith(_z, _y, _c, _h, _p, _r):
    a = _y[0]
    b = _y[1]
    _c0 = (1/2)*a - b/3 + _p[0]*_h
    _r[0] = _c0**2
    _r[1] = a**3 - b**5
    _r[2] = a**-2 + 1/b**7
    _r[3] = abs(b)**0.5 + a**(1/3)
    _r[4] = math.sqrt(a*a + b*b) - math.exp(-a) + math.log(abs(b) + 1)
    _r[5] = math.sin(a) * math.cos(b) + math.tan(a/7) + math.atan2(a, b) + math.tanh(b)
    _r[6] = -(a - b) + +a
    _r[7] = math.expm1(a/9) - math.log1p(abs(b)) + math.asinh(a) + math.copysign(1.0, b)
    _r[8] = 0
"""


def test_arithmetic_and_math_functions_are_bitwise_the_reference(tmp_path):
    mod = _load(tmp_path, "k_arith", ARITH)
    ll = lk.compile_kernel(mod.arith, RES)
    assert isinstance(ll, lk.LLVMKernel)
    rng = np.random.default_rng(1)
    Y = np.concatenate([rng.normal(size=(200, 2)) * 10.0 ** rng.integers(-3, 4, size=(200, 1)),
                        [[1e300, 1e-300], [np.inf, 1.0], [np.nan, 1.0], [-1e-3, 3.0]]])
    with np.errstate(all="ignore"):
        a = _rows(ll, Y, 9)
        b = _rows(_reference(mod, "arith"), Y, 9)
    assert np.array_equal(a, b, equal_nan=True)
    # A negative integer power of 0 is inf, as the modules' error model promises
    with np.errstate(all="ignore"):
        z = _rows(ll, np.array([[0.0, 1.0], [-0.0, 2.0]]), 9)
    assert z[0, 2] == np.inf and z[1, 2] == np.inf
    # control: the translated code is not the reference by construction -- one changed operation shows
    mod2 = _load(tmp_path, "k_arith2", ARITH.replace("_c0**2", "_c0*_c0*1.0000000001"))
    with np.errstate(all="ignore"):
        assert not np.array_equal(_rows(lk.compile_kernel(mod2.arith, RES), Y, 9), b, equal_nan=True)


LOOPS = """
_IDX0 = numpy.array([[0, 1], [1, 2], [2, 0]], dtype=numpy.int64)


def loops(_z, _y, _c, _h, _p, _r):
    _sA = _r[0:3]
    _sA[:] = 0.0
    for _k in range(3):
        _u0 = _y[_IDX0[_k, 0]]
        _u1 = _y[_IDX0[_k, 1]]
        _t0 = (_u0 - _u1)**3
        _sA[_IDX0[_k, 0]] += _t0
        _sA[_IDX0[_k, 1]] += -_t0
    _w = numpy.zeros((2, 2))
    for _i in range(0, 2):
        for _b in range(2):
            _w[_i, _b] = _y[_i + _b] * 2.0
    _k = 0
    _red = _y[_k] * 0.5
    for _e in (9, 16, 1):
        _k = _e >> 3
        if _e & 7 == 0:
            _red = _red + _y[_k]
        elif _e & 7 == 1:
            _red = _red - _w[_k, 1]
    _r[3] = _red
    _r[4] = _w[1, 0] + _w[0, 1]
"""


def test_loops_tables_views_and_unrolled_sums_are_bitwise_the_reference(tmp_path):
    """Control: the same loops reading the table's other column differ."""
    mod = _load(tmp_path, "k_loops", LOOPS)
    ll = lk.compile_kernel(mod.loops, RES)
    Y = np.random.default_rng(2).normal(size=(50, 3))
    assert np.array_equal(_rows(ll, Y, 5), _rows(_reference(mod, "loops"), Y, 5))
    other = _load(tmp_path, "k_loops2", LOOPS.replace("_u1 = _y[_IDX0[_k, 1]]", "_u1 = _y[_IDX0[_k, 0]]"))
    assert not np.array_equal(_rows(lk.compile_kernel(other.loops, RES), Y, 5), _rows(ll, Y, 5))


FLOW = """
def _helper(a, b):
    d = b - a
    if abs(d) < 1.0:
        return 0.5 * d * d
    hi = max(a, b)
    return hi - min(a, b) + (1.0 if d > 0.0 else -1.0)


def _size(_y, _p):
    a = abs(_y[0])
    b = _p[0] * _y[1]
    return max(a, abs(b), abs(_y[2]))


def _field(_y, _p, _out):
    _out[0] = _y[0] * _p[0]
    _out[1] = _y[1] - _p[1]


def flow(_z, _y, _c, _h, _p, _r):
    s = 0.0
    for i in range(3):
        s = s + _y[i] * (i + 1)
        s += 0.5
    _r[0] = s
    if _y[0] > 0.0:
        _r[1] = 1.0
    elif _y[0] != _y[0]:
        _r[1] = 2.0
    else:
        _r[1] = _y[1] if _y[1] <= _y[2] else -_y[2]
    _r[2] = _helper(_y[0], _y[1]) + _helper(_y[2], _y[0])
    _r[3] = max(_y[0], _y[1]) - min(_y[1], _y[2]) + max(abs(_y[0]), _y[1], -_y[2])
    _F = stack_array((2, 2))
    for _k in range(2):
        _field(_y, _p, _F[_k])
    _r[4] = _F[0, 0] + _F[1, 1] + _size(_y, _p)
    _r[5] = _y[0] > 0.5 and _y[1] < 0.5 or not _y[2] >= 0.0
"""


def test_control_flow_helpers_and_stack_buffers_are_bitwise_the_reference(tmp_path):
    """Variables carried across iterations, branches on run-time values (NaN compares false,
    except !=), the module's scalar helpers (called) and array kernels (inlined into a stack
    buffer's rows, or returning a float in an expression, as a scale kernel): translated, and
    bitwise the reference on random inputs with NaN and inf.  Control: a helper's branch
    inverted shows."""
    mod = _load(tmp_path, "k_flow", FLOW)
    ll = lk.compile_kernel(mod.flow, RES)
    assert isinstance(ll, lk.LLVMKernel)
    rng = np.random.default_rng(3)
    Y = np.concatenate([rng.normal(size=(300, 3)) * 2.0,
                        [[np.nan, 1.0, 2.0], [1.0, np.nan, 0.0], [np.inf, -np.inf, np.nan], [0.3, 0.3, 0.3]]])
    with np.errstate(all="ignore"):
        ref = _rows(_reference(mod, "flow"), Y, 6)
        assert np.array_equal(_rows(ll, Y, 6), ref, equal_nan=True)
        inv = _load(tmp_path, "k_flow2", FLOW.replace("if abs(d) < 1.0:", "if abs(d) >= 1.0:"))
        assert not np.array_equal(_rows(lk.compile_kernel(inv.flow, RES), Y, 6), ref, equal_nan=True)


LOOP_EXITS = """
def exits(_z, _y, _c, _h, _p, _r):
    # a Newton-like iteration: while with a counter, continue, break, integer min / max
    it = 0
    x = _y[0]
    prev = math.inf
    ok = 0
    while it < 40:
        it += 1
        d = 0.5 * (x * x - abs(_y[1]) - 1.0) / (abs(x) + 1.0)
        if it == 3 and _y[2] > 0.0:
            prev = math.inf
            continue
        x -= d
        if not abs(d) <= 1e300:
            break
        if abs(d) <= 1e-15 * abs(x) or (abs(d) >= prev and prev <= 1e-8):
            ok = 1
            break
        prev = abs(d)
    _r[0] = x
    _r[1] = it
    _r[2] = ok
    s = 0.0
    for i in range(5):
        if i == 4 - min(3, it, 7) + max(0, it - 40):
            break
        if _y[0] > 10.0 * i:
            continue
        s += _y[1] * i
    _r[3] = s + i
    j = 0
    for k in range(2, 2 + max(1, min(it, 6))):
        j += k * 2
    _r[4] = j
"""


def test_while_break_continue_and_integer_min_max_are_bitwise_the_reference(tmp_path):
    """The constructs of an iteration (the fused Newton loop): ``while`` with a counter,
    ``continue`` (back to the test), ``break`` (out, the index left where it broke), integer
    ``min``/``max`` in bounds: bitwise the reference, NaN and inf included."""
    mod = _load(tmp_path, "k_exits", LOOP_EXITS)
    ll = lk.compile_kernel(mod.exits, RES)
    assert isinstance(ll, lk.LLVMKernel)
    rng = np.random.default_rng(4)
    Y = np.concatenate([rng.normal(size=(300, 3)) * 5.0,
                        [[np.nan, 1.0, 2.0], [1.0, np.nan, -1.0], [np.inf, 2.0, 1.0], [40.0, 0.0, -1.0]]])
    with np.errstate(all="ignore"):
        a, b = _rows(ll, Y, 5), _rows(_reference(mod, "exits"), Y, 5)
    assert np.array_equal(a, b, equal_nan=True)
    assert len(set(a[:, 1])) > 3 and set(a[:, 2]) == {0.0, 1.0}    # the exits were taken
    # control: a continue that skips the update changes the iterates
    mod2 = _load(tmp_path, "k_exits2", LOOP_EXITS.replace("if it == 3 and", "if it <= 4 and"))
    with np.errstate(all="ignore"):
        assert not np.array_equal(_rows(lk.compile_kernel(mod2.exits, RES), Y, 5), b, equal_nan=True)


@pytest.mark.parametrize("body, why", [
    ("    _r[0] = _y[0] % 2.0\n", "%.* of a float"),
    ("    _r[0] = math.hypot(_y[0], _y[1])\n", "call of math.hypot"),
    ("    for i in range(2):\n        _r[i] = 1.0\n    else:\n        _r[0] = 2.0\n", "for … else"),
    ("    _r[0] = _helper(_y[0])\n", "call of _helper"),
])
def test_what_is_not_translated_is_refused_by_name(tmp_path, body, why):
    """The translator refuses what it does not know (Unsupported), naming the function and the
    construct -- there is no other compiler to hand it to; a kernel without a kernel-IR table
    is refused by name too (its text is never translated by the decorator).  Control: a kernel
    with a table compiles."""
    src = "_helper = len\n\n\ndef k(_z, _y, _c, _h, _p, _r):\n" + body
    tag = str(abs(hash(why)))
    mod = _load(tmp_path, f"k_{tag}", src)
    with pytest.raises(lk.Unsupported, match=r"^in k: .*" + why):
        lk.compile_kernel(mod.k, RES)
    with pytest.raises(lk.Unsupported, match=r"^k: no kernel-IR table"):
        lk.kernel(RES, None)(mod.k)
    fn, table = _table_kernel(tmp_path, f"k_ok_{tag}")
    assert isinstance(lk.kernel(RES, table)(fn), lk.LLVMKernel)


def test_a_refusal_inside_an_inlined_kernel_names_it(tmp_path):
    """A construct refused inside a function the translator inlines (a module's kernel in the
    fused loop) names the chain of functions down to it.  Control: the same caller with a
    translatable callee compiles."""
    src = ("def _inner(_y, _out):\n    _out[0] = _y[0] % 2.0\n\n\n"
           "def k(_z, _y, _c, _h, _p, _r):\n    _inner(_y, _r)\n")
    mod = _load(tmp_path, "k_inlined", src)
    with pytest.raises(lk.Unsupported, match=r"^in k: in _inner: .*of a float"):
        lk.compile_kernel(mod.k, RES)
    ok = _load(tmp_path, "k_inlined_ok", src.replace("_y[0] % 2.0", "_y[0] * 2.0"))
    assert isinstance(lk.compile_kernel(ok.k, RES), lk.LLVMKernel)


def _table_kernel(tmp_path, name):
    """``k(_z, _y, _c, _h, _p, _r): _r[0] = _y[0] + _y[1]`` as a generated module has it: the
    function printed from its kernel IR, and the IR's table."""
    from methodgen.codegen import kir

    tree = kir.function("k", ("_z", "_y", "_c", "_h", "_p", "_r"),
                        [("=", ("[]", "_r", (("n", 0),)), ("+", ("[]", "_y", (("n", 0),)), ("[]", "_y", (("n", 1),))))])
    mod = _load(tmp_path, name, "\n".join(kir.function_lines(tree)) + "\n")
    return mod.k, kir.flatten([tree])[0]


def test_a_table_kernel_is_named_at_once_and_never_compiled_for_itself(tmp_path):
    """A generated kernel (one with a kernel-IR table) is not compiled when its module is loaded
    (the fused loop inlines its tree): it gets its symbol then -- the one an eager compilation
    names it by.  Called from Python it compiles its C entry and computes its tree; its own
    machine code is never made.  Control: another kernel's symbol differs."""
    fn, table = _table_kernel(tmp_path, "k_lazy")
    k = lk.kernel(RES, table)(fn)
    assert isinstance(k, lk.LLVMKernel) and k._addr is None            # named, not compiled
    eager = lk.compile_kernel(fn, RES, globals_=getattr(fn, "__kir_names__", None))
    assert eager.symbol == k.symbol and eager._addr
    Y = np.array([[1.5, 2.5, 3.5], [-1.0, 0.5, 0.25]])
    assert np.array_equal(_rows(k, Y, 1), Y[:, :1] + Y[:, 1:2])        # through its C entry
    assert k._addr is None
    other = _load(tmp_path, "k_lazy_other", "def k(_z, _y, _c, _h, _p, _r):\n    _r[0] = _y[0] - _y[1]\n").k
    assert lk.compile_kernel(other, RES).symbol != k.symbol


def test_a_table_of_another_function_is_refused(tmp_path):
    """A kernel table is the definition of the function it is attached to (name and parameters),
    or it is refused: a module cannot compile one function's tree for another."""
    from methodgen.codegen import kir

    fn, table = _table_kernel(tmp_path, "k_mismatch")
    other = kir.flatten([kir.function("j", ("_z", "_y", "_c", "_h", "_p", "_r"), [])])[0]
    with pytest.raises(ValueError, match="its kernel table defines"):
        lk.kernel(RES, other)(fn)


def _chain(n):
    H = (f"Sum(p[i]**2/2, i, 1, {n}) + q[1]**2/2 + Sum((q[i+1] - q[i])**2/2 + beta*(q[i+1] - q[i])**4/4, "
         f"i, 1, {n - 1}) + q[{n}]**2/2")
    system = mg.Hamiltonian(H, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                            params={"beta": 1.0}, name=f"chain{n}")
    y0 = np.array([math.sin(math.pi * i / (n + 1)) for i in range(1, n + 1)] + [0.0] * n)
    return system, y0


@pytest.mark.parametrize("case", ["kepler-sv8", "hh-em2", "nbody3-em2", "chain24-em2",
                                  # loops over like terms as nbody3-em2, at six bodies
                                  pytest.param("oss-em2", marks=pytest.mark.slow)])
def test_modules_compile_every_kernel_and_agree_with_numpy(tmp_path, monkeypatch, case):
    """Every kernel of the module is an LLVM kernel (straight-line code, loops over like terms,
    like rows, unrolled sums); the trajectory is bitwise the stepper run as Python with the
    same kernels and equals the numpy module's to round-off.  Control: a step one ulp longer
    changes the bits."""
    if case == "chain24-em2":
        system, y0 = _chain(24)            # 48 state components: like rows (lower_rows)
        method, opts, h, steps = "energy-momentum", {}, 0.05, 60
    elif case == "nbody3-em2":             # three pair terms: kernels that loop over them (lower_loops)
        from methodgen.app.bench import nbody_initial, nbody_system

        system, y0 = nbody_system(3), nbody_initial(3)
        method, opts, h, steps = "energy-momentum", {}, 0.01, 60
    else:
        name, method, opts = {"kepler-sv8": ("kepler", "stormer-verlet", {"order": 8}),
                              "hh-em2": ("henon-heiles-2d", "energy-momentum", {}),
                              "oss-em2": ("outer-solar-system", "energy-momentum", {})}[case]
        scene = mg.load_scene(name)
        system, y0, h, steps = scene.system, np.array(scene.y0, float), scene.h, 60
    scheme = mg.discretize(system, method, **opts)
    if case in ("nbody3-em2", "oss-em2"):
        assert uses_loops(scheme)
    mod = mg.generate(scheme, tmp_path / module_filename(system.name, case, "numba"), backend="numba")
    ref = mg.generate(scheme, tmp_path / module_filename(system.name, case, "numpy"), backend="numpy")
    kernels = {k: getattr(mod, k) for k in ("_nb_guess", "_nb_res", "_nb_resjac", "_nb_post", "_nb_check",
                                            "_nb_hs") if hasattr(mod, k)}
    assert kernels and all(isinstance(k, lk.LLVMKernel) for k in kernels.values()), kernels
    compiled = mod.integrate(y0, h, steps)
    monkeypatch.setenv("METHODGEN_STEPPER", "python")
    assert np.array_equal(mod.integrate(y0, h, steps), compiled)
    monkeypatch.delenv("METHODGEN_STEPPER")
    scale = max(1.0, float(np.max(np.abs(compiled))))
    np.testing.assert_allclose(compiled, ref.integrate(y0, h, steps), rtol=0, atol=1e-11 * scale)
    assert not np.array_equal(mod.integrate(y0, np.nextafter(h, 1.0), steps), compiled)


def test_kernels_compile_from_several_threads(tmp_path):
    """One LLVM engine per process: kernels compiled from several threads at once (a dask
    worker's threads importing modules) are added one at a time and all run right."""
    import threading

    mods = [_load(tmp_path, f"k_thread{i}", f"def k(_z, _y, _c, _h, _p, _r):\n    _r[0] = _y[0] * {i + 1}.0 + _y[1]\n")
            for i in range(6)]
    got = [None] * 6

    def work(i):
        got[i] = lk.compile_kernel(mods[i].k, RES)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    Y = np.array([[1.0, 0.5, 0.0]])
    assert [float(_rows(k, Y, 1)[0, 0]) for k in got] == [1.0 * (i + 1) + 0.5 for i in range(6)]


def test_a_c_entry_called_through_ctypes_is_the_kernel(tmp_path):
    """compile_kernel(c_entry=True): the same machine code called from Python through ctypes
    (arrays as their structures by pointer; the fused loop's route) -- bitwise the kernel
    called from Python.  Arrays the translated code cannot index
    (not C-contiguous, not float64) are refused by name, never passed."""
    mod = _load(tmp_path, "k_centry", FLOW)
    ll = lk.compile_kernel(mod.flow, RES, c_entry=True)
    rng = np.random.default_rng(5)
    Y = rng.normal(size=(40, 3))
    ref = _rows(ll, Y, 6)
    p = np.array([2.0, -3.0])
    for b in range(Y.shape[0]):
        r = np.zeros(6)
        y, z, c = Y[b].copy(), np.zeros(3), np.zeros(3)
        buf, (az, ay, ac, ap, ar) = lk.packed_structs([z, y, c, p, r])
        ll.c_call(az, ay, ac, 0.1, ap, ar)
        assert np.array_equal(r, ref[b])
    with pytest.raises(ValueError, match="C-contiguous float64"):
        lk.packed_structs([np.zeros((4, 4))[:, 1]])
    with pytest.raises(ValueError, match="C-contiguous float64"):
        lk.packed_structs([np.zeros(3, dtype=np.int64)])
    assert lk.compile_kernel(mod.flow, RES).c_call is None     # only where asked for


SHORT = """
def guarded(_z, _y, _c, _h, _p, _r):
    n = 0
    if _p[0] > 1.0:
        n = 1
    _r[0] = 0.0
    if n > 0 and _y[200000000000] > 0.0:
        _r[0] = 1.0
    if not (n == 0 or _y[300000000000] > 0.0):
        _r[1] = 1.0
"""


@pytest.mark.parametrize("guard", [True, False])
def test_and_or_short_circuit_as_python(tmp_path, guard):
    """``a and b`` / ``a or b`` evaluate b only when a does not decide (as Python):
    a condition guarding an index never reads out of range; and a name first bound to a
    constant, then assigned in one branch, keeps the constant on the other path.  Control: without the guard the
    same read is made (the process dies of it), so the test sees an eager read."""
    import subprocess
    import sys

    src = SHORT if guard else SHORT.replace("n > 0 and ", "").replace("n == 0 or ", "")
    path = tmp_path / "k_short.py"
    path.write_text("import math\nimport numpy\n" + src)
    code = textwrap.dedent(f"""
        import importlib.util, numpy as np
        from methodgen.codegen import abi, llvmkernels as lk
        spec = importlib.util.spec_from_file_location("k_short", {str(path)!r})
        mod = importlib.util.module_from_spec(spec); spec.loader.exec_module(mod)
        ll = lk.compile_kernel(mod.guarded, abi.KERNEL_TYPES["res"])
        R = np.zeros((1, 2))
        ll(np.zeros(3), np.ones(3), np.zeros(3), 0.1, np.array([0.5]), R[0])
        print("ok", R.tolist())
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=dict(os.environ, METHODGEN_LLVM_CACHE="0"), timeout=120)
    if guard:
        assert proc.returncode == 0 and proc.stdout.split()[0] == "ok", proc.stderr[-2000:]
        # n = 0 on the path that does not assign it (a folded constant assigned in a branch)
        assert proc.stdout.split(None, 1)[1].strip() == "[[0.0, 0.0]]"
    else:
        assert proc.returncode != 0


# --- the constructs of the Wisdom–Holman runtime (methodgen.runtime.kepler_flow) ----------------------------
# Compared with the same source run as Python, each with a control.

def _load_plain(tmp_path, name, source):
    """A module of functions written to a file (numpy imported as np)."""
    path = tmp_path / f"{name}.py"
    path.write_text("import math\nimport numpy as np\n\n" + textwrap.dedent(source))
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _ccall(kernel, *args):
    """The kernel's C entry called with numpy arrays (by their structures) and scalars."""
    buf, addrs = lk.packed_structs([a for a in args if isinstance(a, np.ndarray)])
    it = iter(addrs)
    return kernel.c_call(*[next(it) if isinstance(a, np.ndarray) else a for a in args])


_V, _M = kt.float64[::1], kt.float64[:, ::1]
_T3 = kt.float64[:, :, ::1]

TUPLES = """
def _pair(a, b):
    if a > b:
        return b, a                      # an early return of two floats
    return a, b


def _first_above(x, lim):
    # returns (value, index) from inside a loop; (0.0, -1) when none
    for i in range(x.shape[0]):
        if x[i] > lim:
            return x[i], i
    return 0.0, -1


def _fill(w, v):
    for i in range(w.shape[0]):
        for k in range(w.shape[1]):
            w[i, k] = v + i - k


def tuples(x, work, out):
    lo, hi = _pair(x[0], x[1])
    out[0] = lo
    out[1] = hi
    a = x[2]
    b = x[3]
    a, b = b, a                           # simultaneous: a swap
    out[2] = a - 2.0 * b
    v, i = _first_above(x, 0.5)
    out[3] = v
    out[4] = i
    out[5] = i + 1                        # i is an integer (an index)
    q, g = work[0], work[1]               # views of a 3-D array, unpacked
    _fill(q, 1.0)
    _fill(g, x[4])
    out[6] = q[1, 2] + g[2, 0]
    s = t = x[5]                          # chained: one value, two names
    s += 1.0
    out[7] = s * t
    out[8], out[9] = _pair(x[6], x[7])    # into array elements
"""


def test_tuple_returns_unpacking_and_views_as_python(tmp_path):
    """Functions returning tuples (early, from inside loops, of a float and an index), unpacked
    into names, array elements and array views (``q, g = work[0], work[1]`` of a 3-D array),
    a swap, chained assignment: bitwise the same source run as Python.  Control: a swap
    translated as two sequential assignments would differ, and the test sees that."""
    sig = kt.none(_V, _T3, _V)
    mod = _load_plain(tmp_path, "k_tuples", TUPLES)
    ll = lk.compile_kernel(mod.tuples, sig, c_entry=True)
    rng = np.random.default_rng(7)
    for _ in range(50):
        x = rng.normal(size=8)
        work = np.zeros((2, 4, 3))
        got, ref = np.zeros(10), np.zeros(10)
        _ccall(ll, x, work, got)
        mod.tuples(x, np.zeros((2, 4, 3)), ref)
        assert np.array_equal(got, ref), (got, ref)
    # control: sequential assignments (a = b; b = a) are not the swap
    seq = _load_plain(tmp_path, "k_tuples_seq", TUPLES.replace("    a, b = b, a ", "    a = b\n    b = a\n    #"))
    x = np.arange(8.0)
    r1, r2 = np.zeros(10), np.zeros(10)
    mod.tuples(x, np.zeros((2, 4, 3)), r1)
    _ccall(lk.compile_kernel(seq.tuples, sig, c_entry=True), x, np.zeros((2, 4, 3)), r2)
    assert r1[2] != r2[2] and np.array_equal(np.delete(r1, 2), np.delete(r2, 2))


@pytest.mark.parametrize("body, why", [
    ("def _f(x):\n    if x > 0.0:\n        return 1\n    return 0.5\n\n\ndef k(x, out):\n    out[0] = _f(x[0])\n",
     "an integer and a float returned at one place"),
    ("def _f(x):\n    return x, 2.0\n\n\ndef k(x, out):\n    a, b, c = _f(x[0])\n    out[0] = a\n",
     "unpacking of another number of values"),
    ("def k(x, out):\n    a, b = x[0]\n    out[0] = a\n", "unpacking of a non-tuple"),
])
def test_tuple_mistakes_are_refused(tmp_path, body, why):
    """What Python would reject, or a compiler type differently, is refused, never translated."""
    mod = _load_plain(tmp_path, f"k_bad_{abs(hash(why))}", body)
    with pytest.raises(lk.Unsupported, match=why):
        lk.compile_kernel(mod.k, kt.none(_V, _V), c_entry=True)


LOOPS_RT = """
def loops(x, n, out):
    m = x.shape[0]
    s = 0.0
    for i in range(m - 1, -1, -1):          # down to 0: a run-time start, a constant step
        s = s * 0.5 + x[i]
    out[0] = s
    out[1] = i                               # Python leaves the index at its last value
    t = 0.0
    j = -5
    for j in range(1, n):                    # a run-time length (none when n <= 1: j stays -5)
        t += x[j % m] * j
    out[2] = t
    for j in range(2, m, 3):
        out[3] += x[j]
    out[4] = j
    out[5] = (n - 7) % 3                     # Python's signs (of the divisor)
    out[6] = (n - 7) // 3
    out[7] = -n % m
    out[8] = n // -2
    for k in range(n):
        if k > 2:
            break
    out[9] = k                               # where it broke
"""


def test_run_time_length_loops_and_integer_division_as_python(tmp_path):
    """``range`` over run-time lengths (``x.shape[0]``, a count argument), with a constant step
    (``range(m - 1, -1, -1)``), the index after the loop, ``%`` and ``//`` of integers with
    Python's signs: bitwise the source run as Python.  Control: Python's ``%`` is not C's
    (``-n % m`` differs from the truncated remainder), and a loop one short differs."""
    sig = kt.none(_V, kt.int64, _V)
    mod = _load_plain(tmp_path, "k_rtloops", LOOPS_RT)
    ll = lk.compile_kernel(mod.loops, sig, c_entry=True)
    rng = np.random.default_rng(3)
    for m in (1, 3, 4, 7):
        for n in (1, 2, 5, 8, 13):
            x = rng.normal(size=m)
            got, ref = np.zeros(10), np.zeros(10)
            _ccall(ll, x, n, got)
            mod.loops(x, n, ref)
            assert np.array_equal(got, ref), (m, n, got, ref)
    assert math.fmod(-5, 3) != -5 % 3          # (the control of the signs: C's remainder differs)
    short = _load_plain(tmp_path, "k_rtloops2", LOOPS_RT.replace("range(m - 1, -1, -1)", "range(m - 1, 0, -1)"))
    x = rng.normal(size=4)
    a, b = np.zeros(10), np.zeros(10)
    _ccall(ll, x, 5, a)
    _ccall(lk.compile_kernel(short.loops, sig, c_entry=True), x, 5, b)
    assert a[0] != b[0] and a[1] != b[1]
    # a step not known at translation time is refused
    var = _load_plain(tmp_path, "k_rtloops3", "def k(x, n, out):\n    for i in range(0, 4, n):\n        out[i] = 1.0\n")
    with pytest.raises(lk.Unsupported, match="range step"):
        lk.compile_kernel(var.k, sig, c_entry=True)


VALUES = """
def _count(x):
    n = 0
    for i in range(x.shape[0]):
        if math.isfinite(x[i]):
            n += 1
    return n


def ivalue(x, out):
    n = _count(x)
    if not n:
        return -1
    out[0] = math.floor(x[0]) * 2.0
    out[1] = np.inf if x[1] else -np.inf      # the truth of a float (NaN is true)
    out[2] = int(x[2])
    flag = x[0] > 0.0 and n > 2
    if flag:
        out[3] = 1.0
    return n + 10


def fvalue(x, out):
    return x[0] * x[1]
"""


def test_c_entry_returns_values_and_truth_values_as_python(tmp_path):
    """A C entry returns its kernel's int64 or float64 value; ``math.isfinite``, ``math.floor``,
    numpy's constants, ``int()`` where a float is wanted and the truth value of an integer or
    a float (NaN is true) are Python's.  Control: a void kernel's entry returns None."""
    mod = _load_plain(tmp_path, "k_values", VALUES)
    iv = lk.compile_kernel(mod.ivalue, kt.int64(_V, _V), c_entry=True)
    fv = lk.compile_kernel(mod.fvalue, kt.float64(_V, _V), c_entry=True)
    cases = [[1.5, 0.0, -2.7, 3.0], [-1.5, np.nan, 2.7, np.inf], [0.25, np.nan, 0.5, np.nan],
             [3.0, -0.0, 9.9, 1.0], [-2.0, 3.0, 1.0, -np.inf]]
    for c in cases:
        x = np.array(c)
        got, ref = np.zeros(4), np.zeros(4)
        r = _ccall(iv, x, got)
        assert type(r) is int and r == mod.ivalue(x, ref)
        assert np.array_equal(got, ref)
        assert _ccall(fv, x, got) == mod.fvalue(x, ref) or math.isnan(mod.fvalue(x, ref))
    assert _ccall(iv, np.array([np.nan] * 4), np.zeros(4)) == -1
    void = _load_plain(tmp_path, "k_void", "def k(x, out):\n    out[0] = x[0]\n")
    assert _ccall(lk.compile_kernel(void.k, kt.none(_V, _V), c_entry=True), np.ones(1), np.zeros(1)) is None


TUPLE_TABLES = """
_W = (0.5, 0.25, 0.125)
_I = (1, 2, 0)
_BAD = (1.0, "x")


def k(_z, _y, _c, _h, _p, _r):
    s = 0.0
    for i in range(3):
        s += _W[i] * _y[_I[i]]
    _r[0] = s


def bad(_z, _y, _c, _h, _p, _r):
    _r[0] = _BAD[0]
"""


def test_module_tuples_of_numbers_are_constant_tables(tmp_path):
    """A module-level tuple of numbers indexed at run time (the scalar helpers' Gauss–Legendre
    nodes and weights, ``special_helpers._GL8_T``/``_GL8_W``, which a kernel calling
    ``_f_dsincdd`` inlines) is a constant table: floats and integer indices, bitwise the source
    run as Python.  Control: a tuple with a non-number is refused by name."""
    mod = _load(tmp_path, "k_tuple_tables", TUPLE_TABLES)
    Y = np.random.default_rng(8).normal(size=(20, 3))
    assert np.array_equal(_rows(lk.compile_kernel(mod.k, RES), Y, 1), _rows(_reference(mod, "k"), Y, 1))
    with pytest.raises(lk.Unsupported, match=r"in bad: _BAD is not a constant table"):
        lk.compile_kernel(mod.bad, RES)
