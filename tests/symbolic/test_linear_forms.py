"""Energy-momentum for functions of linear forms (issue 15, item 5).

A term ``V(aᵀq + c)`` of U (Toda's ``exp(q1 - q2)``, a torsion spring ``cos(q1 - q2)``,
Calogero–Moser's ``1/(q1 - q2)²``, a 1D Lennard-Jones pair, FPU's ``(q2 - q1)⁴``) gets the
exact discrete gradient ``V[u0, u1] a`` (the cancelled divided difference, the same helper
as AVF).  Checked here:

* the decomposition (and that the terms handled before keep their rule);
* Toda and a 1D Lennard-Jones chain: H and total momentum kept to round-off by the
  generated module, the trajectory against DOP853, verify proves H and P exactly;
* the term-wise structural proof of the identity (new certificate route) for
  energy-momentum and AVF, and negative controls for it: a wrong divided difference or a
  tampered structure is not proved structurally and the identity is refuted;
* total momentum claimed only where every term is translation invariant, angular
  momentum only where every term's form commutes with it (a forced claim is refuted).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
import methodgen.symbolic.verify  # noqa: F401  (makes mg.verify callable)
from methodgen.symbolic.derive import first_integrals, vector_field
from methodgen.symbolic.schemes.energy_momentum import decompose
from methodgen.symbolic.verify.discrete_gradients import dg_identity, kappa_midpoint_gradient
from methodgen.symbolic.verify.invariants import invariant_items
from methodgen.symbolic.verify.structural import identity_structural

TODA_H = "(p1**2 + p2**2 + p3**2)/2 + exp(q1 - q2) + exp(q2 - q3) + exp(q3 - q1)"
TODA_Y0 = np.array([0.0, 0.5, -0.3, 0.8, -0.2, -0.6])
#: Near the Lennard-Jones equilibrium spacing 2^(1/6) ≈ 1.12, with net momentum 0.15.
LJ_Y0 = np.array([0.0, 1.15, 2.2, 3.35, 0.3, -0.1, 0.05, -0.1])


def _toda(extra: str = "", **kw) -> mg.Hamiltonian:
    return mg.Hamiltonian(TODA_H + extra, q=["q1", "q2", "q3"], p=["p1", "p2", "p3"], name="toda3", **kw)


def _lj(n: int = 4) -> mg.Hamiltonian:
    """A 1D Lennard-Jones chain with open ends, r = q_{i+1} - q_i."""
    pair = "4*eps*((sig/(q{b} - q{a}))**12 - (sig/(q{b} - q{a}))**6)"
    U = " + ".join(pair.format(a=i, b=i + 1) for i in range(1, n))
    T = "(" + " + ".join(f"p{i}**2" for i in range(1, n + 1)) + ")/2"
    return mg.Hamiltonian(f"{T} + {U}", q=[f"q{i}" for i in range(1, n + 1)],
                          p=[f"p{i}" for i in range(1, n + 1)], params={"eps": 1.0, "sig": 1.0},
                          name=f"lj{n}")


@pytest.fixture(scope="module")
def toda():
    return _toda()


@pytest.fixture(scope="module")
def lj():
    return _lj(4)


@pytest.fixture(scope="module")
def toda_em(toda):
    return mg.discretize(toda, "energy-momentum")


@pytest.fixture(scope="module")
def lj_em(lj):
    return mg.discretize(lj, "energy-momentum")


def _kinds(system):
    terms = decompose(system)
    return None if terms is None else sorted(t.kind for t in terms)


def _identity(report):
    return next(c for c in report.certificates if "discrete-gradient identity" in c.claim)


def _reference(system, y0, t):
    from scipy.integrate import solve_ivp

    f = sp.lambdify([list(system.y)], list(vector_field(system).xreplace(
        {system.symbol(k): v for k, v in system.param_values.items()})), "numpy")
    sol = solve_ivp(lambda _, y: f(y), (0, t), y0, method="DOP853", rtol=1e-12, atol=1e-14)
    return sol.y[:, -1]


# --- decomposition ----------------------------------------------------------------------

def test_terms_of_one_linear_form_are_recognised():
    assert _kinds(_toda()) == ["linear-form"] * 3
    assert _kinds(_lj(3)) == ["linear-form"] * 2
    pend2 = mg.Hamiltonian("(p1**2 + p2**2)/(2*m*l**2) - m*g*l*(cos(q1) + cos(q2)) + k*(1 - cos(q1 - q2))",
                           q=["q1", "q2"], p=["p1", "p2"], params={"m": 1.0, "l": 1.0, "g": 1.0, "k": 0.1})
    assert _kinds(pend2) == ["coordinate", "coordinate", "linear-form"]
    # the pair sum g²(…) is distributed; the confinement stays a quadratic form
    cal = mg.Hamiltonian("(p1**2 + p2**2 + p3**2)/2 + w**2*(q1**2 + q2**2 + q3**2)/2"
                         " + g**2*(1/(q1 - q2)**2 + 1/(q1 - q3)**2 + 1/(q2 - q3)**2)",
                         q=["q1", "q2", "q3"], p=["p1", "p2", "p3"], params={"w": 1.0, "g": 0.5})
    assert _kinds(cal) == ["linear-form"] * 3 + ["quadratic-form"]
    # FPU: the quadratic spring keeps its rule, the quartic one is a function of q2 - q1
    # (cheaper than its AVF integral, and the same function)
    fpu = mg.Hamiltonian("(p1**2 + p2**2)/2 + q1**2/2 + (q2 - q1)**2/2 + b*(q2 - q1)**4/4",
                         q=["q1", "q2"], p=["p1", "p2"], params={"b": 1.0})
    assert _kinds(fpu) == ["coordinate", "linear-form", "quadratic-form"]
    # terms handled before keep their rule (Hénon–Heiles' x²y stays a polynomial)
    assert _kinds(mg.load_scene("henon-heiles-2d").system) == ["coordinate"] * 3 + ["polynomial"]
    assert _kinds(mg.load_scene("kepler").system) == ["quadratic-form"]


def test_other_terms_still_refused_with_a_clear_message():
    H = mg.Hamiltonian("(px**2 + py**2)/2 + x*exp(y)", q=["x", "y"], p=["px", "py"])
    assert decompose(H) is None
    with pytest.raises(mg.MethodNotApplicable, match="one linear form"):
        mg.discretize(H, "energy-momentum")


def test_energy_momentum_equals_avf_on_functions_of_linear_forms(toda_em, toda):
    """For ½|p|² + Σ V_t(a_tᵀq) both methods are the same map: ∇̄H agree exactly."""
    avf = mg.discretize(toda, "avf")
    diff = toda_em.discrete_gradient - avf.discrete_gradient
    assert all(sp.expand(e) == 0 for e in diff)


def test_fpu_quartic_linear_form_equals_its_avf_integral():
    fpu = mg.Hamiltonian("(p1**2 + p2**2 + p3**2)/2 + b*(q2 - q1)**4/4 + b*(q3 - q2)**4/4 + b*q1**4/4",
                         q=["q1", "q2", "q3"], p=["p1", "p2", "p3"], params={"b": 1.0})
    em, avf = mg.discretize(fpu, "energy-momentum"), mg.discretize(fpu, "avf")
    assert all(sp.expand(a - b) == 0 for a, b in zip(em.discrete_gradient, avf.discrete_gradient))


# --- claims -------------------------------------------------------------------------------

def test_traits_claim_h_and_total_momentum(toda_em, lj_em):
    assert toda_em.traits.preserved == ("H", "P") and toda_em.traits.energy_preserving
    assert lj_em.traits.preserved == ("H", "P")
    assert any("affine form" in n for n in toda_em.traits.notes)


def test_momentum_not_claimed_for_a_term_that_is_not_translation_invariant():
    """Negative control: an external wall exp(q1) is a one-coordinate term (Σa ≠ 0): total
    momentum is no first integral, is not claimed, and a declared P is refuted by verify."""
    walled = _toda(" + exp(q1)", invariants={"P": "p1 + p2 + p3"})
    scheme = mg.discretize(walled, "energy-momentum")
    assert scheme.traits.preserved == ("H",)
    assert "P" not in [i.name for i in first_integrals(walled)]
    rep = mg.verify(scheme, timeout=30)
    assert _identity(rep).status == "proved"
    declared = [c for c in rep.certificates if "declared invariant P" in c.claim]
    assert declared and declared[0].status == "refuted"


def test_forced_momentum_claim_on_a_wrong_gradient_is_refuted(toda_em):
    """Negative control: the same P certificate on a ∇̄H that does not respect it (one term's
    divided difference put on q1 only) is refuted at a counterexample point."""
    wrong = toda_em.discrete_gradient.copy()
    wrong[0] = wrong[0] + wrong[1]
    lying = dataclasses.replace(toda_em, discrete_gradient=wrong)
    cert = dict(invariant_items(lying))["invariant:P"]
    assert cert.status == "refuted" and cert.details.get("counterexample")
    assert dict(invariant_items(toda_em))["invariant:P"].status == "proved"


def test_angular_momentum_claimed_for_mixed_forms_only_where_each_form_commutes():
    """A radial quadratic-form term plus a linear-form term in other coordinates keeps
    L = x py - y px (claimed and proved); a radial U written as ridge functions
    (x + y)⁴, (x - y)⁴, x⁴, y⁴ has L as a first integral, but its term-wise ∇̄H does not
    keep it: not claimed, and a forced claim is refuted (negative control)."""
    mixed = mg.Hamiltonian("(px**2 + py**2 + pz**2 + pw**2)/2 + (x**2 + y**2)**2 + exp(z - w)",
                           q=["x", "y", "z", "w"], p=["px", "py", "pz", "pw"], name="mixed")
    scheme = mg.discretize(mixed, "energy-momentum")
    L = [i.name for i in first_integrals(mixed) if i.name.startswith("L")]
    assert L and set(L) <= set(scheme.traits.preserved) and "P" in scheme.traits.preserved
    certs = dict(invariant_items(scheme))
    assert all(certs[f"invariant:{n}"].status == "proved" for n in scheme.traits.preserved if n != "H")

    ridge = mg.Hamiltonian("(px**2 + py**2)/2 + 2*x**4/3 + 2*y**4/3 + (x + y)**4/6 + (x - y)**4/6",
                           q=["x", "y"], p=["px", "py"], name="ridge")
    assert sorted(t.kind for t in decompose(ridge)) == ["coordinate"] * 2 + ["linear-form"] * 2
    L = [i.name for i in first_integrals(ridge) if i.name != "H"]
    assert L                                  # U = (x² + y²)² is radial
    scheme = mg.discretize(ridge, "energy-momentum")
    assert scheme.traits.preserved == ("H",)
    lying = dataclasses.replace(scheme, traits=dataclasses.replace(scheme.traits, preserved=("H",) + tuple(L)))
    cert = dict(invariant_items(lying))[f"invariant:{L[0]}"]
    assert cert.status == "refuted" and cert.details.get("counterexample")


# --- verify ---------------------------------------------------------------------------------

@pytest.mark.parametrize("which", ["toda", "lj"])
def test_verify_proves_h_and_p_exactly(which, toda_em, lj_em):
    scheme = toda_em if which == "toda" else lj_em
    rep = mg.verify(scheme, timeout=60)
    assert rep.ok and rep.all_passed, str(rep)
    assert {c.status for c in rep.certificates} == {"proved"}, str(rep)
    ident = _identity(rep)
    assert ident.method.startswith("structural") and ident.details.get("structural")
    kept = [c for c in rep.certificates if "P(y1) = P(y0)" in c.claim]
    assert kept and kept[0].status == "proved"
    assert rep.seconds < 30


def test_avf_identity_on_a_lennard_jones_chain_proved_term_wise(lj):
    """Reduced whole, this identity (degree-24 rational function) does not finish in minutes."""
    scheme = mg.discretize(lj, "avf")
    cert = dg_identity(lj, scheme.discrete_gradient, "avf", scheme=scheme)
    assert cert.status == "proved" and cert.method.startswith("structural"), cert.method
    assert cert.seconds < 10


def test_wrong_divided_difference_refuted(toda, toda_em):
    """Negative control: the midpoint gradient (κ ≡ 1 instead of the divided differences) is
    not a discrete gradient of Toda: refuted with a counterexample."""
    cert = dg_identity(toda, kappa_midpoint_gradient(toda, kappa=1), "κ ≡ 1")
    assert cert.status == "refuted" and cert.details.get("counterexample")
    # ... and put into the scheme (structure kept): no structural proof, the fallback refutes it
    bad = dataclasses.replace(toda_em, discrete_gradient=kappa_midpoint_gradient(toda, kappa=1))
    assert identity_structural(bad, "c", "", sp.S.One) is None
    assert _identity(mg.verify(bad, timeout=30)).status == "refuted"


def test_tampered_term_structure_is_not_proved_structurally(toda_em):
    """Negative controls for the term-wise route: each recorded fact is checked, not trusted."""
    def tampered(i, **change):
        terms = list(toda_em.structure["terms"])
        terms[i] = {**terms[i], **change}
        return dataclasses.replace(toda_em, structure={"kind": "term-wise", "terms": tuple(terms)})

    assert identity_structural(toda_em, "c", "", sp.S.One) is not None
    k = next(i for i, t in enumerate(toda_em.structure["terms"]) if t["profile"] is not None)
    t = toda_em.structure["terms"][k]
    V, s, F, w = t["profile"]
    # a profile whose V(F) is not the term
    assert identity_structural(tampered(k, profile=(2 * V, s, F, w)), "c", "", sp.S.One) is None
    # a weight vector w with wᵀΔ ≠ F1 - F0
    assert identity_structural(tampered(k, profile=(V, s, F, [2 * c for c in w])), "c", "", sp.S.One) is None
    # a term that is not the term of H (H ≠ Σ H_t)
    assert identity_structural(tampered(k, expr=2 * t["expr"]), "c", "", sp.S.One) is None
    # pieces that do not add up to the scheme's ∇̄H
    assert identity_structural(tampered(k, dg=[2 * g for g in t["dg"]]), "c", "", sp.S.One) is None


# --- generated modules ------------------------------------------------------------------------

def _relerr(x):
    return np.max(np.abs(x - x[0])) / max(abs(x[0]), 1.0)


@pytest.mark.parametrize("which,h,steps", [("toda", 0.05, 4000), ("lj", 0.005, 4000)])
def test_module_keeps_h_and_p_to_roundoff(which, h, steps, tmp_path, toda_em, lj_em):
    scheme = toda_em if which == "toda" else lj_em
    y0 = TODA_Y0 if which == "toda" else LJ_Y0
    mod = mg.generate(scheme, tmp_path / f"{which}_em.py")
    traj = mod.integrate(y0, h, steps)
    inv = mod.invariants(traj)
    assert _relerr(inv["H"]) < 1e-12
    assert np.max(np.abs(inv["P"] - inv["P"][0])) < 1e-12
    assert np.all(np.isfinite(traj))


@pytest.mark.parametrize("which,n", [("toda", 200), ("lj", 1000)])
def test_trajectory_against_dop853(which, n, tmp_path, toda_em, lj_em):
    """Second order: at h and h/2 the error at t = 1 against DOP853 (rtol 1e-12) is small
    (measured: Toda 1.2e-5, 2.9e-6; Lennard-Jones 3.9e-5, 9.7e-6) and drops 4×."""
    scheme = toda_em if which == "toda" else lj_em
    y0 = TODA_Y0 if which == "toda" else LJ_Y0
    mod = mg.generate(scheme, tmp_path / f"{which}_em_ref.py")
    t = 1.0
    ref = _reference(scheme.system, y0, t)
    errs = []
    for steps in (n, 2 * n):
        traj = mod.integrate(y0, t / steps, steps)
        errs.append(np.max(np.abs(traj[-1] - ref)))
    assert errs[0] < 1e-4 and errs[1] < 2.5e-5, errs
    assert 3.5 < errs[0] / errs[1] < 4.5, errs
