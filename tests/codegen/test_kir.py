"""The kernel IR (methodgen.codegen.kir, kir_build): trees, their two printers, their tables.

(a) The tree the lowering builds from a SymPy expression is the tree Python makes of SymPy's
    code printer's text for it (the rounding every generated kernel always had): checked on
    random expressions of the grammar and on every kernel expression of a built-in scene, for
    the scalar, check and vector (numpy) printers.  Control: a builder that drops the printer's order of
    factors is caught.
(b) ``ast.parse(kir.python(t))`` is ``kir.to_ast(t)``: the Python printer and the tree the LLVM
    translator reads agree, for expressions and whole kernel functions.
(c) A table (``kir.flatten``) gives back its tree, keeps 0, 0.0 and -0.0 apart, and its digest
    changes with any constant (control: the same tree, the same digest).
"""

from __future__ import annotations

import ast
import dataclasses
import random
import re

import pytest
import sympy as sp

import methodgen as mg
from methodgen.codegen import kir, kir_build
from methodgen.codegen.lower import CheckPrinter, ScalarPrinter, VectorPrinter, lower
from methodgen.problem.special import sinc_u

SCALAR = ScalarPrinter({"fully_qualified_modules": True})
CHECK = CheckPrinter({"fully_qualified_modules": True})
VECTOR = VectorPrinter({"fully_qualified_modules": True})
X = sp.symbols("x y z w", real=True)


def _random_expr(rng: random.Random, depth: int = 0) -> sp.Expr:
    """A random expression of the generated kernels' grammar: sums, products, quotients, integer
    and half-integer powers, rationals, floats, the math functions and a removable-singularity
    helper."""
    if depth > 3 or rng.random() < 0.25:
        return rng.choice([*X, sp.Rational(rng.randint(-7, 7), rng.randint(1, 5)), sp.Float(rng.uniform(-3, 3)),
                           sp.Integer(rng.randint(-4, 4))])
    kind = rng.randrange(8)
    a, b = _random_expr(rng, depth + 1), _random_expr(rng, depth + 1)
    if kind == 0:
        return a + b
    if kind == 1:
        return a * b
    if kind == 2:
        return a - b * rng.choice(X)
    if kind == 3:
        return a / (b + rng.choice(X))
    if kind == 4:
        return (a + rng.choice(X)) ** rng.choice([2, 3, -1, -2, sp.Rational(1, 2), sp.Rational(3, 2),
                                                  sp.Rational(-1, 2), sp.Rational(-3, 2), 4])
    if kind == 5:
        return rng.choice([sp.sin, sp.cos, sp.exp, sp.log, sp.atan, sp.tanh])(a)
    if kind == 6:
        return sinc_u(a + rng.choice(X))
    return -a * b / rng.choice(X) ** 2


def _same_tree(expr, printer) -> bool:
    tree = kir_build.from_sympy(expr, printer)
    return ast.dump(ast.parse(printer.doprint(expr), mode="eval").body) == ast.dump(kir.to_ast(tree))


@pytest.mark.parametrize("printer", [SCALAR, CHECK, VECTOR], ids=["scalar", "check", "vector"])
def test_trees_are_the_printers_trees_on_random_expressions(printer):
    rng = random.Random(7)
    n = 0
    for _ in range(400):
        e = _random_expr(rng)
        if e.has(sp.zoo, sp.oo, sp.nan, sp.I):       # (a kernel's expressions are real and finite)
            continue
        assert _same_tree(e, printer), (e, printer.doprint(e), kir.python(kir_build.from_sympy(e, printer)))
        n += 1
    assert n > 300


def test_trees_are_the_printers_trees_on_a_scene(monkeypatch):
    """Every expression the lowering of a built-in scene prints (Hénon–Heiles energy-momentum
    and the outer solar system's Störmer–Verlet with its loops over like terms)."""
    seen = []
    real = kir_build.code

    def recording(printer, expr):
        seen.append((printer, expr))
        return real(printer, expr)

    monkeypatch.setattr("methodgen.codegen.lower._code", recording)
    monkeypatch.setattr("methodgen.codegen.lower_loops._code", recording)
    for name, method in (("henon-heiles-2d", "energy-momentum"), ("outer-solar-system", "stormer-verlet")):
        lower(mg.discretize(mg.load_scene(name).system, method), "s" * 64, "m")
    scalar = [(p, e) for p, e in seen if getattr(p, "kir_flavour", None)]
    assert len(scalar) > 100
    assert all(_same_tree(e, p) for p, e in scalar)


