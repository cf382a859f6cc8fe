"""The 2-D lattice modules' three step solvers (``integrate(..., solver=...)``): the exact Newton
matrix against a finite-difference Jacobian of the residual (a wrong entry across the periodic
seam is caught), the three solvers' steps agree to round-off on both backends (a loosely converged
step is seen), Newton and Newton–Krylov take far fewer iterations where the nonlinearity is strong
and keep H to round-off (the midpoint rule, the control, does not), and failures say what failed."""

from __future__ import annotations

import numpy as np
import pytest

from methodgen.codegen.lattice_emit import build_lattice
from methodgen.problem.lattice import Lattice

KG = ("Sum(Sum(p[i, j]**2/2 + (q[i % N + 1, j] - q[i, j])**2*N**2/(2*L**2)"
      " + (q[i, j % M + 1] - q[i, j])**2*M**2/(2*L**2) + m**2*q[i, j]**2/2 + lam*q[i, j]**4/4, j, 1, M), i, 1, N)")
PARAMS = {"L": 4.0, "m": 1.0, "lam": 1.0}
SOLVERS = ("simplified", "newton", "krylov")


@pytest.fixture(scope="module")
def lattice():
    return Lattice(KG, size=("N", "M"), params=PARAMS, name="kg2s")


@pytest.fixture(scope="module")
def mods(lattice, tmp_path_factory):
    d = tmp_path_factory.mktemp("lat2s")
    return {b: build_lattice(lattice, "avf", d / f"kg_{b}.py", backend=b) for b in ("numpy", "compiled")}


def bump(n, m, amp, seed=None):
    """A Gaussian bump of peak ``amp`` off the grid's centre, and a little momentum."""
    x, y = np.meshgrid(np.arange(n) / n, np.arange(m) / m, indexing="ij")
    q = amp * np.exp(-((x - 0.5) ** 2 + (y - 0.4) ** 2) / 0.08)
    p = 0.3 * np.cos(2 * np.pi * y) + 0.2 * np.sin(2 * np.pi * x)
    out = np.stack([q, p])
    if seed is not None:
        out = out + 0.1 * np.random.default_rng(seed).normal(size=out.shape)
    return out


def fd_jacobian(mod, z, y0, h, eps=1e-5):
    """∂ residual/∂z by central differences, dense (2nm, 2nm).  The residual is cubic in z (a quartic
    H), so the error is eps²/6 times its third derivative: about 1e-10 here."""
    J = np.zeros((z.size, z.size))
    for k in range(z.size):
        d = np.zeros(z.size)
        d[k] = eps
        d = d.reshape(z.shape)
        J[:, k] = (mod.residual(z + d, y0, h) - mod.residual(z - d, y0, h)).reshape(-1) / (2 * eps)
    return J


@pytest.mark.parametrize("n,m", [(3, 3), (4, 3), (5, 4)])
def test_the_sparse_newton_matrix_is_the_residuals_jacobian_and_a_wrong_seam_entry_is_caught(mods, n, m):
    mod = mods["numpy"]
    y0, z = bump(n, m, 2.0, seed=n), bump(n, m, 2.5, seed=n + m)
    h = 0.1
    A = mod.newton_matrix(z, y0, h)
    assert A.format == "csc" and A.shape == (2 * n * m, 2 * n * m)
    J = fd_jacobian(mod, z, y0, h)
    dense = A.toarray()
    assert np.max(np.abs(dense - J)) < 1e-8 * np.max(np.abs(J))
    # negative control: the p-equation of the corner site (0, 0) couples to q at (n - 1, 0) and at
    # (0, m - 1) only across the periodic seam; drop one of those entries and the comparison sees it
    k = n * m
    for col in ((n - 1) * m, m - 1):
        row = k + 0                                    # R_1 (the p-equation) at the site (0, 0)
        assert dense[row, col] != 0.0
        wrong = dense.copy()
        wrong[row, col] = 0.0
        assert np.max(np.abs(wrong - J)) > 1e3 * 1e-8 * np.max(np.abs(J))
    # the matrix-free product used by solver="krylov" is the same matrix
    v = np.random.default_rng(0).normal(size=z.shape)
    S = mod._site_jacobian(y0, z, n, m, mod._params(None))
    assert np.max(np.abs(mod._jvp(S, v, h, n, m).reshape(-1) - dense @ v.reshape(-1))) < 1e-13 * np.max(np.abs(dense))


@pytest.mark.parametrize("backend", ["numpy", "compiled"])
def test_the_three_solvers_give_the_same_steps_and_a_loose_tolerance_is_seen(mods, backend):
    mod = mods[backend]
    y0 = bump(5, 4, 3.0, seed=1)
    runs = {s: mod.integrate(y0, 0.05, 8, solver=s, check_resolution=False) for s in SOLVERS}
    scale = np.max(np.abs(runs["simplified"]))
    for s in ("newton", "krylov"):
        assert np.max(np.abs(runs[s] - runs["simplified"])) <= 1e-13 * scale, s
    # negative control: a step converged to 1e-6 only (the same solver) is not the same step
    loose = mod.integrate(y0, 0.05, 8, solver="simplified", tol=1e-6, check_resolution=False)
    assert np.max(np.abs(loose - runs["simplified"])) > 1e-11 * scale


