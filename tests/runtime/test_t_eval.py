"""``integrate(..., t_eval=times)``: the states at chosen times (issue 16, item 3).

The times must lie on the step grid (an interpolant would not keep the invariants); each
returned row must be *bitwise* that row of the run in one piece, on both backends, for
single trajectories and batches, because every segment continues from the last with its
compensation and solver state.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg

CASES = [("kepler", "energy-momentum"), ("henon-heiles", "kahan"),
         ("simple-pendulum", "stormer-verlet"), ("pendulum", "rattle")]
IDX = [0, 3, 3, 50, 299, 300]


@pytest.mark.parametrize("scene_name,method", CASES)
def test_rows_are_bitwise_the_full_runs(modules, scene_name, method):
    scene = mg.load_scene(scene_name)
    _, mod = modules(scene.system, method)
    y0 = np.array(scene.y0, dtype=float)
    h = scene.h
    full = mod.integrate(y0, h, 300)
    info = {}
    rows = mod.integrate(y0, h, t_eval=np.array(IDX) * h, info=info)
    np.testing.assert_array_equal(rows, full[IDX])
    assert info["newton_iterations"].shape == (300,)
    d = len(y0) // 2
    Y0 = np.array([y0, y0 * np.r_[np.ones(d), np.full(d, 1.001)]])  # momenta scaled: stays on T*Q
    np.testing.assert_array_equal(mod.integrate(Y0, h, t_eval=np.array(IDX) * h),
                                  mod.integrate(Y0, h, 300)[IDX])


def test_negative_control_segments_without_the_carried_state_differ(modules):
    # Without the compensation carried from segment to segment the rows are not the full
    # run's: the carry is what makes t_eval exact.
    scene = mg.load_scene("kepler")
    _, mod = modules(scene.system, "energy-momentum")
    y0 = np.array(scene.y0, dtype=float)
    full = mod.integrate(y0, scene.h, 300)
    y, naive = y0, [y0]
    for a, b in zip(IDX[:-1], IDX[1:]):
        if b > a:
            y = mod.integrate(y, scene.h, b - a)[-1]
        naive.append(y)
    assert not np.array_equal(np.array(naive), full[IDX])


def test_numba_rows_equal_numpy_rows(pair):
    pytest.importorskip("llvmlite")
    np_mod, nb_mod = pair("kepler", "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0, dtype=float)
    h = mg.load_scene("kepler").h
    full = nb_mod.integrate(y0, h, 300)
    np.testing.assert_array_equal(nb_mod.integrate(y0, h, t_eval=np.array(IDX) * h), full[IDX])


def test_out_steps_and_bad_times(modules):
    scene = mg.load_scene("kepler")
    _, mod = modules(scene.system, "energy-momentum")
    y0 = np.array(scene.y0, dtype=float)
    h = scene.h
    out = np.empty((3, 6))
    res = mod.integrate(y0, h, 20, t_eval=[0.0, 10 * h, 20 * h], out=out)
    assert res is out and np.array_equal(out, mod.integrate(y0, h, 20)[[0, 10, 20]])
    with pytest.raises(ValueError, match=r"t_eval\[1\] = 0.005 is not a multiple of h = 0.01"):
        mod.integrate(y0, 0.01, t_eval=[0.0, 0.005])
    with pytest.raises(ValueError, match="non-decreasing"):
        mod.integrate(y0, h, t_eval=[2 * h, h])
    with pytest.raises(ValueError, match="non-decreasing"):
        mod.integrate(y0, h, t_eval=[-h])
    with pytest.raises(ValueError, match="does not reach"):
        mod.integrate(y0, h, 5, t_eval=[10 * h])
    with pytest.raises(ValueError, match="save_every must be 1 with t_eval"):
        mod.integrate(y0, h, t_eval=[h], save_every=2)
    with pytest.raises(TypeError, match="t_eval must be real numbers"):
        mod.integrate(y0, h, t_eval=[True, False])
    with pytest.raises(TypeError, match="needs steps"):
        mod.integrate(y0, h)


def test_failure_reports_the_global_step_and_the_rows_before(modules):
    # Kepler from pericentre with a step that does not resolve it: the error's step is
    # counted from y0, and .trajectory holds the requested states computed before it.
    scene = mg.load_scene("kepler")
    _, mod = modules(scene.system, "energy-momentum")
    y0 = np.array([1.0, 0, 0, 0, 0, 0])  # radial infall from rest
    with pytest.raises(mod.ResolutionError) as one_piece:
        mod.integrate(y0, 0.01, 300)
    with pytest.raises(mod.ResolutionError) as at:
        mod.integrate(y0, 0.01, t_eval=np.arange(0, 301, 25) * 0.01)
    assert at.value.step == one_piece.value.step
    kept = at.value.trajectory
    assert len(kept) == one_piece.value.step // 25 + 1
    np.testing.assert_array_equal(kept, one_piece.value.trajectory[::25][:len(kept)])
