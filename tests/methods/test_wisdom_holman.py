"""Wisdom–Holman splittings of [nbody] problems (methodgen.symbolic.nbody, methodgen.runtime.nbody, methodgen.runtime.kepler_flow).

Numerical checks are labelled as such; the exact ones are SymPy reductions to 0.
"""

from __future__ import annotations

import dataclasses
import math

import mpmath as mp
import numpy as np
import pytest

import methodgen as mg
from methodgen.runtime import kepler_flow as kf
from methodgen.runtime import nbody as W
from methodgen.symbolic import nbody as S
from methodgen.errors import InputError, MethodNotApplicable
from methodgen.symbolic.scene import NBody

pytest.importorskip("llvmlite")   # the runtime runs as Python without it: too slow for these runs


def star_and_planets(eps: float, n_planets: int = 2):
    """A star (mass 1) and planets of mass ``eps`` (G = 1), with an initial state near circular orbits."""
    from methodgen.app.bench import nbody_system

    nb = n_planets + 1
    system = nbody_system(nb, 1.0, [1.0] + [eps] * n_planets, name=f"star{n_planets}")
    nbody = NBody(G="G", masses=tuple(f"m{b}" for b in range(nb)))
    m = np.array([1.0] + [eps] * n_planets)
    Q = np.zeros((nb, 3))
    V = np.zeros((nb, 3))
    for b in range(1, nb):
        a = 1.0 + 0.6 * (b - 1)
        ang = 1.3 * b
        Q[b] = a * np.array([math.cos(ang), math.sin(ang), 0.05 * b])
        v = math.sqrt(1.0 / a) * 1.08          # a little eccentric
        V[b] = v * np.array([-math.sin(ang), math.cos(ang), 0.02])
    V[0] = -(m[1:, None] * V[1:]).sum(axis=0) / m[0]
    y0 = np.concatenate([Q.ravel(), (m[:, None] * V).ravel()])
    return system, nbody, y0


def star_scene(tmp_path, eps: float = 1e-3, n_planets: int = 2):
    """:func:`star_and_planets` as a scene file with its ``[nbody]`` table: ``(scene, y0)``."""
    from methodgen.symbolic.scene import load_scene

    system, nbody, y0 = star_and_planets(eps, n_planets)
    text = "\n".join([
        f'name = "star{n_planets}"', f'description = "a star and {n_planets} planets"', "[system]",
        f'H = "{system.source}"', f"q = {[s.name for s in system.q]}", f"p = {[s.name for s in system.p]}",
        "[params]", *(f"{k} = {v!r}" for k, v in system.param_values.items()),
        "[nbody]", 'G = "G"', f"masses = {list(nbody.masses)}",
        "[run]", 'method = "stormer-verlet"', "h = 0.05", "steps = 40", f"y0 = {list(map(float, y0))}"])
    path = tmp_path / f"star{n_planets}.toml"
    path.write_text(text.replace("'", '"') + "\n")
    return load_scene(path), y0


def reference(system, y0, T):
    """DOP853 at rtol 1e-13 (numerical; ~1e-13 off on these short runs)."""
    from scipy.integrate import solve_ivp

    from methodgen.symbolic.derive import vector_field
    import sympy as sp

    f = sp.lambdify([sp.Matrix(system.y)], vector_field(system).subs(
        {s: system.param_values[s.name] for s in system.params}), "numpy")
    sol = solve_ivp(lambda t, y: np.asarray(f(y), dtype=float).ravel(), (0, T), y0, method="DOP853",
                    rtol=1e-13, atol=1e-15)
    return sol.y[:, -1]


@pytest.fixture(scope="module")
def tiny():
    """ε = 1e-7: the ε terms dominate, the ε² terms are below round-off.  Reference: sbab6 with
    the corrector at 512 steps (ε h¹² and ε² h⁴ far below round-off; the Kepler flow is checked
    against Kepler's equation below; DOP853 at rtol 1e-13 agrees to 1.5e-12)."""
    system, nbody, y0 = star_and_planets(1e-7)
    ref = W.wisdom_holman(system, "sbab6", nbody=nbody).integrate(y0, 6.0 / 512, 512, save_every=512)[-1]
    return system, nbody, y0, ref


@pytest.fixture(scope="module")
def small():
    """ε = 1e-2: the ε² h² term dominates (what the corrector removes)."""
    system, nbody, y0 = star_and_planets(1e-2)
    return system, nbody, y0, reference(system, y0, 2.0)


@pytest.fixture(scope="module")
def mild():
    """ε = 1e-3, no reference (structure tests)."""
    return star_and_planets(1e-3)


def error(wh, y0, ref, T, steps):
    return np.max(np.abs(wh.integrate(y0, T / steps, steps, save_every=steps)[-1] - ref))


# --- coefficients (numerical, 50 digits) ------------------------------------------------------------

@pytest.mark.parametrize("name", S.FAMILIES)
def test_coefficients_conditions(name):
    s = S.splitting(name)
    cert = S.numerical_certificate(s)
    assert cert["consistency"] == (0.0, 0.0) or max(cert["consistency"]) < 1e-40
    assert cert["epsilon_order"] == 2 * s.n          # exactly 2n: the next condition fails
    assert cert["quadrature"][2 * s.n] > 1e-10
    assert cert["bch_check"] < 1e-40                  # the degree-3 log is a Lie element
    if s.n >= 2:
        assert cert["eh2"] < 1e-40                    # no ε h² term
    else:
        assert abs(cert["eh2"] - (1 / 24 if name != "sbab1" else 1 / 12)) < 1e-40


def test_corrector_coefficients_are_laskar_robutels():
    # [LR01] Table: g of SABA1…4 and SBAB1, 2 (SABA3: (54 − 13√15)/648)
    want = {"saba1": 1 / 12, "saba2": (2 - math.sqrt(3)) / 24, "saba3": (54 - 13 * math.sqrt(15)) / 648,
            "saba4": 0.003396775048208601, "sbab1": -1 / 24, "sbab2": 1 / 72}
    for name, g in want.items():
        assert abs(float(S.splitting(name).g) - g) < 1e-15, name