def test_the_backends_agree_for_each_solver(mods):
    y0 = bump(4, 5, 3.0, seed=2)
    for s in SOLVERS:
        a = mods["numpy"].integrate(y0, 0.05, 5, solver=s, check_resolution=False)
        b = mods["compiled"].integrate(y0, 0.05, 5, solver=s, check_resolution=False)
        assert np.max(np.abs(a - b)) <= 1e-13 * np.max(np.abs(a)), s


def test_exact_jacobians_take_far_fewer_iterations_where_the_nonlinearity_is_strong_and_keep_energy(
        mods, lattice, tmp_path):
    """Amplitude 10, h = 0.1 at 6 × 6 (h·ω ≈ 1.7 at the peak): simplified Newton contracts slowly
    (the nonlinear term's Jacobian is missing from its matrix).  Newton–Krylov takes at most a
    quarter of its iterations, Newton (its matrix factored once per step, at the predictor) at
    most 0.6 (measured: 28.9, 5.1, 14.2 a step); each keeps H to round-off over 200 steps."""
    mod = mods["numpy"]
    y0 = bump(6, 6, 10.0)
    H0 = mod.hamiltonian(y0)
    its, drift = {}, {}
    for s in SOLVERS:
        info = {}
        rows = mod.integrate(y0, 0.1, 200, solver=s, info=info, save_every=10, check_resolution=False)
        its[s] = info["newton_iterations"].mean()
        drift[s] = max(abs(mod.hamiltonian(r) - H0) for r in rows) / abs(H0)
    assert its["simplified"] > 20
    assert its["krylov"] <= 0.25 * its["simplified"]
    assert its["newton"] <= 0.6 * its["simplified"]
    for s in SOLVERS:
        assert drift[s] < 5e-14, (s, drift[s])
    # control: the midpoint rule (the same solver, another method) does not keep H at this setting
    mid = build_lattice(lattice, "midpoint", tmp_path / "mid.py")
    rows = mid.integrate(y0, 0.1, 100, solver="krylov", save_every=10, check_resolution=False)
    assert max(abs(mid.hamiltonian(r) - H0) for r in rows) / abs(H0) > 1e-6


def test_where_simplified_newton_fails_newton_and_krylov_converge(mods):
    """Amplitude 14, h = 0.15: the simplified iteration diverges (contraction above 1) within 10
    steps, even with 400 iterations allowed; Newton and Newton–Krylov converge, to the same steps."""
    mod = mods["numpy"]
    y0 = bump(6, 6, 14.0)
    with np.errstate(all="ignore"), pytest.raises((mod.ConvergenceError, mod.NonFiniteError)):
        mod.integrate(y0, 0.15, 10, solver="simplified", maxiter=400, check_resolution=False)
    a = mod.integrate(y0, 0.15, 10, solver="newton", maxiter=400, check_resolution=False)
    b = mod.integrate(y0, 0.15, 10, solver="krylov", maxiter=400, check_resolution=False)
    assert np.max(np.abs(a - b)) <= 1e-13 * np.max(np.abs(a))


@pytest.mark.parametrize("solver", SOLVERS)
def test_a_solver_that_cannot_converge_raises_with_the_step_and_the_residual(mods, solver):
    mod = mods["numpy"]
    y0 = bump(5, 5, 10.0)
    with pytest.raises(mod.ConvergenceError) as exc:
        mod.integrate(y0, 0.1, 3, solver=solver, maxiter=1, check_resolution=False)
    e = exc.value
    assert e.step == 0 and e.residual > 0 and "step 0" in str(e) and "max |residual|" in str(e)
    assert "did not converge in 1 iterations" in str(e)
    assert e.trajectory.shape == (1, 2, 5, 5)
    # control: the same setting with room to converge does
    assert mod.integrate(y0, 0.1, 3, solver=solver, check_resolution=False).shape == (4, 2, 5, 5)


def test_an_unknown_solver_is_refused_naming_the_valid_ones(mods):
    mod = mods["numpy"]
    with pytest.raises(ValueError, match="'simplified', 'newton', 'krylov'"):
        mod.integrate(bump(3, 3, 1.0), 0.1, 1, solver="gauss-seidel")
    assert tuple(mod.SOLVERS) == SOLVERS


def test_scipy_is_imported_lazily(mods):
    """The numpy module's text imports numpy and math at the top; scipy only inside the solvers."""
    text = open(mods["numpy"].__file__).read()
    top = {ln.split()[1] for ln in text.splitlines() if ln.startswith(("import ", "from "))}
    assert top == {"math", "numpy"}
    assert "        import scipy.sparse.linalg" in text
