"""One 2-D lattice module for every N × M: the same step as methodgen's AVF module of the system
written out at small sizes, the FFT solve against a dense one, energy to round-off over many
steps (the midpoint rule, the control, drifts), failures that say what failed, and certificates
decided per template without expanding."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.codegen.lattice_emit import build_lattice
from methodgen.problem.lattice import Lattice, Lattice2D
from methodgen.symbolic.lattice_scheme import (LatticeScheme, TermPieces, certificates, discretize_lattice,
                                               linear_stencil)

KG = ("Sum(Sum(p[i, j]**2/2 + (q[i % N + 1, j] - q[i, j])**2*N**2/(2*L**2)"
      " + (q[i, j % M + 1] - q[i, j])**2*M**2/(2*L**2) + m**2*q[i, j]**2/2 + lam*q[i, j]**4/4, j, 1, M), i, 1, N)")
SG = ("Sum(Sum(p[i, j]**2/2 + ((q[i % N + 1, j] - q[i, j])**2 + (q[i, j % M + 1] - q[i, j])**2)*N**2/(2*L**2)"
      " + (1 - cos(q[i, j])), j, 1, M), i, 1, N)")
PARAMS = {"L": 4.0, "m": 1.0, "lam": 1.0}


@pytest.fixture(scope="module")
def kg_lattice():
    return Lattice(KG, size=("N", "M"), params=PARAMS, name="kg2d")


@pytest.fixture(scope="module")
def kg(kg_lattice, tmp_path_factory):
    return build_lattice(kg_lattice, "avf", tmp_path_factory.mktemp("lat2d") / "kg_avf.py")


@pytest.fixture(scope="module")
def kg_mid(kg_lattice, tmp_path_factory):
    return build_lattice(kg_lattice, "midpoint", tmp_path_factory.mktemp("lat2d") / "kg_mid.py")


def state(n, m, amp=1.5, seed=None):
    x, y = np.meshgrid(np.arange(n) / n, np.arange(m) / m, indexing="ij")
    q = amp * np.exp(-((x - 0.5) ** 2 + (y - 0.4) ** 2) / 0.08) + 0.2 * np.sin(2 * np.pi * x)
    p = 0.3 * np.cos(2 * np.pi * y)
    out = np.stack([q, p])
    if seed is not None:
        out = out + 0.1 * np.random.default_rng(seed).normal(size=out.shape)
    return out


@pytest.mark.parametrize("text,params", [(KG, PARAMS), (SG, {"L": 4.0})])
def test_one_module_at_two_sizes_is_the_expanded_systems_avf_step(text, params, tmp_path):
    """The lattice module (built once) at 3 × 4 and 4 × 3 against methodgen's AVF module of H written
    out at each size (another derivation, another solver: a dense Newton): the same steps to
    round-off (not bitwise: the sums are associated differently)."""
    lat = Lattice(text, size=("N", "M"), params=params, name="lat")
    mod = build_lattice(lat, "avf", tmp_path / "lat.py")
    mid = build_lattice(lat, "midpoint", tmp_path / "mid.py")
    for n, m in ((3, 4), (4, 3)):
        H, qs, ps = lat.expand(n, m)
        used = {k: v for k, v in params.items() if sp.Symbol(k, real=True) in H.free_symbols}
        ref = mg.build(mg.Hamiltonian(H, qs, ps, params=used, name=f"x{n}{m}"), "avf", path=tmp_path / f"r{n}{m}.py")
        y0 = state(n, m, seed=n)
        a = mod.integrate(y0, 0.05, 4, check_resolution=False)
        b = ref.integrate(y0.reshape(-1), 0.05, 4)
        assert np.max(np.abs(a.reshape(len(a), -1) - b)) < 1e-13
        assert abs(mod.hamiltonian(y0) - ref.hamiltonian(y0.reshape(-1))) < 1e-13
        # negative control: the midpoint rule's lattice module (another method, the same solver)
        # is not the reference's AVF step, which the comparison sees
        c = mid.integrate(y0, 0.05, 4, check_resolution=False)
        assert np.max(np.abs(c.reshape(len(c), -1) - b)) > 1e-8


def _dense_linear_part(lat, n, m, h):
    """I - (h/2) J Hess(H) at the zero state, from the lattice written out at n × m (SymPy): for H
    whose non-quadratic part has no quadratic Taylor term at 0, the module's linear matrix."""
    H, qs, ps = lat.expand(n, m)
    H = H.xreplace({sp.Symbol(k, real=True): v for k, v in lat.params.items()})
    ys = qs + ps
    Hess = np.array(sp.hessian(H, ys).xreplace({s: 0 for s in ys}), dtype=float)
    k = n * m
    JH = np.concatenate([Hess[k:], -Hess[:k]])
    return np.eye(2 * k) - 0.5 * h * JH


