"""Declared invariants (issue 15, item 1): API, scene table, exactness, detection, claims, verify.

* A declared invariant is monitored; it is ``exact`` (and may be claimed by a method)
  only when {I, H} = 0 is shown exactly; verify proves or refutes {I, H} = 0.
* Total linear and angular momenta of N-body-like systems are detected and proved.
* Methods claim a first integral only where it is a theorem for them, and every claim
  goes through verify; negative controls force false claims and see them refuted.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.symbolic.derive import invariants
from methodgen.errors import InputError, SceneError

USER = Path(__file__).resolve().parents[1] / "user_problems"
TODA_Y0 = [0.0, 0.5, -0.3, 0.8, -0.2, -0.6]


def _toda(**invs) -> mg.Hamiltonian:
    path = USER / "toda3.toml"
    if path.is_file():
        base = mg.load_scene(str(path)).system
        H, q, p = base.source, [s.name for s in base.q], [s.name for s in base.p]
    else:   # pragma: no cover - tests/user_problems is missing
        H, q, p = ("(p1**2 + p2**2 + p3**2)/2 + exp(q1 - q2) + exp(q2 - q3) + exp(q3 - q1)",
                   ["q1", "q2", "q3"], ["p1", "p2", "p3"])
    return mg.Hamiltonian(H, q=q, p=p, invariants=invs or None, name="toda3")


def _by_name(system):
    return {inv.name: inv for inv in invariants(system)}


def _certs(report, text):
    return [c for c in report.certificates if text in c.claim]


def _two_body():
    H = ("(px1**2 + py1**2)/(2*m1) + (px2**2 + py2**2)/(2*m2) "
         "- m1*m2/sqrt((x1 - x2)**2 + (y1 - y2)**2)")
    return mg.Hamiltonian(H, q=["x1", "y1", "x2", "y2"], p=["px1", "py1", "px2", "py2"],
                          params={"m1": 1.0, "m2": 0.5}, name="twobody")


# --- API ------------------------------------------------------------------------------

def test_declared_invariant_api_and_fingerprint():
    plain = _toda()
    toda = _toda(P="p1 + p2 + p3")
    assert [d.name for d in toda.declared_invariants] == ["P"]
    assert toda.declared_invariants[0].source == "p1 + p2 + p3"
    assert toda.fingerprint() != plain.fingerprint()
    assert plain.declared_invariants == ()
    # a SymPy expression works too, with the user's own symbols (mapped by name)
    p1, p2, p3 = sp.symbols("p1 p2 p3")
    same = _toda(P=p1 + p2 + p3)
    assert same.fingerprint() == toda.fingerprint()
    with pytest.raises(AttributeError):
        toda.declared_invariants = ()
    assert "invariants=" in repr(toda)


@pytest.mark.parametrize("invs, message", [
    ({"P": "p1 + foo"}, "unknown symbol 'foo'"),
    ({"q1": "p1"}, "already a coordinate"),
    ({"H": "p1"}, "monitors itself"),
    ({"Lx": "p1"}, "monitors itself"),
    ({"P": "abs(p1)"}, "not smooth"),
    ({"P": "2"}, "does not depend on the state"),
    ({"_P": "p1"}, "invalid invariant name"),
    ({"P": "__import__('os')"}, "unknown function"),
])
def test_declared_invariant_bad_input(invs, message):
    with pytest.raises(InputError, match=message):
        _toda(**invs) if "_P" not in invs else mg.Hamiltonian(
            "p1**2/2", q=["q1"], p=["p1"], invariants=invs)


def test_declared_names_must_not_clash_with_constraint_monitors():
    with pytest.raises(InputError, match="monitors itself"):
        mg.Hamiltonian("(px**2 + py**2)/2 + y", q=["x", "y"], p=["px", "py"],
                       constraints=["x**2 + y**2 - 1"], invariants={"g1_v": "px"})


# --- exactness and verify's {I, H} = 0 ------------------------------------------------

def test_toda_total_momentum_proved_and_kept_by_midpoint_and_avf():
    toda = _toda(P="p1 + p2 + p3")
    inv = _by_name(toda)
    assert inv["P"].exact and "declared" in inv["P"].why
    # the detected total momentum equals the declared one: monitored once
    assert [i.name for i in invariants(toda)] == ["H", "P"]
    for method in ("midpoint", "avf"):
        scheme = mg.discretize(toda, method)
        assert "P" in scheme.traits.preserved, method
        report = mg.verify(scheme, timeout=30)
        assert report.ok, [(c.claim, c.status) for c in report.certificates if not c.passed]
        first = _certs(report, "declared invariant P")
        assert first and first[0].status == "proved"
        kept = _certs(report, f"{method}: P(y1) = P(y0)")
        assert kept and kept[0].status == "proved"
        mod = mg.generate(scheme)
        assert "P" in mod.INVARIANT_NAMES
        traj = mod.integrate(TODA_Y0, 0.05, 400)
        P = mod.invariants(traj)["P"]
        assert np.max(np.abs(P - P[0])) < 1e-13, method
    # AVF (exact divided differences for exp(q_i - q_j)) keeps H too
    assert "H" in mg.discretize(toda, "avf").traits.preserved


def test_declared_non_invariant_refuted_and_never_claimed():
    toda = _toda(bad="p1")
    inv = _by_name(toda)
    assert not inv["bad"].exact and "≠ 0" in inv["bad"].why
    for method in mg.applicable_methods(toda):
        assert "bad" not in mg.discretize(toda, method).traits.preserved, method
    report = mg.verify(mg.discretize(toda, "midpoint"), timeout=30)
    cert = _certs(report, "declared invariant bad")[0]
    assert cert.status == "refuted"
    assert cert.details.get("counterexample")
    assert not report.ok       # a false declaration is a refuted claim


def test_detected_name_clash_with_declared_name():
    toda = _toda(P="p1")
    inv = _by_name(toda)
    assert not inv["P"].exact
    assert inv["P_auto"].exact and sp.expand(inv["P_auto"].expr - sum(toda.p)) == 0
    assert "P_auto" in mg.discretize(toda, "midpoint").traits.preserved
    assert "P" not in mg.discretize(toda, "midpoint").traits.preserved


def test_discrete_gradients_claim_momentum_only_where_their_gradient_respects_it():
    toda = _toda(P="p1 + p2 + p3")
    assert "P" not in mg.discretize(toda, "gonzalez").traits.preserved
    ia = mg.discretize(toda, "itoh-abe")
    assert "P" not in ia.traits.preserved
    # negative control: force the claim; verify refutes it on Itoh–Abe's ∇̄H
    lying = dataclasses.replace(ia, traits=dataclasses.replace(ia.traits, preserved=ia.traits.preserved + ("P",)))
    from methodgen.symbolic.verify.invariants import invariant_items
    certs = dict(invariant_items(lying))
    assert certs["invariant:P"].status == "refuted"


# --- detection ----------------------------------------------------------------------------

def test_detects_total_linear_and_angular_momentum_of_two_bodies():
    system = _two_body()
    inv = _by_name(system)
    for name in ("P_x", "P_y", "L"):
        assert name in inv and inv[name].exact, name
    assert sp.expand(inv["P_x"].expr - sp.Symbol("px1", real=True) - sp.Symbol("px2", real=True)) == 0
    report = mg.verify(mg.discretize(system, "stormer-verlet"), timeout=30)
    assert report.ok
    for name in ("P_x", "P_y", "L"):
        assert _certs(report, f"detected invariant {name}")[0].status == "proved"
        assert _certs(report, f"stormer-verlet: {name}(y1)")[0].status == "proved"
    em = mg.discretize(system, "energy-momentum")
    assert {"H", "P_x", "P_y", "L"} <= set(em.traits.preserved)


def test_detection_on_a_line_and_nothing_new_elsewhere():
    chain = mg.Hamiltonian("(p1**2 + p2**2 + p3**2)/2 + (q1 - q2)**4 + (q2 - q3)**4",
                           q=["q1", "q2", "q3"], p=["p1", "p2", "p3"])
    assert [i.name for i in invariants(chain)] == ["H", "P"]
    fixed = mg.Hamiltonian("(p1**2 + p2**2)/2 + q1**4 + (q1 - q2)**4", q=["q1", "q2"], p=["p1", "p2"])
    assert [i.name for i in invariants(fixed)] == ["H"]
    kepler = mg.load_scene("kepler").system
    assert [i.name for i in invariants(kepler)] == ["H", "Lx", "Ly", "Lz"]


# --- which method claims what (negative controls) ------------------------------------------

def test_stormer_verlet_does_not_claim_a_non_bilinear_quadratic_invariant():
    system = mg.Hamiltonian("(p1**2 + p2**2)/2 + (q1**2 + q2**2)/2", q=["q1", "q2"], p=["p1", "p2"],
                            invariants={"E1": "(p1**2 + q1**2)/2"})
    assert _by_name(system)["E1"].exact
    mid = mg.discretize(system, "midpoint")
    assert "E1" in mid.traits.preserved
    assert _certs(mg.verify(mid, timeout=30), "midpoint: E1(y1)")[0].status == "proved"
    sv = mg.discretize(system, "stormer-verlet")
    assert "E1" not in sv.traits.preserved
    lying = dataclasses.replace(sv, traits=dataclasses.replace(sv.traits, preserved=sv.traits.preserved + ("E1",)))
    from methodgen.symbolic.verify.invariants import invariant_items
    assert dict(invariant_items(lying))["invariant:E1"].status == "refuted"


def test_avf_does_not_claim_angular_momentum_it_does_not_keep():
    system = mg.Hamiltonian("(px**2 + py**2)/2 + (x**2 + y**2)**2/4", q=["x", "y"], p=["px", "py"])
    assert _by_name(system)["L"].exact
    avf = mg.discretize(system, "avf")
    assert "L" not in avf.traits.preserved
    lying = dataclasses.replace(avf, traits=dataclasses.replace(avf.traits, preserved=avf.traits.preserved + ("L",)))
    from methodgen.symbolic.verify.invariants import invariant_items
    assert dict(invariant_items(lying))["invariant:L"].status == "refuted"


def test_physical_energy_of_a_time_transformed_system_is_never_claimed():
    osc = mg.Hamiltonian("(px**2 + py**2)/2 + (x**2 + y**2)/2", q=["x", "y"], p=["px", "py"],
                         invariants={"A": "x*py - y*px"}, name="osc")
    K = mg.time_transform(osc, "1 + x**2 + y**2")
    inv = _by_name(K)
    assert not inv["H_phys"].exact
    assert "A" in inv        # declared invariants are carried over
    for method in ("midpoint", "gauss"):
        assert "H_phys" not in mg.discretize(K, method).traits.preserved


def test_rattle_claims_only_constraint_monitors():
    system = mg.Hamiltonian("(px**2 + py**2)/2 + y", q=["x", "y"], p=["px", "py"],
                            constraints=["x**2 + y**2 - 1"], invariants={"gx": "px"})
    assert not _by_name(system)["gx"].exact
    assert set(mg.discretize(system, "rattle").traits.preserved) == {"g1", "g1_v"}


# --- scene table ----------------------------------------------------------------------------

SCENE = """
name = "toda3"
[system]
H = "(p1**2 + p2**2 + p3**2)/2 + exp(q1 - q2) + exp(q2 - q3) + exp(q3 - q1)"
q = ["q1", "q2", "q3"]
p = ["p1", "p2", "p3"]
[invariants]
{invariants}
[run]
method = "midpoint"
h = 0.05
steps = 10
y0 = [0.0, 0.5, -0.3, 0.8, -0.2, -0.6]
"""


def test_scene_invariants_table(tmp_path):
    path = tmp_path / "toda.toml"
    path.write_text(SCENE.format(invariants='P = "p1 + p2 + p3"\nbad = "p1"'))
    scene = mg.load_scene(str(path))
    assert [d.name for d in scene.system.declared_invariants] == ["P", "bad"]


@pytest.mark.parametrize("line, message", [
    ('P = "p1 + foo"', "unknown symbol 'foo'"),
    ('q1 = "p1"', "already a coordinate"),
    ('P = "abs(p1)"', "not smooth"),
    ("P = 3", "must be a string"),
])
def test_scene_invariants_bad_input(tmp_path, line, message):
    path = tmp_path / "toda.toml"
    path.write_text(SCENE.format(invariants=line))
    with pytest.raises(SceneError, match=message):
        mg.load_scene(str(path))


def test_run_reports_declared_invariants(tmp_path, capsys):
    import json

    from methodgen.app.cli import main
    path = tmp_path / "toda.toml"
    path.write_text(SCENE.format(invariants='P = "p1 + p2 + p3"'))
    main(["run", str(path), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert "P" in out["invariants"]
    assert out["invariants"]["P"]["max_abs_error"] < 1e-13
