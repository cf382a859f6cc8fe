"""Symmetric projection (methodgen.symbolic.projection): energy to round-off, symmetry, order kept.

Every property has a negative control: the unprojected base step (``_base_integrate``)
drifts in H; the standard (non-symmetric) projection, built here from the same module's
kernels, does not return under ``-h``; the energy-only projection loses the angular
momentum that the base method (and the projection onto H and L) keeps.  numpy backend
(the compiled stepper runs the same iteration; ``test_numba_agrees`` checks it when numba is
there, and tests/test_stepper.py that the stepper compiled and as Python agree bitwise).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg
from conftest import HH_Y0, hh_error_ratio
from methodgen.errors import InputError, MethodNotApplicable

H = 0.1



@pytest.fixture(scope="module")
def proj2(hh):
    return mg.build(hh, "stormer-verlet", project="energy")


@pytest.fixture(scope="module")
def proj4(hh):
    return mg.build(hh, "stormer-verlet", order=4, project="energy")


def _energy_error(mod, traj):
    Hs = mod.hamiltonian(traj)
    return float(np.max(np.abs(Hs - Hs[0])))


def test_energy_to_roundoff_and_control(proj2):
    traj = proj2.integrate(HH_Y0, H, 2000)
    # H = 1/8: a few ulps of H (its terms are of its size) at every step, no drift
    assert _energy_error(proj2, traj) <= 32 * np.finfo(float).eps * 0.125
    # control: the same base step without the projection has an O(h^2) energy error
    base = proj2._base_integrate(HH_Y0, H, 2000)
    assert _energy_error(proj2, base) > 1e-5


def test_symmetric_to_roundoff(proj2, proj4):
    for mod in (proj2, proj4):
        y1 = mod.integrate(HH_Y0, H, 1)[-1]
        back = mod.integrate(y1, -H, 1)[-1]
        assert np.max(np.abs(back - HH_Y0)) <= 1e-15
        # and over many steps
        yN = mod.integrate(HH_Y0, H, 500)[-1]
        assert np.max(np.abs(mod.integrate(yN, -H, 500)[-1] - HH_Y0)) <= 1e-12


def _standard_projection_step(mod, y, h):
    """Standard projection (HLW06 §IV.4): ŷ1 = Φ_h(y0), y1 = ŷ1 + G(ŷ1)ᵀμ with g(y1) = g(y0),
    μ by Newton on the line -- the non-symmetric counterpart, from the module's kernels."""
    tgt = mod._s_proj(list(y), ())[0]
    yh = mod._base_flow(list(y), [0.0] * mod._DIM, h, ())[0]
    G = mod._s_proj(yh, ())[1:1 + mod._DIM]   # (then w, the metric: 1 here)
    mu = 0.0
    for _ in range(50):
        y1 = [a + g * mu for a, g in zip(yh, G)]
        v = mod._s_proj(y1, ())
        d = (tgt - v[0]) / sum(a * b for a, b in zip(v[1:1 + mod._DIM], G))
        mu += d
        if abs(d) < 1e-18:
            break
    return np.array([a + g * mu for a, g in zip(yh, G)])


def test_standard_projection_is_not_symmetric(proj2):
    """Negative control of the symmetry test: the same check fails for standard projection."""
    y1 = _standard_projection_step(proj2, HH_Y0, H)
    back = _standard_projection_step(proj2, y1, -H)
    assert np.max(np.abs(back - HH_Y0)) > 1e-8
    # while it does keep H (so the difference is the symmetry, not the level set)
    assert abs(proj2.hamiltonian(y1) - 0.125) < 1e-15


@pytest.mark.parametrize("project", ["energy", "energy-standard"])
@pytest.mark.parametrize("order,hs,expect", [(2, (0.1, 0.05), 4.0), (4, (0.2, 0.1), 16.0)])
def test_order_kept(hh, hh_reference, order, hs, expect, project):
    """Both projections keep the base step's order (the standard one: tests/test_standard_projection.py)."""
    mod = mg.build(hh, "stormer-verlet", order=order, project=project)
    errs, ratio = hh_error_ratio(mod, hs, hh_reference)
    # order K: halving h divides the error by 2^K (within 25 %)
    assert 0.75 * expect < ratio < 1.25 * expect, (errs, ratio)


