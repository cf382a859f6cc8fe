"""One lattice module for every N: the same steps as the system expanded at that N, the
block-cyclic Newton solve against a dense one, energy to round-off, errors that say what failed."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.problem.lattice import Lattice
from methodgen.codegen.lattice_emit import build_lattice, lattice_signature, render
from methodgen.symbolic.lattice_scheme import certificates, discretize_lattice

SG = ("Sum(p[i]**2/2, i, 1, N) + Sum((q[i % N + 1] - q[i])**2*N**2/(2*L**2), i, 1, N) "
      "+ Sum(1 - cos(q[i]), i, 1, N)")
FPU = ("Sum(p[i]**2/2, i, 1, N) + Sum((q[i+1] - q[i])**2/2 + beta*(q[i+1] - q[i])**4/4, i, 1, N - 1)"
       " + q[1]**2/2 + q[N]**2/2")


@pytest.fixture(scope="module")
def sg_lattice():
    return Lattice(SG, params={"L": 2 * np.pi}, name="sine-gordon")


@pytest.fixture(scope="module")
def sg(sg_lattice, tmp_path_factory):
    return build_lattice(sg_lattice, "avf", tmp_path_factory.mktemp("lat") / "sg_avf.py")


@pytest.fixture(scope="module")
def sg_mid(sg_lattice, tmp_path_factory):
    return build_lattice(sg_lattice, "midpoint", tmp_path_factory.mktemp("lat") / "sg_mid.py")


def sg_state(n, amp=2.0):
    x = np.arange(n) * 2 * np.pi / n
    return np.concatenate([amp * np.sin(x), 0.5 * np.cos(x)])


@pytest.mark.parametrize("text,params,n,y0", [
    (SG, {"L": 2 * np.pi}, 7, sg_state(7)),
    (FPU, {"beta": 0.7}, 4, np.r_[np.sin(np.arange(1, 5)), 0.3 * np.cos(np.arange(1, 5))]),
])
def test_a_step_is_the_expanded_systems_avf_step(text, params, n, y0, tmp_path):
    """The lattice module at N = n against methodgen's AVF module of H written out at n
    (another derivation, another runtime): the same step to round-off."""
    lat = Lattice(text, params=params, name="lat")
    mod = build_lattice(lat, "avf", tmp_path / "lat.py")
    H, qs, ps = lat.expand(n)
    system = mg.Hamiltonian(H, qs, ps, params={k: v for k, v in params.items() if sp.Symbol(k, real=True)
                                               in H.free_symbols}, name=f"expanded{n}")
    ref = mg.build(system, "avf", path=tmp_path / "ref.py")
    h = 0.05
    a = mod.integrate(y0, h, 5)
    b = ref.integrate(y0, h, 5)
    assert np.max(np.abs(a - b)) < 1e-13
    assert abs(mod.hamiltonian(y0) - ref.hamiltonian(y0)) < 1e-13


def test_residual_jacobian_against_finite_differences(sg):
    """Numerical check: the analytic Newton matrix against central differences of residual()."""
    n, h = 9, 0.1
    y0 = sg_state(n)
    z = y0 + 0.01 * np.cos(np.arange(2 * n))
    J = sg.jacobian(z, y0, h)
    eps = 1e-6
    fd = np.empty_like(J)
    for k in range(2 * n):
        dz = np.zeros(2 * n)
        dz[k] = eps
        fd[:, k] = (sg.residual(z + dz, y0, h) - sg.residual(z - dz, y0, h)) / (2 * eps)
    assert np.max(np.abs(J - fd)) < 1e-7
    assert np.max(np.abs(J - np.eye(2 * n))) > 0.1       # not trivially the identity


def _blocks(rng, n, periodic=True):
    blk = lambda s: tuple(rng.normal(size=n) * s for _ in range(4))  # noqa: E731
    A, C = blk(0.2), blk(0.2)
    B = blk(0.2)
    B = (B[0] + 1.0, B[1], B[2], B[3] + 1.0)
    if not periodic:
        for k in range(4):
            A[k][0] = 0.0
            C[k][-1] = 0.0
    return A, B, C


@pytest.mark.parametrize("n", [3, 8, 9, 10, 11, 17, 31, 64, 100, 257])
@pytest.mark.parametrize("periodic", [True, False])
def test_block_cyclic_solve_agrees_with_a_dense_solve(sg, n, periodic):
    rng = np.random.default_rng(n)
    A, B, C = _blocks(rng, n, periodic)
    r = rng.normal(size=(n, 2))
    x = sg.block_cyclic_solve(sg.block_cyclic_factor(A, B, C), r)
    dense = sg._dense(A, B, C)
    xd = np.linalg.solve(dense, r.reshape(-1)).reshape(n, 2)
    assert np.max(np.abs(x - xd)) < 1e-12 * max(1.0, np.max(np.abs(xd)))
    # negative control: a wrong corner entry (the block coupling site 0 to site n-1) gives
    # another solution, which the comparison sees
    if periodic:
        A2 = tuple(a.copy() for a in A)
        A2[1][0] += 0.5
        x2 = sg.block_cyclic_solve(sg.block_cyclic_factor(A2, B, C), r)
        assert np.max(np.abs(x2 - xd)) > 1e-6


@pytest.mark.parametrize("n,steps", [(5, 300), (64, 200), (301, 60)])
def test_one_module_runs_at_every_size_and_keeps_energy(sg, sg_mid, n, steps):
    """The same module (nothing re-derived) at several N: AVF keeps H to round-off; the
    midpoint rule (the control) does not."""
    y0 = sg_state(n)
    h = 0.02
    tr = sg.integrate(y0, h, steps)
    H = np.array([sg.hamiltonian(r) for r in tr])
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 2e-14
    mid = sg_mid.integrate(y0, h, steps)
    Hm = np.array([sg_mid.hamiltonian(r) for r in mid])
    assert np.max(np.abs(Hm - Hm[0])) / abs(Hm[0]) > 1e-9
    assert np.max(np.abs(mid - tr)) < 1e-2            # the same motion, to the methods' error


@pytest.mark.slow
def test_energy_over_ten_thousand_steps(sg_compiled):
    """The issue's target: relative energy error ≤ 1e-14 over 10⁴ steps (N = 256, compiled)."""
    y0 = sg_state(256)
    tr = sg_compiled.integrate(y0, 0.01, 10_000, save_every=100)
    H = np.array([sg_compiled.hamiltonian(r) for r in tr])
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-14