def test_a_moved_node_is_caught():
    """Negative control: a kick moved by 1e-6 of the step fails the quadrature condition of order 2."""
    s = S.splitting("saba3")
    drifts = list(s.drifts)
    drifts[1] += mp.mpf("1e-6")
    drifts[2] -= mp.mpf("1e-6")
    bad = dataclasses.replace(s, drifts=tuple(drifts))
    cert = S.numerical_certificate(bad)
    assert cert["epsilon_order"] < 6
    assert cert["quadrature"][2] > 1e-8


def test_unknown_splitting_is_named():
    with pytest.raises(InputError, match="valid: wisdom-holman, saba1"):
        S.splitting("saba9")


# --- the splitting of H (exact) ----------------------------------------------------------------------

def test_splitting_certificate_exact():
    sc = mg.load_scene("outer-solar-system")
    cert = S.certify(sc.system, sc.nbody)
    assert cert["hamiltonian"] == "symbolic"
    assert cert["splitting"] == {"canonical": True, "kinetic": True, "kepler": True}


def test_kepler_scene_is_certified_at_its_parameter_values_only():
    sc = mg.load_scene("kepler")   # H = p²/2m − k/r, declared G k m/r: equal for m = 1
    assert S.certify(sc.system, sc.nbody)["hamiltonian"] == "at the parameter values"
    other = mg.Hamiltonian(sc.system.source, q=["x", "y", "z"], p=["px", "py", "pz"], params={"m": 2.0, "k": 1.0})
    # negative control: with m = 2 the Hamiltonian is not the declared one
    assert S.certify(other, sc.nbody)["hamiltonian"] is False
    with pytest.raises(MethodNotApplicable, match="not the one its \\[nbody\\] table declares"):
        W.wisdom_holman(other, "saba2", nbody=sc.nbody)


def test_wrong_jacobi_momenta_fail_the_identities(monkeypatch):
    """Negative control: momenta mapped with A_q instead of A⁻ᵀ are not canonical."""
    real = S._jacobi_matrices

    def wrong(n, m):
        Aq, Ap, M = real(n, m)
        return Aq, Aq, M

    monkeypatch.setattr(S, "_jacobi_matrices", wrong)
    S._jacobi_identities.cache_clear()
    try:
        ids = S._jacobi_identities(3)
        assert not ids["canonical"] and not ids["kinetic"]
    finally:
        monkeypatch.undo()
        S._jacobi_identities.cache_clear()


def _brute_force_identities(n):
    """The identities reduced whole, as one rational function each (the test's oracle:
    exponential in n, so for small n only)."""
    import sympy as sp

    m = sp.symbols(f"m0:{n}", positive=True)
    P = sp.symbols(f"p0:{n}", real=True)
    Aq, Ap, M = S._jacobi_matrices(n, m)
    canonical = all(sp.cancel(e) == 0 for e in (Ap * Aq.T - sp.eye(n)))
    pj = Ap * sp.Matrix(P)
    mj = [M[n - 1]] + [m[i] * M[i - 1] / M[i] for i in range(1, n)]
    kin = sum(P[b] ** 2 / (2 * m[b]) for b in range(n)) - sum(pj[i] ** 2 / (2 * mj[i]) for i in range(n))
    return {"canonical": canonical, "kinetic": sp.cancel(sp.together(kin)) == 0,
            "kepler": all(sp.cancel(M[i] * mj[i] - m[i] * M[i - 1]) == 0 for i in range(1, n))}


@pytest.mark.parametrize("n", [2, 3, 4])
def test_structural_identities_agree_with_the_whole_reduction(n):
    assert S._jacobi_identities(n) == _brute_force_identities(n) == \
        {"canonical": True, "kinetic": True, "kepler": True}


@pytest.mark.parametrize("where", ["momentum diagonal", "momentum below", "position below", "position row 0"])
def test_one_wrong_entry_of_the_last_body_fails(monkeypatch, where):
    """Negative controls for the structural proof: one entry of the last body's rows (or of
    row 0) changed is caught at 4 and at 21 bodies, as the whole reduction catches it at 4."""
    import sympy as sp

    real = S._jacobi_matrices

    def wrong(n, m):
        Aq, Ap, M = real(n, m)
        Aq, Ap = Aq.copy(), Ap.copy()
        i = n - 1
        if where == "momentum diagonal":
            Ap[i, i] = Ap[i, i] * 2
        elif where == "momentum below":
            Ap[i, 0] = Ap[i, 0] + m[i] / M[i] / 3
        elif where == "position below":
            Aq[i, 1] = Aq[i, 1] * sp.Rational(1, 2)
        else:
            Aq[0, i] = Aq[0, i] * 2
        return Aq, Ap, M

    monkeypatch.setattr(S, "_jacobi_matrices", wrong)
    S._jacobi_identities.cache_clear()
    try:
        assert not all(_brute_force_identities(4).values())
        for n in (4, 21):
            ids = S._jacobi_identities(n)
            assert not all(ids.values()), (n, ids)
            assert ids["canonical"] is False
    finally:
        monkeypatch.undo()
        S._jacobi_identities.cache_clear()


def test_certificate_of_many_bodies_returns():
    """The certificate is polynomial in the number of bodies (it grew ~4.5x a body and did
    not return at 11): 21 and 41 bodies proved here (timed in the closing note, not here)."""
    S._jacobi_identities.cache_clear()
    for n in (21, 41):
        assert S._jacobi_identities(n) == {"canonical": True, "kinetic": True, "kepler": True}


def test_not_an_nbody_problem_is_refused():
    with pytest.raises(MethodNotApplicable, match="declares no \\[nbody\\] table"):
        W.wisdom_holman(mg.load_scene("henon-heiles"), "saba2")


# --- the runtime (numerical) ---------------------------------------------------------------------------

