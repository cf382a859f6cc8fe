"""One module for every N for a skew lattice (KdV, u' = S ∇H): the paired Newton solve against a
dense one, the steps against methodgen's AVF of the Poisson system written out at N, energy to
round-off over 10⁴ steps (the midpoint rule, the control, drifts), the compiled steps against the
numpy module's and against their own source run as Python (bitwise)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.codegen.lattice_emit import build_lattice, lattice_signature, render
from methodgen.problem.lattice import Lattice
from methodgen.symbolic.lattice_scheme import discretize_lattice

KDV = "Sum(L/N*(-u[i]**3 + (u[i % N + 1] - u[i])**2*N**2/(2*L**2)), i, 1, N)"
KDV_S = "(g[i+1] - g[i-1])*N**2/(2*L**2)"
L = 20.0


@pytest.fixture(scope="module")
def lat():
    return Lattice(KDV, fields=("u",), skew=KDV_S, params={"L": L}, name="kdv",
                   invariants={"mass": "Sum(L/N*u[i], i, 1, N)"})


@pytest.fixture(scope="module")
def avf(lat, tmp_path_factory):
    return build_lattice(lat, "avf", tmp_path_factory.mktemp("kdv") / "kdv_avf.py")


@pytest.fixture(scope="module")
def mid(lat, tmp_path_factory):
    return build_lattice(lat, "midpoint", tmp_path_factory.mktemp("kdv") / "kdv_mid.py")


@pytest.fixture(scope="module")
def compiled(lat, tmp_path_factory):
    pytest.importorskip("llvmlite")
    return build_lattice(lat, "avf", tmp_path_factory.mktemp("kdv") / "kdv_avf_c.py", backend="compiled")


def soliton(n, c=1.0, x0=L / 2):
    x = np.arange(n) * L / n
    return c / 2 / np.cosh(np.sqrt(c) / 2 * (x - x0)) ** 2


def rough(n, seed=0):
    return 0.5 + 0.3 * np.random.default_rng(seed).normal(size=n)


def _dense_newton(mod, lat, z, y0, h):
    """I - h S ∂∇̄H/∂z assembled densely in u from the module's derivative diagonals and the
    lattice's stencil matrix (no pairing, no rolls): the reference for the paired solve."""
    n = y0.size
    p = mod._params(None)
    _, D = mod._gradient(y0.reshape(1, n), z.reshape(1, n), n, p, True)
    dG = np.zeros((n, n))
    for d in (-1, 0, 1):
        for s in range(n):
            dG[s, (s + d) % n] += D[d + 1, 0, 0, s]
    S = np.array(lat.stencil_matrix(n).xreplace({sp.Symbol("L", real=True): L}), dtype=float)
    return np.eye(n) - h * S @ dG


@pytest.mark.parametrize("n", [5, 6, 7, 8, 10, 18, 63, 64])
def test_newton_solve_agrees_with_a_dense_solve(avf, lat, n):
    """The module's Newton matrix (pentadiagonal: site diagonals grouped two sites a block, the last
    group a border for odd N, solved by block cyclic reduction) against numpy's dense solve of
    I - h S ∂∇̄H assembled in u; negative control: a wrong corner entry (row 0 to the site N - 2,
    cyclically two to the left) gives another solution, which the comparison sees."""
    h = 2.0 * (L / n) ** 3           # h/dx³ of order 1: the matrix is far from I
    y0 = rough(n, n)
    z = y0 + 0.05 * np.cos(np.arange(n))
    dense = _dense_newton(avf, lat, z, y0, h)
    assert np.max(np.abs(avf.jacobian(z, y0, h) - dense)) < 1e-12 * np.max(np.abs(dense))
    assert np.max(np.abs(dense - np.eye(n))) > 0.5
    assert dense[0, n - 2] != 0.0 and dense[1, n - 1] != 0.0          # the pentadiagonal corners
    _, M = avf._residual(z.reshape(1, n), y0.reshape(1, n), h, n, avf._params(None), True)
    r = np.random.default_rng(n).normal(size=n)
    x = avf.newton_solve(avf.newton_factor(M), r.reshape(1, n)).reshape(n)
    xd = np.linalg.solve(dense, r)
    assert np.max(np.abs(x - xd)) < 1e-12 * max(1.0, np.max(np.abs(xd)))
    wrong = dense.copy()
    wrong[0, n - 2] += 0.5
    assert np.max(np.abs(x - np.linalg.solve(wrong, r))) > 1e-6


