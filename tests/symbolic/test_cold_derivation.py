"""The cheaper exact tests of a cold derivation decide what the general tests decide.

* :func:`methodgen.symbolic.schemes.base._kick_zero_by_families`: a splitting's kick
  ``Σ_k ∂I/∂p_k ∂U/∂q_k ≡ 0`` shown once per family of like terms and weight pattern,
  against the reduction of the whole sum (the reference); negative controls: a weight
  that is not conserved, a weight that reads another body's coordinate, a potential
  without families.
* :func:`methodgen.symbolic.derive._is_zero_expr`: ``simplify(e) == 0`` decided by
  ``cancel`` for rational functions, against ``simplify`` itself, both ways.
"""

from __future__ import annotations

import sympy as sp

import methodgen as mg
from methodgen.symbolic import derive
from methodgen.symbolic.schemes import base


def _gravity(n: int, dims: int = 2) -> mg.Hamiltonian:
    """n bodies of masses m0..m(n-1) under pairwise gravity in ``dims`` dimensions."""
    ax = "xyz"[:dims]
    q = [f"{a}{b}" for b in range(n) for a in ax]
    p = [f"p{a}{b}" for b in range(n) for a in ax]
    T = " + ".join(f"p{a}{b}**2/(2*m{b})" for b in range(n) for a in ax)
    U = " + ".join(f"- m{a}*m{b}/sqrt({' + '.join(f'({c}{a} - {c}{b})**2' for c in ax)})"
                   for a in range(n) for b in range(a + 1, n))
    return mg.Hamiltonian(f"{T} {U}", q=q, p=p, params={f"m{b}": 1.0 + b for b in range(n)},
                          name=f"gravity{n}")


def _whole(weights, system) -> bool:
    """The reference: the kick reduced as one sum (what splitting_invariants did before)."""
    _, gradU = derive.separable_gradients(system)
    return base._claim_zero(sp.Add(*[w * g for w, g in zip(weights, gradU)]), system)


def _momentum_weights(system, expr):
    return [sp.diff(expr, s) for s in system.p]


def test_kick_by_families_proves_total_momenta_as_the_whole_sum_does():
    system = _gravity(4)
    q = system.q
    x, y = q[0::2], q[1::2]
    px, py = system.p[0::2], system.p[1::2]
    P_x = sp.Add(*px)
    L = sp.Add(*[a * pb - b * pa for a, b, pa, pb in zip(x, y, px, py)])
    for I in (P_x, L):
        w = _momentum_weights(system, I)
        assert base._kick_zero_by_families(w, system) is True
        assert _whole(w, system) is True
    assert set(base.splitting_invariants(system)) >= {"P_x", "P_y", "L"}


def test_kick_by_families_negative_controls():
    system = _gravity(3)
    px0 = system.p[0]
    # one body's momentum is not conserved: neither test shows its kick zero
    w = _momentum_weights(system, px0)
    assert base._kick_zero_by_families(w, system) is False
    assert _whole(w, system) is False
    # a weight reading another body's coordinate is not decided pattern by pattern
    x0, x2 = system.q[0], system.q[4]
    w = [sp.S.Zero] * system.dim
    w[2] = x2 - x0          # body 1's x weighted by bodies 0 and 2
    assert base._kick_zero_by_families(w, system) is False
    # H not written term by term as T + U over families: no family test, the caller's whole sum
    r = mg.Hamiltonian("(px**2 + py**2)/2 + (x**2 + y**2)**2/4", q=["x", "y"], p=["px", "py"])
    assert derive.potential_families(r) is None or not base._kick_zero_by_families([sp.S.One, sp.S.Zero], r)


def test_splitting_invariants_unchanged_on_the_outer_solar_system():
    system = mg.load_scene("outer-solar-system").system
    assert base.splitting_invariants(system) == ("P_x", "P_y", "P_z", "L_x", "L_y", "L_z")


def test_is_zero_expr_agrees_with_simplify():
    m0, m1 = sp.symbols("m0 m1", positive=True)
    x = sp.Symbol("x", real=True)
    cases = [sp.S.Zero, 1 / m0 - 1 / m0, 1 / m1 - 1 / m0, (m0**2 - m1**2) / (m0 - m1) - m0 - m1,
             (m0 + m1) / (m0 * m1) - 1 / m0 - 1 / m1, sp.sin(x)**2 + sp.cos(x)**2 - 1, sp.sin(x) - x,
             sp.Integer(3)]
    got = [derive._is_zero_expr(e) for e in cases]
    assert got == [sp.simplify(e) == 0 for e in cases]
    assert got == [True, True, False, True, True, True, False, False]   # both answers occur


def test_isotropic_mass_matrices():
    oss = mg.load_scene("outer-solar-system").system
    assert derive.separable_split(oss).isotropic is False        # different masses
    kepler = mg.load_scene("kepler").system
    assert derive.separable_split(kepler).isotropic is True
