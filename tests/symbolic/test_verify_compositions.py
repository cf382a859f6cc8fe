"""Verification of symmetric compositions (issue 14, item 5): the order of the coefficients, the
float64 coefficients, symmetry and the inherited properties — and negative controls showing
that each certificate can fail."""

from __future__ import annotations

import dataclasses

import pytest
import sympy as sp

import methodgen as mg
import methodgen.symbolic.verify  # noqa: F401  (makes mg.verify callable)
from methodgen.symbolic.compositions import Composition, composition
from methodgen.symbolic.scene import load_scene
from methodgen.symbolic.verify.compositions import (BaseResults, exactly_palindromic, float_coefficients_certificate,
                                           holds_for_every_real_h, inherited_certificates, order_certificate,
                                           recursion_levels, compose_levels, symmetry_certificate)
from methodgen.symbolic.verify.report import Certificate

#: (scene, method, order, family) and what the composition's derived claims must be.
CASES = {
    "em-kepler-4-suzuki": ("kepler", "energy-momentum", 4, "suzuki"),
    "em-kepler-4-triple-jump": ("kepler", "energy-momentum", 4, "triple-jump"),
    "em-kepler-8-kahan-li": ("kepler", "energy-momentum", 8, "kahan-li"),
    "rattle-pendulum-4": ("pendulum", "rattle", 4, None),
    "sv-henon-heiles-2d-6": ("henon-heiles-2d", "stormer-verlet", 6, None),
}
_REPORTS: dict = {}


def _system(scene):
    return load_scene(scene).system


def report(case):
    """The (cached) scheme and report of one case: each verification runs once per session."""
    if case not in _REPORTS:
        scene, method, order, family = CASES[case]
        scheme = mg.discretize(_system(scene), method, order=order, composition=family)
        _REPORTS[case] = (scheme, mg.verify(scheme))
    return _REPORTS[case]


def composed(rep, scheme):
    """The certificates about the composition itself (named by its key)."""
    return [c for c in rep.certificates if c.claim.startswith(scheme.key + ":")]


def one(rep, text):
    found = rep.find(text)
    assert len(found) == 1, f"expected one certificate mentioning {text!r}, got {[c.claim for c in found]}"
    return found[0]


# --- positive: every new certificate proved or numerical as appropriate -------------------

@pytest.mark.parametrize("case", list(CASES))
def test_composed_scheme_verifies(case):
    scheme, rep = report(case)
    assert rep.ok and rep.all_passed and rep.decided, str(rep)
    assert scheme.key in rep.title and rep.method == scheme.key
    d = rep.to_dict()
    assert d["method"] == scheme.key and d["composition"]["order"] == scheme.composition.order
    assert d["composition"]["family"] == scheme.composition.family
    # The coefficients: exact families proved, published decimals numerical.
    order = one(rep, "composition coefficients")
    assert order.status == ("proved" if scheme.composition.exact else "numerical")
    if not scheme.composition.exact:
        assert order.details["conditions_hold_to_digits"] >= 24
        assert order.details["achieved_order"] == scheme.composition.order
    floats = one(rep, "float64 coefficients")
    assert floats.status == "numerical" and floats.details["passed"] and floats.details["nearest_double"]
    # Claims about the base step are labelled as such; the derived ones name the composed method.
    assert any(c.claim.startswith("base step Φ_h: ") for c in rep.certificates)
    assert composed(rep, scheme)


def test_energy_momentum_invariants_inherited_exactly():
    for case in ("em-kepler-4-suzuki", "em-kepler-4-triple-jump", "em-kepler-8-kahan-li"):
        scheme, rep = report(case)
        for name in ("H", "Lx", "Ly", "Lz"):
            cert = one(rep, f"composition keeps {name} =")
            assert cert.status == "proved", cert
            assert "real symbol h" in cert.details["every_real_h"]
        assert one(rep, "composition is symmetric").status == "proved"


def test_exact_order_proof_states_the_theorem_and_the_rebuild():
    _, rep = report("em-kepler-4-triple-jump")
    cert = one(rep, "composition coefficients")
    assert "§II.4" in cert.details["theorem"] and "Σγ^{2k+1} = 0" in cert.details["theorem"]
    assert cert.details["gammas_are_the_recursion"] == "structural equality"
    assert cert.details["cross_check_free_algebra"]["achieved_order"] == 4
    assert "Float" not in sp.srepr(sp.sympify(cert.details["levels"][0]["coefficients"][0]))


