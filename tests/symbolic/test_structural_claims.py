"""Structural proofs of the non-discrete-gradient claims: Kahan's modified energy and volume,
RATTLE's hidden constraint, Störmer–Verlet's symplecticity — fast, exact, and each can fail."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
import sympy as sp

import methodgen as mg
from methodgen.symbolic.schemes.base import STEP
from methodgen.symbolic import derive
from methodgen.symbolic.verify import kahan as K
from methodgen.symbolic.verify.constrained import field_zero, velocity_constraint, velocity_structural
from methodgen.symbolic.verify.maps import splitting_symplectic, symplectic_certificate

USER = Path(__file__).resolve().parents[1] / "user_problems"
HH2 = mg.Hamiltonian("(px**2 + py**2)/2 + (x**2 + y**2)/2 + x**2*y - y**3/3",
                     q=["x", "y"], p=["px", "py"], name="hh2")
CUBIC1 = mg.Hamiltonian("p**2/2 + q**2/2 - a*q**3/3", q=["q"], p=["p"], params={"a": 1.0},
                        name="cubic1")
CHAIN3 = mg.Hamiltonian("(p1x**2 + p1y**2 + p2x**2 + p2y**2 + p3x**2 + p3y**2)/2 + g*(y1 + y2 + y3)",
                        q=["x1", "y1", "x2", "y2", "x3", "y3"], p=["p1x", "p1y", "p2x", "p2y", "p3x", "p3y"],
                        params={"g": 1.0},
                        constraints=["x1**2 + y1**2 - 1", "(x2 - x1)**2 + (y2 - y1)**2 - 1",
                                     "(x3 - x2)**2 + (y3 - y2)**2 - 1"], name="chain3")
TORUS = mg.Hamiltonian("(px**2 + py**2 + pz**2)/(2*m) + m*g*z", q=["x", "y", "z"], p=["px", "py", "pz"],
                       params={"m": 1.0, "g": 1.0, "R": 2.0, "r": 1.0},
                       constraints=["(x**2 + y**2 + z**2 + R**2 - r**2)**2 - 4*R**2*(x**2 + y**2)"],
                       name="torus")
CALOGERO = mg.Hamiltonian("(p1**2 + p2**2 + p3**2)/2 + w**2*(q1**2 + q2**2 + q3**2)/2 "
                          "+ g**2*(1/(q1 - q2)**2 + 1/(q1 - q3)**2 + 1/(q2 - q3)**2)",
                          q=["q1", "q2", "q3"], p=["p1", "p2", "p3"], params={"w": 1.0, "g": 0.5},
                          name="calogero")


# --- Kahan ----------------------------------------------------------------------------

def test_kahan_modified_energy_and_volume_proved_structurally_for_two_dof():
    e, v = K.modified_energy_structural(HH2), K.modified_volume_structural(HH2)
    assert e.status == v.status == "proved"
    assert e.details["structural"] and v.details["structural"]
    assert e.details["lemmas"] == ["L0", "L1", "L2", "L3", "L4", "L5"]


def test_kahan_structural_agrees_with_the_full_reduction_on_one_dof():
    assert K.modified_energy_structural(CUBIC1).status == "proved"
    assert K.modified_energy_fast(CUBIC1).status == "proved"        # the whole identity, exact
    assert K.modified_volume_structural(CUBIC1).status == "proved"
    assert K.modified_volume(CUBIC1).status == "proved"


def test_kahan_lemma_fails_for_another_linearly_implicit_scheme():
    """Negative control: A = I - θh f' with θ ≠ 1/2 is not Kahan's method; L2 fails and no
    structural proof is given — and that scheme's H̃ is really not conserved."""
    third = sp.Rational(1, 3)
    assert K._lemmas(HH2, ("L2",), third) == {"L2": False}
    assert K.modified_energy_structural(HH2, theta=third) is None
    assert K.modified_volume_structural(HH2, theta=third) is None
    # The θ = 1/3 map does not keep H̃ (exact rational point, 1 DOF): the claim was worth checking.
    s = CUBIC1
    y = sp.Matrix(s.y)
    f = derive.vector_field(s)
    A = sp.eye(2) - third * STEP * f.jacobian(y)
    y1 = y + STEP * A.LUsolve(f)
    Ht = K.modified_energy_expr(s)
    pt = {s.y[0]: sp.Rational(1, 3), s.y[1]: sp.Rational(1, 2), STEP: sp.Rational(1, 10),
          s.params[0]: 1}
    val = (Ht.xreplace(dict(zip(s.y, y1))) - Ht).xreplace(pt)
    assert sp.nsimplify(val) != 0