def test_order_two(sg):
    """Numerical: the global error at T = 1 against DOP853 falls by 4 when h halves."""
    from scipy.integrate import solve_ivp

    n = 8
    y0 = sg_state(n, amp=1.0)
    L = 2 * np.pi

    def f(t, y):
        q, p = y[:n], y[n:]
        lap = (np.roll(q, -1) - 2 * q + np.roll(q, 1)) * n**2 / L**2
        return np.r_[p, lap - np.sin(q)]

    ref = solve_ivp(f, (0, 1), y0, method="DOP853", rtol=1e-13, atol=1e-13).y[:, -1]
    errs = [np.max(np.abs(sg.integrate(y0, 1 / k, k)[-1] - ref)) for k in (20, 40)]
    assert 3.6 < errs[0] / errs[1] < 4.4


def test_nonconvergence_raises_with_step_and_residual(sg):
    y0 = sg_state(16, amp=3.0)
    with pytest.raises(sg.ConvergenceError) as info:
        sg.integrate(y0, 50.0, 3, maxiter=3)
    assert info.value.step == 0 and info.value.residual > 0
    assert "step 0" in str(info.value) and "residual" in str(info.value)
    sol = sg.solve(y0, (0, 150.0), 50.0, maxiter=3)
    assert not sol.success and sol.status == -1 and "step 0" in sol.message


def test_bad_input_names_what_is_valid(sg):
    with pytest.raises(ValueError, match="N ≥ 3"):
        sg.integrate(np.zeros(4), 0.1, 1)
    with pytest.raises(ValueError, match="flat state"):
        sg.integrate(np.zeros(7), 0.1, 1)
    with pytest.raises(KeyError, match="parameters are"):
        sg.integrate(sg_state(5), 0.1, 1, params={"c": 1.0})
    with pytest.raises(ValueError, match="solver"):
        sg.integrate(sg_state(5), 0.1, 1, solver="lu")


def test_simplified_newton_gives_the_step_to_round_off(sg):
    y0 = sg_state(40)
    a = sg.integrate(y0, 0.05, 20, solver="newton")
    b = sg.integrate(y0, 0.05, 20)                    # the default: simplified
    assert np.max(np.abs(a - y0)) > 0.01              # (they moved)
    assert np.max(np.abs(a - b)) < 1e-13


def test_solution_object(sg):
    sol = sg.solve(sg_state(12), (0.0, 1.0), 0.03)
    assert sol.success and sol.t[-1] == 1.0 and sol.y.shape == (len(sol.t), 24)
    assert sol.nsteps == 34 and abs(sol.h - 1 / 34) < 1e-15
    assert sol.invariant_errors["H"] < 1e-13