def test_kepler_invariants_projection_keeps_L():
    # planar Kepler, e = 0.6: H and the angular momentum
    kepler = mg.Hamiltonian("(px**2 + py**2)/2 - 1/sqrt(x**2 + y**2)", ["x", "y"], ["px", "py"],
                            name="kepler_planar_projection")
    both = mg.build(kepler, "stormer-verlet", project="invariants")
    energy = mg.build(kepler, "stormer-verlet", project="energy")
    assert both.PROJECTED[0] == "H" and len(both.PROJECTED) >= 2
    assert both.TRAITS["symplectic"] is False and both.TRAITS["symmetric"] is True
    y0 = np.array([0.4, 0.0, 0.0, 2.0])
    t_both = both.integrate(y0, 0.05, 1000)
    t_en = energy.integrate(y0, 0.05, 1000)
    I_both = both.invariants(t_both)
    I_en = energy.invariants(t_en)
    for name in both.PROJECTED:
        assert np.max(np.abs(I_both[name] - I_both[name][0])) <= 1e-13
    # control: the energy-only projection keeps H but not the angular momentum
    L = both.PROJECTED[1]
    assert np.max(np.abs(I_en["H"] - I_en["H"][0])) <= 1e-13
    assert np.max(np.abs(I_en[L] - I_en[L][0])) > 1e-8
    assert "H" in energy.TRAITS["preserved"] and L not in energy.TRAITS["preserved"]


def test_kepler_3d_projection_onto_four_invariants(kepler):
    """H and L_x, L_y, L_z (m = 4: the elimination path of the solve), e = 0.6."""
    mod = mg.build(kepler, "stormer-verlet", project="invariants")
    assert mod.PROJECTED == ("H", "Lx", "Ly", "Lz")
    traj = mod.integrate(np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2]), 0.02, 2000)
    inv = mod.invariants(traj)
    for name in mod.PROJECTED:
        assert np.max(np.abs(inv[name] - inv[name][0])) <= 1e-14, name


def test_chunks_equal_one_piece(proj4):
    whole = proj4.integrate(HH_Y0, H, 300)
    parts = np.concatenate(list(proj4.iterate(HH_Y0, H, 300, chunk=70)))
    assert np.array_equal(whole, parts)


def test_batch_equals_single(proj2):
    Y0 = np.stack([HH_Y0, HH_Y0 * 0.9])
    batch = proj2.integrate(Y0, H, 50)
    for b in range(2):
        assert np.array_equal(batch[:, b], proj2.integrate(Y0[b], H, 50))


def test_not_converged_raises_with_step_and_residual(proj2):
    with pytest.raises(proj2.ConvergenceError) as ei:
        proj2.integrate(HH_Y0, H, 10, maxiter=1)
    exc = ei.value
    assert exc.step == 0 and "symmetric projection" in str(exc) and math.isfinite(exc.residual_norm)
    assert exc.trajectory.shape[0] == 1


def test_bad_input(hh):
    with pytest.raises(InputError, match="project must be one of"):
        mg.discretize(hh, "stormer-verlet", project="orbit")
    with pytest.raises(MethodNotApplicable, match="symmetric explicit"):
        mg.discretize(hh, "midpoint", project="energy")
    mod = mg.build(hh, "stormer-verlet", project="energy")
    with pytest.raises(ValueError, match="t_eval"):
        mod.integrate(HH_Y0, H, t_eval=[0.0, 0.1])


def test_key_and_traits(hh):
    s = mg.discretize(hh, "stormer-verlet", order=4, project="energy")
    assert s.key == "stormer-verlet-projectenergy-order4-suzuki"
    t = s.traits
    assert (t.order, t.symmetric, t.symplectic, t.energy_preserving, t.solve) == (4, True, False, True,
                                                                                   "projection")