def test_jacobi_map_is_the_certified_matrix():
    import sympy as sp

    system, nbody, y0 = star_and_planets(1e-3, 3)
    m = np.array([1.0, 1e-3, 2e-3, 5e-4])
    Aq, Ap, _ = S._jacobi_matrices(4, [sp.Rational(repr(float(v))) for v in m])
    Aq = np.array(Aq.evalf(30), dtype=float)
    Ap = np.array(Ap.evalf(30), dtype=float)
    rng = np.random.default_rng(1)
    q, p = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    qj, pj = np.empty_like(q), np.empty_like(p)
    kf.to_jacobi(q, p, m, np.cumsum(m), True, qj, pj)
    assert np.allclose(qj, Aq @ q, rtol=0, atol=1e-14) and np.allclose(pj, Ap @ p, rtol=0, atol=1e-14)
    qb, pb = np.empty_like(q), np.empty_like(p)
    kf.from_jacobi(qj, pj, m, np.cumsum(m), True, qb, pb)
    assert np.max(np.abs(qb - q)) < 1e-14 and np.max(np.abs(pb - p)) < 1e-14


def kepler_solution(r0, v0, mu, t):
    """Independent reference: elements, Kepler's equation by mpmath at 40 digits (elliptic or hyperbolic)."""
    with mp.workdps(40):
        r0 = [mp.mpf(x) for x in r0]
        v0 = [mp.mpf(x) for x in v0]
        mu = mp.mpf(mu)
        r = mp.sqrt(sum(x * x for x in r0))
        v2 = sum(x * x for x in v0)
        rv = sum(a * b for a, b in zip(r0, v0))
        a = 1 / (2 / r - v2 / mu)
        if a > 0:
            n = mp.sqrt(mu / a ** 3)
            E0 = mp.atan2(rv / mp.sqrt(mu * a), 1 - r / a)
            M = E0 - rv / mp.sqrt(mu * a) + n * mp.mpf(t)
            # Kepler's equation in the eccentric anomaly's change dE
            def kep(dE):
                return dE + (rv / mp.sqrt(mu * a)) * (1 - mp.cos(dE)) - (1 - r / a) * mp.sin(dE) - n * mp.mpf(t)
            dE = mp.findroot(kep, n * mp.mpf(t))
            f = 1 - a / r * (1 - mp.cos(dE))
            g = mp.mpf(t) - (dE - mp.sin(dE)) / n
            rn = [f * x + g * y for x, y in zip(r0, v0)]
            rr = mp.sqrt(sum(x * x for x in rn))
            fd = -mp.sqrt(mu * a) / (rr * r) * mp.sin(dE)
            gd = 1 - a / rr * (1 - mp.cos(dE))
        else:
            a = -a
            n = mp.sqrt(mu / a ** 3)

            def kep(dF):
                return -dF + (rv / mp.sqrt(mu * a)) * (mp.cosh(dF) - 1) + (1 + r / a) * mp.sinh(dF) - n * mp.mpf(t)
            dF = mp.findroot(kep, mp.asinh(n * mp.mpf(t)))
            f = 1 - a / r * (mp.cosh(dF) - 1)
            g = mp.mpf(t) - (mp.sinh(dF) - dF) / n
            rn = [f * x + g * y for x, y in zip(r0, v0)]
            rr = mp.sqrt(sum(x * x for x in rn))
            fd = -mp.sqrt(mu * a) / (rr * r) * mp.sinh(dF)
            gd = 1 - a / rr * (mp.cosh(dF) - 1)
        vn = [fd * x + gd * y for x, y in zip(r0, v0)]
        return np.array([float(x) for x in rn]), np.array([float(x) for x in vn])


@pytest.mark.parametrize("e, t", [(0.6, 0.3), (0.6, 5.0), (0.99, 0.05), (0.99, 4.0), (0.6, 61.0), (1.5, 2.0)])
def test_kepler_drift_against_keplers_equation(e, t):
    """Numerical: the universal-variable drift against Kepler's equation at 40 digits (incl. ten periods)."""
    mu = 1.0
    rp = 0.5
    r0 = np.array([rp, 0.0, 0.0])
    v0 = np.array([0.0, math.sqrt(mu * (1 + e) / rp) * 0.8, math.sqrt(mu * (1 + e) / rp) * 0.6])
    qj, pj = r0[None].copy(), (3.0 * v0)[None].copy()
    cq, cp = np.zeros_like(qj), np.zeros_like(pj)
    assert kf.kepler_drift(qj, pj, cq, cp, 0, 3.0, mu, t) > 0
    qj, pj = qj - cq, pj - cp
    rw, vw = kepler_solution(r0, v0, mu, t)
    scale = max(1.0, np.max(np.abs(rw)))
    assert np.max(np.abs(qj[0] - rw)) < 1e-14 * scale
    assert np.max(np.abs(pj[0] / 3.0 - vw)) < 1e-14 * max(1.0, np.max(np.abs(vw)))


def test_kepler_drift_of_a_body_at_the_centre_fails_without_a_result():
    qj, pj = np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]])
    assert kf.kepler_drift(qj, pj, np.zeros((1, 3)), np.zeros((1, 3)), 0, 1.0, 1.0, 0.1) == -2
    assert np.array_equal(qj, np.zeros((1, 3)))


def test_one_body_about_a_fixed_centre_is_exact_at_e099():
    """Numerical: about a fixed centre with one body H_I = 0: the method is the exact flow; e = 0.99,
    50 steps per orbit, 20 orbits.  Energy and the eccentricity vector are kept to 1e-11 relative
    (f and g lose a few digits in the steps through pericentre; measured 1.4e-11 after 1000
    steps and 3e-11 after 5000, not growing with the steps)."""
    sc = mg.load_scene("kepler")
    wh = W.wisdom_holman(sc, "wisdom-holman")
    e, rp = 0.99, 0.01
    y0 = np.array([rp, 0, 0, 0, math.sqrt((1 + e) / rp), 0.0])
    P = 2 * math.pi * (rp / (1 - e)) ** 1.5
    Y = wh.integrate(y0, P / 50, 1000)
    H = wh.hamiltonian(Y)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-10
    q, p = Y[:, :3], Y[:, 3:]
    L = np.cross(q, p)
    ecc = np.cross(p, L) - q / np.linalg.norm(q, axis=1)[:, None]
    assert np.max(np.abs(ecc - ecc[0])) < 1e-10
    assert np.max(np.abs(L - L[0])) < 1e-13
    # back at pericentre after 20 periods: the position to 3e-8 (the radial velocity there, which
    # changes by v²/r = 2e4 per unit time, shows the ~1e-9 time shift of the 1e-11 energy error)
    assert np.max(np.abs(Y[-1, :3] - y0[:3])) < 1e-7