def test_kahan_lemma_l0_fails_for_a_non_hamiltonian_field(monkeypatch):
    real = K.vector_field
    monkeypatch.setattr(K, "vector_field", lambda system: 2 * real(system))
    assert K._lemmas(HH2, ("L0",)) == {"L0": False}
    assert K.modified_energy_structural(HH2) is None


def test_kahan_lemmas_fail_beyond_cubic_h():
    """L4 is Simpson's rule: exact up to quartic H (cubic ∇H), false for quintic; L2 (Kahan's
    step is its symmetric form) needs a quadratic field and fails for quartic H."""
    quartic = mg.Hamiltonian("p**2/2 + q**4/4", q=["q"], p=["p"])
    quintic = mg.Hamiltonian("p**2/2 + q**5/5", q=["q"], p=["p"])
    assert K._lemmas(quartic, ("L2", "L4")) == {"L2": False, "L4": True}
    assert K._lemmas(quintic, ("L4",)) == {"L4": False}
    assert K.modified_energy_structural(quartic) is None    # not a quadratic field at all


def test_kahan_claims_in_verify_are_structural_and_quick():
    rep = mg.verify(mg.discretize(HH2, "kahan"), timeout=60)
    by = {c.claim.split(" H̃")[0].split(":")[0]: c for c in rep.certificates}
    assert rep.ok and not rep.undecided
    mod = [c for c in rep.certificates if "modified energy" in c.claim or "volume form" in c.claim]
    assert len(mod) == 2 and all(c.status == "proved" and c.details.get("structural") for c in mod), by


# --- RATTLE -----------------------------------------------------------------------------

@pytest.mark.parametrize("system", [CHAIN3, TORUS], ids=["chain3", "torus"])
def test_rattle_velocity_constraint_proved_structurally(system):
    cert = velocity_constraint(mg.discretize(system, "rattle"))
    assert cert.status == "proved" and cert.details["structural"]


def test_rattle_velocity_structure_checked_against_the_scheme():
    """Negative control: the recorded pieces must be what the scheme computes."""
    scheme = mg.discretize(TORUS, "rattle")
    d = TORUS.dim
    st = scheme.structure
    # p1 without the projection (SHAKE's velocities) is not w - G1ᵀc: refused, not proved.
    shake = mg.discretize(TORUS, "shake")
    tampered = replace(scheme, increment=sp.Matrix(list(scheme.increment[:d]) + list(shake.increment[d:])))
    assert velocity_structural(tampered) is None
    # a c that is not the LU solution is refused too
    bad = replace(scheme, structure={**st, "c": 2 * st["c"]},
                  increment=sp.Matrix(list(scheme.increment[:d]) +
                                      [w - g - p for w, g, p in zip(st["w"], st["G1"].T * (2 * st["c"]),
                                                                    TORUS.p)]))
    assert velocity_structural(bad) is None


def test_field_zero_decides_both_ways():
    a, b = sp.symbols("a b")
    A = sp.Matrix([[a, b], [b, a + 1]])
    rhs = sp.Matrix([1, a])
    assert field_zero(A * A.LUsolve(rhs) - rhs)
    assert not field_zero(A * A.LUsolve(rhs) - 2 * rhs)


# --- Störmer–Verlet ---------------------------------------------------------------------

def test_stormer_verlet_symplectic_by_composition_of_shears():
    scheme = mg.discretize(CALOGERO, "stormer-verlet")
    cert = symplectic_certificate(scheme)
    assert cert.status == "proved" and cert.details["structural"]
    assert "shears" in cert.method


def test_splitting_structure_must_match_the_increment():
    """Negative controls: wrong stage coefficients, or an increment that is not a composition
    of shears, are refused; the full check then refutes a non-symplectic map."""
    scheme = mg.discretize(CALOGERO, "stormer-verlet")
    h = STEP
    wrong = replace(scheme, structure={"kind": "splitting",
                                       "stages": (("kick", h / 3), ("drift", h), ("kick", h / 2))})
    assert splitting_symplectic(wrong, "x") is None
    pend = mg.load_scene("simple-pendulum").system
    sv = mg.discretize(pend, "stormer-verlet")
    inc = sv.increment
    skewed = replace(sv, increment=sp.Matrix([inc[0], inc[1] * (1 + h)]))   # p1 scaled: not symplectic
    assert splitting_symplectic(skewed, "x") is None
    assert symplectic_certificate(skewed).status == "refuted"


