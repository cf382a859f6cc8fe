"""``integrate(..., save_every=k)``: keep every k-th state (issue 16, item 3).

The rows kept must be *bitwise* the rows of the full run (the stepping is the same, only
the stores are skipped), on both backends, for single trajectories and batches, and with
the last state kept when ``steps`` is not a multiple of k.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg

#: Newton (reduced energy-momentum), linearly implicit, explicit, constrained.
CASES = [("kepler", "energy-momentum"), ("henon-heiles", "kahan"),
         ("simple-pendulum", "stormer-verlet"), ("pendulum", "rattle")]


def _kept(steps, k):
    idx = list(range(0, steps + 1, k))
    if idx[-1] != steps:
        idx.append(steps)
    return idx


def _check(mod, y0, h, steps, k):
    full = mod.integrate(y0, h, steps)
    part = mod.integrate(y0, h, steps, save_every=k)
    np.testing.assert_array_equal(part, full[_kept(steps, k)])
    return full, part


@pytest.mark.parametrize("scene_name,method", CASES)
@pytest.mark.parametrize("steps,k", [(300, 7), (300, 100), (300, 1), (5, 10), (0, 3)])
def test_numpy_rows_are_bitwise_the_full_runs(modules, scene_name, method, steps, k):
    scene = mg.load_scene(scene_name)
    _, mod = modules(scene.system, method)
    y0 = np.array(scene.y0)
    full, part = _check(mod, y0, scene.h, steps, k)
    assert len(part) == len(_kept(steps, k))
    # batches: two rows, the second a little off the first
    Y0 = np.stack([y0, y0 * (1 + 1e-3)])
    if scene_name == "pendulum":
        Y0 = mod.project(Y0)
    _check(mod, Y0, scene.h, steps, k)


def test_composed_and_numba_rows_are_bitwise(modules, pair, tmp_path):
    pytest.importorskip("llvmlite")
    kep = mg.load_scene("kepler")
    mod = mg.build(kep.system, "energy-momentum", tmp_path / "k8.py", order=8)
    _check(mod, np.array(kep.y0), kep.h, 103, 10)
    for scene_name, method in CASES:
        scene = mg.load_scene(scene_name)
        _, nb = pair(scene_name, method)
        y0 = np.array(scene.y0)
        _check(nb, y0, scene.h, 301, 25)
        _check(nb, np.stack([y0, y0]), scene.h, 300, 30)


def test_out_has_the_kept_rows_and_bad_values_are_refused(modules):
    scene = mg.load_scene("kepler")
    _, mod = modules(scene.system, "energy-momentum")
    y0 = np.array(scene.y0)
    out = np.empty((5, 6))            # steps 0, 25, 50, 75, 90
    got = mod.integrate(y0, scene.h, 90, save_every=25, out=out)
    assert got is out
    np.testing.assert_array_equal(out, mod.integrate(y0, scene.h, 90)[[0, 25, 50, 75, 90]])
    with pytest.raises(ValueError, match=r"out must have shape \(5, 6\)"):
        mod.integrate(y0, scene.h, 90, save_every=25, out=np.empty((91, 6)))
    for bad in (0, -2, 1.5, True, "3"):
        with pytest.raises(ValueError, match="save_every must be a positive integer"):
            mod.integrate(y0, scene.h, 10, save_every=bad)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_failure_hands_back_the_kept_rows_before_it(modules, pair, backend):
    """Kepler at e = 0.99 with a step that cannot resolve the pericentre: the local error
    estimate stops the run; the trajectory handed back holds the kept rows up to the
    failing step (here the failure is at step n, so n // k + 1 rows)."""
    if backend == "numba":
        pytest.importorskip("llvmlite")
        _, mod = pair("kepler", "energy-momentum")
    else:
        _, mod = modules(mg.load_scene("kepler").system, "energy-momentum")
    e = 0.99
    y0 = np.array([1 + e, 0, 0, 0, np.sqrt((1 - e) / (1 + e)), 0])
    with pytest.raises(mod.ResolutionError) as full:
        mod.integrate(y0, 0.05, 400)
    with pytest.raises(mod.ResolutionError) as part:
        mod.integrate(y0, 0.05, 400, save_every=9)
    n = full.value.step
    assert part.value.step == n
    np.testing.assert_array_equal(part.value.trajectory, full.value.trajectory[::9][: n // 9 + 1])


def test_run_save_every_writes_the_kept_rows(tmp_path, capsys):
    """``methodgen run --save-every 7 --chunk 100 --save F``: the file holds rows 0, 7, 14, …
    and the last (chunks are rounded up to multiples of 7 so the grid is kept), bitwise the
    rows of one full run of the module."""
    import json

    from methodgen.app import cli
    from methodgen.runtime.runio import load_trajectory

    out = tmp_path / "k.npz"
    code = cli.main(["run", "kepler", "--steps", "1000", "--save-every", "7", "--chunk", "100",
                     "--save", str(out), "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert code == 0 and rep["save_every"] == 7 and rep["steps"] == 1000
    traj, meta = load_trajectory(out)
    assert int(meta["save_every"]) == 7
    scene = mg.load_scene("kepler")
    mod = mg.build(scene.system, "energy-momentum", tmp_path / "k.py")
    full = mod.integrate(np.array(scene.y0), scene.h, 1000)
    np.testing.assert_array_equal(traj, full[_kept(1000, 7)])
    assert rep["y_final"] == full[-1].tolist()
    code = cli.main(["run", "kepler", "--steps", "10", "--save-every", "0"])
    err = capsys.readouterr().err
    assert code == 2 and "--save-every" in err and "Traceback" not in err