def interaction(wh, Y):
    """H − H_K at states Y (numerical, through the Jacobi map): H_I."""
    m, M, mj, mu, KM = wh._const
    out = []
    for y in Y:
        q, p = wh._bodies(y)
        qj, pj = np.empty_like(q), np.empty_like(p)
        kf.to_jacobi(np.ascontiguousarray(q), np.ascontiguousarray(p), m, M, True, qj, pj)
        HK = np.sum(pj[0] ** 2) / (2 * mj[0]) + sum(
            np.sum(pj[i] ** 2) / (2 * mj[i]) - mu[i] * mj[i] / np.linalg.norm(qj[i]) for i in range(1, len(m)))
        out.append(wh.hamiltonian(y) - HK)
    return np.array(out)


def test_interaction_depends_on_positions_only_and_its_gradient():
    """Numerical: H − H_K does not change with the momenta; the runtime's ∇H_I and ∇C against
    central differences (the Hessian applied exactly against differences of the gradient)."""
    system, nbody, y0 = star_and_planets(1e-3, 3)
    wh = W.wisdom_holman(system, "saba2", nbody=nbody)
    rng = np.random.default_rng(3)
    Y = np.array([y0, y0 + np.r_[np.zeros(12), rng.normal(size=12) * 1e-2]])
    HI = interaction(wh, Y)
    assert abs(HI[1] - HI[0]) < 1e-15
    m, M, mj, mu, KM = wh._const
    q, p = wh._bodies(y0)
    qj, pj = np.empty_like(q), np.empty_like(p)
    kf.to_jacobi(np.ascontiguousarray(q), np.ascontiguousarray(p), m, M, True, qj, pj)
    work = np.empty((7, 4, 3))

    def grad(x):
        kf.interaction_gradient(x, m, M, KM, wh.G, True, work[0], work[1], work[2])
        return work[2].copy()

    def HI_of(x):
        qq, pp = np.empty_like(x), np.empty_like(x)
        kf.from_jacobi(x, pj, m, M, True, qq, pp)
        return interaction(wh, [np.r_[qq.ravel(), pp.ravel()]])[0]

    def C_of(x):
        g = grad(x)
        return sum(np.sum(g[i] ** 2) / mj[i] for i in range(1, 4))

    g = grad(qj)
    kf.corrector_gradient(qj, g, m, M, mj, KM, wh.G, True, work[0], work[3], work[4], work[5], work[6])
    gC = work[6].copy()
    d = 1e-5
    for i in range(1, 4):
        for k in range(3):
            e = np.zeros_like(qj)
            e[i, k] = d
            fd = (HI_of(qj + e) - HI_of(qj - e)) / (2 * d)
            assert abs(fd - g[i, k]) < 1e-7 * np.max(np.abs(g)), (i, k)
            fdC = (C_of(qj + e) - C_of(qj - e)) / (2 * d)
            assert abs(fdC - gC[i, k]) < 1e-6 * np.max(np.abs(gC)), (i, k)


# --- orders, corrector, structure (numerical) ---------------------------------------------------

#: (family, ε-order, steps over T = 6 of the coarser run): where the error is above the
#: reference's round-off and the ε² terms (ε = 1e-7) are not yet visible.
ORDER_RUNS = [("saba1", 2, 6), ("sbab1", 2, 6), ("saba2", 4, 12), ("sbab2", 4, 12), ("saba3", 6, 8), ("sbab3", 6, 8)]


@pytest.mark.parametrize("name, order, steps", ORDER_RUNS)
def test_epsilon_order(tiny, name, order, steps):
    """With ε = 1e-7 the error is ε h^{2n}: the measured order under halving h is 2n (measured:
    2.01, 2.01, 4.03, 4.03, 6.93, 6.01; the order-6 pair's finer run is 5e-15 from the reference)."""
    system, nbody, y0, ref = tiny
    wh = W.wisdom_holman(system, name, nbody=nbody, corrector=False)
    e1, e2 = error(wh, y0, ref, 6.0, steps), error(wh, y0, ref, 6.0, 2 * steps)
    measured = math.log2(e1 / e2)
    assert order - 0.5 < measured < order + 2.5, (e1, e2, measured)


def test_a_perturbed_kick_loses_the_order(tiny):
    """Negative control: saba3 with one kick weight moved by 1e-3 (and another back: still
    consistent) is no longer of ε-order 6."""
    system, nbody, y0, ref = tiny
    s = S.splitting("saba3")
    kicks = list(s.kicks)
    kicks[1] += mp.mpf("1e-3")
    kicks[3] -= mp.mpf("1e-3")
    wh = W.wisdom_holman(system, "saba3", nbody=nbody, corrector=False)
    bad = W.WisdomHolman(system, nbody, dataclasses.replace(s, kicks=tuple(kicks)), False, wh.certificate)
    e1, e2 = error(bad, y0, ref, 6.0, 6), error(bad, y0, ref, 6.0, 12)
    assert math.log2(e1 / e2) < 3


def test_corrector_removes_the_eps2_h2_term(small):
    """ε = 1e-2, saba4: without the corrector the error goes like h² (ε² h²), with it ≥ 10× smaller
    and of order 4 (ε² h⁴); with the corrector's sign flipped (negative control) it does not help."""
    system, nbody, y0, ref = small
    plain = W.wisdom_holman(system, "saba4", nbody=nbody, corrector=False)
    corr = W.wisdom_holman(system, "saba4", nbody=nbody)
    flipped = W.wisdom_holman(system, "saba4", nbody=nbody)
    flipped._g = -flipped._g
    e = {k: (error(w, y0, ref, 2.0, 8), error(w, y0, ref, 2.0, 16))
         for k, w in (("plain", plain), ("corr", corr), ("flipped", flipped))}
    assert abs(math.log2(e["plain"][0] / e["plain"][1]) - 2) < 0.3, e
    assert e["corr"][0] < e["plain"][0] / 10, e
    assert abs(math.log2(e["corr"][0] / e["corr"][1]) - 4) < 0.3, e
    assert e["flipped"][0] > e["plain"][0] / 2, e