def test_negative_control_a_builder_without_the_printers_order_is_caught(monkeypatch):
    """Control for (a): the comparison fails when the builder takes a product's factors in
    SymPy's internal order instead of the printer's."""
    monkeypatch.setattr(sp.Mul, "as_ordered_factors", lambda self, order=None: list(self.args)[::-1])
    rng = random.Random(7)
    exprs = [_random_expr(rng) for _ in range(200)]
    monkeypatch.undo()
    trees = []
    # a fresh printer: the builder it gets builds every tree anew (SCALAR's remembers its trees)
    printer = ScalarPrinter({"fully_qualified_modules": True})
    monkeypatch.setattr(sp.Mul, "as_ordered_factors", lambda self, order=None: list(self.args)[::-1])
    for e in exprs:
        try:
            trees.append((e, kir_build.from_sympy(e, printer)))
        except kir.Unsupported:
            pass
    monkeypatch.undo()
    wrong = [e for e, t in trees
             if ast.dump(ast.parse(SCALAR.doprint(e), mode="eval").body) != ast.dump(kir.to_ast(t))]
    assert wrong


def test_python_text_parses_to_the_tree():
    rng = random.Random(11)
    for _ in range(300):
        e = _random_expr(rng)
        if e.has(sp.zoo, sp.oo, sp.nan, sp.I):
            continue
        t = kir_build.from_sympy(e, SCALAR)
        assert ast.dump(ast.parse(kir.python(t), mode="eval").body) == ast.dump(kir.to_ast(t))
    # the nodes the builder never makes but kernels use: unary minus under a power, integer
    # arithmetic of indices, comparisons, not
    for t in [("**", ("neg", ("v", "a")), ("n", 2)), ("neg", ("**", ("v", "a"), ("n", 2))),
              ("-", ("v", "a"), ("-", ("v", "b"), ("v", "c"))), ("/", ("v", "a"), ("*", ("v", "b"), ("v", "c"))),
              ("**", ("v", "a"), ("**", ("v", "b"), ("v", "c"))), ("**", ("**", ("v", "a"), ("v", "b")), ("v", "c")),
              ("//", ("+", ("v", "i"), ("n", 3)), ("n", 2)), ("%", ("-", ("v", "i"), ("n", 1)), ("v", "n")),
              ("not", ("==", ("-", ("v", "u"), ("v", "u")), ("n", 0.0))), ("&", (">>", ("v", "e"), ("n", 3)), ("n", 7)),
              ("*", ("/", ("n", 1), ("n", 3)), ("v", "x"))]:
        assert ast.dump(ast.parse(kir.python(t), mode="eval").body) == ast.dump(kir.to_ast(t)), kir.python(t)


def _module_kernels():
    from methodgen.codegen.compiled_kernels import kernel_function, stage_kernel

    out = []
    for name, method, opts in (("outer-solar-system", "energy-momentum", {}), ("kepler", "gauss", {"stages": 2}),
                               ("henon-heiles-2d", "stormer-verlet", {"order": 4})):
        ir = lower(mg.discretize(mg.load_scene(name).system, method, **opts), "s" * 64, "m")
        args = ["_z", "_y", "_c", "_g", "_ha", "_hd", "_hb", "_p"]
        out.append(kernel_function("_nb_post", ir.scalar["post"], ir, args, ["_out"], "_hd"))
        if ir.stage:
            out.append(stage_kernel("_nb_resjac", ir, "resjac"))
    return out


def test_functions_print_as_their_definitions():
    """A kernel function's printed Python parses to the FunctionDef the translator reads."""
    for fn in _module_kernels():
        assert fn is not None
        text = "\n".join(kir.function_lines(fn))
        assert ast.dump(ast.parse(text).body[0]) == ast.dump(kir.function_def(fn))


def test_tables_give_back_their_trees_and_keep_constants_apart():
    for fn in _module_kernels():
        table, (root,) = kir.flatten([fn])
        assert repr(kir.unflatten(table, root)) == repr(fn)
    fn = kir.function("k", ("_y",), [("=", ("v", a), ("n", v)) for a, v in (("a", 0), ("b", 0.0), ("c", -0.0))])
    table, (root,) = kir.flatten([fn])
    values = [st[2][1] for st in kir.unflatten(table, root)[3]]
    assert [(type(v), repr(v)) for v in values] == [(int, "0"), (float, "0.0"), (float, "-0.0")]