def test_rattle_constraints_proved_symplecticity_numerical():
    _, rep = report("rattle-pendulum-4")
    assert one(rep, "composition stays on g(q) = 0").status == "proved"
    assert one(rep, "hidden constraints G(q)M⁻¹p = 0").status == "proved"
    # The base step's symplecticity and generated-step symmetry are numerical: so are the composition's,
    # with a 60-digit check of the composed map itself (negative stage steps included).
    for text in ("composition is symplectic on T*Q", "composition is symmetric"):
        cert = one(rep, text)
        assert cert.status == "numerical" and cert.details["passed"]
        assert "composed_map_check" in cert.details


def test_stormer_verlet_symplectic_and_symmetric_proved():
    _, rep = report("sv-henon-heiles-2d-6")
    assert one(rep, "composition is symplectic").status == "proved"
    assert one(rep, "composition is symmetric").status == "proved"


def test_base_method_reports_are_unchanged(kepler):
    rep = mg.verify(mg.discretize(kepler, "energy-momentum"))
    assert rep.method == "energy-momentum" and rep.composition is None
    assert "composition" not in rep.to_dict()
    assert not any("base step" in c.claim or "composition" in c.claim for c in rep.certificates)


def test_renderers_name_the_composed_method():
    scheme, rep = report("em-kepler-4-suzuki")
    for text in (rep.markdown(), rep.latex(), str(rep), rep.to_json()):
        assert "energy-momentum-order4-suzuki" in text


def test_retiming_carries_over_to_the_composition():
    scheme = mg.discretize(_system("harmonic"), "midpoint", order=4)
    rep = mg.verify(scheme)
    base = [c for c in rep.find("exact flow at time τ") if c.claim.startswith("base step")]
    comp = one(rep, "composed step is the exact flow")
    assert base and base[0].status == "proved"
    assert comp.status == "proved" and "Σ_i τ(γ_i h)" in comp.claim


# --- negative controls: each certificate can fail ---------------------------------------

def test_perturbed_exact_coefficients_refuted():
    comp = composition(4, "triple-jump")
    g = list(comp.gammas)
    eps = sp.Rational(1, 10**6)
    g[0] += eps
    g[-1] += eps
    g[1] -= 2 * eps                    # still palindromic, still Σγ = 1: only Σγ³ = 0 breaks
    bad = Composition("triple-jump", 4, tuple(g), True, "perturbed")
    cert = order_certificate(bad)
    assert cert.status == "refuted", cert
    assert cert.details["gammas_are_the_recursion"].startswith("NO")
    assert cert.details["achieved_order"] < 4


def test_wrong_root_in_the_level_conditions_refuted():
    # Level 1 (order 2 → 4) needs the cube root of 2; the fourth root breaks Σγ³ = 0 exactly.
    r = sp.Integer(2) ** sp.Rational(1, 4)
    g1 = 1 / (2 - r)
    level = (g1, -r * g1, g1)
    bad = Composition("triple-jump", 4, compose_levels([level]), True, "wrong root")
    cert = order_certificate(bad, levels=[level])
    assert cert.status == "refuted", cert
    assert any("minimal polynomial" in f and "Σγ^3" in f for f in cert.details["failing_conditions"])
    # The right root, through the same code path, is proved.
    good = recursion_levels(4, 3)
    assert order_certificate(Composition("triple-jump", 4, compose_levels(good), True, "ok"),
                             levels=good).status == "proved"


