"""Banded Newton solves (issue 16 item 2): the Newton matrix's structural band is found at
lowering (``ModuleIR.band``) and Gaussian elimination with partial pivoting stays inside it.
Outside the band every entry is an exact zero of the derivation, so the banded elimination
is the dense one: the same pivots, the same values, bitwise the same trajectories."""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.app.bench import nbody_system
from methodgen.codegen.emit import load_module, render, write_atomic
from methodgen.codegen.lower import jacobian_band, lower

from helpers import fpu_chain


def _module(scheme, tmp_path, loops=None, backend="numpy", tag=""):
    ir = lower(scheme, "test", f"band{tag}", loops=loops)
    path = tmp_path / f"band_{scheme.system.name}_{scheme.method}_{loops}{tag}_{backend}.py"
    write_atomic(path, render(ir, backend))
    return ir, load_module(path)


def test_band_of_a_pattern():
    assert jacobian_band(4, [(0, 0), (1, 0), (0, 2)]) == (1, 2)
    assert jacobian_band(3, []) == (0, 0)
    assert jacobian_band(3, [(2, 0), (0, 2)]) == (2, 2)


@pytest.mark.parametrize("method,loops", [("energy-momentum", None), ("energy-momentum", False),
                                          ("midpoint", None), ("avf", False)])
def test_chain_is_tridiagonal_and_nbody_dense(method, loops):
    """Nearest-neighbour coupling: one band either side, from the accumulated pattern (loops)
    or from the unrolled Jacobian's nonzero entries; all pairs coupled: dense."""
    chain = mg.discretize(fpu_chain(10), method)
    assert lower(chain, "s", "m", loops=loops).band == (1, 1)
    if method != "avf":    # (AVF of 1/r is a quadrature: slow to lower unrolled)
        nbody = mg.discretize(nbody_system(3), method)
        assert lower(nbody, "s", "m", loops=loops).band == (8, 8)


@pytest.fixture(scope="module")
def chain10(tmp_path_factory):
    """``chain10(loops)`` -> (ir, module): the 10-mass FPU chain's energy-momentum module, lowered
    and loaded once per choice of loops for the three solvers' tests (each test restores the
    band it widens)."""
    scheme = mg.discretize(fpu_chain(10), "energy-momentum")
    cache = {}

    def get(loops):
        if loops not in cache:
            cache[loops] = _module(scheme, tmp_path_factory.mktemp("band"), loops)
        return cache[loops]

    return get


@pytest.mark.parametrize("loops", [None, False])
@pytest.mark.parametrize("solver", ["newton", "reuse", "auto"])
def test_banded_solve_is_bitwise_the_dense_one(chain10, loops, solver):
    """The numpy module's elimination reads _KL/_KU at call time: widening them to the full
    matrix runs the dense elimination, and the trajectories are bitwise equal."""
    n = 10
    ir, mod = chain10(loops)
    assert (mod._KL, mod._KU) == ir.band == (1, 1) and mod._N == n
    rng = np.random.default_rng(5)
    y0 = np.concatenate([0.6 * rng.normal(size=n), rng.normal(size=n)])
    banded = mod.integrate(y0, 0.1, 300, solver=solver)
    try:
        mod._KL = mod._KU = n - 1
        dense = mod.integrate(y0, 0.1, 300, solver=solver)
    finally:
        mod._KL, mod._KU = ir.band
    assert np.array_equal(banded, dense)
    H = mod.hamiltonian(banded)
    assert np.abs(H - H[0]).max() < 1e-13 * abs(H[0])


def test_negative_control_a_band_too_narrow_gives_a_wrong_solve(tmp_path):
    """The band limits are really used: on a matrix with entries outside a declared band the
    elimination ignores them and the solution is wrong; with the true band it is right."""
    scheme = mg.discretize(fpu_chain(6), "energy-momentum")
    _, mod = _module(scheme, tmp_path)
    rng = np.random.default_rng(0)
    a = rng.normal(size=(6, 6)) + 3 * np.eye(6)
    b = rng.normal(size=6)
    want = np.linalg.solve(a, b)
    try:
        mod._KL = mod._KU = 5
        np.testing.assert_allclose(mod._solve_small(a.tolist(), b.tolist()), want, rtol=1e-12)
        mod._KL = mod._KU = 1
        assert not np.allclose(mod._solve_small(a.tolist(), b.tolist()), want, rtol=1e-3)
    finally:
        mod._KL, mod._KU = (1, 1)


def test_numba_banded_solve_agrees_with_numpy(tmp_path):
    pytest.importorskip("llvmlite")
    n = 12
    scheme = mg.discretize(fpu_chain(n), "energy-momentum")
    _, np_mod = _module(scheme, tmp_path)
    ir, nb_mod = _module(scheme, tmp_path, backend="numba")
    assert nb_mod._KL == nb_mod._KU == 1
    rng = np.random.default_rng(2)
    y0 = np.concatenate([0.6 * rng.normal(size=n), rng.normal(size=n)])
    for solver in ("newton", "reuse"):
        a = nb_mod.integrate(y0, 0.1, 300, solver=solver)
        b = np_mod.integrate(y0, 0.1, 300, solver=solver)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