def test_numba_agrees(hh):
    pytest.importorskip("llvmlite")
    nb = mg.build(hh, "stormer-verlet", project="energy", backend="numba")
    npy = mg.build(hh, "stormer-verlet", project="energy")
    a = nb.integrate(HH_Y0, H, 200)
    b = npy.integrate(HH_Y0, H, 200)
    assert np.max(np.abs(a - b)) <= 1e-12
    assert _energy_error(nb, a) <= 32 * np.finfo(float).eps * 0.125
    with pytest.raises(nb.ResolutionError):
        nb.integrate(HH_Y0, 1.0, 5)
    with pytest.raises(nb.ConvergenceError, match="symmetric projection"):
        nb.integrate(HH_Y0, H, 5, maxiter=1)


def test_verify_certificates(hh):
    from methodgen.symbolic.verify.projection import projection_certificates
    from methodgen.symbolic.verify.report import NUMERICAL, PROVED, REFUTED, Certificate

    s = mg.discretize(hh, "stormer-verlet-projected", order=4)
    assert s.key == "stormer-verlet-projected-order4-suzuki" and s.projection == ("H",)
    rep = mg.verify(s)
    assert rep.ok
    own = [c for c in rep.certificates if not c.claim.startswith("unprojected step:")]
    sym = [c for c in own if "projected step is symmetric" in c.claim]
    assert len(sym) == 1 and sym[0].status == PROVED and sym[0].details["symmetry_defect"] < 1e-40
    # the kept invariant is an equation the step solves, not an identity reduced to 0: numerical
    # (measured on the 60-digit projected step), never "proved"
    inv = [c for c in own if "projected invariants kept: H" in c.claim]
    assert len(inv) == 1 and inv[0].status == NUMERICAL and "not a proof" in inv[0].method
    assert inv[0].details["invariant_change"] < 1e-40
    # symplecticity is not claimed for the projected method (only for the unprojected step)
    assert not any("symplectic" in c.claim for c in own)
    # control: the projected symmetry follows the base step's certificate -- a refuted one refutes it
    bad = [Certificate(claim="x: the composition is symmetric, Ψ_(-h) ∘ Ψ_h = id", status=REFUTED)]
    sym = [c for c in projection_certificates(s, bad) if "symmetric" in c.claim]
    assert sym and sym[0].status == REFUTED


def test_method_name_runs_like_option(hh):
    a = mg.build(hh, "stormer-verlet-projected", order=4)
    b = mg.build(hh, "stormer-verlet", order=4, project="energy")
    assert a.METHOD == "stormer-verlet-projected" and b.METHOD == "stormer-verlet"
    assert np.array_equal(a.integrate(HH_Y0, H, 20), b.integrate(HH_Y0, H, 20))


def test_unresolved_step_is_refused_and_control(hh):
    """The base step's local error guard holds for the projected step too (h = 1 on
    Hénon–Heiles is not resolved); control: without the guard the run is accepted, and wrong."""
    mod = mg.build(hh, "stormer-verlet", project="energy")
    with pytest.raises(mod.ResolutionError) as ei:
        mod.integrate(HH_Y0, 1.0, 5)
    assert ei.value.step == 0 and ei.value.trajectory.shape[0] == 1
    coarse = mod.integrate(HH_Y0, 1.0, 5, check_resolution=False)[-1]
    fine = mod.integrate(HH_Y0, 0.005, 1000)[-1]
    assert np.max(np.abs(coarse - fine)) > 1e-2


def test_bench_and_run_take_the_method():
    """`methodgen bench` rows of the projected method: its own rows, no fsolve row (which would
    be the unprojected step under its name: the failure seen before the fix), and the solver
    table runs it; `run` labels its iterations as the projection's."""
    from methodgen.app import bench
    from methodgen.app.cli import main

    sc = mg.load_scene("henon-heiles-2d")
    rep = bench.work_precision(sc, ["stormer-verlet-projected"], quick=True)
    rows = [r for r in rep["rows"] if r["method"].startswith("stormer-verlet-projected")]
    assert rows and all(r["kind"] == "methodgen" for r in rows)
    assert all(r["energy_error"] < 1e-14 for r in rows)
    sv = bench.solver_variants(sc, ["stormer-verlet-projected"], steps=20)
    assert sv
    assert main(["run", "henon-heiles-2d", "--method", "stormer-verlet-projected", "--steps", "20"]) == 0


