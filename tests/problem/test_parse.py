"""The safe expression parser: accepted grammar, refused input, no evaluation."""

from __future__ import annotations

import pytest
import sympy as sp

import methodgen as mg
from methodgen.errors import InputError, ParseError
from methodgen.problem.parse import parse_expr

X, Y = sp.symbols("x y", real=True)
SYMS = {"x": X, "y": Y}


def test_arithmetic_and_functions():
    e = parse_expr("x**2/2 - 3*sqrt(x*y) + exp(-y) + sin(pi*x)", SYMS)
    assert sp.simplify(e - (X**2 / 2 - 3 * sp.sqrt(X * Y) + sp.exp(-Y) + sp.sin(sp.pi * X))) == 0


def test_float_literals_become_exact_rationals():
    e = parse_expr("0.1*x + 2.5", SYMS)
    assert e == sp.Rational(1, 10) * X + sp.Rational(5, 2)
    assert not e.atoms(sp.Float)


@pytest.mark.parametrize("text, fragment", [
    ("x +", "syntax error"),
    ("x + z", "unknown symbol 'z'"),
    ("x.real", "attribute access"),
    ("x[0]", "subscripting"),
    ("(lambda: 1)()", "only direct calls"),
    ("lambda x: x", "lambda"),
    ("foo(x)", "unknown function 'foo'"),
    ("sqrt(x, y)", "exactly one positional argument"),
    ("sqrt", "must be called"),
    ("__import__('os').system('true')", "only direct calls"),
    ("__class__", "not allowed"),
    ("'abc'", "not a real number"),
    ("(x, y)", "tuple"),
    ("x < y", "comparison"),
    ("9**9**9", "exponent"),
    ("x // y", "operator FloorDiv"),
    ("sqrt(-1)*x", "not a finite real"),
    ("x/0", "division by zero"),
    ("", "empty"),
])
def test_refused(text, fragment):
    with pytest.raises(ParseError) as err:
        parse_expr(text, SYMS)
    assert fragment in str(err.value)


def test_hostile_text_is_never_executed(tmp_path):
    marker = tmp_path / "pwned"
    payloads = [
        f"__import__('os').system('touch {marker}')",
        f"exp(__import__('os').system('touch {marker}'))",
        f"[c for c in ().__class__.__base__.__subclasses__()]",
        f"x + eval(\"__import__('os').system('touch {marker}')\")",
    ]
    for text in payloads:
        with pytest.raises(ParseError):
            parse_expr(text, SYMS)
    # Negative control for the check itself: the marker *can* be created.
    assert not marker.exists()
    marker.touch()
    assert marker.exists()


@pytest.mark.parametrize("name", ["lambda", "class", "_x", "__x__", "1x", "x-y", "sqrt", "pi", "match"])
def test_bad_symbol_names(name):
    with pytest.raises(ParseError):
        mg.Hamiltonian("p**2/2", q=[name], p=["p"])


def test_names_that_collide_with_printer_and_python_names_work():
    # e, E, I, N, S, beta, gamma, sum, np are fine as *symbols*: they are never
    # interpreted by SymPy (no sympify) and are renamed in generated code.
    names = ["E", "I", "N", "S", "beta", "gamma", "sum", "np", "e", "numpy", "math"]
    text = " + ".join(f"{n}*q**2" for n in names) + " + p**2/2"
    sys_ = mg.Hamiltonian(text, q=["q"], p=["p"], params={n: 1.0 for n in names})
    assert len(sys_.params) == len(names)
    assert sys_.H.free_symbols == set(sys_.q) | set(sys_.p) | set(sys_.params)


