"""Lattices with wider stencils: a fourth-order sine-Gordon (terms two sites wide, canonical) and a
fourth-order KdV (a skew stencil of half-width 2 with terms two sites wide: the Newton matrix
couples sites 4 apart).  One module for every N against methodgen's AVF module of the system
written out at small N (odd N too), the module's grouped Newton solve against a dense one, energy
to round-off over thousands of steps (the midpoint rule, the control, drifts), the compiled step
loop against its own source run as Python (bitwise)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.codegen.lattice_emit import build_lattice
from methodgen.problem.lattice import Lattice

# ∇H_i = -(-q_(i+2) + 16 q_(i+1) - 30 q_i + 16 q_(i-1) - q_(i-2)) N²/(12 L²) + sin q_i: the fourth-order Laplacian
SG4 = ("Sum(p[i]**2/2, i, 1, N) + Sum((16*(q[i % N + 1] - q[i])**2 - (q[(i + 1) % N + 1] - q[i])**2)*N**2/(24*L**2),"
       " i, 1, N) + Sum(1 - cos(q[i]), i, 1, N)")
# a non-periodic chain with second neighbours (fixed ends): the range forms of half-width 1, wider
CHAIN2 = ("Sum(p[i]**2/2, i, 1, N) + Sum((q[i+1] - q[i])**2/2 + (q[i+1] - q[i])**4/4, i, 1, N - 1)"
          " + Sum(a*(q[i+2] - q[i])**2/2, i, 1, N - 2) + q[1]**2/2 + q[N]**2/2")
KDV4 = ("Sum(L/N*(-u[i]**3 + (16*(u[i % N + 1] - u[i])**2 - (u[(i + 1) % N + 1] - u[i])**2)*N**2/(24*L**2)),"
        " i, 1, N)")
KDV4_S = "(-g[i+2] + 8*g[i+1] - 8*g[i-1] + g[i-2])*N**2/(12*L**2)"
L = 20.0


@pytest.fixture(scope="module")
def sg4_lattice():
    return Lattice(SG4, params={"L": 2 * np.pi}, name="sg4")


@pytest.fixture(scope="module")
def sg4(sg4_lattice, tmp_path_factory):
    return build_lattice(sg4_lattice, "avf", tmp_path_factory.mktemp("wide") / "sg4_avf.py")


@pytest.fixture(scope="module")
def kdv4_lattice():
    return Lattice(KDV4, fields=("u",), skew=KDV4_S, params={"L": L}, name="kdv4",
                   invariants={"mass": "Sum(L/N*u[i], i, 1, N)"})


@pytest.fixture(scope="module")
def kdv4(kdv4_lattice, tmp_path_factory):
    return build_lattice(kdv4_lattice, "avf", tmp_path_factory.mktemp("wide") / "kdv4_avf.py")


def sg_state(n, amp=2.0):
    x = np.arange(n) * 2 * np.pi / n
    return np.concatenate([amp * np.sin(x), 0.5 * np.cos(x)])


def soliton(n, c=1.0, x0=L / 2):
    x = np.arange(n) * L / n
    return c / 2 / np.cosh(np.sqrt(c) / 2 * (x - x0)) ** 2


def test_the_lattices_widths_and_minimum_sizes(sg4_lattice, kdv4_lattice):
    assert (sg4_lattice.jacobian_half_width, sg4_lattice.half_width, sg4_lattice.nmin) == (2, 2, 5)
    assert (kdv4_lattice.jacobian_half_width, kdv4_lattice.half_width, kdv4_lattice.nmin) == (2, 4, 9)
    assert kdv4_lattice.stencil[2] == -kdv4_lattice.stencil[-2] and 0 not in kdv4_lattice.stencil


@pytest.mark.parametrize("text,params,n", [(SG4, {"L": 2 * np.pi}, 5),
                                           pytest.param(SG4, {"L": 2 * np.pi}, 8, marks=pytest.mark.slow),
                                           (CHAIN2, {"a": 0.4}, 5),
                                           pytest.param(CHAIN2, {"a": 0.4}, 8, marks=pytest.mark.slow)])
def test_a_step_is_the_expanded_systems_avf_step(text, params, n, tmp_path):
    """The lattice module at N = n (the minimum, odd, not divisible by the group of 2 sites) against
    methodgen's AVF module of H written out at n (another derivation, another runtime): the same
    steps to round-off, on both backends."""
    lat = Lattice(text, params=params, name="lat")
    H, qs, ps = lat.expand(n)
    system = mg.Hamiltonian(H, qs, ps, params={k: v for k, v in params.items() if sp.Symbol(k, real=True)
                                               in H.free_symbols}, name=f"expanded{n}")
    ref = mg.build(system, "avf", path=tmp_path / "ref.py")
    y0 = np.r_[np.sin(np.arange(1, n + 1) * 1.3), 0.3 * np.cos(np.arange(1, n + 1))]
    b = ref.integrate(y0, 0.05, 5)
    for backend in ("numpy", "compiled"):
        if backend == "compiled":
            pytest.importorskip("llvmlite")
        mod = build_lattice(lat, "avf", tmp_path / f"lat_{backend}.py", backend=backend)
        a = mod.integrate(y0, 0.05, 5)
        assert np.max(np.abs(a - y0)) > 1e-3                                # (it moved)
        assert np.max(np.abs(a - b)) < 1e-13
        assert abs(mod.hamiltonian(y0) - ref.hamiltonian(y0)) < 1e-13


@pytest.mark.parametrize("n", [9, pytest.param(10, marks=pytest.mark.slow), pytest.param(11, marks=pytest.mark.slow)])
def test_the_skew_module_is_the_written_out_poisson_systems_avf(kdv4, kdv4_lattice, n, tmp_path):
    """kdv4 at N = 9 (the minimum: 2 groups, one of 5 sites), 10, 11 against methodgen's AVF module
    of u' = S ∇H written out (H expanded, S the dense stencil matrix): the same steps to round-off."""
    H, us, _ = kdv4_lattice.expand(n)
    S = kdv4_lattice.stencil_matrix(n)
    system = mg.PoissonSystem(H, y=[u.name for u in us], S=[[S[i, j] for j in range(n)] for i in range(n)],
                              params={"L": L}, name=f"kdv4_written_out_{n}")
    ref = mg.build(system, "avf", path=tmp_path / f"ref{n}.py")
    y0 = 0.5 + 0.3 * np.random.default_rng(n).normal(size=n)
    a = kdv4.integrate(y0, 0.002, 6, check_resolution=False)
    b = np.asarray(ref.integrate(y0, 0.002, 6))
    assert np.max(np.abs(a - y0)) > 1e-3
    assert np.max(np.abs(a - b)) < 1e-12 * max(1.0, np.max(np.abs(b)))


