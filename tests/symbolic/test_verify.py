"""The exact verification layer: proofs, refutations (negative controls), numerics, CLI."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import sympy as sp

import methodgen as mg
import methodgen.symbolic.verify  # noqa: F401  (makes mg.verify callable)
from methodgen.symbolic.verify.conjugacy import conjugacy_certificate
from methodgen.symbolic.verify.discrete_gradients import dg_identity, kappa_midpoint_gradient
from methodgen.symbolic.verify.invariants import angular_momentum_generic
from methodgen.symbolic.verify.kahan import forms_agree_generic, modified_energy
from methodgen.symbolic.verify.maps import symplectic_certificate


@pytest.fixture(scope="module")
def kepler():
    return mg.load_scene("kepler").system


def _status(report, text):
    found = report.find(text)
    assert found, f"no certificate mentioning {text!r} in {report}"
    return {c.status for c in found}


def _no_float(cert):
    assert "Float" not in sp.srepr(sp.sympify(cert.expression)) if cert.expression else True


# --- positive claims ------------------------------------------------------------

def test_energy_momentum_kepler_all_proved(kepler):
    rep = mg.verify(mg.discretize(kepler, "energy-momentum"))
    assert rep.ok and rep.all_passed
    assert {c.status for c in rep.certificates} == {"proved"}
    assert _status(rep, "discrete-gradient identity") == {"proved"}
    assert _status(rep, "consistency") == {"proved"}
    assert _status(rep, "notes' κ") == {"proved"}
    for name in ("Lx", "Ly", "Lz"):                       # claim 3
        assert _status(rep, f"{name}(y1) = {name}(y0)") == {"proved"}
    assert any("Ex. 1.1.3" in c.ref for c in rep.certificates)


def test_generic_radial_potential_angular_momentum():
    certs = angular_momentum_generic(3)
    assert len(certs) == 3 and all(c.status == "proved" for c in certs)


@pytest.mark.parametrize("scene,method", [("simple-pendulum", "itoh-abe"), ("simple-pendulum", "gonzalez"),
                                          ("double-well", "avf"), ("double-well", "gonzalez")])
def test_discrete_gradient_methods_proved(scene, method):
    rep = mg.verify(mg.discretize(mg.load_scene(scene).system, method))
    assert rep.ok
    assert _status(rep, "discrete-gradient identity") == {"proved"}
    assert _status(rep, "consistency") == {"proved"}
    assert _status(rep, "symmetric") == {"proved"}


def test_avf_quadrature_is_numerical_never_proved():
    system = mg.Hamiltonian("p**2/2 + exp(q*p)/10", ["q"], ["p"])
    scheme = mg.discretize(system, "avf")
    cert = dg_identity(system, scheme.discrete_gradient, "avf")
    assert cert.status == "numerical" and cert.details["passed"]
    assert "tolerance" in cert.details and cert.details["sample_points"]


def test_conjugacy_any_dimension():
    for n in (1, 3, 6):
        assert conjugacy_certificate(n).status == "proved"


def test_kahan_claims_henon_heiles():
    rep = mg.verify(mg.discretize(mg.load_scene("henon-heiles").system, "kahan"))
    assert rep.ok and {c.status for c in rep.certificates} == {"proved"}
    assert _status(rep, "modified energy") == {"proved"}
    assert _status(rep, "volume form") == {"proved"}
    assert forms_agree_generic(3).status == "proved"


def test_quadratic_midpoint_symplectic_and_retimed():
    rep = mg.verify(mg.discretize(mg.load_scene("linear").system, "midpoint"))
    assert _status(rep, "symplectic") == {"proved"}
    cert = rep.find("exact flow at time")[0]
    assert cert.status == "proved"
    assert cert.details["omega"] == "sqrt(26)"
    assert "atan" in cert.details["omega_h"]


def test_rattle_pendulum():
    rep = mg.verify(mg.discretize(mg.load_scene("pendulum").system, "rattle"))
    assert rep.ok and rep.all_passed
    assert _status(rep, "g(q1) = 0") == {"proved"}
    assert _status(rep, "G(q1) M⁻¹ p1 = 0") == {"proved"}
    assert _status(rep, "self-adjoint") == {"proved"}
    sym = rep.find("symplectic on T*Q")[0]
    assert sym.status == "numerical" and sym.details["passed"] and sym.details["tolerance"] > 0


def test_builtin_scenes_ok_and_fast():
    for name in ("kepler", "simple-pendulum", "linear"):
        scene = mg.load_scene(name)
        for m in scene.methods:
            rep = mg.verify(mg.discretize(scene.system, m))
            assert rep.ok and rep.all_passed, str(rep)
            assert rep.seconds < 30


# --- negative controls -----------------------------------------------------------

def test_midpoint_on_kepler_is_not_a_discrete_gradient(kepler):
    scheme = mg.discretize(kepler, "midpoint")
    cert = dg_identity(kepler, scheme.discrete_gradient, "midpoint")
    assert cert.status == "refuted"
    point = {sp.Symbol(k, real=True): sp.Rational(v) for k, v in cert.details["counterexample"].items()}
    value = sp.sympify(cert.expression, locals={s.name: s for s in point}).xreplace(
        {s: point[s] for s in point})
    assert sp.nsimplify(value) != 0   # the counterexample really is one


def test_kappa_one_refuted(kepler):
    cert = dg_identity(kepler, kappa_midpoint_gradient(kepler, kappa=1), "κ ≡ 1")
    assert cert.status == "refuted" and "counterexample" in cert.details
    assert dg_identity(kepler, kappa_midpoint_gradient(kepler), "notes κ").status == "proved"


def test_trapezoidal_not_symplectic_on_cubic_h():
    scheme = mg.discretize(mg.load_scene("henon-heiles").system, "trapezoidal")
    cert = symplectic_certificate(scheme)
    assert cert.status == "refuted" and "counterexample" in cert.details


@pytest.mark.parametrize("a", [1, 0, sp.Rational(1, 4)])
def test_wrong_conjugating_map_refuted(a):
    cert = conjugacy_certificate(2, a)
    assert cert.status == "refuted" and cert.details["counterexample"]


def test_wrong_modified_energy_refuted():
    system = mg.load_scene("henon-heiles").system
    cert = modified_energy(system, Ht=system.H)   # H itself is not preserved by Kahan
    assert cert.status == "refuted"


def test_report_ok_false_when_refuted(kepler):
    from methodgen.symbolic.verify import Report
    cert = dg_identity(kepler, kappa_midpoint_gradient(kepler, kappa=1), "κ ≡ 1")
    rep = Report("negative control", [cert])
    assert not rep.ok
    assert json.loads(rep.to_json())["ok"] is False


# --- rendering and CLI ------------------------------------------------------------

def test_renderers(kepler):
    rep = mg.verify(mg.discretize(kepler, "energy-momentum"))
    d = rep.to_dict()
    assert set(d) >= {"ok", "certificates"}
    for c in d["certificates"]:
        assert {"claim", "status", "seconds"} <= set(c) and c["status"] in ("proved", "refuted", "numerical")
    assert "| # | claim |" in rep.markdown()
    assert r"\begin{description}" in rep.latex()
    # a notebook renders the report (IPython's display protocol): its Markdown
    assert rep._repr_markdown_() == rep.markdown()


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "methodgen", *args], capture_output=True, text=True,
                          timeout=120)


def test_cli_json():
    r = _cli("verify", "harmonic", "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["ok"] is True and d["certificates"]
    assert all(c["status"] in ("proved", "refuted", "numerical") for c in d["certificates"])


def test_cli_errors():
    r = _cli("verify", "no-such-scene")
    assert r.returncode == 2 and r.stderr.startswith("methodgen: error:") and "Traceback" not in r.stderr
    r = _cli("verify", "kepler", "--method", "rattle")
    assert r.returncode == 2 and "Traceback" not in r.stderr


_TEXT_OF_A_LONG_SUM = """
import sympy as sp
from methodgen.symbolic.verify.exact import expression_text
x = sp.symbols("x0:120", real=True)
e = sp.Add(*[sp.exp(x[i] - x[i + 1]) * (x[i + 1] - x[i]) for i in range(119)])
print(expression_text(e))
"""


def test_long_expressions_are_printed_fast_and_deterministically():
    """Certificates of sums over many instances print in SymPy's internal term order (no sort):
    the same text whatever the hash seed, and the same expression; small ones keep str()."""
    import subprocess
    import sys

    import sympy as sp

    from methodgen.symbolic.verify.exact import expression_text

    texts = {subprocess.run([sys.executable, "-c", _TEXT_OF_A_LONG_SUM], capture_output=True, text=True, check=True,
                            env={**__import__("os").environ, "PYTHONHASHSEED": seed}).stdout
             for seed in ("1", "2", "3")}
    assert len(texts) == 1
    x = sp.symbols("x0:120", real=True)
    e = sp.Add(*[sp.exp(x[i] - x[i + 1]) * (x[i + 1] - x[i]) for i in range(119)])
    assert sp.parse_expr(texts.pop(), local_dict={str(s): s for s in x}) == e   # our own output, not user text
    small = x[0] ** 2 + 3 * x[1] - x[2]
    assert expression_text(small) == str(small)
    # control: the harness sees a text that depends on the hash seed (a set of strings)
    hashed = "print(list({f'x{i}' for i in range(120)}))"
    assert len({subprocess.run([sys.executable, "-c", hashed], capture_output=True, text=True, check=True,
                               env={**__import__("os").environ, "PYTHONHASHSEED": seed}).stdout
                for seed in ("1", "2", "3")}) > 1