@pytest.mark.skipif(not USER.exists(), reason="tests/user_problems not present")
@pytest.mark.parametrize("problem, method", [("hh", "kahan"), ("calogero", "stormer-verlet"),
                                             ("torus", "rattle"), ("toda3", "stormer-verlet")])
def test_formerly_slow_user_problems_are_decided(problem, method):
    sc = mg.load_scene(str(USER / f"{problem}.toml"))
    rep = mg.verify(mg.discretize(sc.system, method), timeout=60)
    assert rep.ok and not rep.undecided, [(c.claim, c.details.get("reason")) for c in rep.undecided]


# --- AVF term by term -------------------------------------------------------------------

def test_avf_exact_for_functions_of_affine_forms():
    """Toda's exp(q1 - q2), a pendulum pair's cos(q1 - q2), Calogero's 1/(q1 - q2)**2: exact
    divided differences, H claimed and proved — no quadrature."""
    from methodgen.symbolic.verify.discrete_gradients import dg_identity
    for system in (CALOGERO, mg.Hamiltonian("(p1**2 + p2**2)/2 + exp(q1 - q2) - k*cos(q1 - q2)*(1 + q1)",
                                            q=["q1", "q2"], p=["p1", "p2"], params={"k": 1.0})):
        scheme = mg.discretize(system, "avf")
        if system is CALOGERO:
            assert scheme.traits.preserved == ("H",) and not scheme.traits.approximate
            assert not any(e.has(sp.Float) for e in scheme.discrete_gradient)
            assert dg_identity(system, scheme.discrete_gradient, scheme.y1, "avf",
                               scheme=scheme).status == "proved"
        else:
            # cos(q1 - q2)*q1 is not a function of one affine form: quadrature, honestly labelled
            assert scheme.traits.approximate == ("H",) and "H" not in scheme.traits.preserved
            assert not scheme.traits.energy_preserving


def test_linear_form_detection_and_its_limits():
    from methodgen.symbolic.schemes.discrete_gradients import additive_terms, linear_form_term
    q1, q2, q3, g = sp.symbols("q1 q2 q3 g")
    ys = (q1, q2, q3)
    terms = additive_terms(g**2 * (1 / (q1 - q2)**2 + 1 / (q2 - q3)**2))
    assert len(terms) == 2
    L, u, G = linear_form_term(terms[0], ys)
    assert sp.expand(G.xreplace({u: L}) - terms[0]) == 0 and not (G.free_symbols & set(ys))
    assert linear_form_term(sp.exp(q1 - 2 * q3 + 1), ys)[0] == q1 - 2 * q3 + 1
    # not one affine form: refused
    assert linear_form_term(sp.cos(q1) * sp.cos(q2), ys) is None
    assert linear_form_term(1 / sp.sqrt(q1**2 + q2**2), ys) is None


# --- midpoint: Cayley transform -----------------------------------------------------------

def test_midpoint_symplectic_structurally_on_nonlinear_h():
    from methodgen.symbolic.verify.maps import midpoint_symplectic
    scheme = mg.discretize(CALOGERO, "midpoint")
    cert = symplectic_certificate(scheme)
    assert cert.status == "proved" and cert.details["structural"] and "Cayley" in cert.claim
    # Negative control: a gradient not taken at the midpoint is not this structure.
    y0, y1 = CALOGERO.y, scheme.y1
    at_y0 = derive.gradient(CALOGERO)
    assert midpoint_symplectic(replace(scheme, discrete_gradient=at_y0), "x") is None
    # and the Cayley lemma needs a symmetric block: with a generic (non-symmetric) S it fails.
    S = sp.Matrix(2, 2, sp.symbols("a b c d"))
    J = sp.Matrix([[0, 1], [-1, 0]])
    A = J * S / 2
    I = sp.eye(2)
    assert any(sp.expand(e) != 0 for e in ((I + A).T * J * (I + A) - (I - A).T * J * (I - A)))