def test_module_is_deterministic(sg_lattice):
    scheme = discretize_lattice(sg_lattice, "avf")
    sig = lattice_signature(sg_lattice, "avf")
    a, b = render(scheme, sig), render(discretize_lattice(sg_lattice, "avf"), sig)
    assert a == b
    body = a.split('"""', 2)[2]
    assert "import numpy" in body and "scipy" not in body and "methodgen" not in body.split("\n# ")[0]


def test_avf_term_lemmas_are_proved_and_a_wrong_piece_is_refuted(sg_lattice):
    """The energy claim per template (independent of N): each term lemma reduces to 0 exactly;
    negative control: a piece scaled by 3/2 is refuted at an exact point."""
    scheme = discretize_lattice(sg_lattice, "avf")
    certs = certificates(scheme)
    assert [c.status for c in certs] == ["proved"] * 6
    assert [c.claim.split(":")[0] for c in certs[:2]] == ["term lemma", "symmetric"]
    tp = scheme.terms[2]
    bad = replace(tp, pieces=(tp.pieces[0] * sp.Rational(3, 2),))
    wrong = replace(scheme, terms=scheme.terms[:2] + (bad,))
    assert certificates(wrong)[4].status == "refuted"
    assert certificates(wrong)[5].status == "proved"      # still symmetric: only the lemma sees it


def test_symmetry_is_proved_and_a_one_sided_piece_is_refuted(sg_lattice):
    scheme = discretize_lattice(sg_lattice, "midpoint")
    certs = certificates(scheme)
    assert [c.status for c in certs] == ["proved"] * 3
    tp = scheme.terms[2]                         # sin at the midpoint -> sin at the start: not symmetric
    bad = replace(tp, pieces=(sp.sin(tp.z0[0]),))
    assert certificates(replace(scheme, terms=scheme.terms[:2] + (bad,)))[2].status == "refuted"


NLS = ("Sum(((q[i % N + 1] - q[i])**2 + (p[i % N + 1] - p[i])**2)*N**2/L**2 - (q[i]**2 + p[i]**2)**2/2, "
       "i, 1, N)")


def test_schrodinger_lattice_mass_and_energy(tmp_path):
    """Cubic NLS on a periodic lattice, u = q + i p: AVF keeps H to round-off and the midpoint
    rule keeps the mass Σ|u|² (a quadratic invariant) to round-off; each is the other's control."""
    lat = Lattice(NLS, params={"L": 8.0}, name="nls", invariants={"mass": "Sum(q[i]**2 + p[i]**2, i, 1, N)"})
    avf = build_lattice(lat, "avf", tmp_path / "nls_avf.py")
    mid = build_lattice(lat, "midpoint", tmp_path / "nls_mid.py")
    assert avf.INVARIANT_NAMES == ("H", "mass")
    n = 32
    x = np.arange(n) * 8.0 / n - 4.0
    u = 1.2 / np.cosh(1.2 * x) * np.exp(0.7j * x)
    y0 = np.r_[u.real, u.imag]
    sa = avf.solve(y0, (0, 1.0), 0.01)
    sm = mid.solve(y0, (0, 1.0), 0.01)
    I0 = avf.invariants(y0)
    assert sa.invariant_errors["H"] < 1e-14 * abs(I0["H"]) * 20
    assert sm.invariant_errors["mass"] < 1e-14 * I0["mass"] * 20
    assert sa.invariant_errors["mass"] > 1e-10 * I0["mass"]
    assert sm.invariant_errors["H"] > 1e-10 * abs(I0["H"])


# --- the compiled backend: the same steps through methodgen.runtime.lattice_stepper ------------------------

@pytest.fixture(scope="module")
def sg_compiled(sg_lattice, tmp_path_factory):
    pytest.importorskip("llvmlite")
    return build_lattice(sg_lattice, "avf", tmp_path_factory.mktemp("lat") / "sg_avf_c.py", backend="compiled")


@pytest.mark.parametrize("text,params,n", [(SG, {"L": 2 * np.pi}, 7), (SG, {"L": 2 * np.pi}, 64),
                                           (FPU, {"beta": 0.7}, 9), (NLS, {"L": 8.0}, 12)])