def _dense_newton(mod, lat, z, y0, h):
    """I - h K ∂∇̄H/∂z assembled densely (site-major) from the module's derivative diagonals and the
    structure written out (J, or the lattice's stencil matrix), with no grouping: the reference."""
    nf = len(lat.fields)
    n = y0.size // nf
    _, D = mod._gradient(y0.reshape(nf, n), z.reshape(nf, n), n, mod._params(None), True)
    wh = (D.shape[0] - 1) // 2
    dG = np.zeros((nf * n, nf * n))
    for e in range(-wh, wh + 1):
        for s in range(n):
            t = (s + e) % n
            dG[nf * s:nf * s + nf, nf * t:nf * t + nf] += D[e + wh, :, :, s]
    if nf == 1:
        K = np.array(lat.stencil_matrix(n).xreplace({sp.Symbol("L", real=True): L}), dtype=float)
    else:
        K = np.kron(np.eye(n), np.array([[0.0, 1.0], [-1.0, 0.0]]))
    return np.eye(nf * n) - h * K @ dG


@pytest.mark.parametrize("which,n", [("sg4", 5), ("sg4", 6), ("sg4", 9), ("sg4", 64),
                                     ("kdv4", 9), ("kdv4", 10), ("kdv4", 12), ("kdv4", 13), ("kdv4", 67)])
