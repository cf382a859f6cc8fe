"""The standard projection (``project="energy-standard"``, methodgen.symbolic.projection): the base step
once, then onto H = H0 -- energy to round-off and the order kept at about the explicit cost,
not symmetric.

Each property has its control: the unprojected base step drifts in H; the symmetric projection
of the same module returns under ``-h`` where this one does not; the base step's evaluations are
counted (once per step here, once per iterate for the symmetric projection).  numpy backend;
``test_numba_agrees`` runs the compiled loop.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from conftest import HH_Y0, hh_error_ratio
from methodgen.errors import InputError, MethodNotApplicable

H = 0.1
EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def std2(hh):
    return mg.build(hh, "stormer-verlet", project="energy-standard")


@pytest.fixture(scope="module")
def sym2(hh):
    return mg.build(hh, "stormer-verlet", project="energy")


def _energy_error(mod, traj):
    Hs = mod.hamiltonian(traj)
    return float(np.max(np.abs(Hs - Hs[0])))


def test_energy_to_roundoff_and_control(std2):
    traj = std2.integrate(HH_Y0, H, 2000)
    assert _energy_error(std2, traj) <= 32 * EPS * 0.125
    base = std2._base_integrate(HH_Y0, H, 2000)
    assert _energy_error(std2, base) > 1e-5      # control: the base step alone


def test_kepler_log_form_energy_within_a_few_ulps_and_control(kepler):
    """The standard projection iterates to 1 eps of g's size (an iterate costs g and G only):
    Kepler's physical H on the log form, e = 0.6 from pericentre (|T| + |U| = 4.5 there against
    |H| = 0.5), stays within 8e-15 relative over 4000 steps (measured 4.9e-15).  Control: the
    same module stopped at Newton's 4 eps leaves 1.5e-14."""
    mod = mg.build(mg.time_transform(kepler, form="log"), "stormer-verlet",
                   project="energy-standard")
    e = 0.6
    v0 = np.sqrt((1 + e) / (1 - e))
    y0 = mod.initial_state(np.array([1 - e, 0.0, 0.0, 0.0, 0.8 * v0, 0.6 * v0]))

    def rel_energy_error():
        y, _ = mod.physical_state(mod.integrate(y0, 2 * np.pi / 13, 4000))
        E = 0.5 * np.sum(y[:, 3:] ** 2, axis=1) - 1 / np.sqrt(np.sum(y[:, :3] ** 2, axis=1))
        return float(np.max(np.abs(E - E[0])) / abs(E[0]))

    assert mod._PROJ_TOL == EPS
    assert rel_energy_error() <= 8e-15
    mod._PROJ_TOL = 4 * EPS          # the module object may be shared (build's cache)
    try:
        assert rel_energy_error() > 1e-14
    finally:
        mod._PROJ_TOL = EPS


def test_not_symmetric_and_control(std2, sym2):
    """One step forward, one back: the standard projection does not return (its defect is
    O(h^3) here); the symmetric projection of the same base step does, to round-off."""
    y1 = std2.integrate(HH_Y0, H, 1)[-1]
    assert np.max(np.abs(std2.integrate(y1, -H, 1)[-1] - HH_Y0)) > 1e-9
    y1 = sym2.integrate(HH_Y0, H, 1)[-1]
    assert np.max(np.abs(sym2.integrate(y1, -H, 1)[-1] - HH_Y0)) <= 1e-15


def test_the_base_step_is_evaluated_once_per_step(std2, sym2):
    """What makes it cheap: Φ_h once per step, the iterations on g alone.  Control: the
    symmetric projection evaluates Φ_h at every iterate (as many times as its iterations)."""
    for mod, once in ((std2, True), (sym2, False)):
        calls = []
        flow = mod._base_flow

        def counted(*a, _flow=flow):
            calls.append(1)
            return _flow(*a)

        mod._base_flow = counted
        try:
            info = {}
            mod.integrate(HH_Y0, H, 100, info=info)
        finally:
            mod._base_flow = flow
        its = info["newton_iterations"]
        if once:
            assert len(calls) == 100 and its.max() >= 2
        else:
            assert len(calls) == int(its.sum()) > 100