def test_residual_jacobian_against_finite_differences(avf):
    """Numerical check: the derivative the Newton matrix is built from, against central
    differences of residual()."""
    n, h = 10, 0.002
    y0 = rough(n, 3)
    z = y0 + 0.01 * np.cos(np.arange(n))
    J = avf.jacobian(z, y0, h)
    eps = 1e-6
    fd = np.empty_like(J)
    for k in range(n):
        dz = np.zeros(n)
        dz[k] = eps
        fd[:, k] = (avf.residual(z + dz, y0, h) - avf.residual(z - dz, y0, h)) / (2 * eps)
    assert np.max(np.abs(J - fd)) < 1e-6 * np.max(np.abs(J))


@pytest.mark.parametrize("n", [5, 6, 7, 10, 12, 32])
def test_compiled_bordered_elimination_solves_the_skew_matrix(n):
    """methodgen.runtime.lattice_stepper's newton/factor/solve in the skew mode (as Python) on a random
    tridiagonal ∂∇̄H, against numpy's dense solve of I - h (E - E⁻¹) ∂∇̄H; negative control: a
    wrong corner entry is seen."""
    from methodgen.runtime import lattice_stepper as ls
    from methodgen.runtime.lattice_driver import shape_constants, stepper_functions

    rng = np.random.default_rng(200 + n)
    h = 0.3
    Dd = {d: rng.normal(size=n) for d in (-1, 0, 1)}
    D = np.zeros((3, n))
    dG = np.zeros((n, n))
    for d, vals in Dd.items():
        D[d + 1] = vals
        for s in range(n):
            dG[s, (s + d) % n] += vals[s]
    S = np.zeros((n, n))
    for s in range(n):
        S[s, (s + 1) % n] += 1.0
        S[s, (s - 1) % n] -= 1.0
    dense = np.eye(n) - h * S @ dG
    rhs = rng.normal(size=n)
    st = stepper_functions(shape_constants(n, 1, 1, 1, skew=True))
    P = np.zeros((5, n))
    st.newton(D, P, n, h, np.array([-1.0, 0.0, 1.0]))
    F = np.zeros(ls.factor_size(n, 1, 2))
    W = np.zeros((ls.W_ROWS, n))
    W[ls._IR] = -rhs
    assert st.factor(P, F, n) == 0
    st.solve(W, F, n)
    x = W[ls._IR].copy()
    xd = np.linalg.solve(dense, rhs)
    assert np.max(np.abs(x - xd)) < 1e-10 * max(1.0, np.max(np.abs(xd)))
    dense[1, n - 1] += 0.5
    assert np.max(np.abs(x - np.linalg.solve(dense, rhs))) > 1e-6


@pytest.mark.parametrize("n", [6, 10])
def test_one_module_is_the_written_out_poisson_systems_avf_at_two_sizes(avf, lat, n, tmp_path):
    """The module (one file, built once for the whole test module) at N = 6 and N = 10 against
    methodgen's AVF module of the Poisson system u' = S ∇H written out at that N (H expanded, S
    the dense stencil matrix; another derivation, another runtime): the same steps to round-off
    (1e-13 on |u| ≤ 2)."""
    H, us, _ = lat.expand(n)
    S = lat.stencil_matrix(n)
    system = mg.PoissonSystem(H, y=[u.name for u in us], S=[[S[i, j] for j in range(n)] for i in range(n)],
                              params={"L": L}, name=f"kdv_written_out_{n}")
    ref = mg.build(system, "avf", path=tmp_path / f"ref{n}.py")
    y0 = rough(n, n)
    h = 0.002
    a = avf.integrate(y0, h, 6, check_resolution=False)
    b = np.asarray(ref.integrate(y0, h, 6))
    assert a.shape == b.shape == (7, n)
    assert np.max(np.abs(a - y0)) > 1e-3                     # (they moved)
    assert np.max(np.abs(a - b)) < 1e-13
    assert abs(avf.hamiltonian(y0) - ref.hamiltonian(y0)) < 1e-13