@pytest.mark.parametrize("n,m", [(3, 3), (4, 5), (6, 4)])
def test_fft_solve_agrees_with_a_dense_solve(kg, kg_lattice, n, m):
    h = 0.3
    dense = _dense_linear_part(kg_lattice, n, m, h)
    assert np.max(np.abs(kg.linear_matrix(n, m, h) - dense)) < 1e-12
    r = np.random.default_rng(n * m).normal(size=(2, n, m))
    x = kg.linear_solve(r, h)
    xd = np.linalg.solve(dense, r.reshape(-1)).reshape(2, n, m)
    assert np.max(np.abs(x - xd)) < 1e-12 * max(1.0, np.max(np.abs(xd)))
    # negative control: one wrong entry (a coupling across the periodic seam) is seen
    wrong = dense.copy()
    wrong[0, (n - 1) * m] += 0.5
    assert np.max(np.abs(np.linalg.solve(wrong, r.reshape(-1)).reshape(2, n, m) - x)) > 1e-6


def test_linear_stencil_is_the_quadratic_parts_hessian(kg_lattice):
    N, M, L, m = sp.symbols("N M L m", positive=True)
    K = {k: v.subs({s: sp.Symbol(s.name, positive=True) for s in v.free_symbols}) for k, v in
         linear_stencil(kg_lattice).items()}
    assert sp.simplify(K[(0, 0, (0, 0))] - (2 * N**2 / L**2 + 2 * M**2 / L**2 + m**2)) == 0
    assert sp.simplify(K[(0, 0, (1, 0))] + N**2 / L**2) == 0 and sp.simplify(K[(0, 0, (0, -1))] + M**2 / L**2) == 0
    assert K[(1, 1, (0, 0))] == 1 and len(K) == 6        # the quartic term is not in it


def test_residual_of_the_converged_step_is_round_off(kg):
    y0 = state(8, 6)
    y1 = kg.step(y0, 0.02)
    assert np.max(np.abs(kg.residual(y1, y0, 0.02))) < 1e-14
    assert np.max(np.abs(kg.residual(y0, y0, 0.02))) > 1e-3          # not trivially zero


@pytest.mark.parametrize("n,m,steps", [(16, 16, 3000), (12, 20, 1000)])
def test_energy_to_round_off_over_many_steps_and_the_midpoint_rule_drifts(kg, kg_mid, n, m, steps):
    y0 = state(n, m)
    h = 0.01
    info = {}
    tr = kg.integrate(y0, h, steps, save_every=10, info=info)
    H = np.array([kg.hamiltonian(r) for r in tr])
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-14
    assert 2 <= info["newton_iterations"].mean() <= 6
    mid = kg_mid.integrate(y0, h, steps, save_every=10)
    Hm = np.array([kg.hamiltonian(r) for r in mid])
    assert np.max(np.abs(Hm - Hm[0])) / abs(Hm[0]) > 1e-9             # the control: not kept
    assert np.max(np.abs(mid - tr)) < 0.05                            # the same motion, to the methods' error