@pytest.mark.parametrize("name", ["saba3", "sbab4"])
def test_symmetric_and_momenta_kept(mild, name):
    """Numerical: h then −h returns to y0; total momentum and angular momentum kept to round-off."""
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, name, nbody=nbody)
    y1 = wh.step(y0, 0.1)
    back = wh.step(y1, -0.1)
    assert np.max(np.abs(back - y0)) < 1e-14
    Y = wh.integrate(y0, 0.1, 2000, save_every=10)
    P, L = wh.linear_momentum(Y), wh.angular_momentum(Y)
    assert np.max(np.abs(P - P[0])) < 1e-15
    assert np.max(np.abs(L - L[0])) < 1e-14
    H = wh.hamiltonian(Y)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-7     # bounded, not kept


@pytest.mark.parametrize("project", [None, "energy-output", "energy-standard"])
def test_chunks_and_save_every_are_bitwise(mild, project):
    """Chunks continued with ``info`` (the carried state, and a projection's target) are the run
    in one piece bitwise; ``save_every`` rows are those rows (tests/test_wisdom_holman_projection.py
    for the projections)."""
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "sbab3", nbody=nbody, project=project)
    whole = wh.integrate(y0, 0.05, 300)
    every = wh.integrate(y0, 0.05, 300, save_every=7)
    assert np.array_equal(every[1:-1], whole[7::7][: len(every) - 2]) and np.array_equal(every[-1], whole[-1])
    info = {}
    a = wh.integrate(y0, 0.05, 120, info=info)
    b = wh.integrate(a[-1], 0.05, 180, info=info)
    assert np.array_equal(b[-1], whole[-1])
    if project:
        assert 1.0 <= info["projection_iterations"]["mean"] <= 3.0
    # negative control: without the carried state (and target) the restart is a different
    # (round-off) run
    c = wh.integrate(wh.integrate(y0, 0.05, 120)[-1], 0.05, 180)
    assert not np.array_equal(c[-1], whole[-1])


def test_bad_input_and_collisions_are_errors(mild):
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "saba2", nbody=nbody)
    with pytest.raises(InputError, match="shape \\(18,\\)"):
        wh.integrate(y0[:-1], 0.1, 3)
    with pytest.raises(InputError, match="finite nonzero"):
        wh.integrate(y0, 0.0, 3)
    with pytest.raises(InputError, match="steps"):
        wh.integrate(y0, 0.1, -1)
    y = y0.copy()
    y[6:9] = y[3:6]                     # two planets at the same place: not a state of H
    with pytest.raises(InputError, match="same place"):
        wh.integrate(y, 0.1, 5)
    y = y0.copy()
    y[10] = np.nan                      # the non-finite entry is named
    with pytest.raises(InputError, match=f"non-finite entry: {wh.STATE_NAMES[10]} = nan"):
        wh.integrate(y, 0.1, 5)


def test_outer_solar_system_with_the_corrector():
    """Numerical, the built-in scene: sbab4 with the corrector at h = 180 days over 2·10⁴ days
    against DOP853 (rtol 1e-13): the corrector gains ≥ 100× at this step."""
    sc = mg.load_scene("outer-solar-system")
    y0 = np.array(sc.y0)
    ref = reference(sc.system, y0, 2.0e4)
    corr = W.wisdom_holman(sc, "sbab4")
    plain = W.wisdom_holman(sc, "sbab4", corrector=False)
    ec, ep = error(corr, y0, ref, 2.0e4, 111), error(plain, y0, ref, 2.0e4, 111)
    assert ec < 1e-9 and ep > 100 * ec, (ec, ep)


# --- resolution, parameters, the command line, the bench ---------------------------------------------

def test_a_step_beyond_the_resolution_limit_is_refused(mild):
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "sbab3", nbody=nbody)
    P = float(np.min(wh.periods(y0)))
    with pytest.raises(W.ResolutionError, match="shortest Kepler period") as err:
        wh.integrate(y0, 0.2 * P, 3)
    assert err.value.step == 0 and np.array_equal(err.value.trajectory, y0[None])
    # negative control: just inside the limit it runs, and check_resolution=False runs it anyway
    assert wh.integrate(y0, 0.12 * P, 3).shape == (4, 18)
    assert wh.integrate(y0, 0.2 * P, 3, check_resolution=False).shape == (4, 18)


def test_parameters_are_the_integrators_constants(mild):
    system, nbody, y0 = mild
    heavy = W.wisdom_holman(system, "saba2", nbody=nbody, params={"m1": 2e-3})
    assert heavy.masses[1] == 2e-3 and heavy.certificate["hamiltonian"] == "symbolic"
    base = W.wisdom_holman(system, "saba2", nbody=nbody)
    assert not np.array_equal(heavy.integrate(y0, 0.1, 5)[-1], base.integrate(y0, 0.1, 5)[-1])
    with pytest.raises(InputError, match="built for the parameter values"):
        base.integrate(y0, 0.1, 5, {"m1": 2e-3})
    with pytest.raises(InputError, match="unknown parameter"):
        W.wisdom_holman(system, "saba2", nbody=nbody, params={"mass": 1.0})
    with pytest.raises(MethodNotApplicable, match="positive and finite"):
        W.wisdom_holman(system, "saba2", nbody=nbody, params={"m1": -1.0})