def test_energy_and_mass_over_ten_thousand_steps(compiled, lat, tmp_path):
    """KdV at N = 64, one soliton, 10⁴ steps: AVF keeps H and the mass to round-off (relative
    1e-13); the control, the midpoint rule (compiled, same steps), keeps the mass but not H."""
    n, h = 64, 0.01
    y0 = soliton(n)
    tr = compiled.integrate(y0, h, 10_000, save_every=50)
    I = [compiled.invariants(r) for r in tr]
    H = np.array([v["H"] for v in I])
    mass = np.array([v["mass"] for v in I])
    assert np.max(np.abs(H - H[0])) < 1e-13 * abs(H[0])
    assert np.max(np.abs(mass - mass[0])) < 1e-13 * abs(mass[0])
    mid = build_lattice(lat, "midpoint", tmp_path / "mid_c.py", backend="compiled")
    trm = mid.integrate(y0, h, 10_000, save_every=50)
    Hm = np.array([mid.hamiltonian(r) for r in trm])
    Mm = np.array([mid.invariants(r)["mass"] for r in trm])
    assert np.max(np.abs(Hm - Hm[0])) > 1e-9 * abs(Hm[0])
    assert np.max(np.abs(Mm - Mm[0])) < 1e-13 * abs(Mm[0])
    assert np.max(np.abs(trm[-1] - tr[-1])) < 0.05               # the same motion, to the methods' error


def test_numpy_module_keeps_energy_and_midpoint_does_not(avf, mid):
    y0 = soliton(32)
    a, b = avf.solve(y0, (0, 2.0), 0.01), mid.solve(y0, (0, 2.0), 0.01)
    assert a.success and b.success
    H0 = abs(avf.hamiltonian(y0))
    assert a.invariant_errors["H"] < 1e-13 * H0 and b.invariant_errors["H"] > 1e-9 * H0
    assert max(a.invariant_errors["mass"], b.invariant_errors["mass"]) < 1e-13


def test_order_two_and_the_soliton_moves_at_its_speed(avf):
    """Numerical: the error at T = 1 against DOP853 on the semi-discrete system falls by 4 when h
    halves; and the soliton of speed c = 1 has moved by about 1 at T = 1.  (At N = 32, h/dx³ ≤ 0.2:
    the asymptotic regime for every mode; at N = 64 and h = 0.02 the highest modes have h ω ≈ 3
    and the ratio is 2.3 -- a stiff dispersion stepped over, not an error of the method.)"""
    from scipy.integrate import solve_ivp

    n = 32
    dx = L / n
    y0 = soliton(n)

    def f(t, u):
        D = lambda v: (np.roll(v, -1) - np.roll(v, 1)) / (2 * dx)  # noqa: E731
        D3 = (np.roll(u, -2) - 2 * np.roll(u, -1) + 2 * np.roll(u, 1) - np.roll(u, 2)) / (2 * dx**3)
        return -3 * D(u * u) - D3

    ref = solve_ivp(f, (0, 1), y0, method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
    errs = [np.max(np.abs(avf.integrate(y0, 1 / k, k)[-1] - ref)) for k in (50, 100)]
    assert 3.6 < errs[0] / errs[1] < 4.4
    x = np.arange(n) * dx
    moved = x[np.argmax(ref)] - x[np.argmax(y0)]
    assert abs(moved - 1.0) < 2 * dx


def test_bad_input_names_what_is_valid(avf):
    with pytest.raises(ValueError, match="N ≥ 5"):
        avf.integrate(np.zeros(4), 0.1, 1)
    with pytest.raises(ValueError, match="N ≥ 5"):
        avf.integrate(np.zeros((2, 6)), 0.1, 1)
    with pytest.raises(KeyError, match="parameters are"):
        avf.integrate(soliton(8), 0.1, 1, params={"c": 1.0})


def test_nonconvergence_raises_with_step_and_residual(avf, compiled):
    y0 = 3 * soliton(16, c=4.0)
    for mod in (avf, compiled):
        with pytest.raises(mod.ConvergenceError) as info:
            mod.integrate(y0, 5.0, 3, maxiter=3, check_resolution=False)
        assert info.value.step == 0 and "step 0" in str(info.value)


def test_module_is_deterministic_and_imports_numpy_only(lat):
    sig = lattice_signature(lat, "avf")
    a = render(discretize_lattice(lat, "avf"), sig)
    assert a == render(discretize_lattice(lat, "avf"), sig)
    body = a.split('"""', 2)[2]
    imports = {ln.split()[1] for ln in body.splitlines() if ln.startswith(("import ", "from "))}
    assert imports == {"math", "numpy"}
    assert "STRUCTURE = 'skew'" in a and "def _skew_coefficients(n, p):" in a


# --- the compiled backend ---------------------------------------------------------------------

@pytest.mark.parametrize("solver", ["newton", "simplified"])
@pytest.mark.parametrize("n", [5, 6, 7, 8, 64])
def test_compiled_steps_are_the_numpy_modules(avf, compiled, n, solver):
    y0 = soliton(n) + 0.05 * np.sin(np.arange(n))
    ia, ic = {}, {}
    ra = avf.integrate(y0, 0.01, 25, save_every=4, solver=solver, info=ia, check_resolution=False)
    rc = compiled.integrate(y0, 0.01, 25, save_every=4, solver=solver, info=ic, check_resolution=False)
    assert ra.shape == rc.shape == (8, n)
    assert np.max(np.abs(ra - rc)) < 1e-13
    assert np.max(np.abs(ia["newton_iterations"] - ic["newton_iterations"])) <= 1


def test_compiled_loop_is_its_python_source_bitwise(compiled):
    """The skew step loop compiled and the same source run as Python: the same bits."""
    from methodgen.runtime.lattice_driver import run_steps

    n = 13
    out = []
    c = compiled._skew_coefficients(n, compiled._params(None))
    for python in (False, True):
        Y = soliton(n).reshape(1, n).copy()
        T, its, st = run_steps(compiled._grad_sites, Y, 0.01, 5, 1, np.array([L]), 50, 4 * 2.2e-16,
                               True, True, 1.0, python=python, jac_half_width=1, stencil=c)
        out.append((T, its, st))
    assert out[0][2] == (0, 0, 0, 0.0, 0)
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])
    assert np.max(np.abs(out[0][0][-1] - out[0][0][0])) > 1e-4          # (it moved)