def test_order_two(kg):
    """Numerical: the error at T = 0.4 against a step 32 times smaller falls by ~4 when h halves."""
    y0 = state(8, 8)
    ref = kg.integrate(y0, 0.1 / 64, 256)[-1]
    e = [np.max(np.abs(kg.integrate(y0, h, int(round(0.4 / h)))[-1] - ref)) for h in (0.1 / 2, 0.1 / 4)]
    assert 3.5 < e[0] / e[1] < 4.5


def test_nonconvergence_raises_with_step_and_residual(kg):
    y0 = 6.0 * state(6, 6)
    with pytest.raises(kg.ConvergenceError) as exc:
        kg.integrate(y0, 0.5, 3, maxiter=4, check_resolution=False)
    assert exc.value.step == 0 and exc.value.residual > 0 and "did not converge in 4 iterations" in str(exc.value)
    assert exc.value.trajectory.shape == (1, 2, 6, 6)


def test_bad_input_names_what_is_valid(kg):
    with pytest.raises(ValueError, match=r"shape \(2, N, M\)"):
        kg.integrate(np.zeros(72), 0.01, 1)
    with pytest.raises(ValueError, match="≥ 3"):
        kg.integrate(np.zeros((2, 2, 5)), 0.01, 1)
    with pytest.raises(KeyError, match="unknown parameter"):
        kg.integrate(state(4, 4), 0.01, 1, {"nope": 1.0})
    with pytest.raises(ValueError, match="the solvers are 'simplified', 'newton', 'krylov'"):
        kg.integrate(state(4, 4), 0.01, 1, solver="block")


@pytest.mark.parametrize("text,params", [(KG, PARAMS), (SG, {"L": 4.0})])
def test_the_compiled_site_kernel_gives_the_numpy_modules_steps(text, params, tmp_path):
    """backend="compiled": the residual's gradient by the site kernel compiled through LLVM (the FFT
    solve numpy's): its gradient is the vectorised pieces' to round-off, at two sizes, and so are
    the steps; its Python form (no LLVM) gives the compiled one's bits.  Control: the kernel of
    another lattice (the other text) gives another gradient."""
    from methodgen.runtime import lattice_driver

    pytest.importorskip("llvmlite")
    lat = Lattice(text, size=("N", "M"), params=params, name="c")
    comp = build_lattice(lat, "avf", tmp_path / "c.py", backend="compiled")
    ref = build_lattice(lat, "avf", tmp_path / "n.py")
    assert (comp.BACKEND, ref.BACKEND) == ("compiled", "numpy")
    for n, m in ((5, 7), (16, 12)):
        y0 = state(n, m, seed=n)
        z = y0 + 0.05 * np.cos(np.arange(y0.size)).reshape(y0.shape)
        p = comp._params(None)
        g = comp._gradient(y0, z, n, m, p)
        assert np.max(np.abs(g - comp._gradient_numpy(y0, z, n, m, p))) < 1e-13 * max(1.0, np.max(np.abs(g)))
        assert np.array_equal(g, lattice_driver.gradient_2d(comp._grad2d, y0, z, n, m, p, python=True))
        a, b = comp.integrate(y0, 0.02, 20), ref.integrate(y0, 0.02, 20)
        assert np.max(np.abs(a - b)) < 1e-13
    other = build_lattice(Lattice(SG if text == KG else KG, size=("N", "M"), params={**PARAMS, **params}, name="o"),
                          "avf", tmp_path / "o.py", backend="compiled")
    assert np.max(np.abs(other._gradient(y0, z, n, m, other._params(None)) - g)) > 1e-3


def test_module_is_deterministic_and_imports_numpy_only(kg_lattice, tmp_path):
    a = build_lattice(kg_lattice, "avf", tmp_path / "a.py")
    b = build_lattice(kg_lattice, "avf", tmp_path / "b.py")
    text = open(a.__file__).read()
    assert text == open(b.__file__).read()
    imports = {ln.split()[1] for ln in text.splitlines() if ln.startswith(("import ", "from "))}
    assert imports == {"math", "numpy"}