@pytest.mark.slow
def test_numba_several_invariants(kepler):
    """The numba loop with m = 4 (elimination, Broyden over 4 multipliers); fast sibling:
    test_kepler_3d_projection_onto_four_invariants (numpy)."""
    pytest.importorskip("llvmlite")
    y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])
    nb = mg.build(kepler, "stormer-verlet", project="invariants", backend="numba")
    npy = mg.build(kepler, "stormer-verlet", project="invariants")
    a = nb.integrate(y0, 0.02, 2000)
    assert np.max(np.abs(a - npy.integrate(y0, 0.02, 2000))) <= 1e-11
    inv = nb.invariants(a)
    for name in nb.PROJECTED:
        assert np.max(np.abs(inv[name] - inv[name][0])) <= 1e-14, name


def test_sixty_digit_measure_and_control(hh):
    """The 60-digit projected step of the verify certificates: H kept and symmetric to ~1e-55;
    control: the standard projection (no pre-correction of y0) keeps H but is not symmetric,
    and fed to the certificates it refutes the symmetry claim."""
    from methodgen.symbolic.verify import projection as vp
    from methodgen.symbolic.verify.report import REFUTED

    s = mg.discretize(hh, "stormer-verlet", project="energy")
    good = vp.measure(s)
    assert good["invariant_change"] < 1e-50 and good["symmetry_defect"] < 1e-50
    bad = vp.measure(s, symmetric=False)
    assert bad["invariant_change"] < 1e-50 and bad["symmetry_defect"] > 1e-8
    base = mg.verify(s.projected_from).certificates
    orig = vp.measure
    try:
        vp.measure = lambda scheme, **kw: orig(scheme, symmetric=False)
        certs = vp.projection_certificates(s, base)
    finally:
        vp.measure = orig
    assert [c.status for c in certs if "symmetric" in c.claim] == [REFUTED]


def test_projected_splitting_keeps_h_symmetry_order(hh, hh_reference):
    """A splitting family projected (the post kernel's KICK_A, DRIFT, KICK_B per stage): H to
    round-off, symmetric, order 4 kept; control: the unprojected splitting drifts in H."""
    mod = mg.build(hh, "stormer-verlet", order=4, composition="blanes-moan-rkn", project="energy")
    traj = mod.integrate(HH_Y0, H, 2000)
    assert _energy_error(mod, traj) <= 32 * np.finfo(float).eps * 0.125
    assert _energy_error(mod, mod._base_integrate(HH_Y0, H, 2000)) > 1e-11
    yN = mod.integrate(HH_Y0, H, 500)[-1]
    assert np.max(np.abs(mod.integrate(yN, -H, 500)[-1] - HH_Y0)) <= 1e-13
    errs, ratio = hh_error_ratio(mod, (0.2, 0.1), hh_reference)
    assert 12.0 < ratio < 20.0, errs


def test_projected_splitting_certificates(hh):
    """verify names the splitting's symmetry for the projected step (it was left out: the
    filter looked for "composition" in the claim); control: without a symmetry certificate of
    the step the claim is undecided, not omitted."""
    from methodgen.symbolic.verify.projection import projection_certificates
    from methodgen.symbolic.verify.report import NUMERICAL, PROVED, UNDECIDED

    s = mg.discretize(hh, "stormer-verlet", order=4, composition="blanes-moan-rkn", project="energy")
    rep = mg.verify(s)
    own = {c.claim.split(" (")[0]: c for c in rep.certificates if not c.claim.startswith("unprojected step:")}
    assert own["the projected step is symmetric"].status == PROVED
    assert "the splitting is symmetric" in own["the projected step is symmetric"].method
    assert own["projected invariants kept: H at the run's initial level"].status == NUMERICAL
    base = [c for c in mg.verify(s.projected_from).certificates if "splitting is symmetric" not in c.claim]
    sym = [c for c in projection_certificates(s, base) if "symmetric" in c.claim]
    assert [c.status for c in sym] == [UNDECIDED]