def test_perturbed_decimal_coefficients_refuted():
    comp = composition(8, "kahan-li")
    g = [sp.Rational(str(x)) for x in comp.gammas]
    g[0] += sp.Rational(1, 10**12)
    g[-1] += sp.Rational(1, 10**12)
    g[len(g) // 2] -= sp.Rational(2, 10**12)
    bad = Composition("kahan-li", 8, tuple(str(sp.N(x, 40)) for x in g), False, "perturbed")
    cert = order_certificate(bad)
    assert cert.status == "refuted" and cert.details["achieved_order"] < 8


def test_float_coefficients_wrong_value_refuted():
    comp = composition(6, "kahan-li")
    good = float_coefficients_certificate(comp)
    assert good.status == "numerical" and good.details["passed"]
    fl = list(comp.floats())
    fl[0] += 1e-7
    fl[-1] += 1e-7
    bad = float_coefficients_certificate(comp, floats=fl)
    assert bad.status == "refuted", bad


def test_non_palindromic_sequence_refuted():
    comp = composition(4, "suzuki")
    g = list(comp.gammas)
    g[0], g[2] = g[2], g[0]            # same multiset (Σγ = 1, Σγ³ = 0) but not palindromic
    skew = Composition("suzuki", 4, tuple(g), True, "not palindromic")
    ok, why = exactly_palindromic(skew)
    assert not ok and "γ_1 ≠ γ_5" in why
    scheme = mg.discretize(_system("henon-heiles-2d"), "stormer-verlet").compose(skew)
    rep = mg.verify(scheme)
    sym = one(rep, "composition is symmetric")
    assert sym.status == "refuted", sym
    assert float(sym.details["counterexample"]["defect"]) > 1e-10
    assert one(rep, "composition coefficients").status == "refuted"


def test_non_palindromic_on_a_linear_field_is_not_proved():
    # The stages of a linear field commute, so the composed map happens to be symmetric:
    # no refutation exists, but the premise of the proof fails and nothing is proved.
    comp = composition(4, "suzuki")
    g = list(comp.gammas)
    g[0], g[2] = g[2], g[0]
    scheme = mg.discretize(_system("harmonic"), "midpoint").compose(
        Composition("suzuki", 4, tuple(g), True, "not palindromic"))
    cert = one(mg.verify(scheme), "composition is symmetric")
    assert cert.status == "numerical" and not cert.details["passed"]
    assert "premise fails" in cert.details["why_numerical"]


def test_decimal_palindrome_is_compared_exactly():
    assert exactly_palindromic(Composition("kahan-li", 6, ("0.25", "0.5", "0.250"), False, "t"))[0]
    assert not exactly_palindromic(Composition("kahan-li", 6, ("0.25", "0.5", "0.25000000000000000000001"),
                                               False, "t"))[0]


def test_refuted_base_invariant_never_yields_a_proved_composition(kepler):
    # Midpoint does not keep the (non-quadratic) Kepler energy; claim it anyway.
    mid = mg.discretize(kepler, "midpoint")
    liar = dataclasses.replace(mid, traits=dataclasses.replace(mid.traits,
                                                               preserved=mid.traits.preserved + ("H",)))
    rep = mg.verify(liar.compose(composition(4, "suzuki")))
    base = [c for c in rep.find("H(y1) = H(y0)") if c.claim.startswith("base step")]
    assert base and base[0].status == "refuted"
    cert = one(rep, "composition keeps H =")
    assert cert.status == "refuted" and "counterexample" in cert.details
    assert not rep.ok
    # The true invariants are still proved.
    assert one(rep, "composition keeps Lz =").status == "proved"


def _fake(status, method):
    return Certificate("fake base certificate", status, method=method,
                       details={} if status != "numerical" else {"passed": True})


def test_every_real_h_needs_an_exact_route():
    assert holds_for_every_real_h(_fake("proved", "cancel"))[0]
    assert holds_for_every_real_h(_fake("proved", "structural: shears"))[0]
    assert not holds_for_every_real_h(_fake("proved", "60-digit evaluation at rational points"))[0]
    assert not holds_for_every_real_h(_fake("proved", "trust me"))[0]
    assert not holds_for_every_real_h(_fake("numerical", "cancel"))[0]


@pytest.mark.parametrize("status, method", [("proved", "trust me"), ("numerical", "50-digit evaluation"),
                                            ("undecided", "")])
def test_derived_status_no_stronger_than_base(status, method):
    scheme = mg.discretize(_system("henon-heiles-2d"), "stormer-verlet", order=4)
    base = BaseResults()
    base.items.append(("symplectic", _fake(status, method)))
    cert = next(c for c in inherited_certificates(scheme, base) if "symplectic" in c.claim)
    assert cert.status != "proved"
    assert cert.status == "numerical" and "composed_map_check" in cert.details   # checked on Ψ itself


def test_missing_base_evidence_is_never_proved():
    scheme = mg.discretize(_system("pendulum"), "rattle", order=4)
    base = BaseResults()
    base.failed["constraints, symmetry and symplecticity on T*Q"] = "BudgetExceeded: time budget"
    certs = inherited_certificates(scheme, base) + [symmetry_certificate(scheme, base)]
    assert certs and all(c.status == "numerical" for c in certs)
    assert all("did not finish" in c.details["missing_base_evidence"] for c in certs)


def test_refuted_base_without_a_composed_check_stays_refuted():
    scheme = mg.discretize(_system("harmonic"), "midpoint", order=4)
    base = BaseResults()
    base.items.append(("retiming", Certificate("fake re-timing", "refuted", method="counterexample",
                                               details={"counterexample": {"h": "1/10"}})))
    cert = next(c for c in inherited_certificates(scheme, base) if "exact flow" in c.claim)
    assert cert.status == "refuted"
