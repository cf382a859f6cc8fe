"""Total momentum is found at any size where U is a sum of like terms (issue 27.9).

It was found for a Toda ring of N = 10 but not N = 200: detection was skipped above
``DETECT_MAX_DIM = 60`` degrees of freedom.  Now the exact test is family by family
(:func:`methodgen.symbolic.derive._commutes_by_families`) and the size limit applies only to systems
without families.  Negative controls: an external field breaks translation invariance
(no P), and a Hamiltonian without families above the limit is still not searched.
"""

from __future__ import annotations

import time

import sympy as sp

import methodgen as mg
from methodgen.symbolic import derive


def _toda_ring(n: int, field: str = "") -> mg.Hamiltonian:
    T = " + ".join(f"p{i}**2/2" for i in range(n))
    U = " + ".join(f"exp(q{i} - q{(i + 1) % n})" for i in range(n))
    extra = (" + " + " + ".join(f"{field}*q{i}" for i in range(n))) if field else ""
    return mg.Hamiltonian(T + " + " + U + extra, q=[f"q{i}" for i in range(n)],
                          p=[f"p{i}" for i in range(n)], name=f"toda{n}")


def test_total_momentum_of_a_toda_ring_of_200():
    """Exact: P = Σ p_i is detected and proved for N = 200 (above DETECT_MAX_DIM)."""
    system = _toda_ring(200)
    assert system.dim > derive.DETECT_MAX_DIM
    t0 = time.perf_counter()
    found = derive.detected_momenta(system)
    elapsed = time.perf_counter() - t0   # reported, never asserted (benchmarks are not tests)
    assert [inv.name for inv in found] == ["P"], found
    assert sp.expand(found[0].expr - sp.Add(*system.p)) == 0 and found[0].exact
    print(f"detected_momenta, Toda N = 200: {elapsed:.2f} s")


def test_external_field_has_no_momentum():
    """Negative control: the same ring in a field Σ 0.1 q_i is not translation invariant."""
    found = derive.detected_momenta(_toda_ring(200, field="0.1"))
    assert not [inv for inv in found if inv.name.startswith("P")]


def test_small_ring_unchanged():
    """N = 10 (below the limit) as before: P."""
    assert [inv.name for inv in derive.detected_momenta(_toda_ring(10))] == ["P"]


def test_no_families_above_the_limit_is_still_skipped():
    """The gate that remains: U without like terms (each spring a different power, so every
    family has one instance) above DETECT_MAX_DIM is not searched (its P goes undetected,
    documented), while the same springs below the limit are."""
    def chain(n):
        U = " + ".join(f"(q{i} - q{i + 1})**{2 + i}" for i in range(n - 1))
        return mg.Hamiltonian(" + ".join(f"p{i}**2/2" for i in range(n)) + " + " + U,
                              q=[f"q{i}" for i in range(n)], p=[f"p{i}" for i in range(n)], name=f"powers{n}")
    big = chain(derive.DETECT_MAX_DIM + 2)
    assert all(f.size == 1 for f in derive.potential_families(big))
    assert derive.detected_momenta(big) == ()
    assert [inv.name for inv in derive.detected_momenta(chain(6))] == ["P"]


def test_mass_matrix_read_off_monomials_equals_the_hessian():
    """The monomial read-off that replaced sp.hessian gives the same M⁻¹, and None where
    T is not ½ pᵀ M⁻¹ p with constant M⁻¹ (a linear term, a q- or p-dependent coefficient)."""
    p1, p2, q1, m = sp.symbols("p1 p2 q1 m", real=True)
    state = {p1, p2, q1}
    for T in (p1**2 / (2 * m) + p2**2 / 2, p1**2 / 2 + p1 * p2 / 3 + 2 * p2**2):
        assert derive._mass_inverse(T, [p1, p2], state) == sp.hessian(T, [p1, p2])
    for T in (p1**2 / 2 + p1, q1 * p1**2 / 2, p1**4 + p2**2, sp.sqrt(1 + p1**2) + p2**2):
        assert derive._mass_inverse(T, [p1, p2], state) is None


def _planar_gravity(n: int) -> mg.Hamiltonian:
    q = [c for b in range(n) for c in (f"x{b}", f"y{b}")]
    p = [c for b in range(n) for c in (f"u{b}", f"v{b}")]
    T = " + ".join(f"(u{b}**2 + v{b}**2)/2" for b in range(n))
    U = " + ".join(f"-1/sqrt((x{i} - x{j})**2 + (y{i} - y{j})**2)" for i in range(n) for j in range(i + 1, n))
    return mg.Hamiltonian(T + " + " + U, q=q, p=p, name=f"grav{n}")


