"""The resolution guard reads h·ω off the eigenvalues of the Newton Jacobian, so a change of
units does not change its verdict (issue 27.4): GeometricProblems.jl's double pendulum in
angles at its own h = 0.01 (momenta up to ~49) runs on both backends, matches a DOP853
reference to the midpoint rule's error, and the same system in units where the momenta are
100 times larger gets the same verdict.  Negative control: the row-sum norm the guard used
before exceeds MAX_RESOLUTION on this orbit (it refused the step), and it changes with the
units."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.symbolic.derive import vector_field

H = ("(m2*l2**2*p1**2 + (m1 + m2)*l1**2*p2**2 - 2*m2*l1*l2*p1*p2*cos(q1 - q2))"
     "/(2*m2*l1**2*l2**2*(m1 + m2*sin(q1 - q2)**2)) - (m1 + m2)*g*l1*cos(q1) - m2*g*l2*cos(q2)")
PARAMS = dict(l1=2.0, l2=3.0, m1=1.0, m2=2.0, g=9.80665)
THETA0, OMEGA0 = np.array([np.pi / 4, np.pi / 2]), np.array([0.0, np.pi / 8])
H_STEP, STEPS = 0.01, 1000


def _system(scale=1.0):
    """Masses times ``scale``: H and p scale by ``scale``, the motion in the angles is the same."""
    P = dict(PARAMS, m1=PARAMS["m1"] * scale, m2=PARAMS["m2"] * scale)
    return mg.Hamiltonian(H, q=["q1", "q2"], p=["p1", "p2"], params=P, name="double-pendulum-angles"), P


def _y0(P):
    """p0 = ∂L/∂θ̇ at GeometricProblems.jl's initial angles and angular velocities."""
    (t1, t2), (w1, w2) = THETA0, OMEGA0
    m1, m2, l1, l2 = P["m1"], P["m2"], P["l1"], P["l2"]
    c = np.cos(t1 - t2)
    return np.array([t1, t2, (m1 + m2) * l1**2 * w1 + m2 * l1 * l2 * w2 * c, m2 * l2**2 * w2 + m2 * l1 * l2 * w1 * c])


@pytest.fixture(scope="module")
def reference():
    from scipy.integrate import solve_ivp
    S, P = _system()
    f = sp.lambdify([list(S.y)], list(vector_field(S).xreplace({s: P[s.name] for s in S.params})), "numpy")
    sol = solve_ivp(lambda t, y: np.array(f(y), dtype=float), (0, H_STEP * STEPS), _y0(P), method="DOP853",
                    rtol=1e-13, atol=1e-13, t_eval=H_STEP * np.arange(STEPS + 1))
    return sol.y.T


@pytest.fixture(scope="module")
def gen(tmp_path_factory):
    root = tmp_path_factory.mktemp("dpa")
    cache = {}

    def get(method, scale=1.0, backend="numpy", order=2):
        key = (method, scale, backend, order)
        if key not in cache:
            S, _ = _system(scale)
            cache[key] = mg.generate(mg.discretize(S, method, order=order),
                                     root / f"dpa_{method}_{int(scale)}_{backend}_{order}.py", backend=backend)
        return cache[key]

    return get


def test_p0_is_geometricproblems(reference):
    assert _y0(PARAMS)[2:] == pytest.approx([3.3321622, 7.06858347], abs=1e-7)


@pytest.mark.parametrize("method", ["midpoint", "avf", "gonzalez"])
def test_double_pendulum_runs_at_h_001(gen, reference, method):
    mod = gen(method)
    tr = mod.integrate(_y0(PARAMS), H_STEP, STEPS)
    assert np.abs(tr[:, 2:]).max() > 45                # the large momenta that inflated the norm
    err = np.abs(tr[:, :2] - reference[:, :2]).max()
    assert err < 0.02                                   # angles: the method's own error ...
    if method == "midpoint":
        # ... second order: halving h quarters it (so it is the midpoint rule's error)
        tr2 = mod.integrate(_y0(PARAMS), H_STEP / 2, 2 * STEPS)
        ratio = np.abs(tr2[::2, :2] - reference[:, :2]).max() / err
        assert 0.2 < ratio < 0.3


def test_composition_runs_at_h_001(gen, reference):
    tr = gen("midpoint", order=4).integrate(_y0(PARAMS), H_STEP, STEPS)
    assert np.abs(tr[:, :2] - reference[:, :2]).max() < 1e-4


def test_units_do_not_change_the_verdict(gen):
    """Momenta 100 times larger (masses x100): same verdict, same angles; the eigenvalue-based
    h·ω is the same while the old row-sum bound is not (negative control: it refused)."""
    mod, big = gen("midpoint"), gen("midpoint", 100.0)
    y0, y0_big = _y0(PARAMS), _y0(_system(100.0)[1])
    assert y0_big[2:] == pytest.approx(100 * y0[2:])
    tr, tr_big = mod.integrate(y0, H_STEP, STEPS), big.integrate(y0_big, H_STEP, STEPS)
    assert np.abs(tr_big[:, :2] - tr[:, :2]).max() < 1e-9
    # h·ω from J - I along the run, by eigenvalues and by the max row sum
    z = np.zeros(4)
    J, Jb = mod.jacobian(z, tr[:-1], H_STEP) - np.eye(4), big.jacobian(z, tr_big[:-1], H_STEP) - np.eye(4)
    eig = 2 * np.abs(np.linalg.eigvals(J)).max(axis=-1)
    eig_b = 2 * np.abs(np.linalg.eigvals(Jb)).max(axis=-1)
    assert eig.max() < 0.2 and eig_b == pytest.approx(eig, rel=1e-6)
    rowsum = 2 * np.abs(J).sum(axis=-1).max(axis=-1)
    rowsum_b = 2 * np.abs(Jb).sum(axis=-1).max(axis=-1)
    assert rowsum.max() > mod.MAX_RESOLUTION            # the old guard refused this run ...
    assert rowsum_b.max() > 10 * rowsum.max()           # ... and its verdict depended on the units
    # both systems still refuse a step that does not resolve the motion, at the same h
    for m, y in ((mod, y0), (big, y0_big)):
        with pytest.raises(m.ResolutionError):
            m.integrate(y, 0.5, 40)


def test_double_pendulum_numba(gen, reference):
    pytest.importorskip("llvmlite")
    mod = gen("midpoint", backend="numba")
    tr = mod.integrate(_y0(PARAMS), H_STEP, STEPS)
    assert np.abs(tr[:, :2] - reference[:, :2]).max() < 0.02
    tr_np = gen("midpoint").integrate(_y0(PARAMS), H_STEP, STEPS)
    assert np.abs(tr - tr_np).max() < 1e-9
    with pytest.raises(mod.ResolutionError):
        mod.integrate(_y0(PARAMS), 0.5, 40)