@pytest.mark.parametrize("text,skew", [
    # a left neighbour, a site-only term, a constant; the stencil written with periodic indices
    ("Sum(u[i]**4/4 + a*u[i]*u[(i - 2) % N + 1], i, 1, N) + Sum(a, i, 1, N) + 2",
     "a*(g[i % N + 1] - g[(i - 2) % N + 1])"),
    # the right neighbour, a non-polynomial term (a divided difference), N in the stencil
    ("Sum((u[i % N + 1] - u[i])**2/8 + cos(u[i]), i, 1, N)", "N*(g[i+1] - g[i-1])/a"),
])
@pytest.mark.parametrize("method", ["avf", "midpoint"])
@pytest.mark.parametrize("backend", ["numpy", "compiled"])
def test_every_term_form_against_the_written_out_lattice(text, skew, method, backend, tmp_path):
    """Both backends, both methods, terms with each neighbour: the step equations at z = y0 are
    -h S ∇H(y0) of the lattice written out at N = 8 and differentiated by SymPy; the compiled
    steps are the numpy module's; AVF keeps H."""
    if backend == "compiled":
        pytest.importorskip("llvmlite")
    lat = Lattice(text, fields=("u",), skew=skew, params={"a": 0.7}, name="forms")
    mod = build_lattice(lat, method, tmp_path / "m.py", backend=backend)
    n, h = 8, 0.05
    H, us, _ = lat.expand(n)
    vals = {sp.Symbol("a", real=True): 0.7}
    S = np.array(lat.stencil_matrix(n).xreplace(vals), dtype=float)
    f = sp.lambdify(us, [H.xreplace(vals)] + [sp.diff(H, u).xreplace(vals) for u in us])
    y0 = np.sin(np.arange(n) * 1.3) + 0.2
    out = np.array(f(*y0), dtype=float)
    assert abs(mod.hamiltonian(y0) - out[0]) < 1e-13 * max(1.0, abs(out[0]))
    assert np.max(np.abs(mod.residual(y0, y0, h) + h * S @ out[1:])) < 1e-13
    rows = mod.integrate(y0, h, 4, check_resolution=False)
    if backend == "compiled":
        ref = build_lattice(lat, method, tmp_path / "ref.py").integrate(y0, h, 4, check_resolution=False)
        assert np.max(np.abs(rows - ref)) < 1e-13
    if method == "avf":
        Hs = np.array([mod.hamiltonian(r) for r in rows])
        assert np.max(np.abs(Hs - Hs[0])) < 1e-13 * max(1.0, abs(Hs[0]))