@pytest.mark.parametrize("solver", ["newton", "simplified"])
def test_compiled_steps_are_the_numpy_modules(text, params, n, solver, tmp_path):
    pytest.importorskip("llvmlite")
    lat = Lattice(text, params=params, name="lat")
    a = build_lattice(lat, "avf", tmp_path / "a.py")
    c = build_lattice(lat, "avf", tmp_path / "c.py", backend="compiled")
    assert (a.BACKEND, c.BACKEND) == ("numpy", "compiled")
    y0 = np.r_[np.sin(np.arange(n) * 0.7), 0.3 * np.cos(np.arange(n) * 1.3)]
    ia, ic = {}, {}
    ra = a.integrate(y0, 0.03, 25, save_every=4, solver=solver, info=ia)
    rc = c.integrate(y0, 0.03, 25, save_every=4, solver=solver, info=ic)
    assert ra.shape == rc.shape == (8, 2 * n)
    assert np.max(np.abs(ra - rc)) < 1e-13
    # (two arithmetics: a step may stop one iteration apart at the round-off plateau)
    assert np.max(np.abs(ia["newton_iterations"] - ic["newton_iterations"])) <= 1


def test_compiled_loop_is_its_python_source_bitwise(sg_compiled):
    """The step loop compiled and the same source run as Python: the same bits."""
    from methodgen.runtime.lattice_driver import run_steps

    n = 6
    out = []
    for python in (False, True):
        Y = sg_state(n).reshape(2, n).copy()
        T, its, st = run_steps(sg_compiled._grad_sites, Y, 0.05, 4, 1, np.array([2 * np.pi]), 50, 4 * 2.2e-16,
                               True, False, 1.0, python=python)
        out.append((T, its, st))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1]) and out[0][2] == out[1][2]


@pytest.mark.parametrize("n", [3, 4, 5, 9, 32])
@pytest.mark.parametrize("periodic", [True, False])
def test_bordered_block_elimination_agrees_with_a_dense_solve(sg, n, periodic):
    """methodgen.runtime.lattice_stepper's factor/solve (as Python) against numpy's dense solve of the
    same Newton matrix; negative control: a wrong corner block is seen."""
    from methodgen.runtime import lattice_stepper as ls
    from methodgen.runtime.lattice_driver import shape_constants, stepper_functions

    rng = np.random.default_rng(100 + n)
    h = 0.3
    D = rng.normal(size=(12, n))                 # ∂∇̄H's site diagonals, rows e nf² + f nf + f'
    if not periodic:
        D[0:4, 0] = 0.0                          # no coupling of site 0 to site n-1
        D[8:12, n - 1] = 0.0
    Dm = D.reshape(3, 2, 2, n)
    M = [(-h * d[1, 0], -h * d[1, 1], h * d[0, 0], h * d[0, 1]) for d in Dm]    # the module's blocks
    M = [tuple(a.copy() for a in blk) for blk in M]
    M[1][0][:] += 1.0
    M[1][3][:] += 1.0
    dense = sg._dense(*M)
    r = rng.normal(size=(n, 2))
    st = stepper_functions(shape_constants(n, 2, 1))
    P = np.zeros((12, n))
    st.newton(D, P, n, h, np.zeros(1))
    assert np.array_equal(P.reshape(3, 2, 2, n), np.array(M).reshape(3, 2, 2, n))    # the same arithmetic
    F = np.zeros(ls.factor_size(n, 2, 1))
    W = np.zeros((ls.W_ROWS, n))
    W[ls._IR:ls._IR + 2] = -r.T                  # solve() takes -R and leaves the update
    assert st.factor(P, F, n) == 0
    st.solve(W, F, n)
    x = W[ls._IR:ls._IR + 2].T
    xd = np.linalg.solve(dense, r.reshape(-1)).reshape(n, 2)
    assert np.max(np.abs(x - xd)) < 1e-11 * max(1.0, np.max(np.abs(xd)))
    if periodic:
        M[0][1][0] += 0.5                        # the corner block (site 0 to site n-1), wrong
        wrong = np.linalg.solve(sg._dense(*M), r.reshape(-1)).reshape(n, 2)
        assert np.max(np.abs(x - wrong)) > 1e-6


def test_compiled_failures_raise_the_modules_errors(sg_compiled):
    y0 = sg_state(16, amp=3.0)
    with pytest.raises(sg_compiled.ConvergenceError) as info:
        sg_compiled.integrate(y0, 50.0, 3, maxiter=3)
    assert info.value.step == 0 and info.value.residual > 0 and info.value.trajectory.shape == (1, 32)
    with pytest.raises(sg_compiled.ResolutionError, match="does not resolve the motion"):
        sg_compiled.integrate(sg_state(16), 2.0, 3)
    rows = sg_compiled.integrate(sg_state(16), 2.0, 3, check_resolution=False)
    assert rows.shape == (4, 32)