def test_certificates_are_per_template_and_never_expand(kg_lattice, monkeypatch):
    """verify decides from the templates: Lattice2D.expand is never called, and the term lemma is
    proved; a wrong piece (the midpoint one for the quartic term) is refuted (the control)."""
    def boom(*a, **k):
        raise AssertionError("expanded")

    monkeypatch.setattr(Lattice2D, "expand", boom)
    with pytest.raises(AssertionError, match="expanded"):     # (the guard is armed)
        kg_lattice.expand(3, 3)
    scheme = discretize_lattice(kg_lattice, "avf")
    certs = certificates(scheme)
    assert [c.status for c in certs] == ["proved", "proved"] and "term lemma" in certs[0].claim
    mid = discretize_lattice(kg_lattice, "midpoint")
    wrong = LatticeScheme(kg_lattice, "avf", tuple(TermPieces(tp.term, tp.z0, tp.z1, m.pieces, m.jac, tp.rules)
                                                   for tp, m in zip(scheme.terms, mid.terms)), True)
    got = [c.status for c in certificates(wrong)]
    assert got[0] == "refuted"
    # symmetry's control: a one-sided piece (the pieces at the step's start only)
    one = LatticeScheme(kg_lattice, "avf", tuple(
        TermPieces(tp.term, tp.z0, tp.z1, tuple(a.xreplace(dict(zip(tp.z1, tp.z0))) for a in tp.pieces), tp.jac,
                   tp.rules) for tp in scheme.terms), True)
    assert [c.status for c in certificates(one)][1] == "refuted"


def test_a_linear_lattice_converges_in_one_iteration_and_a_singular_linear_part_is_refused(tmp_path):
    """The wave equation (H quadratic): the linear part is the whole Newton matrix, so the first
    update solves the step (a second one only confirms it, at round-off).  Control: with the
    quartic term added, more iterations.  An h at which I - (h/2) J K is singular raises
    ConvergenceError saying so."""
    wave = Lattice("Sum(Sum(p[i, j]**2/2 + (q[i % N + 1, j] - q[i, j])**2/2 + (q[i, j % M + 1] - q[i, j])**2/2"
                   " + q[i, j]**2/2, j, 1, M), i, 1, N)", size=("N", "M"), name="wave")
    mod = build_lattice(wave, "avf", tmp_path / "wave.py")
    info = {}
    mod.integrate(state(8, 8), 0.05, 20, info=info)
    assert np.all(info["newton_iterations"] <= 2)
    quartic = Lattice(wave.text.replace("q[i, j]**2/2,", "q[i, j]**2/2 + q[i, j]**4,"), size=("N", "M"), name="w4")
    info4 = {}
    build_lattice(quartic, "avf", tmp_path / "w4.py").integrate(state(8, 8), 0.05, 20, info=info4)
    assert info4["newton_iterations"].mean() > 2.5
    inverted = Lattice("Sum(Sum(p[i, j]**2/2 - 2*q[i, j]**2, j, 1, M), i, 1, N)",
                       size=("N", "M"), name="inv")
    bad = build_lattice(inverted, "avf", tmp_path / "inv.py")       # det of each block: 1 - h² (K_qq = -4)
    with pytest.raises(bad.ConvergenceError, match="singular"):
        bad.integrate(state(4, 4), 1.0, 2, check_resolution=False)
    bad.integrate(state(4, 4), 0.1, 2, check_resolution=False)      # another h: regular