def test_cli_run(capsys, tmp_path):
    from helpers import cli_main, one_line, strict_json

    code, out, err = cli_main(capsys, "run", "outer-solar-system", "--method", "sbab4", "--h", "180",
                              "--steps", "200", "--json")
    assert code == 0, err
    rep = strict_json(out)
    assert rep["method"] == "sbab4" and rep["steps_done"] == 200
    inv = rep["invariants"]
    assert inv["Px"]["claim"] == "exact" and inv["H"]["claim"] == "approximate"
    assert inv["Lz"]["max_rel_error"] < 1e-13 and inv["H"]["max_rel_error"] < 1e-9
    # chunked and saved: the same final state
    code, out, err = cli_main(capsys, "run", "outer-solar-system", "--method", "sbab4", "--h", "180",
                              "--steps", "200", "--chunk", "30", "--save", tmp_path / "t.npz", "--json")
    assert code == 0 and strict_json(out)["y_final"] == rep["y_final"]
    for argv, want, status in [
        (("--method", "sbab4", "--h", "900", "--steps", "3"), "pass --no-check-resolution", 3),
        (("--method", "sbab4", "--order", "4"), "--order does not apply", 2),
        (("--method", "saba9"), "unknown method 'saba9'", 2),
        (("--method", "saba2", "--param", "m1=-1"), "positive and finite", 2),
    ]:
        code, out, err = cli_main(capsys, "run", "outer-solar-system", *argv)
        assert code == status and want in one_line(err), err
    code, out, err = cli_main(capsys, "run", "henon-heiles", "--method", "sbab4")
    assert code == 2 and "declares no [nbody] table" in one_line(err)


def test_bench_rows(tmp_path):
    """bench --peers' Wisdom–Holman rows on a star with two planets (quick ladder), timed for the end
    state, their errors from a run keeping every step; none about a fixed centre."""
    from methodgen.app import bench
    from methodgen.codegen.build import build
    from methodgen.symbolic.scene import load_scene

    scene, y0 = star_scene(tmp_path)
    base = build(scene.system, "stormer-verlet", path=tmp_path / "sv.py")
    ref = bench.reference(scene.system, y0, 2.0)
    notes = []
    rows = bench._wisdom_holman_rows(scene, y0, 2.0, ref, None, base, True, notes)
    assert {r["base_method"] for r in rows} == set(bench.WH_PEER_FAMILIES)
    assert all(n.startswith("--quick: the Wisdom–Holman families run at") for n in notes) and notes
    for r in rows:
        assert r["kind"] == "methodgen" and r["seconds"] >= 0 and math.isfinite(r["error"])
        assert r["h"] <= W.MAX_STEP_FRACTION * 2 * math.pi * 1.5 ** 1.5
    best = min(r["error"] for r in rows if r["base_method"] == "sbab4")
    worst = min(r["error"] for r in rows if r["base_method"] == "wisdom-holman")
    assert best < worst / 100                                  # the corrected high-order family pays
    assert bench._wisdom_holman_rows(load_scene("kepler"), np.array(load_scene("kepler").y0), 1.0, ref,
                                     None, base, True, notes) == []


def test_cli_verify(capsys, monkeypatch):
    from helpers import cli_main, one_line, strict_json

    code, out, err = cli_main(capsys, "verify", "outer-solar-system", "--method", "sbab4", "--json")
    assert code == 0, err
    rep = strict_json(out)
    kinds = {c["claim"].split(":")[0]: (c["status"], c["kind"]) for c in rep["certificates"]}
    assert kinds["H is the [nbody] Hamiltonian"] == ("proved", "exact")
    assert ("proved", "numerical") in kinds.values() and ("not claimed", "argument") in kinds.values()
    code, out, err = cli_main(capsys, "verify", "outer-solar-system", "--method", "sbab4", "--order", "4")
    assert code == 2 and "--order does not apply" in one_line(err)
    # negative control: a splitting whose order condition fails is reported refuted (exit 1)
    real = S.numerical_certificate

    def broken(s):
        c = real(s)
        return dict(c, epsilon_order=c["epsilon_order"] - 1)

    monkeypatch.setattr(W, "numerical_certificate", broken)
    code, out, err = cli_main(capsys, "verify", "outer-solar-system", "--method", "sbab4")
    assert code == 1 and "[refuted, numerical] ε-order 8" in out


def test_compensated_summation_removes_the_roundoff_floor():
    """Numerical: outer solar system, sbab4 at h = 65 days over 2·10⁵ days against heyoka in long
    double: below 5e-12 AU with compensated sums (the splitting's ε² h⁴ error there is ~1.5e-12);
    negative control: plain sums end ≥ 3× farther off (their rounding accumulates over the 3077
    steps).  Chunks carry the compensations: a run in pieces with info is the same run bitwise."""
    pytest.importorskip("heyoka")
    from methodgen.app import peers

    sc = mg.load_scene("outer-solar-system")
    y0 = np.array(sc.y0)
    T, steps = 2.0e5, 3077
    ref = peers.heyoka_reference(sc.system, y0, T)
    wh = W.wisdom_holman(sc, "sbab4")
    end = wh.integrate(y0, T / steps, steps, save_every=steps)[-1]
    good = np.max(np.abs(end - ref))
    assert good < 5e-12, good
    plain = W.wisdom_holman(sc, "sbab4", compensated=False)
    bad = np.max(np.abs(plain.integrate(y0, T / steps, steps, save_every=steps)[-1] - ref))
    assert bad > 3 * good, (good, bad)
    info = {}
    y = wh.integrate(y0, T / steps, 1000, save_every=1000, info=info)[-1]
    y = wh.integrate(y, T / steps, steps - 1000, save_every=steps - 1000, info=info)[-1]
    assert np.array_equal(y, end)


def test_a_scene_of_splittings(capsys, tmp_path):
    """A scene file whose [run] method is a splitting: run and verify take it; methods lists them."""
    from helpers import cli_main, strict_json

    from methodgen.symbolic.scene import builtin_scene_dir

    text = (builtin_scene_dir() / "outer-solar-system.toml").read_text()
    text = text.replace('method = ["energy-momentum", "stormer-verlet"]', 'method = "sbab3"')
    text = text.replace('name = "outer-solar-system"', 'name = "oss-splitting"')
    path = tmp_path / "oss.toml"
    path.write_text(text)
    code, out, err = cli_main(capsys, "run", path, "--h", "135", "--steps", "50", "--json")
    assert code == 0 and strict_json(out)["method"] == "sbab3", err
    code, out, err = cli_main(capsys, "verify", path, "--json")
    assert code == 0 and strict_json(out)["method"] == "sbab3-corrected", err
    code, out, err = cli_main(capsys, "methods", "--json")
    assert "sbab4" in strict_json(out)["nbody"]["splittings"]