def test_the_modules_newton_solve_agrees_with_a_dense_solve(which, n, request):
    """The numpy module's Newton matrix (site diagonals grouped GROUP sites a block, the last group a
    border where GROUP does not divide N) against the dense matrix assembled without grouping, and its
    solve against numpy's dense solve; negative controls: a wrong corner entry (the wrap) and a wrong
    entry at the band's edge give other solutions, which the comparison sees."""
    mod = request.getfixturevalue(which)
    lat = request.getfixturevalue(f"{which}_lattice")
    nf = len(lat.fields)
    rng = np.random.default_rng(n)
    y0 = (sg_state(n) if nf == 2 else 0.5 + 0.3 * rng.normal(size=n))
    z = y0 + 0.05 * np.cos(np.arange(nf * n))
    h = 0.3 if nf == 2 else 2.0 * (L / n) ** 3          # far from I
    dense = _dense_newton(mod, lat, z, y0, h)
    assert np.max(np.abs(dense - np.eye(nf * n))) > 0.3
    _, P = mod._residual(z.reshape(nf, n), y0.reshape(nf, n), h, n, mod._params(None), True)
    assert np.max(np.abs(mod._dense_sites(P) - dense)) < 1e-12 * np.max(np.abs(dense))
    r = rng.normal(size=(nf, n))
    x = mod.newton_solve(mod.newton_factor(P), r)
    xd = np.linalg.solve(dense, r.T.reshape(-1)).reshape(n, nf).T
    assert np.max(np.abs(x - xd)) < 1e-11 * max(1.0, np.max(np.abs(xd)))
    w = lat.half_width
    # (row p_0 or u_0 to the site n - w, cyclically w to the left; a row to the site w to the right)
    for i, j in ((nf - 1, nf * (n - w)), (nf * (n // 2) + nf - 1, nf * (n // 2 + w))):
        assert dense[i, j] != 0.0
        wrong = dense.copy()
        wrong[i, j] += 0.5
        xw = np.linalg.solve(wrong, r.T.reshape(-1)).reshape(n, nf).T
        assert np.max(np.abs(x - xw)) > 1e-6


def test_energy_over_thousands_of_steps_and_the_midpoint_control_drifts(sg4_lattice, sg4, tmp_path):
    mid = build_lattice(sg4_lattice, "midpoint", tmp_path / "sg4_mid.py")
    n = 17
    y0 = sg_state(n)
    rows = sg4.integrate(y0, 0.05, 2000, save_every=100)
    H = np.array([sg4.hamiltonian(r) for r in rows])
    assert np.max(np.abs(H - H[0])) < 1e-13 * abs(H[0])
    rows = mid.integrate(y0, 0.05, 2000, save_every=100)
    Hm = np.array([sg4.hamiltonian(r) for r in rows])
    assert np.max(np.abs(Hm - Hm[0])) > 1e-6 * abs(Hm[0])


def test_skew_energy_and_mass_over_thousands_of_steps(kdv4_lattice, kdv4, tmp_path):
    mid = build_lattice(kdv4_lattice, "midpoint", tmp_path / "kdv4_mid.py")
    n = 19
    y0 = soliton(n, 1.0) + 0.3 * soliton(n, 0.5, 3.0)
    for mod, keeps_h in ((kdv4, True), (mid, False)):
        rows = mod.integrate(y0, 0.02, 2000, save_every=50)
        H = np.array([kdv4.hamiltonian(r) for r in rows])
        mass = np.array([kdv4.invariants(r)["mass"] for r in rows])
        assert np.max(np.abs(mass - mass[0])) < 1e-13 * abs(mass[0])
        if keeps_h:
            assert np.max(np.abs(H - H[0])) < 1e-13 * max(1.0, abs(H[0]))
        else:
            assert np.max(np.abs(H - H[0])) > 1e-8 * max(1.0, abs(H[0]))


@pytest.mark.parametrize("which,n", [("sg4", 9), ("kdv4", 11), ("kdv4", 12)])
def test_compiled_loop_is_its_python_source_bitwise_and_the_numpy_modules_step(which, n, request, tmp_path):
    """The wide stencils' step loop compiled and the same source run as Python: the same bits; and
    the compiled module's steps are the numpy module's to round-off."""
    pytest.importorskip("llvmlite")
    from methodgen.runtime.lattice_driver import run_steps

    lat = request.getfixturevalue(f"{which}_lattice")
    ref = request.getfixturevalue(which)
    mod = build_lattice(lat, "avf", tmp_path / f"{which}_c.py", backend="compiled")
    nf = len(lat.fields)
    y0 = sg_state(n) if nf == 2 else soliton(n)
    p = mod._params(None)
    stencil = mod._skew_coefficients(n, p) if nf == 1 else None
    out = []
    for python in (False, True):
        Y = y0.reshape(nf, n).copy()
        out.append(run_steps(mod._grad_sites, Y, 0.01, 5, 1, np.array(p), 50, 4 * 2.2e-16, True, False, 1.0,
                             python=python, jac_half_width=mod.JAC_HALF_WIDTH, stencil=stencil))
    assert out[0][2] == (0, 0, 0, 0.0, 0)
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
    assert np.max(np.abs(out[0][0][-1] - out[0][0][0])) > 1e-4                 # (it moved)
    a = mod.integrate(y0, 0.01, 5, solver="newton")
    assert np.max(np.abs(a - ref.integrate(y0, 0.01, 5, solver="newton"))) < 1e-13


def test_failures_raise_the_modules_errors_with_step_and_residual(kdv4, kdv4_lattice, tmp_path):
    pytest.importorskip("llvmlite")
    compiled = build_lattice(kdv4_lattice, "avf", tmp_path / "kdv4_c.py", backend="compiled")
    y0 = 3 * soliton(13, c=4.0)
    for mod in (kdv4, compiled):
        with pytest.raises(mod.ConvergenceError) as info:
            mod.integrate(y0, 5.0, 3, maxiter=3, check_resolution=False)
        assert info.value.step == 0 and "step 0" in str(info.value) and info.value.residual > 0
        with pytest.raises(ValueError, match="N ≥ 9"):
            mod.integrate(np.zeros(8), 0.01, 1)
