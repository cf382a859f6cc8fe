"""The energy projections of the Wisdom–Holman splittings (``wisdom_holman(..., project=...)``,
methodgen.runtime.kepler_flow.project): states onto the run's H and angular momentum by scaling and
rotating the Jacobi momenta -- every returned state (``"energy-output"``, the run itself the
splitting's) or every step, fed back (``"energy-standard"``).

Numerical checks (double precision runs).  Each property has its control: the unprojected run of
the same splitting drifts in H where the projected one does not, returns under ``-h`` where the
projected one does not, and a perturbed kick loses the order with the projection on too.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg
from methodgen.runtime import nbody as W
from methodgen.symbolic import nbody as S
from methodgen.errors import InputError
from test_wisdom_holman import error, reference, star_and_planets

pytest.importorskip("llvmlite")   # the runtime runs as Python without it: too slow for these runs

EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def mild():
    return star_and_planets(1e-3)


def _drift(wh, Y):
    H, L, P = wh.hamiltonian(Y), wh.angular_momentum(Y), wh.linear_momentum(Y)
    return (float(np.max(np.abs(H - H[0])) / abs(H[0])), float(np.max(np.abs(L - L[0]))),
            float(np.max(np.abs(P - P[0]))))


MODES = ["energy-output", "energy-standard"]


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", ["sbab3", "saba2", "wisdom-holman"])
def test_energy_and_momenta_to_roundoff_and_control(mild, name, mode):
    """Every step: H to a few ulps of |T| + |U| (the projection's own evaluation and the user's
    Cartesian one differ by round-off), L and P to round-off.  Control: the same splitting
    unprojected keeps L and P but not H (above 1e-12 relative here, 100 times the projected)."""
    system, nbody, y0 = mild
    corrected = name != "wisdom-holman"
    proj = W.wisdom_holman(system, name, nbody=nbody, corrector=corrected, project=mode)
    plain = W.wisdom_holman(system, name, nbody=nbody, corrector=corrected)
    dH, dL, dP = _drift(proj, proj.integrate(y0, 0.1, 2000))
    assert dH < 2e-14 and dL < 1e-14 and dP < 1e-15, (dH, dL, dP)
    dH0, dL0, dP0 = _drift(plain, plain.integrate(y0, 0.1, 2000))
    assert dH0 > max(1e-12, 100 * dH) and dL0 < 1e-14 and dP0 < 1e-15, (dH0, dL0, dP0)


@pytest.mark.parametrize("mode", MODES)
def test_order_kept_and_control(mode):
    """ε = 1e-2, saba4 with the corrector (error ε² h⁴, tests/test_wisdom_holman.py): projected,
    the order under halving h is still 4.  Control: a kick weight moved by 1e-3 (and another
    back) is not, with the projection on as well."""
    import dataclasses

    import mpmath as mp

    system, nbody, y0 = star_and_planets(1e-2)
    ref = reference(system, y0, 2.0)
    wh = W.wisdom_holman(system, "saba4", nbody=nbody, project=mode)
    e1, e2 = error(wh, y0, ref, 2.0, 8), error(wh, y0, ref, 2.0, 16)
    assert abs(math.log2(e1 / e2) - 4) < 0.3, (e1, e2)
    s = S.splitting("saba4")
    kicks = list(s.kicks)
    kicks[1] += mp.mpf("1e-3")
    kicks[3] -= mp.mpf("1e-3")
    bad = W.WisdomHolman(system, nbody, dataclasses.replace(s, kicks=tuple(kicks)), True, wh.certificate,
                         project=mode)
    b1, b2 = error(bad, y0, ref, 2.0, 8), error(bad, y0, ref, 2.0, 16)
    assert math.log2(b1 / b2) < 3, (b1, b2)


@pytest.mark.parametrize("mode", MODES)
def test_not_symmetric_and_control(mild, mode):
    """A step h then −h: the projected splitting misses y0 (the projection is not symmetric;
    "energy-output" starts the step back from a projected state); control: the unprojected one
    returns to round-off."""
    system, nbody, y0 = mild
    proj = W.wisdom_holman(system, "sbab3", nbody=nbody, project=mode)
    plain = W.wisdom_holman(system, "sbab3", nbody=nbody)
    miss = np.max(np.abs(proj.step(proj.step(y0, 0.3), -0.3) - y0))
    assert miss > 1e-13, miss
    assert np.max(np.abs(plain.step(plain.step(y0, 0.3), -0.3) - y0)) < 1e-14


def test_one_jacobi_body_and_a_fixed_centre(mild):
    """Degenerate rotations: a star and one planet (one moved Jacobi body: its inertia tensor is
    singular along its radius), and the kepler scene (one body about a fixed centre, the exact
    flow): finite, H and L kept."""
    system, nbody, y0 = star_and_planets(1e-3, n_planets=1)
    wh = W.wisdom_holman(system, "sbab3", nbody=nbody, project="energy-standard")
    Y = wh.integrate(y0, 0.1, 500)
    dH, dL, dP = _drift(wh, Y)
    assert np.all(np.isfinite(Y)) and dH < 2e-14 and dL < 1e-14, (dH, dL)
    sc = mg.load_scene("kepler")
    wh = W.wisdom_holman(sc, "sbab3", project="energy-standard")
    Y = wh.integrate(np.array(sc.y0), 0.1, 500)
    H, L = wh.hamiltonian(Y), wh.angular_momentum(Y)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 2e-14 and np.max(np.abs(L - L[0])) < 1e-14


def test_outer_solar_system_output_projection_keeps_the_error():
    """The built-in scene at the frontier's step (h = 135 d, sbab3 with the corrector, 2·10⁴ d)
    against DOP853 (rtol 1e-13): every returned state has H to round-off, and the states are the
    splitting's to within the size of its energy error (the run is not changed).  Control: the
    run fed back ("energy-standard") drifts away from the splitting's states by far more
    (the velocity scaling moves energy between the orbits: their periods drift)."""
    sc = mg.load_scene("outer-solar-system")
    y0 = np.array(sc.y0)
    ref = reference(sc.system, y0, 2.0e4)
    plain = W.wisdom_holman(sc, "sbab3").integrate(y0, 2.0e4 / 148, 148)
    out = W.wisdom_holman(sc, "sbab3", project="energy-output")
    Y = out.integrate(y0, 2.0e4 / 148, 148)
    assert _drift(out, Y)[0] < 1e-14 and _drift(out, plain)[0] > 1e-12
    assert np.max(np.abs(Y - plain)) < 1e-13
    assert np.max(np.abs(Y[-1] - ref)) < 1e-9
    fed = W.wisdom_holman(sc, "sbab3", project="energy-standard").integrate(y0, 2.0e4 / 148, 148)
    assert np.max(np.abs(fed - plain)) > 100 * np.max(np.abs(Y - plain))


def test_traits_errors_and_a_failed_projection(mild):
    system, nbody, y0 = mild
    wh = W.wisdom_holman(system, "sbab3", nbody=nbody, project="energy-standard")
    assert wh.METHOD == "sbab3-corrected-projected"
    assert W.wisdom_holman(system, "sbab3", nbody=nbody, project="energy-output").METHOD \
        == "sbab3-corrected-projected-output"
    assert wh.TRAITS["symplectic"] is False and wh.TRAITS["symmetric"] is False
    assert "H" in wh.TRAITS["preserved"] and wh.TRAITS["approximate"] == ()
    with pytest.raises(InputError, match="valid: None, 'energy-output'.*'energy-standard'"):
        W.wisdom_holman(system, "sbab3", nbody=nbody, project="energy")
    with pytest.raises(InputError, match="maxiter"):
        wh.integrate(y0, 0.1, 3, maxiter=0)
    # one iteration corrects but cannot confirm round-off: a ProjectionError at the first step
    with pytest.raises(W.ProjectionError, match="did not converge at step 1") as exc:
        wh.integrate(y0, 0.1, 3, maxiter=1)
    assert exc.value.step == 1 and exc.value.trajectory.shape == (1, 18) and exc.value.residual > EPS
    # control: the default limit converges on the same steps
    assert np.all(np.isfinite(wh.integrate(y0, 0.1, 3)))


def test_the_solve_does_not_depend_on_the_unit_of_time():
    """The projection's 4×4 matrix mixes an energy (2T) with inertias (m r²): in SI units (a
    Jupiter about the Sun, seconds) they are 16 orders apart, where a cutoff relative to the
    largest entry dropped the energy direction (λ_H = 0).  The scaled solve agrees with
    numpy's on it; control: a direction that moves nothing (zero diagonal) gets 0 and the
    others still solve."""
    from methodgen.runtime import kepler_flow as kf

    m, r, v = 1.9e27, 7.8e11, 1.3e4
    q = np.array([r, 0.0, 0.1 * r])
    p = m * np.array([0.0, v, 0.0])
    A = np.zeros((4, 4))
    A[0, 0] = p @ p / m
    L = np.cross(q, p)
    A[0, 1:] = A[1:, 0] = L
    A[1:, 1:] = m * (q @ q * np.eye(3) - np.outer(q, q)) + m * r * r * 1e-3 * np.eye(3)
    b = np.array([1e25, 1e30, -2e29, 3e28])
    want = np.linalg.solve(A, b)
    x = b.copy()
    kf._solve_sym(A.copy(), x)
    assert np.max(np.abs(x - want) / np.abs(want)) < 1e-8, (x, want)
    B = A.copy()
    B[2, :] = B[:, 2] = 0.0
    x = b.copy()
    kf._solve_sym(B.copy(), x)
    keep = [0, 1, 3]
    assert x[2] == 0.0
    np.testing.assert_allclose(x[keep], np.linalg.solve(B[np.ix_(keep, keep)], b[keep]), rtol=1e-8)


def test_si_units_keep_the_energy():
    """The same star and planets as the tests above, in SI-like units (lengths ×1.5e11, time in
    seconds: G and the masses rescaled so the motion is the same): H kept to round-off."""
    from methodgen.app.bench import nbody_system
    from methodgen.symbolic.scene import NBody

    system, nbody, y0 = star_and_planets(1e-3)
    Lu, Tu, Mu = 1.5e11, 5.0e6, 2.0e30                 # units of length, time, mass
    G = 1.0 * Lu ** 3 / (Mu * Tu ** 2)
    si = nbody_system(3, G, [Mu, 1e-3 * Mu, 1e-3 * Mu], name="star2si")
    n = 3
    y = y0.copy()
    y[:3 * n] *= Lu
    y[3 * n:] *= Mu * Lu / Tu
    wh = W.wisdom_holman(si, "sbab3", nbody=NBody(G="G", masses=("m0", "m1", "m2")), project="energy-output")
    Y = wh.integrate(y, 0.1 * Tu, 500)
    assert _drift(wh, Y)[0] < 2e-14


def test_non_finite_energy_is_a_non_finite_error_and_claims():
    """project() on a row with U = -inf (two bodies at one place) says "not finite" (status 2),
    never converged; and the projected splitting's verify claims drop symmetry and
    symplecticity (not claimed) and claim the energy."""
    from methodgen.runtime import kepler_flow as kf

    q = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    p = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    inv = np.empty(9)
    st, _ = kf.project(q, p.copy(), np.zeros_like(p), p.copy(), np.zeros_like(p), np.zeros(4), -np.inf,
                       np.array([2.0, 0.5]), True, inv, True, 20, False)
    assert st == 2 and np.isnan(inv[8])
    system, nbody, y0 = star_and_planets(1e-3)
    got = {c["claim"]: c["status"] for c in W.claims(W.wisdom_holman(system, "sbab3", nbody=nbody,
                                                                       project="energy-output"))}
    assert got["symmetric"] == got["symplectic"] == "not claimed" and got["energy"] == "proved"
    plain = {c["claim"]: c["status"] for c in W.claims(W.wisdom_holman(system, "sbab3", nbody=nbody))}
    assert plain["symmetric"] == plain["symplectic"] == "proved" and plain["energy"] == "not claimed"