def test_midpoint_quadratic_invariants_are_decided_per_template():
    """{Q, H} summed over a periodic lattice, decided by the discrete Euler operator of its site
    density (N never enters): the NLS mass is proved kept by the midpoint rule; Σ q² (negative
    control) and a discrete momentum (not an invariant of this lattice) are refuted; a lattice
    with boundaries is not decided (nothing claimed)."""
    from methodgen.symbolic.lattice_scheme import quadratic_invariant_certificates

    lat = Lattice(NLS, params={"L": 8.0}, invariants={
        "mass": "Sum(q[i]**2 + p[i]**2, i, 1, N)", "bad": "Sum(q[i]**2, i, 1, N)",
        "momentum": "Sum(q[i]*p[i % N + 1] - p[i]*q[i % N + 1], i, 1, N)"})
    got = {c.claim.split(":")[0].rsplit(" ", 1)[1]: c.status for c in quadratic_invariant_certificates(lat)}
    assert got == {"mass": "proved", "bad": "refuted", "momentum": "refuted"}
    assert [c.status for c in certificates(discretize_lattice(lat, "midpoint"))].count("proved") == 2
    open_chain = Lattice(FPU, params={"beta": 1.0}, invariants={"e": "Sum(p[i]**2, i, 1, N)"})
    assert quadratic_invariant_certificates(open_chain) == []



def _dense_check(lat, n, mod, h=0.05):
    """H and the step equations at z = y0 (-h J ∇H(y0)) of ``mod`` against the lattice written out
    at n (Lattice.expand) and differentiated by SymPy."""
    H, qs, ps = lat.expand(n)
    vals = {sp.Symbol(k, real=True): v for k, v in lat.params.items()}
    H = H.xreplace(vals)
    y0 = 0.5 * np.random.default_rng(n).normal(size=2 * n)
    f = sp.lambdify(qs + ps, [H] + [sp.diff(H, s) for s in qs + ps])
    out = np.array(f(*y0), dtype=float)
    g = out[1:]
    R = mod.residual(y0, y0, h)
    assert abs(mod.hamiltonian(y0) - out[0]) < 1e-13 * max(1.0, abs(out[0]))
    assert np.max(np.abs(R - np.r_[-h * g[n:], h * g[:n]])) < 1e-13
    return y0


@pytest.mark.parametrize("text,n", [
    # a range starting at 0 with periodic indices (each site once, shifted)
    ("Sum(p[i]**2/2 + q[i]**4, i, 1, N) + Sum(q[i+1]**2*q[(i-1)%N+1]**2, i, 0, N-1)", 4),
    ("Sum(p[i]**2/2, i, 1, N) + Sum(q[(i-1)%N+1]**4/4, i, 2, N+1)", 6),
    # a range of N + 1 sites: one site twice (numpy.add.at in the scatters)
    ("Sum(p[i]**2/2, i, 1, N) + Sum(q[(i-1) % N + 1]**4/4, i, 0, N)", 3),
    ("Sum(p[i]**2/2, i, 1, N) + Sum(q[(i-1) % N + 1]**4/4 + q[i % N + 1]*q[(i-1) % N + 1], i, 0, N)", 5),
    # constants (a site sum and a number: part of H, no gradient); a boundary term that wraps
    ("Sum(p[i]**2/2 + q[i]**2, i, 1, N) + Sum(L, i, 1, N) + 3", 5),
    ("Sum(p[i]**2/2 + q[i]**2*q[i % N + 1]**2, i, 1, N) + q[1]*q[N] + p[N]*q[N - 1]", 5),
    # a fixed-count range with N symbolic elsewhere
    ("Sum(p[i]**2/2 + cos(q[i]), i, 1, N) + Sum(q[i+1]*q[i], i, 1, 3)", 4),
])
@pytest.mark.parametrize("method", ["avf", "midpoint"])
@pytest.mark.parametrize("backend", ["numpy", "compiled"])
def test_every_range_form_against_the_written_out_lattice(text, n, method, backend, tmp_path):
    """Both backends, both methods, each range form: H and the step equations are those of the
    lattice written out at n; the compiled steps are the numpy module's; AVF keeps H."""
    if backend == "compiled":
        pytest.importorskip("llvmlite")
    lat = Lattice(text, params={"L": 1.0} if "L" in text else None, name="forms")
    mod = build_lattice(lat, method, tmp_path / "m.py", backend=backend)
    y0 = _dense_check(lat, n, mod)
    rows = mod.integrate(y0, 0.05, 4, check_resolution=False)
    if backend == "compiled":
        ref = build_lattice(lat, method, tmp_path / "ref.py").integrate(y0, 0.05, 4, check_resolution=False)
        assert np.max(np.abs(rows - ref)) < 1e-13
    if method == "avf":
        H = np.array([mod.hamiltonian(r) for r in rows])
        assert np.max(np.abs(H - H[0])) < 1e-13 * max(1.0, abs(H[0]))
