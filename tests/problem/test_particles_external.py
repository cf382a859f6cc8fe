"""Energy-momentum for particle families with an external potential W, and above order 2: the
discrete gradient of W per particle proved exactly per template (central W: the chord form;
otherwise the symmetrised Itoh–Abe form), the invariants claimed only where proved, each with a
negative control; the orders offered and the refusal naming them."""

from __future__ import annotations

import dataclasses

import pytest
import sympy as sp

from methodgen.errors import InputError
from methodgen.problem.particles import Particles
from methodgen.symbolic.particle_scheme import (ORDERS, _itoh_abe_parts, certificates, central_profile,
                                                discretize_particles, dg_identity, external_dg_identity,
                                                external_discrete_gradient, proved_invariants)
from methodgen.symbolic.verify.exact import certify

KIN2 = "Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N)"
COUL2 = " + Sum(Sum(k/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)"
TRAP2 = " + Sum(m[i]*w**2*(x[i]**2 + y[i]**2)/2, i, 1, N)"
ANIS2 = " + Sum(m[i]*(w**2*x[i]**2 + 4*y[i]**2)/2 + x[i]**4/4, i, 1, N)"
KIN3 = "Sum((px[i]**2 + py[i]**2 + pz[i]**2)/(2*m[i]), i, 1, N)"
PAIR3 = " + Sum(Sum(k/((x[i] - x[j])**2 + (y[i] - y[j])**2 + (z[i] - z[j])**2 + 1), j, i + 1, N), i, 1, N)"


def fam2(text):
    return Particles(text, q=["x", "y"], p=["px", "py"], arrays=["m"], params={"k": 1.0, "w": 1.0})


def fam3(text):
    return Particles(text, q=["x", "y", "z"], p=["px", "py", "pz"], arrays=["m"], params={"k": 1.0, "w": 1.0})


def test_central_trap_keeps_h_and_l_not_p():
    f = fam2(KIN2 + COUL2 + TRAP2)
    assert central_profile(f) is not None
    em = discretize_particles(f, "energy-momentum")
    assert em.external_kind == "central"
    certs = certificates(em)
    # "proved": reduced to exactly 0 by SymPy, no floating point in the expression (verify.report)
    assert all(c.status == "proved" for c in certs)
    assert any("one-body chord identity" in c.claim for c in certs)
    assert set(proved_invariants(em, certs)) == {"H", "L"}           # P never with a trap


def test_central_form_at_equal_ends_is_the_gradient():
    """No removable singularity: G(q0, q0) is ∇W(q0) by substitution (no 0/0)."""
    f = fam2(KIN2 + COUL2 + " - Sum(m[i]/sqrt(x[i]**2 + y[i]**2 + 1), i, 1, N)")
    xd = external_discrete_gradient(f)
    assert xd["kind"] == "central"
    qa, q1 = f.q_slots[0], xd["q1"]
    for gk, v in zip(xd["G"], qa):
        at_equal = gk.xreplace(dict(zip(q1, qa)))
        assert not at_equal.has(sp.nan, sp.zoo)
        assert sp.simplify(at_equal - sp.diff(f.external, v)) == 0


def test_anisotropic_trap_itoh_abe_keeps_h_and_claims_neither_l_nor_p():
    f = fam2(KIN2 + COUL2 + ANIS2)
    assert central_profile(f) is None
    em = discretize_particles(f, "energy-momentum", 4)
    assert em.external_kind == "itoh-abe" and em.order == 4 and len(em.gammas) > 1
    certs = certificates(em)
    by = {c.claim.split(":")[0]: c for c in certs}
    assert by["the external potential is rotation invariant about the origin"].status == "refuted"
    ia = [c for c in certs if "Itoh & Abe" in c.ref]
    assert len(ia) == 4 and all(c.status == "proved" for c in ia)
    assert set(proved_invariants(em, certs)) == {"H"}
    # the whole identity G·(q1 - q0) = W(q1) - W(q0) also reduces to 0 directly (polynomial W)
    assert certify("G is a discrete gradient of W",
                   external_dg_identity(f.external, f.q_slots[0], em.q1_slots, em.external_dg)).status == "proved"


def test_itoh_abe_in_three_dimensions_is_exact_and_symmetric():
    f = fam3(KIN3 + PAIR3 + " + Sum(m[i]*(x[i]**2 + 2*y[i]**2 + 3*z[i]**2)/2 + x[i]*y[i]*z[i], i, 1, N)")
    em = discretize_particles(f, "energy-momentum")
    assert em.external_kind == "itoh-abe"
    parts = _itoh_abe_parts(f.external, f.q_slots[0], em.q1_slots)
    assert [len(p) for p in parts] == [4, 4, 4]                       # 2^(d-1) quotients per component
    assert all(sum(w for w, _, _ in p) == 1 for p in parts)           # the weights over the orderings
    certs = certificates(em)
    assert all(c.status == "proved" for c in certs if "Itoh & Abe" in c.ref)
    assert set(proved_invariants(em, certs)) == {"H"}
    assert certify("dg", external_dg_identity(f.external, f.q_slots[0], em.q1_slots,
                                              em.external_dg)).status == "proved"


