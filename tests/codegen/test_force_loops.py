"""Kernels that loop over U's families where they were unrolled (issue 25): Störmer–Verlet's
post kernel (end force Σ_t ∇U_t(q0 + c + Δq), H at y1 through Σ_t U_t), and the H / field
kernels (check, hs, hamiltonian) of looped modules through Σ_t U_t and Σ_t ∇U_t.

Agreement with the unrolled kernels is to round-off, not to the bit: the loops add the
instances in table order, the unrolled code in SymPy's canonical order of the expanded sum.
Δq (computed ahead of the loops by the same straight-line code) is bitwise.  Each agreement
test has a negative control: one wrong index-table entry in the looped module is detected.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.app.bench import nbody_initial, nbody_system
from methodgen.codegen.emit import load_module, render, write_atomic
from methodgen.codegen.lower import lower
from methodgen.codegen.lower_loops import force_plan, potential_via_sums

#: Round-off agreement of one kernel evaluation (|values| ~ 1).
TOL = 1e-13


def _module(scheme, loops, tmp_path, backend="numpy", tag=""):
    ir = lower(scheme, "test", f"fl{int(bool(loops is not False))}{tag}", loops=loops)
    path = tmp_path / f"fl_{scheme.system.name}_{scheme.method}_{loops}{tag}_{backend}.py"
    write_atomic(path, render(ir, backend))
    return ir, load_module(path)


@pytest.fixture(scope="module")
def sv(tmp_path_factory):
    cache = {}

    def get(n, order=2):
        if (n, order) not in cache:
            scheme = mg.discretize(nbody_system(n), "stormer-verlet", order=order)
            root = tmp_path_factory.mktemp(f"sv{n}_{order}")
            cache[n, order] = (scheme, _module(scheme, None, root), _module(scheme, False, root))
        return cache[n, order]

    return get


def _wrong_table(mod):
    """One wrong index-table entry (a coordinate of the first instance moved to another body)."""
    t = [list(r) for r in mod._IDX0]
    t[0][0] = (t[0][0] + 3) % (3 * (max(max(r) for r in t) // 3 + 1))
    return tuple(tuple(r) for r in t) if isinstance(mod._IDX0, tuple) else np.array(t, dtype=mod._IDX0.dtype)


def _post_args(mod, y, n):
    c = [1e-17 * ((i % 3) - 1) for i in range(len(y))]
    g = mod._s_force(list(y), c, mod._params(None))
    return list(y), c, g, 0.005, 0.01, 0.005, mod._params(None)


def test_force_plan_is_the_potential_term_by_term():
    """The plan's instances are U's q-dependent terms (checked structurally by
    potential_via_sums), one family of n(n-1)/2 pair terms for N bodies."""
    system = nbody_system(5)
    plan = force_plan(system)
    assert [lf.family.size for lf in plan.families] == [10] and plan.looped
    assert potential_via_sums(system, plan) is not None
    # control: a plan missing one instance is refused
    import dataclasses
    fam = plan.families[0].family
    short = dataclasses.replace(fam, index=fam.index[1:], pindex=fam.pindex[1:], terms=fam.terms[1:])
    bad = dataclasses.replace(plan, families=(dataclasses.replace(plan.families[0], family=short),))
    assert potential_via_sums(system, bad) is None


def test_sv_post_loops_agree_with_the_unrolled_kernel(sv):
    scheme, (ir, a), (ir_u, b) = sv(4)
    assert ir.scalar["post"].loops and ir.scalar["hs"].loops and not ir_u.scalar["post"].loops
    y = nbody_initial(4)
    args = _post_args(b, y, 4)
    pa, pb = np.array(a._s_post(*args)), np.array(b._s_post(*args))
    d = scheme.system.dim
    assert np.array_equal(pa[:d], pb[:d])                     # Δq: the same code, bitwise
    assert np.max(np.abs(pa - pb)) < TOL
    Y = np.stack([y, y * 1.01, y * 0.98])
    G = np.stack([b._s_force(list(r), [0.0] * len(r), b._params(None)) for r in Y])
    va = a._v_post(Y, np.zeros_like(Y), G, 0.005, 0.01, 0.005, a._params(None))
    vb = b._v_post(Y, np.zeros_like(Y), G, 0.005, 0.01, 0.005, b._params(None))
    assert np.max(np.abs(va - vb)) < TOL
    # the scalar and batch flavours of the looped kernel agree too
    assert np.max(np.abs(np.array(a._s_post(list(Y[1]), [0.0] * len(y), list(G[1]), 0.005, 0.01, 0.005,
                                            a._params(None))) - va[1])) < TOL
    # negative control: one wrong index-table entry is seen in the end force
    good = a._IDX0
    try:
        a._IDX0 = _wrong_table(a)
        assert np.max(np.abs(np.array(a._s_post(*args)) - pb)) > 1e-3
    finally:
        a._IDX0 = good


@pytest.mark.parametrize("order", [2, 4])
def test_sv_looped_trajectory_agrees_with_the_unrolled_module(sv, order):
    scheme, (_, a), (_, b) = sv(4, order)
    y0 = nbody_initial(4)
    ta, tb = a.integrate(y0, 0.01, 200), b.integrate(y0, 0.01, 200)
    # round-off of 200 steps (|y| ~ 1), far below the method's error
    assert np.max(np.abs(ta - tb)) < 1e-11
    # H through the loops (hs, hamiltonian) is the unrolled H to round-off
    assert abs(a.hamiltonian(ta[-1]) - b.hamiltonian(ta[-1])) < 1e-14
    assert np.max(np.abs(np.array(a._s_hs(list(y0), a._params(None)))
                         - np.array(b._s_hs(list(y0), b._params(None))))) < 1e-14


def test_check_kernels_loop_in_energy_momentum(tmp_path):
    scheme = mg.discretize(nbody_system(4), "energy-momentum")
    (ir, a), (ir_u, b) = _module(scheme, None, tmp_path), _module(scheme, False, tmp_path)
    assert ir.scalar["check"].loops and ir.vector["hamiltonian"].loops and not ir_u.scalar["check"].loops
    y = nbody_initial(4)
    ca, cb = np.array(a._s_check(list(y), a._params(None))), np.array(b._s_check(list(y), b._params(None)))
    assert np.max(np.abs(ca - cb)) < TOL
    Y = np.stack([y, 1.1 * y])
    assert np.max(np.abs(a._v_check(Y, a._params(None)) - b._v_check(Y, b._params(None)))) < TOL
    assert np.max(np.abs(a.hamiltonian(Y) - b.hamiltonian(Y))) < TOL
    good = a._IDX0
    try:   # negative control: a wrong table entry changes H and the field
        a._IDX0 = _wrong_table(a)
        assert np.max(np.abs(np.array(a._s_check(list(y), a._params(None))) - cb)) > 1e-3
    finally:
        a._IDX0 = good


def _loop_code(kern) -> str:
    return "\n".join([f"{v}={s}{c}" for L in kern.loops for v, s, c in L.loads]
                     + [f"{v}={c}" for L in kern.loops for v, c in L.temps]
                     + [f"{a}{cols}+={c}" for L in kern.loops for a, cols, c in L.adds])


def _straight(kern) -> int:
    return sum(len(c) for _, c in kern.pre + kern.temps + kern.outputs)


def test_looped_code_does_not_grow_with_the_instances():
    """N = 3 (3 pairs) vs N = 6 (15 pairs): the loops' code is the same text; the
    straight-line code grows like the degrees of freedom (×2), not like the pairs (×5).
    Control: the unrolled post kernel grows faster than the degrees of freedom."""
    irs = {}
    for n in (3, 6):
        scheme = mg.discretize(nbody_system(n), "stormer-verlet")
        irs[n] = (lower(scheme, "s", "m"), lower(scheme, "s", "m", loops=False))
    for kind in ("post", "hs"):
        assert _loop_code(irs[3][0].scalar[kind]) == _loop_code(irs[6][0].scalar[kind]) != ""
    looped = _straight(irs[6][0].scalar["post"]) / _straight(irs[3][0].scalar["post"])
    unrolled = _straight(irs[6][1].scalar["post"]) / _straight(irs[3][1].scalar["post"])
    assert looped < 2.6 < unrolled, (looped, unrolled)


@pytest.mark.slow
def test_sv_looped_numba_module_agrees_with_numpy(sv):
    """The compiled looped post kernel (Δq written into the output ahead of the loops) runs
    the numpy module's trajectory to round-off (fast sibling: the numpy tests above)."""
    pytest.importorskip("llvmlite")
    scheme = mg.discretize(nbody_system(4), "stormer-verlet")
    m = mg.build(scheme.system, "stormer-verlet", backend="numba")
    ref = mg.build(scheme.system, "stormer-verlet")
    y0 = nbody_initial(4)
    assert np.max(np.abs(m.integrate(y0, 0.01, 200) - ref.integrate(y0, 0.01, 200))) < 1e-11
