"""Non-smooth input is refused at Hamiltonian(...): text and SymPy, H and constraints.

A discrete gradient (and the exact proofs of methodgen.verify) need a smooth H:
Abs, Max, Min, sign, Heaviside, Piecewise, floor, … are refused with one line
naming the function and the reason — also when SymPy produces them itself, as
``sqrt(q**2) -> Abs(q)`` and ``(q**2)**(3/2) -> q**2*Abs(q)`` for real q.
"""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
import sympy as sp

import methodgen as mg
from methodgen.errors import InputError, ParseError
from methodgen.problem.parse import check_smooth

q, p, x, y = sp.symbols("q p x y")  # plain symbols, as a user would write them

# (text, SymPy expression, name the message must contain)
REFUSED = [
    ("Abs(q)", sp.Abs(q), "Abs"),
    ("abs(q - 1)", sp.Abs(q - 1), "Abs"),
    ("Max(q, 0)**2", sp.Max(q, 0) ** 2, "Max"),
    ("Min(q, 1)", sp.Min(q, 1), "Min"),
    ("sign(q)*q", sp.sign(q) * q, "sign"),
    ("Heaviside(q)", sp.Heaviside(q), "Heaviside"),
    ("Piecewise(q)", sp.Piecewise((q**2, q > 0), (0, True)), "Piecewise"),
    ("floor(q)", sp.floor(q), "floor"),
    ("sqrt(q**2)", sp.sqrt(q**2), "Abs"),
    ("(q**2)**(3/2)", (q**2) ** sp.Rational(3, 2), "Abs"),
]


def _hamiltonian(U, **kw):
    H = f"p**2/2 + {U}" if isinstance(U, str) else p**2 / 2 + U
    return mg.Hamiltonian(H, q=["q"], p=["p"], **kw)


@pytest.mark.parametrize("text, expr, name", REFUSED, ids=[r[0] for r in REFUSED])
def test_refused_as_text(text, expr, name):
    with pytest.raises(ParseError) as err:
        _hamiltonian(text)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith("Hamiltonian")
    assert name in msg or name.lower() in msg
    assert "not smooth" in msg and "a discrete gradient needs a smooth H" in msg


@pytest.mark.parametrize("text, expr, name", REFUSED, ids=[r[0] for r in REFUSED])
def test_refused_as_sympy(text, expr, name):
    with pytest.raises(InputError) as err:
        _hamiltonian(expr)
    msg = str(err.value)
    assert "\n" not in msg
    assert f"{name}(" in msg
    assert "not smooth" in msg and "a discrete gradient needs a smooth H" in msg


def test_abs_message_explains_sqrt_of_square_and_suggests_a_fix():
    with pytest.raises(ParseError) as err:
        _hamiltonian("sqrt(q**2)")
    msg = str(err.value)
    assert "Abs(q)" in msg and "kink" in msg and "sqrt(q**2) is Abs(q)" in msg
    assert "write q**2 or sqrt(q**2 + eps**2)" in msg


@pytest.mark.parametrize("expr, fragment", [
    (sp.ceiling(q), "ceiling(q) is not smooth"),
    (sp.frac(q), "frac(q) is not smooth"),
    (sp.DiracDelta(q), "DiracDelta(q) is not smooth"),
    (sp.arg(q), "arg(q) is not smooth"),
    (sp.asin(q), "function asin"),
    (sp.Function("f")(q), "function f"),
    (sp.EulerGamma * q, "EulerGamma"),
])
def test_other_nodes_are_refused_with_their_name(expr, fragment):
    with pytest.raises(InputError, match=re.escape(fragment)) as err:
        _hamiltonian(expr)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("g", ["sqrt(x**2) - 1", sp.Abs(x) - 1, sp.Max(x, y) - 1])
def test_constraints_are_checked_too(g):
    with pytest.raises(InputError, match=r"constraint 1: .* is not smooth") as err:
        mg.Hamiltonian("(px**2 + py**2)/2 + y", q=["x", "y"], p=["px", "py"], constraints=[g])
    assert "Jacobian" in str(err.value)


def test_check_smooth_directly():
    X = sp.Symbol("X", real=True)
    with pytest.raises(ParseError, match="Abs"):
        check_smooth(sp.sqrt(X**2) + X, "potential")
    assert check_smooth(X**2, "potential") == X**2


# --- negative control: smooth input with every allowed function is accepted ---------------

SMOOTH_TEXT = ("p**2/2 + exp(-q) + log(1 + q**2) + sin(q) + cos(2*q) + tan(q/4) + sinh(q/3) + cosh(q/5)"
               " + tanh(q) + atan(q) + sqrt(1 + q**2) + q**(1/3) + (q - 1)**(3/2) + 2**q + pi*q + 0.1*q**4"
               " + sqrt(q**4) + k*q**2")


def test_smooth_text_with_every_allowed_function_is_accepted():
    h = _hamiltonian(SMOOTH_TEXT.removeprefix("p**2/2 + "), params={"k": 1.0})
    funcs = {type(f) for f in h.H.atoms(sp.Function)}
    assert funcs == {sp.exp, sp.log, sp.sin, sp.cos, sp.tan, sp.sinh, sp.cosh, sp.tanh, sp.atan}
    assert not h.H.has(sp.Abs)


def test_smooth_sympy_with_every_allowed_function_is_accepted():
    k = sp.Symbol("k")
    U = (sp.exp(-q) + sp.log(1 + q**2) + sp.sin(q) + sp.cos(2 * q) + sp.tan(q / 4) + sp.sinh(q / 3)
         + sp.cosh(q / 5) + sp.tanh(q) + sp.atan(q) + sp.sqrt(1 + q**2) + q ** sp.Rational(1, 3)
         + (q - 1) ** sp.Rational(3, 2) + 2**q + sp.pi * q + sp.E * q + k * q**2 + sp.exp(1) * q**3)
    h = _hamiltonian(U, params={"k": 1.0})
    assert h.H.has(sp.atan) and h.H.has(sp.E)
    # Floats in SymPy input are kept as they were (number handling unchanged).
    hf = _hamiltonian(sp.Float("0.25") * q**2)
    assert hf.H.has(sp.Float)


def test_smooth_constraint_is_accepted():
    sys_ = mg.Hamiltonian("(px**2 + py**2)/2 + y", q=["x", "y"], p=["px", "py"],
                          constraints=["sqrt(x**2 + y**2) - 1"])
    assert len(sys_.constraints) == 1


@pytest.mark.parametrize("name", ["pendulum", "kepler", "double-pendulum", "simple-pendulum"])
def test_builtin_scenes_are_smooth(name):
    system = mg.load_scene(name).system
    check_smooth(system.H, "Hamiltonian")
    for g in system.constraints:
        check_smooth(g, "constraint")


# --- the command line ------------------------------------------------------------------------

def test_cli_refuses_non_smooth_scene_with_one_line(tmp_path):
    f = tmp_path / "kink.toml"
    f.write_text('name = "kink"\n[system]\nH = "p**2/2 + sqrt(q**2)"\nq = ["q"]\np = ["p"]\n'
                 '[run]\nmethod = "energy-momentum"\nh = 0.05\nsteps = 20\ny0 = [0.1, 0.5]\n')
    res = subprocess.run([sys.executable, "-m", "methodgen", "run", str(f)], capture_output=True, text=True)
    assert res.returncode == 2
    assert "Traceback" not in res.stderr and res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "Abs(q) is not smooth" in lines[0] and "discrete gradient" in lines[0]