def test_monitored_invariants_are_sums_over_the_torus(tmp_path):
    lat = Lattice(KG, size=("N", "M"), params=PARAMS, name="kgi",
                  invariants={"charge": "Sum(Sum(q[i, j]*p[i % N + 1, j], j, 1, M), i, 1, N)"})
    mod = build_lattice(lat, "avf", tmp_path / "kgi.py")
    y = state(5, 4, seed=1)
    got = mod.invariants(y)
    assert abs(got["charge"] - np.sum(y[0] * np.roll(y[1], -1, axis=0))) < 1e-14
    assert abs(got["charge"] - np.sum(y[0] * np.roll(y[1], -1, axis=1))) > 1e-3     # the other direction
    assert got["H"] == mod.hamiltonian(y)


NLS2 = ("Sum(Sum(((q[i % N + 1, j] - q[i, j])**2 + (p[i % N + 1, j] - p[i, j])**2 + (q[i, j % M + 1] - q[i, j])**2"
        " + (p[i, j % M + 1] - p[i, j])**2)/(2*dx**2) - (q[i, j]**2 + p[i, j]**2)**2/4, j, 1, M), i, 1, N)")


def test_midpoint_quadratic_invariants_of_a_2d_lattice_are_decided_per_template():
    """{Q, H} summed over the torus, decided by the 2-D discrete Euler operator of its site density
    (N and M never enter): the mass of a 2-D cubic NLS lattice is proved kept by the midpoint rule;
    Σ q² (negative control) and a discrete momentum along i (not kept by this lattice) are refuted."""
    from methodgen.symbolic.lattice_scheme import quadratic_invariant_certificates

    lat = Lattice(NLS2, size=("N", "M"), params={"dx": 0.5}, invariants={
        "mass": "Sum(Sum(q[i, j]**2 + p[i, j]**2, j, 1, M), i, 1, N)",
        "bad": "Sum(Sum(q[i, j]**2, j, 1, M), i, 1, N)",
        "momentum": "Sum(Sum(q[i, j]*p[i % N + 1, j] - p[i, j]*q[i % N + 1, j], j, 1, M), i, 1, N)"})
    got = {c.claim.split(":")[0].rsplit(" ", 1)[1]: c.status for c in quadratic_invariant_certificates(lat)}
    assert got == {"mass": "proved", "bad": "refuted", "momentum": "refuted"}
    scheme = discretize_lattice(lat, "midpoint")
    from methodgen.symbolic.lattice_scheme import proved_invariants
    assert proved_invariants(scheme, certificates(scheme)) == ["mass"]


def test_2d_midpoint_keeps_the_mass_and_avf_the_energy(tmp_path):
    """Numerical, to round-off: the 2-D NLS lattice's midpoint module keeps the mass (proved above),
    its AVF module the energy; each drifts in the other's invariant (the controls)."""
    lat = Lattice(NLS2, size=("N", "M"), params={"dx": 0.5}, name="nls2",
                  invariants={"mass": "Sum(Sum(q[i, j]**2 + p[i, j]**2, j, 1, M), i, 1, N)"})
    avf = build_lattice(lat, "avf", tmp_path / "nls2_avf.py")
    mid = build_lattice(lat, "midpoint", tmp_path / "nls2_mid.py")
    n, m = 12, 10
    x = (np.arange(n) - n / 2) * 0.5
    yy = (np.arange(m) - m / 2) * 0.5
    X, Y = np.meshgrid(x, yy, indexing="ij")
    u = 1.1 * np.exp(-(X**2 + Y**2) / 2) * np.exp(0.6j * X)
    y0 = np.stack([u.real, u.imag])
    sa = avf.solve(y0, (0, 1.0), 0.01)
    sm = mid.solve(y0, (0, 1.0), 0.01)
    assert sa.success and sm.success
    I0 = avf.invariants(y0)
    assert sm.invariant_errors["mass"] < 20 * 2.2e-16 * I0["mass"]
    assert sa.invariant_errors["H"] < 20 * 2.2e-16 * abs(I0["H"])
    assert sa.invariant_errors["mass"] > 1e-10 * I0["mass"]
    assert sm.invariant_errors["H"] > 1e-10 * abs(I0["H"])