def test_a_close_encounter_stops_the_run(mild):
    """Two planets 0.005 apart: the first kick changes a Jacobi momentum by far more than MAX_KICK,
    so the run stops (ResolutionError, step 1, the rows so far); check_resolution=False runs it
    (negative control), and a run without the encounter never comes near the limit."""
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "sbab3", nbody=nbody)
    y = y0.copy()
    y[6:9] = y[3:6] + np.array([0.005, 0.0, 0.0])
    with pytest.raises(W.ResolutionError, match="close encounter at step 1") as err:
        wh.integrate(y, 0.05, 10)
    assert err.value.step == 1 and len(err.value.trajectory) == 1 and err.value.body in (1, 2)
    assert np.all(np.isfinite(wh.integrate(y, 0.05, 10, check_resolution=False)))
    info = {}
    wh.integrate(y0, 0.05, 400, info=info)
    assert 0 < info["peak_kick"] < W.MAX_KICK / 10


@pytest.mark.parametrize("e, t", [(1.5, 50.0), (1.5, -50.0), (3.0, 500.0)])
def test_long_hyperbolic_drift(e, t):
    """Numerical: a long drift on a hyperbolic orbit starts from the logarithmic estimate (from the
    Taylor value the solve walked a few units per iteration until cosh overflowed)."""
    mu, rp = 1.0, 0.5
    r0 = np.array([rp, 0.0, 0.0])
    v0 = np.array([0.0, 0.8, 0.6]) * math.sqrt(mu * (1 + e) / rp)
    qj, pj = r0[None].copy(), v0[None].copy()
    cq, cp = np.zeros_like(qj), np.zeros_like(pj)
    assert 0 < kf.kepler_drift(qj, pj, cq, cp, 0, 1.0, mu, t) <= 6
    rw, vw = kepler_solution(r0, v0, mu, t)
    assert np.max(np.abs(qj[0] - cq[0] - rw)) < 1e-14 * np.max(np.abs(rw))
    assert np.max(np.abs(pj[0] - cp[0] - vw)) < 1e-14 * np.max(np.abs(vw))


def test_fixed_centre_claims_angular_momentum_only(capsys):
    """About a fixed centre the total momentum is not a first integral: not claimed (run --json's
    Px is "monitored"), and verify's argument names the angular momentum about the centre."""
    from helpers import cli_main, strict_json

    code, out, err = cli_main(capsys, "run", "kepler", "--method", "saba2", "--h", "0.5", "--steps", "20", "--json")
    assert code == 0, err
    inv = strict_json(out)["invariants"]
    assert inv["Lz"]["claim"] == "exact" and inv["Px"]["claim"] == "monitored"
    assert inv["Lx"]["max_abs_error"] < 1e-14 and inv["Py"]["max_abs_error"] > 0.1   # P really changes
    code, out, err = cli_main(capsys, "verify", "kepler", "--method", "saba2")
    assert code == 0 and "angular momentum about the centre kept" in out and "total linear" not in out


def test_singular_initial_states_are_input_errors(mild):
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "saba2", nbody=nbody)
    y = y0.copy()
    y[6:9] = y[3:6]
    with pytest.raises(InputError, match="bodies 1 and 2 at the same place"):
        wh.integrate(y, 0.1, 3)
    y = y0.copy()
    y[3:6] = y[0:3]                 # planet 1 on the star: the centre of mass of body 0
    with pytest.raises(InputError, match="same place"):
        wh.integrate(y, 0.1, 3)
    sc = mg.load_scene("kepler")
    with pytest.raises(InputError, match="at the fixed centre"):
        W.wisdom_holman(sc, "saba2").integrate(np.array([0, 0, 0, 0, 1.0, 0]), 0.1, 3)
    # a body at the centre of mass of the inner ones (distinct from them)
    m = wh.masses
    y = y0.copy()
    y[6:9] = (m[0] * y[0:3] + m[1] * y[3:6]) / (m[0] + m[1])
    with pytest.raises(InputError, match="centre of mass of bodies 0…1"):
        wh.integrate(y, 0.1, 3)


def test_a_planet_at_rest_is_not_an_encounter(mild):
    """The kick size is relative to the larger of |p'| and a circular orbit's momentum: a planet
    released from rest far from the other one runs (it used to stop at step 1)."""
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "sbab3", nbody=nbody)
    y = y0.copy()
    y[6:9] = [0.0, 3.0, 0.0]
    y[15:18] = 0.0
    Y = wh.integrate(y, 0.02, 50)
    assert np.all(np.isfinite(Y))


def test_steps_zero_and_chunks_with_a_remainder(mild):
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "sbab4", nbody=nbody)
    assert np.array_equal(wh.integrate(y0, 0.05, 0), y0[None])
    whole = wh.integrate(y0, -0.05, 30, save_every=3)
    info = {}
    a = wh.integrate(y0, -0.05, 10, save_every=3, info=info)
    b = wh.integrate(a[-1], -0.05, 20, save_every=3, info=info)
    assert np.array_equal(b[-1], whole[-1])


def test_kepler_drift_random_cases():
    """Numerical: 60 random drifts (e in [0, 0.95] and hyperbolic e in [1.05, 3], random phase and
    direction, |t| up to two periods or 20 time units) against Kepler's equation at 40 digits: the
    position and velocity to 1e-13 of their size, in at most 6 iterations (the solve stops after a
    Laguerre–Conway step below 1e-7 |s|, whose cubic convergence leaves ~1e-21 |s|)."""
    rng = np.random.default_rng(11)
    worst = 0.0
    for k in range(60):
        e = rng.uniform(0.0, 0.95) if k % 3 else rng.uniform(1.05, 3.0)
        rp = rng.uniform(0.2, 2.0)
        vp = math.sqrt((1 + e) / rp)
        ang = rng.uniform(0, 2 * math.pi)
        r0 = rp * np.array([math.cos(ang), math.sin(ang), 0.0])
        v0 = vp * np.array([-math.sin(ang), math.cos(ang), 0.0])
        # start somewhere along the orbit: the exact state after a random time
        t0 = rng.uniform(-3.0, 3.0)
        ra, va = kepler_solution(r0, v0, 1.0, t0)
        span = 2 * 2 * math.pi * (rp / (1 - e)) ** 1.5 if e < 1 else 20.0
        t = rng.uniform(-span, span)
        qj, pj = ra[None].copy(), (2.0 * va)[None].copy()
        cq, cp = np.zeros_like(qj), np.zeros_like(pj)
        it = kf.kepler_drift(qj, pj, cq, cp, 0, 2.0, 1.0, t)
        assert 0 < it <= 6, (e, t, it)
        rw, vw = kepler_solution(r0, v0, 1.0, t0 + t)
        dq = np.max(np.abs(qj[0] - cq[0] - rw)) / np.max(np.abs(rw))
        dv = np.max(np.abs((pj[0] - cp[0]) / 2.0 - vw)) / np.max(np.abs(vw))
        worst = max(worst, dq, dv)
    assert worst < 1e-13, worst