def test_digest_changes_with_any_constant():
    fn = _module_kernels()[0]
    assert kir.digest(fn) == kir.digest(kir.unflatten(*[(t, r) for t, (r,) in [kir.flatten([fn])]][0]))  # control
    table, (root,) = kir.flatten([fn])
    i = next(k for k, entry in enumerate(table) if entry[0] == "n" and entry[1] not in (0, 1, 2))
    edited = list(table)
    v = table[i][1]
    edited[i] = ("n", v + 1 if isinstance(v, int) else v * (1 + 2 ** -52))   # one constant: one more, one ulp
    assert kir.digest(kir.unflatten(tuple(edited), root)) != kir.digest(fn)


@pytest.mark.parametrize("scene, method, opts", [
    ("outer-solar-system", "energy-momentum", {}),      # loops over like terms
    ("pendulum", "rattle", {}),                         # constraints, projection
    ("kepler", "gauss", {"stages": 2}),                 # stage loops
    ("henon-heiles", "kahan", {}),                      # linearly implicit
    ("kepler", "stormer-verlet", {"order": 4}),         # composition, first-same-as-last, block kernel
])
def test_every_compiled_kernel_is_a_tree(scene, method, opts):
    """A compiled module's kernels all carry their tables (there is no text route).  Control: a
    kernel whose expression has no tree is refused by name."""
    from methodgen.codegen.emit import render

    ir = lower(mg.discretize(mg.load_scene(scene).system, method, **opts), "s" * 64, "m")
    text = render(ir, "numba")
    kernels = re.findall(r"^def (_nb_\w+|_py_post_block)\(", text, re.M)
    assert kernels
    for name in kernels:
        assert f"_KIR{name} = (" in text, name
    assert not re.search(r"^@_(kernel|inline|jit)\b", text, re.M)
    # control: the same module with one expression left as SymPy's text
    post = ir.scalar["post"]
    var, code = post.temps[0] if post.temps else (None, None)
    if var is not None:
        bad = dataclasses.replace(ir, scalar={**ir.scalar, "post": dataclasses.replace(
            post, temps=((var, str(code)),) + post.temps[1:])})
        with pytest.raises(mg.GenerationError, match="cannot print the kernel _nb_post"):
            render(bad, "numba")


@pytest.mark.parametrize("key", ["tree", "name"])
def test_a_lattice_module_regenerated_at_one_path_runs_its_own_kernel(tmp_path, monkeypatch, key):
    """Two lattices of one shape (another coupling) built in a row at one path, compiled: each
    run is its numpy module's (the site kernel is compiled from its tree, keyed by its digest).
    Control (``key="name"``): with the machine code keyed by the kernel's name instead, the
    second lattice runs the first one's kernel and the comparison fails."""
    pytest.importorskip("llvmlite")
    from methodgen.codegen import llvmcache

    if key == "name":
        monkeypatch.setattr(llvmcache, "_function_part", lambda fn: "fn:" + getattr(fn, "py_func", fn).__name__)
    import numpy as np

    from methodgen.codegen.lattice_emit import build_lattice
    from methodgen.problem.lattice import Lattice

    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    n = 16
    y0 = np.r_[np.sin(np.arange(n) * 0.7), 0.3 * np.cos(np.arange(n) * 1.3)]
    for k in (1, 3):
        lat = Lattice(f"Sum(p[i]**2/2, i, 1, N) + Sum({k}*(q[i % N + 1] - q[i])**2/2, i, 1, N) "
                      "+ Sum(1 - cos(q[i]), i, 1, N)", name="lat")
        c = build_lattice(lat, "avf", tmp_path / "c.py", backend="compiled")
        a = build_lattice(lat, "avf", tmp_path / f"a{k}.py")
        err = np.max(np.abs(c.integrate(y0, 0.05, 40) - a.integrate(y0, 0.05, 40)))
        if key == "tree" or k == 1:
            assert err < 1e-12, (k, err)
        else:
            assert err > 1e-3, err           # the stale kernel: another coupling