def test_cli_extended_is_one_line_exit_2(capsys):
    """`run --extended` with the projected method: exit 2 and one line (was a ValueError
    traceback from integrate(), exit 1); control: the same run without --extended runs."""
    from methodgen.app.cli import main

    argv = ["run", "henon-heiles-2d", "--method", "stormer-verlet-projected", "--steps", "5"]
    assert main(argv + ["--extended"]) == 2
    err = capsys.readouterr().err
    assert "--extended is not available for a projected method" in err and "Traceback" not in err
    assert main(argv) == 0


def test_projected_method_name_takes_a_splitting(hh, capsys):
    """`--method stormer-verlet-projected --composition blanes-moan-rkn` (was refused: 'run
    with method stormer-verlet only'): the same steps as project="energy" on the splitting;
    control: a splitting family on another method is still refused."""
    from methodgen.app.cli import main

    a = mg.build(hh, "stormer-verlet-projected", order=4, composition="blanes-moan-rkn")
    b = mg.build(hh, "stormer-verlet", order=4, composition="blanes-moan-rkn", project="energy")
    assert np.array_equal(a.integrate(HH_Y0, H, 30), b.integrate(HH_Y0, H, 30))
    assert main(["run", "henon-heiles-2d", "--method", "stormer-verlet-projected", "--order", "4",
                 "--composition", "blanes-moan-rkn", "--steps", "20"]) == 0
    with pytest.raises(InputError, match="splitting of H = T \\+ U"):
        mg.discretize(hh, "midpoint", order=4, composition="blanes-moan-rkn")


@pytest.mark.parametrize("y0,what", [([1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "linearly dependent"),   # circular
                                     ([0.5, 0.0, 0.0, 0.3, 0.0, 0.0], "gradient of Lx vanishes")])  # radial
def test_dependent_gradients_refused_at_the_start(kepler, y0, what):
    """Kepler with H, Lx, Ly, Lz from a circular orbit (∇H ∥ ∇Lz) or a radial one (∇Lx = 0): a
    clear ValueError up front (was a ConvergenceError after 50 iterations, residual 1.4e16, or
    'singular matrix', both advising a smaller h, which cannot help); control: the energy-only
    projection runs from the same state, and a generic state runs with all four."""
    mod = mg.build(kepler, "stormer-verlet", project="invariants")
    with pytest.raises(ValueError, match=what):
        mod.integrate(np.array(y0), 0.01, 5)
    energy = mg.build(kepler, "stormer-verlet", project="energy")
    traj = energy.integrate(np.array(y0), 0.01, 5)
    assert np.all(np.isfinite(traj))
    assert np.all(np.isfinite(mod.integrate(np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2]), 0.01, 5)))


def test_sixty_digit_measure_keeps_the_time_budget(kepler):
    """The 60-digit measurement runs under verify's per-claim budget (it ran unbounded: 21 s
    on the outer solar system with 7 invariants): out of time it is undecided, not proved;
    control: with the default budget the same claim is numerical."""
    from methodgen.symbolic.verify.budget import budget_supported
    from methodgen.symbolic.verify.projection import projection_certificates
    from methodgen.symbolic.verify.report import NUMERICAL, UNDECIDED

    if not budget_supported():
        pytest.skip("no SIGALRM budget here")
    s = mg.discretize(kepler, "stormer-verlet", project="invariants")
    short = projection_certificates(s, [], seconds=1e-3)[0]
    assert short.status == UNDECIDED and "time budget" in short.method
    assert projection_certificates(s, [], seconds=60.0)[0].status == NUMERICAL


def test_equilibrium_start_with_vanishing_gradient(proj2):
    """∇H = 0 at the start (the origin of Hénon–Heiles, an equilibrium): the energy projection
    takes one iterate per step and stays exactly there (its residual's scale is 0, not a
    division by 0); control: a state next to it moves and keeps H to round-off."""
    info = {}
    traj = proj2.integrate(np.zeros(4), H, 20, info=info)
    assert np.array_equal(traj, np.zeros((21, 4))) and info["newton_iterations"].max() == 1
    near = proj2.integrate(np.array([1e-3, 0.0, 0.0, 0.0]), H, 20)
    assert np.max(np.abs(near[-1] - near[0])) > 1e-5
    assert _energy_error(proj2, near) <= 4 * np.finfo(float).eps * 5e-7
