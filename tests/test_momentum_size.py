"""Total momentum is found at any size where U is a sum of like terms (issue 27.9).

It was found for a Toda ring of N = 10 but not N = 200: detection was skipped above
``DETECT_MAX_DIM = 60`` degrees of freedom.  Now the exact test is family by family
(:func:`methodgen.derive._commutes_by_families`) and the size limit applies only to systems
without families.  Negative controls: an external field breaks translation invariance
(no P), and a Hamiltonian without families above the limit is still not searched.
"""

from __future__ import annotations

import time

import sympy as sp

import methodgen as mg
from methodgen import derive


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