def test_negative_controls_a_perturbed_discrete_gradient_is_refused():
    # Itoh–Abe: the emitted G perturbed by a term of the size of the increment -> the "emitted" certificate
    # is refuted and H is no longer claimed
    f = fam2(KIN2 + COUL2 + ANIS2)
    em = discretize_particles(f, "energy-momentum")
    (xa, ya), (x1, y1) = f.q_slots[0], em.q1_slots
    bad = dataclasses.replace(em, external_dg=(em.external_dg[0] + (y1 - ya), em.external_dg[1]))
    certs = certificates(bad)
    assert any(c.status == "refuted" for c in certs if "emitted" in c.claim)
    assert "H" not in proved_invariants(bad, certs)
    assert certify("control", external_dg_identity(f.external, f.q_slots[0], em.q1_slots,
                                                   bad.external_dg)).status == "refuted"
    # a one-variable quotient replaced by the derivative at the midpoint: not a divided difference of x⁴
    xi, a, b = sp.symbols("xi a b", real=True)
    W = xi ** 4 / 4
    assert certify("control", dg_identity(W, xi, sp.diff(W, xi).xreplace({xi: (a + b) / 2}), a, b)).status \
        == "refuted"
    # one ordering only (not symmetrised): still a discrete gradient, but not symmetric (a W coupling x and y)
    W2 = xa ** 3 * ya + ya ** 2
    one = [sp.Add(*[wt * D for wt, S, D in comp if len(S) == (1 if k == 1 else 0)]) * 2
           for k, comp in enumerate(_itoh_abe_parts(W2, f.q_slots[0], em.q1_slots))]
    assert certify("ordering", external_dg_identity(W2, f.q_slots[0], em.q1_slots, one)).status == "proved"
    swap = {**dict(zip(f.q_slots[0], em.q1_slots)), **dict(zip(em.q1_slots, f.q_slots[0]))}
    assert certify("control", sp.Matrix([g - g.xreplace(swap) for g in one])).status == "refuted"
    # central: a perturbed w (its derivative at the mean σ) is refused, and H is not claimed
    c = fam2(KIN2 + COUL2 + " - Sum(m[i]/sqrt(x[i]**2 + y[i]**2 + 1), i, 1, N)")
    ec = discretize_particles(c, "energy-momentum")
    wrong = sp.diff(ec.external_profile, ec.sigma).xreplace({ec.sigma: (ec.sigma0 + ec.sigma1) / 2})
    certs = certificates(dataclasses.replace(ec, w=wrong))
    assert any(c.status == "refuted" for c in certs if c.claim.startswith("discrete gradient of W"))
    assert "H" not in proved_invariants(ec, certs)


def test_l_is_not_claimed_without_the_chord_form():
    """A rotation-invariant W taken through Itoh–Abe (as if the central check had failed): the
    rotation-invariance certificate is proved, but Itoh–Abe's G is not along q̄, so L is not claimed;
    the chord form (the control) claims it."""
    f = fam2(KIN2 + COUL2 + TRAP2)
    em = discretize_particles(f, "energy-momentum")
    parts = _itoh_abe_parts(f.external, f.q_slots[0], em.q1_slots)
    G = tuple(sp.Add(*[wt * D for wt, _, D in comp]) for comp in parts)
    forced = dataclasses.replace(em, external_kind="itoh-abe", external_dg=G)
    certs = certificates(forced)
    assert all(c.status == "proved" for c in certs)
    assert set(proved_invariants(forced, certs)) == {"H"}
    assert set(proved_invariants(em, certificates(em))) == {"H", "L"}


def test_one_dimension_and_a_family_without_pairs():
    f = Particles("Sum(px[i]**2/(2*m[i]), i, 1, N) + Sum(x[i]**4/4 - x[i]**2/2, i, 1, N)", q=["x"], p=["px"],
                  arrays=["m"])
    em = discretize_particles(f, "energy-momentum", 6)
    assert em.external_kind == "central"
    certs = certificates(em)
    assert all(c.status == "proved" for c in certs)
    assert set(proved_invariants(em, certs)) == {"H"}


@pytest.mark.parametrize("method", ["stormer-verlet", "energy-momentum"])
@pytest.mark.parametrize("order", [3, 10, 0, True])
def test_an_order_not_offered_names_the_valid_ones(method, order):
    with pytest.raises(InputError, match="2, 4, 6, 8"):
        discretize_particles(fam2(KIN2 + COUL2 + TRAP2), method, order)
    assert ORDERS == (2, 4, 6, 8)
