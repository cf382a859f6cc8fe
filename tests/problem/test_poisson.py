"""Poisson systems y' = S(y)∇H (issue 15 item 4): construction, structure checks, Casimirs,
the generated midpoint / discrete-gradient / Kahan modules against DOP853, and the
certificates with a negative control each."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.symbolic.derive import invariants, vector_field
from methodgen.symbolic.verify.exact import Domain, certify
from methodgen.symbolic.verify.invariants import invariant_preserved
from methodgen.symbolic.schemes.base import STEP
from methodgen.symbolic.verify.kahan import modified_energy_expr, modified_energy_structural
from methodgen.symbolic.verify.poisson import (casimir_certificate, jacobi_certificate, kahan_conditions,
                                      skew_certificate, structure_symmetry)

RB_H = "m1**2/(2*I1) + m2**2/(2*I2) + m3**2/(2*I3)"
RB_S = [["0", "-m3", "m2"], ["m3", "0", "-m1"], ["-m2", "m1", "0"]]
RB_PARAMS = {"I1": 2.0, "I2": 1.0, "I3": 2.0 / 3.0}
RB_Y0 = np.array([np.cos(1.1), 0.0, np.sin(1.1)])
#: skew, but not Poisson: S_ij = -ε_ijk v_k with v = (m2, m3, m1), v·curl v = -(m1 + m2 + m3) ≠ 0
ALMOST_S = [["0", "-m1", "m3"], ["m1", "0", "-m2"], ["-m3", "m2", "0"]]
LV_H = "u - log(u) + v - 2*log(v)"
LV_S = [["0", "u*v"], ["-u*v", "0"]]


@pytest.fixture(scope="module")
def rigid():
    return mg.PoissonSystem(RB_H, y=["m1", "m2", "m3"], S=RB_S, params=RB_PARAMS, name="rb")


@pytest.fixture(scope="module")
def lotka():
    return mg.PoissonSystem(LV_H, y=["u", "v"], S=LV_S, name="lv")


@pytest.fixture(scope="module")
def almost():
    return mg.PoissonSystem("m1**2/2 + m2**2 + m3**2/3", y=["m1", "m2", "m3"], S=ALMOST_S, name="almost")


@pytest.fixture(scope="module")
def modules(tmp_path_factory, rigid, lotka, almost):
    """Generated modules, built once: {(system name, method): module}."""
    out = {}
    folder = tmp_path_factory.mktemp("poisson")
    for system, methods in ((rigid, ("avf", "gonzalez", "midpoint", "kahan")), (lotka, ("avf", "gonzalez")),
                            (almost, ("avf",))):
        for m in methods:
            out[system.name, m] = mg.generate(mg.discretize(system, m), path=folder / f"{system.name}_{m}.py")
    return out


def _rhs(system):
    f = sp.lambdify(list(system.y), list(vector_field(system).xreplace(
        {s: system.param_values[s.name] for s in system.params})), "numpy")
    return lambda t, y: f(*y)


def _dop853(system, y0, T):
    from scipy.integrate import solve_ivp

    return solve_ivp(_rhs(system), (0, T), y0, method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]


# --- construction --------------------------------------------------------------------

def test_non_skew_S_names_the_entry():
    with pytest.raises(mg.InputError, match=r"S\[0\]\[1\] \+ S\[1\]\[0\] = 2\*u is not 0 \(rows u, v\)"):
        mg.PoissonSystem("u + v", y=["u", "v"], S=[["0", "u"], ["u", "0"]])
    with pytest.raises(mg.InputError, match=r"S\[1\]\[1\] = v is not 0"):
        mg.PoissonSystem("u + v", y=["u", "v"], S=[["0", "1"], ["-1", "v"]])


@pytest.mark.parametrize("S, match", [
    ([["0", "1"]], "S has 1 rows but y has 2 names"),
    ([["0", "1"], ["-1"]], "S row 1 has 1 entries"),
    ("[[0, 1], [-1, 0]]", "S must be an n×n list of lists"),
    ([["0", "w"], ["-w", "0"]], "unknown symbol 'w'"),
    ([["0", "0"], ["0", "0"]], "zero matrix"),
    ([["0", "abs(u)"], ["-abs(u)", "0"]], "not smooth"),
])
def test_construction_errors(S, match):
    with pytest.raises(mg.InputError, match=match):
        mg.PoissonSystem("u + v", y=["u", "v"], S=S)


def test_canonical_style_arguments_are_refused():
    with pytest.raises(mg.InputError, match="takes its state as y"):
        mg.PoissonSystem("q*p", q=["q"], p=["p"], S=[["0"]])
    with pytest.raises(mg.InputError, match="at least 2 state variables"):
        mg.PoissonSystem("u**2", y=["u"], S=[["0"]])
    with pytest.raises(mg.InputError, match="declared twice"):
        mg.PoissonSystem("u + v", y=["u", "v"], S=LV_S, params={"u": 1.0})
    with pytest.raises(mg.InputError, match="does not depend on the state"):
        mg.PoissonSystem("a", y=["u", "v"], S=LV_S, params={"a": 1.0})


def test_hamiltonian_without_momenta_points_to_poisson_system():
    with pytest.raises(mg.InputError, match="q has 3 names but p has 0.*PoissonSystem"):
        mg.Hamiltonian("m1**2", q=["m1", "m2", "m3"], p=[])


def test_time_transform_of_a_poisson_system_says_why(rigid):
    with pytest.raises(mg.InputError, match="canonical system.*PoissonSystem it is not implemented"):
        mg.time_transform(rigid, "1 + m1**2")


def test_immutable_and_fingerprint(rigid):
    with pytest.raises(AttributeError):
        rigid.H = 0
    again = mg.PoissonSystem(RB_H, y=["m1", "m2", "m3"], S=RB_S, params=RB_PARAMS, name="rb")
    assert again.fingerprint() == rigid.fingerprint()
    other = mg.PoissonSystem(RB_H, y=["m1", "m2", "m3"], S=ALMOST_S, params=RB_PARAMS, name="rb")
    assert other.fingerprint() != rigid.fingerprint()


# --- structure: Jacobi identity, Casimirs -------------------------------------------

def test_jacobi_proved_for_the_rigid_body_and_refuted_for_an_almost_poisson_S(rigid, almost, lotka):
    assert rigid.jacobi().status == "proved"
    assert lotka.jacobi().status == "proved"          # 2×2: nothing to check
    bad = almost.jacobi()
    assert bad.status == "refuted" and bad.triple == (0, 1, 2)
    assert sp.expand(bad.expression - (almost.y[0] + almost.y[1] + almost.y[2])) == 0


def test_casimirs(rigid, lotka):
    m1, m2, m3 = rigid.y
    assert [(c.name, sp.expand(c.expr)) for c in rigid.casimirs()] == [("C", m1**2 + m2**2 + m3**2)]
    assert lotka.casimirs() == ()
    # a linear Casimir (kernel of a constant S); its square is not listed again
    lin = mg.PoissonSystem("a**2 + b**3 + c", y=["a", "b", "c"],
                           S=[["0", "1", "-1"], ["-1", "0", "1"], ["1", "-1", "0"]])
    a, b, c = lin.y
    assert [sp.expand(k.expr) for k in lin.casimirs()] == [a + b + c]
    assert [inv.name for inv in invariants(rigid)] == ["H", "C"]


def test_methods_for_poisson_systems(rigid, lotka):
    assert set(mg.applicable_methods(rigid)) == {"midpoint", "avf", "gonzalez", "itoh-abe", "kahan"}
    assert "kahan" in mg.applicable_methods(lotka)     # f = (u v - 2u, v - u v) is quadratic
    with pytest.raises(mg.MethodNotApplicable, match="needs canonical coordinates"):
        mg.discretize(rigid, "stormer-verlet")
    with pytest.raises(mg.MethodNotApplicable, match="one-step form is not generated"):
        mg.discretize(rigid, "kahan", form="rk")
    for m in ("avf", "gonzalez", "midpoint", "itoh-abe"):
        t = mg.discretize(rigid, m).traits
        assert set(t.preserved) == {"H", "C"} and not t.symplectic
    assert mg.discretize(rigid, "kahan").traits.preserved == ()


# --- generated modules against DOP853 -------------------------------------------------

@pytest.mark.parametrize("method", ["avf", "gonzalez"])
def test_rigid_body_discrete_gradient_keeps_H_and_C_to_roundoff(modules, method):
    mod = modules["rb", method]
    assert mod.STATE_NAMES == ("m1", "m2", "m3") and mod.Q_NAMES == () and mod.P_NAMES == ()
    assert mod.CASIMIR_NAMES == ("C",) and mod.JACOBI_IDENTITY == "proved"
    assert mod.STRUCTURE_MATRIX == tuple(tuple(r) for r in RB_S)
    traj = mod.integrate(RB_Y0, 0.1, 1000)
    inv = mod.invariants(traj)
    assert np.max(np.abs(inv["H"] - inv["H"][0])) < 4e-15
    assert np.max(np.abs(inv["C"] - inv["C"][0])) < 4e-15


@pytest.mark.parametrize("method", ["avf", "gonzalez", "midpoint"])
def test_rigid_body_against_dop853_is_second_order(rigid, modules, method):
    mod = modules["rb", method]
    T = 5.0
    ref = _dop853(rigid, RB_Y0, T)
    errs = [np.max(np.abs(mod.integrate(RB_Y0, T / n, n)[-1] - ref)) for n in (50, 100, 200)]
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(np.abs(rates - 2.0) < 0.1), (errs, rates)
    assert errs[-1] < 1e-3


def test_rigid_body_midpoint_keeps_the_casimir(modules):
    traj = modules["rb", "midpoint"].integrate(RB_Y0, 0.1, 1000)
    C = np.sum(traj**2, axis=1)
    assert np.max(np.abs(C - C[0])) < 4e-15


def test_rigid_body_kahan_keeps_neither_exactly_but_converges(rigid, modules):
    mod = modules["rb", "kahan"]
    assert mod.SOLVERS == ("linear",)
    ref = _dop853(rigid, RB_Y0, 5.0)
    e1, e2 = (np.max(np.abs(mod.integrate(RB_Y0, 5.0 / n, n)[-1] - ref)) for n in (100, 200))
    assert abs(np.log2(e1 / e2) - 2.0) < 0.1
    inv = mod.invariants(mod.integrate(RB_Y0, 0.1, 200))
    assert np.max(np.abs(inv["C"] - 1.0)) > 1e-8     # Kahan is not the midpoint rule here


@pytest.mark.parametrize("method", ["avf", "gonzalez"])
def test_lotka_volterra_keeps_H_to_roundoff(lotka, modules, method):
    mod = modules["lv", method]
    y0 = np.array([1.0, 4.0])
    traj = mod.integrate(y0, 0.05, 1000)
    H = mod.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) < 1e-14 * abs(H[0]) * 10
    ref = _dop853(lotka, y0, 50.0)
    assert np.max(np.abs(traj[-1] - ref)) < 0.05          # h = 0.05: O(h²) phase error
    err = np.max(np.abs(mod.integrate(y0, 0.025, 2000)[-1] - ref))
    assert np.max(np.abs(traj[-1] - ref)) / err == pytest.approx(4.0, rel=0.1)


def test_almost_poisson_system_still_runs_and_keeps_H(modules):
    mod = modules["almost", "avf"]
    assert mod.JACOBI_IDENTITY == "refuted" and mod.CASIMIR_NAMES == ()
    # (its flow contracts onto an attracting equilibrium on the level set of H — no Poisson flow
    # can; past t ≈ 25 the steps are below Newton's round-off floor, so stop at t = 20)
    traj = mod.integrate(RB_Y0, 0.1, 200)
    H = mod.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) < 4e-15


# --- certificates and their negative controls -------------------------------------------

def test_verify_rigid_body_proves_every_claim(rigid):
    for m in ("avf", "gonzalez", "midpoint"):
        rep = mg.verify(mg.discretize(rigid, m))
        assert rep.ok and rep.decided and all(c.status == "proved" for c in rep), rep
        claims = " | ".join(c.claim for c in rep)
        assert "Jacobi identity" in claims and "Casimir of S" in claims and "C(y1) = C(y0)" in claims
        assert "S̄(y0, y1) = S̄(y1, y0)" in claims


def test_verify_reports_the_claim_an_almost_poisson_S_loses(almost):
    rep = mg.verify(mg.discretize(almost, "avf"))
    jac = rep.find("Jacobi identity")[0]
    assert jac.status == "refuted" and jac.details["failing_triple"] == ["m1", "m2", "m3"]
    assert "not a Poisson map" in jac.details["lost"]
    assert not rep.ok
    # everything else still holds (H by the discrete-gradient identity, symmetry)
    assert all(c.status == "proved" for c in rep if c is not jac)


def test_skew_and_casimir_negative_controls(rigid):
    assert skew_certificate(rigid).status == "proved"
    assert skew_certificate(rigid, sp.Matrix(3, 3, lambda i, j: rigid.y[0] if i == j else 0)).status == "refuted"
    m1, m2, m3 = rigid.y
    assert casimir_certificate(rigid, "C", m1**2 + m2**2 + m3**2).status == "proved"
    assert casimir_certificate(rigid, "K", m1**2).status == "refuted"
    assert jacobi_certificate(rigid).status == "proved"
    assert jacobi_certificate(rigid, sp.Matrix([[0, -m1, m3], [m1, 0, -m2], [-m3, m2, 0]])).status == "refuted"


def test_step_certificates_negative_controls(rigid):
    scheme = mg.discretize(rigid, "avf")
    m1, m2, m3 = rigid.y
    C = m1**2 + m2**2 + m3**2
    assert invariant_preserved(scheme, "C", C).status == "proved"
    # S evaluated at y0 instead of the midpoint: S(y0)∇C(ȳ) ≠ 0, the Casimir is not kept
    at_y0 = dataclasses.replace(scheme, structure_matrix=sp.Matrix(rigid.S))
    assert invariant_preserved(at_y0, "C", C).status == "refuted"
    assert structure_symmetry(scheme).status == "proved"
    assert structure_symmetry(scheme, sp.Matrix(rigid.S)).status == "refuted"


def test_kahan_modified_energy_where_cmoq_conditions_hold():
    const = mg.PoissonSystem("a**3/3 + a*b**2 + b**2/2", y=["a", "b"], S=[["0", "2"], ["-2", "0"]])
    assert kahan_conditions(const) == {"energy": True, "volume": True, "why": ""}
    rep = mg.verify(mg.discretize(const, "kahan"))
    assert rep.ok and rep.decided
    assert [c.status for c in rep.find("Kahan preserves")] == ["proved", "proved"]
    # negative control: a non-symmetric θ = 1/3 breaks the lemmas
    assert modified_energy_structural(const, theta=sp.Rational(1, 3)) is None


def test_kahan_modified_energy_refuted_for_a_state_dependent_S(rigid):
    # CMOQ's H̃ needs a constant S: for the rigid body it is not preserved (and not claimed)
    assert not kahan_conditions(rigid)["energy"]
    assert modified_energy_structural(rigid) is None           # lemma L1 (KS + SKᵀ = 0) fails
    # and H̃(y1) ≠ H̃(y0) at an exact rational point (I = (2, 1, 2/3), h = 1/10)
    pv = {rigid.symbol("I1"): 2, rigid.symbol("I2"): 1, rigid.symbol("I3"): sp.Rational(2, 3),
          STEP: sp.Rational(1, 10)}
    Ht = modified_energy_expr(rigid).xreplace(pv)
    f = vector_field(rigid).xreplace(pv)
    A = sp.eye(3) - pv[STEP] / 2 * f.jacobian(sp.Matrix(rigid.y))
    y0 = dict(zip(rigid.y, [sp.Rational(1, 3), sp.Rational(1, 5), sp.Rational(2, 3)]))
    y1 = sp.Matrix(list(y0.values())) + pv[STEP] * A.xreplace(y0).LUsolve(f.xreplace(y0))
    assert sp.nsimplify(Ht.xreplace(dict(zip(rigid.y, y1))) - Ht.xreplace(y0)) != 0
    rep = mg.verify(mg.discretize(rigid, "kahan"))
    assert rep.ok and not rep.find("modified energy")


# --- scenes -------------------------------------------------------------------------------

def test_builtin_scenes():
    rb = mg.load_scene("rigid-body")
    assert isinstance(rb.system, mg.PoissonSystem) and len(rb.y0) == 3
    lv = mg.load_scene("lotka-volterra")
    assert lv.system.state_names == ("u", "v")


def test_scene_errors(tmp_path):
    path = tmp_path / "bad.toml"
    base = 'name = "bad"\n[run]\nmethod = "avf"\nh = 0.1\nsteps = 1\ny0 = [1.0, 1.0]\n[system]\nH = "u + v"\n'
    path.write_text(base + 'y = ["u", "v"]\nS = [["0", "u"], ["-u", "0"]]\nq = ["u"]\n')
    with pytest.raises(mg.SceneError, match="takes no q"):
        mg.load_scene(path)
    path.write_text(base + 'y = ["u", "v"]\nS = [["0", 1], ["-1", "0"]]\n')
    with pytest.raises(mg.SceneError, match="rows of strings"):
        mg.load_scene(path)
    path.write_text(base + 'y = ["u", "v"]\nS = [["0", "u"], ["u", "0"]]\n')
    with pytest.raises(mg.SceneError, match="skew-symmetric"):
        mg.load_scene(path)
    path.write_text(base + 'y = ["u", "v", "w"]\nS = [["0", "u", "0"], ["-u", "0", "0"], ["0", "0", "0"]]\n')
    with pytest.raises(mg.SceneError, match="y0 has 2 values but the state"):
        mg.load_scene(path)


def test_a_non_polynomial_casimir_is_declared_and_then_proved():
    """The Casimir search covers polynomials of degree ≤ 2 only: log u + log v + log w of the
    3-d Lotka–Volterra system is not found, and declared it is proved a first integral (about
    the exact flow).  Negative control: a declared log u + log v is refuted."""
    from methodgen.symbolic.verify.report import FLOW

    kw = dict(y=["u", "v", "w"], S=[["0", "u*v", "-u*w"], ["-u*v", "0", "v*w"], ["u*w", "-v*w", "0"]])
    H = "u + v + w - log(u) - log(v) - log(w)"
    assert mg.PoissonSystem(H, **kw).casimirs() == ()
    lv = mg.PoissonSystem(H, invariants={"C": "log(u) + log(v) + log(w)"}, **kw)
    (cert,) = mg.verify(mg.discretize(lv, "avf")).find("declared invariant C")
    assert cert.status == "proved" and cert.subject == FLOW
    wrong = mg.PoissonSystem(H, invariants={"C": "log(u) + log(v)"}, **kw)
    (cert,) = mg.verify(mg.discretize(wrong, "avf")).find("declared invariant C")
    assert cert.status == "refuted"
