"""Composed Störmer–Verlet with merged kicks (``ModuleIR.merged_kicks``).

Every stage of a composed first-same-as-last Störmer–Verlet step is called at y + D, D the
composed step's increment so far (started from the compensation), with the kick b_{k-1} + a_k
merged and no closing kick; y + D is summed once per composed step (Kahan).  What is checked:
every route gives the same bits (the compiled stepper, the stepper as Python, the lock-step
loop of a batch, the numpy module's batch loop; its one-trajectory loop to round-off: its
scalar kernels print x² as x**2), a run in chunks is the run in one piece, the arithmetic is
the composed method's (against a long-double run of the unmerged stages; control: the same
comparison sees closing kicks 1e-6 off), a resolution failure names the same step and
stage on every route, and which modules take the merged stages.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg

pytest.importorskip("numba")


def _mode(monkeypatch, fused):
    monkeypatch.setenv("METHODGEN_STEPPER", "" if fused else "python")


@pytest.fixture(scope="module")
def hh():
    scene = mg.load_scene("henon-heiles-2d")
    return (mg.build(scene.system, "stormer-verlet", backend="numba", order=10),
            mg.build(scene.system, "stormer-verlet", backend="numpy", order=10),
            np.array(scene.y0, float))


def test_every_route_gives_the_same_bits(hh, monkeypatch):
    mod, num, y0 = hh
    from methodgen.runtime import fused as fz, nbabi

    h = 0.2
    Y0 = np.array([y0 * (1 + 1e-3 * i) for i in range(17)])
    assert len(Y0) >= nbabi.MIN_BATCH
    lockstep = []
    real = fz.run_lockstep
    monkeypatch.setattr(fz, "run_lockstep", lambda *a, **k: lockstep.append(1) or real(*a, **k))
    for chk in (False, True):
        for comp in (True, False):
            runs = {}
            for fused in (True, False):
                _mode(monkeypatch, fused)
                info = {}
                one = mod.integrate(y0, h, 60, check_resolution=chk, compensated=comp, info=info)
                batch = mod.integrate(Y0, h, 25, check_resolution=chk, compensated=comp)
                i2 = {}
                first = mod.integrate(y0, h, 23, check_resolution=chk, compensated=comp, info=i2)
                second = mod.integrate(first[-1], h, 37, check_resolution=chk, compensated=comp, info=i2)
                runs[fused] = (one, info["compensation"], batch, np.concatenate([first, second[1:]]),
                               i2["compensation"])
            for a, b in zip(runs[True], runs[False]):
                assert np.array_equal(a, b)
            one, c1, batch, chunked, c2 = runs[True]
            assert np.array_equal(one, chunked) and np.array_equal(c1, c2)
            assert np.array_equal(batch[:, 0], one[:26])
            assert np.array_equal(batch[:, 5], mod.integrate(Y0[5], h, 25, check_resolution=chk, compensated=comp))
            assert np.array_equal(num.integrate(Y0, h, 25, check_resolution=chk, compensated=comp), batch)
            alone = num.integrate(y0, h, 60, check_resolution=chk, compensated=comp)
            assert np.abs(alone - one).max() < 1e-14
            if not comp:
                assert not c1.any()        # (compensated=False: the compensation as it came)
    assert lockstep


def _reference(mod, y0, h, steps, kick_b=1.0):
    """The composition of Störmer–Verlet stages (kick a_k, drift d_k, kick b_k, unmerged) in
    long double on Hénon–Heiles.  ``kick_b``: a factor on the closing kicks (another method)."""
    L = np.longdouble
    q, p = y0[:2].astype(L), y0[2:].astype(L)
    ka, kd = np.array(mod.KICK_A, dtype=L), np.array(mod.DRIFT, dtype=L)
    kb = np.array(mod.KICK_B, dtype=float) * kick_b
    H = L(repr(h))

    def force(q):
        return np.array([q[0] + 2 * q[0] * q[1], q[1] + q[0] ** 2 - q[1] ** 2])

    out = [np.concatenate([q, p])]
    for _ in range(steps):
        for k in range(len(kd)):
            p = p - H * ka[k] * force(q)
            q = q + H * kd[k] * p
            p = p - H * L(kb[k]) * force(q)
        out.append(np.concatenate([q, p]))
    return np.array(out)


def test_the_merged_stages_are_the_composed_method(hh, monkeypatch):
    mod, num, y0 = hh
    h, steps = 0.2, 200
    ref = _reference(mod, y0, h, steps)
    for m in (mod, num):
        traj = m.integrate(y0, h, steps, check_resolution=False)
        assert np.abs(traj - ref).max() < 1e-13
    # control: the comparison sees a module whose closing kicks are 1e-6 off (what it runs is
    # then the reference with those kicks)
    monkeypatch.setattr(num, "_KICK_B", tuple(np.array(num._KICK_B) * (1 + 1e-6)))
    off = num.integrate(y0, h, steps, check_resolution=False)
    assert np.abs(off - ref).max() > 1e-9
    assert np.abs(off - _reference(mod, y0, h, steps, kick_b=1 + 1e-6)).max() < 1e-13


def test_a_resolution_failure_names_the_same_step_and_stage(monkeypatch):
    scene = mg.load_scene("kepler")
    e = 0.99
    y0 = np.array([1 + e, 0, 0, 0, np.sqrt((1 - e) / (1 + e)), 0])
    seen = []
    for backend, fused in (("numba", True), ("numba", False), ("numpy", True)):
        _mode(monkeypatch, fused)
        mod = mg.build(scene.system, "stormer-verlet", backend=backend, order=8)
        assert mod._MERGED_KICKS
        with pytest.raises(mod.ResolutionError) as info:
            mod.integrate(y0, 0.05, 2000)
        exc = info.value
        assert "of the order-8 composition" in str(exc)
        seen.append((exc.step, str(exc).split("[stage ")[1].split(" ")[0], len(exc.trajectory)))
        # a batch (the lock-step loop for 16 or more) fails at the same step, in the same stage
        with pytest.raises(mod.ResolutionError) as info:
            mod.integrate(np.stack([y0] * 16), 0.05, 2000)
        assert info.value.step == exc.step and str(exc).split("[stage ")[1] in str(info.value)
    assert len(set(seen)) == 1, seen


def test_which_modules_merge_their_kicks():
    hh = mg.load_scene("henon-heiles-2d").system
    kep = mg.load_scene("kepler").system
    assert mg.build(hh, "stormer-verlet", backend="numba", order=4)._MERGED_KICKS
    assert mg.build(kep, "stormer-verlet", backend="numpy", order=6)._MERGED_KICKS
    # the method alone (no composed step), a splitting's stages, an implicit composition, a
    # projected one: the stages as they were
    for mod in (mg.build(hh, "stormer-verlet", backend="numba"),
                mg.build(hh, "stormer-verlet", backend="numba", order=4, composition="blanes-moan"),
                mg.build(hh, "energy-momentum", backend="numba", order=4),
                mg.build(hh, "stormer-verlet", backend="numba", order=4, project="energy-standard")):
        assert not mod._MERGED_KICKS
