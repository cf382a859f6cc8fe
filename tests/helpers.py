"""Test helpers shared by several test files."""

from __future__ import annotations

import functools
import importlib.util
import tempfile
from pathlib import Path
from types import SimpleNamespace

from methodgen.codegen.emit import _environment
from methodgen.problem.problem import Hamiltonian
from methodgen.problem.special import SPECIAL_FUNCTIONS


@functools.lru_cache(maxsize=None)
def special_helpers() -> dict:
    """The removable-singularity helpers exactly as templates/_special.py.j2 emits them."""
    names = tuple(sorted(v[1:] for v in SPECIAL_FUNCTIONS.values()))
    text = "import math\nimport numpy\n" + _environment().get_template("_special.py.j2").render(
        ir=SimpleNamespace(helpers=names))
    path = Path(tempfile.mkdtemp()) / "special_helpers.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("special_helpers", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return {k: getattr(mod, k) for k in dir(mod) if k.startswith(("_f_", "_v_"))}


def oracle_namespace() -> dict:
    """Numerical implementations keyed by the SymPy function names, for lambdify oracles."""
    helpers = special_helpers()
    return {cls.__name__: helpers["_v" + name] for cls, name in SPECIAL_FUNCTIONS.items()}


def fpu_chain(n):
    """A Fermi-Pasta-Ulam-beta chain of n unit masses between fixed walls: the nearest-neighbour
    springs (n - 1 of them) form one family, the two wall springs others."""
    q = [f"q{i}" for i in range(n)]
    springs = [f"(q{i + 1} - q{i})**2/2 + beta*(q{i + 1} - q{i})**4/4" for i in range(n - 1)]
    walls = ["q0**2/2 + beta*q0**4/4", f"q{n - 1}**2/2 + beta*q{n - 1}**4/4"]
    T = " + ".join(f"p{i}**2/2" for i in range(n))
    return Hamiltonian(" + ".join([T] + springs + walls), q=q, p=[f"p{i}" for i in range(n)],
                       params={"beta": 0.7}, name=f"fpu{n}")


# --- the CLI tests' shared pieces ------------------------------------------------------------------

#: A time-dependent scene (forced oscillator) starting at t0 = 0.5.
FORCED_SCENE = """name = "forced"
[system]
H = "p**2/2 + x**2/2 - F*x*cos(t)"
q = ["x"]
p = ["p"]
time = "t"
[params]
F = 0.5
[run]
method = "midpoint"
h = 0.05
steps = 20
y0 = [1.0, 0.0]
t0 = 0.5
"""


def cli_main(capsys, *argv):
    """Run ``methodgen argv`` in-process: (exit code, stdout, stderr)."""
    import methodgen.app.cli as cli
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line(err: str) -> str:
    """The single line of ``err`` (asserting one line and no traceback)."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def strict_json(text):
    """``json.loads`` refusing NaN and Infinity (a report must say null, never NaN)."""
    import json

    def refuse(token):
        raise AssertionError(f"{token} in the JSON output")
    return json.loads(text, parse_constant=refuse)