def test_sympy_input_and_undeclared_symbols():
    q, p, k, z = sp.symbols("q p k z")
    sys_ = mg.Hamiltonian(p**2 / 2 + k * q**2 / 2, q=[q], p=[p], params={"k": 2.0})
    assert all(s.is_real for s in sys_.H.free_symbols)
    with pytest.raises(InputError, match="unknown symbol 'z'"):
        mg.Hamiltonian(p**2 / 2 + z * q**2, q=[q], p=[p])


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(H="p**2/2 + q**2", q=["q"], p=["p", "r"]), "each coordinate needs one momentum"),
    (dict(H="p**2/2 + q**2", q=["q"], p=["q"]), "declared twice"),
    (dict(H="q**2", q=["q"], p=["p"]), "does not depend on any momentum"),
    (dict(H="p**2/2 + k*q**2", q=["q"], p=["p"], params={"k": float("nan")}), "finite"),
    (dict(H="p**2/2 + k*q**2", q=["q"], p=["p"], params={"k": "1"}), "real number"),
    (dict(H="p**2/2 + k*q**2", q=["q"], p=["p"]), "unknown symbol 'k'"),
    (dict(H="p**2/2 + q**2", q="q", p=["p"]), "list of names"),
    (dict(H="p**2/2 + q**2", q=[], p=[]), "at least one coordinate"),
])
def test_bad_hamiltonians(kwargs, fragment):
    with pytest.raises(InputError, match=fragment):
        mg.Hamiltonian(**kwargs)


@pytest.mark.parametrize("text, fragment", [
    ("sqrt(x**2)", "Abs(x) is not smooth"),
    ("(x**2)**(3/2) + y", "Abs(x) is not smooth"),
    ("abs(x)", "abs(x) is not smooth"),
    ("Max(x, y)", "Max(x, y) is not smooth"),
    ("Heaviside(x)", "Heaviside(x) is not smooth"),
])
def test_non_smooth_text_is_refused_with_the_reason(text, fragment):
    with pytest.raises(ParseError) as err:
        parse_expr(text, SYMS)
    assert fragment in str(err.value) and "smooth H" in str(err.value)


def test_rational_powers_of_signed_expressions_are_smooth_and_accepted():
    e = parse_expr("x**(1/3) + (x - y)**(3/2) + sqrt(x**4) + sqrt(x**2 + y**2)", SYMS)
    assert not e.has(sp.Abs)


def test_long_sums_and_products_are_not_deep():
    """A chain of 64 particles is a sum of ~130 terms: Python parses it as a left-leaning
    chain, which must not count as nesting (it did: "nested deeper than 60 levels")."""
    q = sp.symbols("q0:100", real=True)
    names = {s.name: s for s in q}
    text = " + ".join(f"(q{i + 1} - q{i})**4" for i in range(99)) + " - q0*q1*" + "*".join(f"q{i}" for i in range(2, 99))
    e = parse_expr(text, names)
    assert e == sp.Add(*[(q[i + 1] - q[i])**4 for i in range(99)]) - sp.Mul(*q[:99])
    # negative control: real nesting is still limited
    with pytest.raises(ParseError, match="deeper than"):
        parse_expr("(" * 80 + "q0" + ")**2" * 80, names)
    with pytest.raises(ParseError, match="deeper than"):
        parse_expr("sin(" * 80 + "q0" + ")" * 80, names)


def test_flattened_chains_give_the_nested_expressions():
    """Walking a chain iteratively changes nothing: the same SymPy expression, structurally,
    as the operators applied pairwise left to right (SymPy distributes a number over a sum
    only in a two-factor product, so the order of folding is visible)."""
    x, y, z = sp.symbols("x y z", real=True)
    names = {"x": x, "y": y, "z": z}
    for text, want in (("2*(y+1)*x", (2 * (y + 1)) * x), ("2*(x+y)*(x-y)", (2 * (x + y)) * (x - y)),
                       ("x - y - z", (x - y) - z), ("x - (y - z)", x - (y - z)), ("-x - y", -x - y),
                       ("x*y/z*x", ((x * y) / z) * x), ("3*(x+1) + 2*(y+1)*z", 3 * (x + 1) + (2 * (y + 1)) * z)):
        got = parse_expr(text, names)
        assert got == want and sp.srepr(got) == sp.srepr(want), text