def test_splitting_names_elsewhere_say_where_they_belong(capsys, tmp_path):
    from helpers import cli_main, one_line

    with pytest.raises(InputError, match="is a Wisdom–Holman splitting of \\[nbody\\] scenes"):
        mg.discretize(mg.load_scene("outer-solar-system").system, "sbab4")
    code, out, err = cli_main(capsys, "bench", "outer-solar-system", "--methods", "sbab4", "--quick")
    assert code == 2 and "benchmarked by --peers" in one_line(err)


def test_without_llvmlite_the_runtime_runs_as_python_bitwise(tmp_path):
    """In a process where llvmlite cannot be imported the runtime runs as Python (a RuntimeWarning
    says so) and gives the compiled run's numbers bitwise (no fastmath, the same operations)."""
    import subprocess
    import sys

    script = tmp_path / "nollvm.py"
    script.write_text(
        "import sys\n"
        "sys.modules['llvmlite'] = None\n"
        "import warnings, numpy as np, methodgen as mg\n"
        "sc = mg.load_scene('outer-solar-system')\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    wh = mg.wisdom_holman(sc, 'sbab3')\n"
        "assert any('runs as Python' in str(x.message) for x in w), w\n"
        "assert wh.BACKEND == 'python'\n"
        f"np.save({str(tmp_path / 'y.npy')!r}, wh.integrate(np.array(sc.y0), 135.0, 12))\n"
        "assert 'llvmlite.binding' not in sys.modules\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    sc = mg.load_scene("outer-solar-system")
    Y = W.wisdom_holman(sc, "sbab3").integrate(np.array(sc.y0), 135.0, 12)
    assert kf.compiled() and np.array_equal(np.load(tmp_path / "y.npy"), Y)


def test_a_wisdom_holman_run_needs_no_numba(tmp_path):
    """The runtime is compiled through LLVM IR (methodgen.codegen.llvmkernels): a process where
    any import of numba fails builds and runs Wisdom–Holman splittings (with the projection,
    and the Jacobi map and kicks called from Python).  Control: the block works (an import of
    numba in that process fails)."""
    import subprocess
    import sys

    script = tmp_path / "nonumba.py"
    script.write_text(
        "import sys\n"
        "sys.modules['numba'] = None\n"
        "import numpy as np, methodgen as mg\n"
        "sc = mg.load_scene('outer-solar-system')\n"
        "for project in (None, 'energy-output'):\n"
        "    wh = mg.wisdom_holman(sc, 'sbab3', project=project)\n"
        "    wh.integrate(np.array(sc.y0), 135.0, 5, info={})\n"
        "try:\n"
        "    import numba\n"
        "    blocked = False\n"
        "except ImportError:\n"
        "    blocked = True\n"
        "print(blocked, wh.BACKEND)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "numba"]      # ("numba": the compiled backend's name)


def test_every_entry_compiles_and_is_the_python_functions_bitwise(monkeypatch):
    """Each function Python calls is compiled (the translator refuses nothing of this module: a
    refusal would raise), its machine code cacheable, keyed by this file's and the stepper's
    source (the compensated add it shares); and a run, plain and projected, gives bitwise the
    numbers of the same functions run as Python (``METHODGEN_STEPPER=python``).  Control: the
    Python run really is Python (no compiled entry is used)."""
    from methodgen.codegen import llvmcache, llvmkernels
    from methodgen.runtime import stepper

    entries = [v for v in vars(kf).values() if isinstance(v, kf._Kernel)]
    assert {e.__name__ for e in entries} >= {"to_jacobi", "kick", "potential", "invariants", "_run", "_run_projected"}
    for e in entries:
        assert e.entry() is not None
        assert llvmcache.key(e.py_func, e.sig, kf._kernel_globals(), True, llvmkernels._STATE) is not None
    assert kf._kernel_globals()["compensated_add"] is stepper.compensated_add
    sc = mg.load_scene("outer-solar-system")
    y0 = np.array(sc.y0)
    runs = {}
    for route in ("compiled", "python"):
        if route == "python":
            monkeypatch.setenv("METHODGEN_STEPPER", "python")
            monkeypatch.setattr(kf._Kernel, "entry", lambda self: pytest.fail("a compiled entry on the Python route"))
        runs[route] = [W.wisdom_holman(sc, "saba3", project=p).integrate(y0, 135.0, 6, save_every=2)
                       for p in (None, "energy-standard")]
    assert kf.compiled() is False
    for a, b in zip(runs["compiled"], runs["python"]):
        assert a.tobytes() == b.tobytes()


def test_comparable_masses_are_warned():
    """ε = 0.5 (no dominant body): a RuntimeWarning; ε = 1e-3 (negative control): none."""
    import warnings

    system, nbody, y0 = star_and_planets(0.5)
    with pytest.warns(RuntimeWarning, match="ε = 0.5"):
        W.wisdom_holman(system, "saba2", nbody=nbody)
    # the star listed last: the warning says which body to list first
    from methodgen.app.bench import nbody_system

    last = nbody_system(3, 1.0, [1e-3, 1e-3, 1.0])
    with pytest.warns(RuntimeWarning, match="Body 2 is the heaviest: list it first"):
        W.wisdom_holman(last, "saba2", nbody=NBody(G="G", masses=("m0", "m1", "m2")))
    system, nbody, y0 = star_and_planets(1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        W.wisdom_holman(system, "saba2", nbody=nbody)