def test_order_control(hh, hh_reference):
    """Control of the order test (tests/test_projection.py::test_order_kept, which runs this
    projection too): the order-2 step's ratio is 4, not the order-4 step's 16."""
    mod = mg.build(hh, "stormer-verlet", order=2, project="energy-standard")
    errs, ratio = hh_error_ratio(mod, (0.2, 0.1), hh_reference)
    assert 3.0 < ratio < 5.0 and not 12.0 < ratio < 20.0, (errs, ratio)


def test_chunks_equal_one_piece(std2):
    one = std2.integrate(HH_Y0, H, 60)
    info = {}
    a = std2.integrate(HH_Y0, H, 25, info=info)
    b = std2.integrate(a[-1], H, 35, info=info)
    assert np.array_equal(np.vstack([a, b[1:]]), one)


def test_numba_agrees(hh, std2):
    pytest.importorskip("llvmlite")
    nb = mg.build(hh, "stormer-verlet", project="energy-standard", backend="numba")
    a = nb.integrate(HH_Y0, H, 300)
    b = std2.integrate(HH_Y0, H, 300)
    assert np.max(np.abs(a - b)) <= 1e-12
    assert _energy_error(nb, a) <= 32 * EPS * 0.125
    assert nb.TRAITS["symmetric"] is False
    # its failure names it (not the symmetric projection)
    with pytest.raises(nb.ConvergenceError, match="the standard projection's solve did not converge"):
        nb.integrate(HH_Y0, H, 5, maxiter=1)


def test_key_traits_and_bad_value(hh):
    s = mg.discretize(hh, "stormer-verlet", order=4, project="energy-standard")
    assert s.key == "stormer-verlet-projectenergy-standard-order4-suzuki" and s.projection == ("H",)
    t = s.traits
    assert (t.order, t.symmetric, t.symplectic, t.energy_preserving) == (4, False, False, True)
    assert any("standard projection" in n for n in t.notes)
    with pytest.raises(InputError, match="energy-standard"):
        mg.discretize(hh, "stormer-verlet", project="energy-standrd")
    with pytest.raises(MethodNotApplicable, match="standard projection wraps a symmetric explicit method"):
        mg.discretize(hh, "midpoint", project="energy-standard")


def test_verify_certificates(hh):
    from methodgen.symbolic.verify.report import NUMERICAL

    s = mg.discretize(hh, "stormer-verlet", project="energy-standard")
    rep = mg.verify(s)
    assert rep.ok
    own = [c for c in rep.certificates if not c.claim.startswith("unprojected step:")]
    inv = [c for c in own if "projected invariants kept: H" in c.claim]
    assert len(inv) == 1 and inv[0].status == NUMERICAL and inv[0].details["invariant_change"] < 1e-40
    # no symmetry claim: the measured defect of the 60-digit step is far above round-off
    assert not any("projected step is symmetric" in c.claim for c in own)
    assert inv[0].details["symmetry_defect"] > 1e-8


def test_verify_decides_at_a_strong_force():
    """Three particles with 1/(q_i - q_j)² pair forces (Calogero–Moser, confined): at verify's
    start points the standard projection's λ is large (symmetry defect ~0.08 at h = 1/10), where
    a plain fixed-point iteration for y1 = ŷ1 + D(y1)λ diverged and verify said "undecided";
    solved by Newton it decides (the invariant to 60 digits).  The symmetric projection of the
    same base is decided too, and symmetric (control of the defect's size)."""
    from methodgen.symbolic.verify.report import NUMERICAL

    cm = mg.Hamiltonian("(p1**2 + p2**2 + p3**2)/2 + w**2*(q1**2 + q2**2 + q3**2)/2"
                        " + g**2*(1/(q1 - q2)**2 + 1/(q1 - q3)**2 + 1/(q2 - q3)**2)",
                        q=["q1", "q2", "q3"], p=["p1", "p2", "p3"], params={"w": 1.0, "g": 0.5},
                        name="calogero3")
    defects = {}
    for project in ("energy-standard", "energy"):
        rep = mg.verify(mg.discretize(cm, "stormer-verlet", order=4, project=project))
        inv = [c for c in rep.certificates
               if "projected invariants kept: H" in c.claim and not c.claim.startswith("unprojected")]
        assert rep.ok and len(inv) == 1 and inv[0].status == NUMERICAL, [c.status for c in inv]
        assert inv[0].details["invariant_change"] < 1e-40
        defects[project] = inv[0].details["symmetry_defect"]
    assert defects["energy-standard"] > 1e-3 and defects["energy"] < 1e-40, defects
