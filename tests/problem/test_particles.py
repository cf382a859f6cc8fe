"""Particle families of symbolic size: the parser's templates and refusals, and the N-free
certificates with their negative controls."""

from __future__ import annotations

import pytest
import sympy as sp

import methodgen as mg
from methodgen.errors import MethodNotApplicable, ParseError
from methodgen.problem.particles import Particles
from methodgen.symbolic.particle_scheme import (certificates, discretize_particles, dg_identity,
                                                kinetic_midpoint_identity, proved_invariants, radial_profile)
from methodgen.symbolic.verify.exact import certify

KIN = "Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N)"
GRAV = KIN + " - Sum(Sum(G*m[i]*m[j]/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)"


def fam(text=GRAV, **kw):
    return Particles(text, q=["x", "y"], p=["px", "py"], arrays=["m"], params={"G": 1.0, "k": 2.0}, **kw)


def test_templates_and_the_written_out_hamiltonian():
    f = fam()
    xa, ya = f.q_slots[0]
    assert f.pair.free_symbols >= {xa, ya} and f.external == 0 and f.dim == 2
    H, q, p, arrays = f.expand(3)
    assert [s.name for s in q] == ["x1", "y1", "x2", "y2", "x3", "y3"]
    assert len(sp.Add.make_args(H)) == 3 + 3     # three kinetic terms, three pairs


def test_the_lower_triangle_is_the_same_pairs():
    a = fam()
    b = fam(KIN + " - Sum(Sum(G*m[i]*m[j]/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, 1, i - 1), i, 1, N)")
    assert sp.simplify(a.expand(3)[0] - b.expand(3)[0]) == 0


@pytest.mark.parametrize("text,words", [
    (KIN + " + Sum(Sum(Sum(x[i]*x[j]*x[l], l, 1, N), j, i + 1, N), i, 1, N)", "three nested Sums"),
    (KIN + " + Sum(Sum(1/((x[i] - x[j])**2 + 1), j, 1, N), i, 1, N)", "includes j = i"),
    (KIN + " + Sum(Sum(1/((x[i] - x[j])**2 + 1), j, i + 2, N), i, 1, N)", "other ranges are not supported"),
    (KIN + " + Sum(Sum(1/((x[i] - x[j])**2 + 1), j, i + 1, N), i, 2, N)", "runs over every particle"),
    (KIN + " + Sum(x[i]*Sum(1/((x[i] - x[j])**2 + 1), j, i + 1, N), i, 1, N)", "whole summand"),
    (KIN + " + Sum(Sum(px[j]*x[i], j, i + 1, N), i, 1, N)", "momentum in a pair term"),
    (KIN + " + Sum(Sum(x[i]**2, j, i + 1, N), i, 1, N)", "positions of both particles"),
    ("Sum(px[i]**4 + py[i]**2, i, 1, N) + Sum(x[i]**2, i, 1, N)", "not a quadratic form"),
    ("Sum(px[i]*x[i] + py[i]**2, i, 1, N) + Sum(x[i]**2, i, 1, N)", "couples positions and momenta"),
    (KIN + " + x[1]", "outside a Sum"),
    (KIN + " + Sum(x[i + 1]**2, i, 1, N)", "index of its Sum alone"),
    (KIN + "*Sum(x[i]**2, i, 1, N)", "non-linearly"),
    (KIN + " + N*Sum(x[i]**2, i, 1, N)", "only as a Sum bound"),
])
def test_refusals_say_what_is_valid(text, words):
    with pytest.raises(ParseError, match=words):
        fam(text)


def test_certificates_prove_the_claims_of_both_methods():
    f = fam()
    sv = discretize_particles(f, "stormer-verlet", 8)
    em = discretize_particles(f, "energy-momentum")
    csv, cem = certificates(sv), certificates(em)
    assert all(c.status == "proved" for c in csv + cem)
    assert set(proved_invariants(sv, csv)) == {"P", "L", "symplectic"}
    assert set(proved_invariants(em, cem)) == {"H", "P", "L"}
    assert sv.kicks and len(sv.kicks) == len(sv.drifts) + 1 and abs(sum(sv.drifts) - 1) < 1e-15


def test_verify_decides_without_expanding_in_n():
    """The certificates are about the templates: no certificate mentions N or a particle's number,
    and their size is the same whatever N the family is later run at (the written-out H, the
    control, grows as N²)."""
    f = fam()
    certs = mg.verify_particles(f, "energy-momentum")
    sizes = []
    for c in certs:
        names = {s.name for s in sp.sympify(c.expression if hasattr(c, "expression") else 0).free_symbols}
        assert "N" not in names and not any(n[-1:].isdigit() and n[:1] in "xy" for n in names)
        sizes.append(len(c.claim))
    again = [len(c.claim) for c in mg.verify_particles(fam(), "energy-momentum")]
    assert sizes == again
    ops = [sp.count_ops(f.expand(n)[0]) for n in (3, 5)]
    assert ops[1] > ops[0]                                    # the control does grow with N
    assert all(f.size not in sp.sympify(x).free_symbols for x in (f.kinetic, f.pair, em_g(f)))


def em_g(f):
    return discretize_particles(f, "energy-momentum").g


def test_negative_controls():
    # a pair term depending on x_a + x_b: not translation invariant (P not proved) and refused by EM
    f = fam(KIN + " + Sum(Sum(k*m[i]*m[j]/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2 + 1) + x[i]*x[j], j, i + 1, N), i, 1, N)")
    sv = discretize_particles(f, "stormer-verlet")
    certs = certificates(sv)
    assert "P" not in proved_invariants(sv, certs) and "L" not in proved_invariants(sv, certs)
    with pytest.raises(MethodNotApplicable, match="function of s"):
        discretize_particles(f, "energy-momentum")
    # translation invariant but anisotropic: L not proved, EM refused
    g = fam(KIN + " + Sum(Sum(k*(2*(x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)")
    assert radial_profile(g) is None
    c = certificates(discretize_particles(g, "stormer-verlet"))
    assert "L" not in proved_invariants(discretize_particles(g, "stormer-verlet"), c)
    assert "P" in proved_invariants(discretize_particles(g, "stormer-verlet"), c)
    # a wrong discrete gradient (the derivative at the midpoint) fails the identity
    s, s0, s1 = sp.Symbol("s", positive=True), sp.Symbol("s0", positive=True), sp.Symbol("s1", positive=True)
    V = -1 / sp.sqrt(s)
    wrong = sp.diff(V, s).xreplace({s: (s0 + s1) / 2})
    assert certify("control", dg_identity(V, s, wrong, s0, s1)).status != "proved"
    # a quartic kinetic energy breaks the midpoint identity
    p = sp.Symbol("p", real=True)
    assert certify("control", kinetic_midpoint_identity(p**4, [p])).status != "proved"
    # an external potential: neither method claims P (EM's own certificates: tests/problem/test_particles_external.py)
    w = fam(GRAV + " + Sum(k*(x[i]**2 + y[i]**2), i, 1, N)")
    ew = discretize_particles(w, "energy-momentum")
    assert set(proved_invariants(ew, certificates(ew))) == {"H", "L"}
    sw = discretize_particles(w, "stormer-verlet")
    assert set(proved_invariants(sw, certificates(sw))) == {"L", "symplectic"}