def test_sample_points_are_distinct_and_regular_for_a_pair_potential():
    """The screens' sample points (derive.sample_points) give every coordinate its own value, so
    the gravitational pair potential of 14 bodies (28 coordinates) is finite there.  Negative
    control: the former periodic points 0.37 + 0.11·((i·k) mod 13) put bodies 0 and 13 on one
    point (the screen then fails and every plane went to whole-sum exact reduction: > 300 s)."""
    import math

    system = _planar_gravity(14)
    n = len(system.y)
    for y in derive.sample_points(n):
        assert len(set(y)) == n
    samples = derive._gradient_samples(system)
    assert samples is not None and all(math.isfinite(v) for _, g in samples for v in g)
    for k in (3, 7):
        old = [0.37 + 0.11 * ((i * k) % 13) for i in range(n)]
        assert (old[0], old[1]) == (old[26], old[27])   # x0 = x13 and y0 = y13


def test_pair_potential_of_fourteen_bodies_finds_P_and_L():
    """Exact: planar gravity, N = 14 (past the period of the former sample points): P_x, P_y and
    the total angular momentum L are detected and proved (~1 s; N = 31, d = 62: ~3 s)."""
    found = derive.detected_momenta(_planar_gravity(14))
    assert [(inv.name, inv.exact) for inv in found] == [("P_x", True), ("P_y", True), ("L", True)]
    assert derive.angular_momenta(_planar_gravity(14)) == ()   # no single plane is a symmetry


def test_unscreened_angular_search_is_bounded():
    """Where H cannot be evaluated at the sample points (sqrt of a negative number there), planes
    are tested exactly only up to ANGULAR_UNSCREENED_MAX_DIM degrees of freedom: a rotation-
    invariant H finds Lx, Ly, Lz in 3D, and nothing (not searched, documented) in 8D."""
    def radial(d):
        qs, ps = [f"q{i}" for i in range(d)], [f"p{i}" for i in range(d)]
        return mg.Hamiltonian(" + ".join(f"{v}**2/2" for v in ps) + " + sqrt("
                              + " + ".join(f"{v}**2" for v in qs) + " - 100)", q=qs, p=ps, name=f"rad{d}")
    three = radial(3)
    assert derive._angular_screen(three) is None
    assert [inv.name for inv in derive.angular_momenta(three)] == ["Lx", "Ly", "Lz"]
    eight = radial(8)
    assert eight.dim > derive.ANGULAR_UNSCREENED_MAX_DIM
    assert derive._angular_screen(eight) is None and derive.angular_momenta(eight) == ()


def test_above_the_limit_a_candidate_not_shown_by_families_is_not_detected(monkeypatch):
    """Above DETECT_MAX_DIM, a bracket that cancels only across families (the linear terms
    2 q0 and -2 q1 are families of their own, each piece nonzero) is not reduced on the whole
    sum: P is not detected (documented), while below the limit the whole sum shows it.
    Negative control: with the limit raised, the same 62-dof system finds P by the whole-sum
    reduction the gate now skips."""
    def ring(n):
        T = " + ".join(f"p{i}**2/2" for i in range(n))
        U = " + ".join(f"exp(q{i} - q{(i + 1) % n})" for i in range(n))
        return mg.Hamiltonian(T + " + " + U + " + 2*q0 - 2*q1", q=[f"q{i}" for i in range(n)],
                              p=[f"p{i}" for i in range(n)], name=f"ring_lin{n}")
    big = ring(derive.DETECT_MAX_DIM + 2)
    assert derive._commutes_by_families(big, sp.Add(*big.p)) is None
    assert derive.detected_momenta(big) == ()
    assert [inv.name for inv in derive.detected_momenta(ring(10))] == ["P"]
    monkeypatch.setattr(derive, "DETECT_MAX_DIM", 1000)
    assert [inv.name for inv in derive.detected_momenta(ring(62))] == ["P"]


def test_bilinear_invariants_quick_rejection():
    """bilinear_invariants rejects an invariant with a squared variable before building its Poly
    (H of an FPU chain of 64: half of the derivation went there); what it returns is unchanged:
    Kepler's angular momenta are bilinear, H and the Toda ring's P are not (P is linear)."""
    from methodgen.symbolic.schemes.base import _second_power, bilinear_invariants

    kepler = mg.load_scene("kepler").system
    names = bilinear_invariants(kepler)
    assert set(names) >= {"Lx", "Ly", "Lz"} and "H" not in names
    assert bilinear_invariants(_toda_ring(12)) == ()
    x, y, px, py = kepler.q[0], kepler.q[1], kepler.p[0], kepler.p[1]
    assert not _second_power(x * py - y * px, kepler.y)                     # bilinear: not rejected
    assert not _second_power((x + y) * (px - py), kepler.y)
    assert _second_power(px**2 / 2 + x * py, kepler.y)                       # negative control
