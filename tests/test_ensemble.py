"""Lock-step batches of explicit methods on the numba backend (methodgen.nbbatch).

A batch of at least ``nbabi.MIN_BATCH`` trajectories of an explicit method runs in
blocks of ``_BLOCK_LANES`` lanes, stepped together through a vectorised block kernel;
smaller batches and implicit methods keep the one-trajectory runtime.  These tests
check that both paths give *bitwise* the same rows (no fastmath: the block kernel is
the same arithmetic), including a batch that is not a multiple of the block, chunked
runs, ``save_every`` and ``out=``, and that a failing lane is reported with its index
and step.  Each has a negative control showing that the comparison can fail.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.emit import module_filename

pytest.importorskip("numba")

from methodgen import nbabi, nbbatch, nbruntime  # noqa: E402

B = 300  # two full blocks of 128 and a remainder of 44
# (label, order, composition): Störmer–Verlet, a composition of it, a splitting family
CASES = [("sv2", 2, None), ("sv4", 4, None), ("bm-rkn4", 4, "blanes-moan-rkn")]


@pytest.fixture(scope="module")
def modules(tmp_path_factory):
    root = tmp_path_factory.mktemp("ensemble")
    scene = mg.load_scene("kepler")
    out = {}
    for label, order, comp in CASES:
        scheme = mg.discretize(scene.system, "stormer-verlet", order=order, composition=comp)
        out[label] = mg.generate(scheme, root / module_filename(scene.name, f"sv_{label}", "numba"), backend="numba")
    return out


def orbits(n, seed=0):
    """n bound Kepler states near the scene's orbit (e about 0.6, tilted)."""
    rng = np.random.default_rng(seed)
    y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])
    return y0 * (1.0 + 0.05 * rng.standard_normal((n, 6)))


def run(mod, path, *args, **kw):
    """``mod.integrate`` on the lock-step path (``path="block"``) or the one-trajectory one."""
    saved = nbabi.MIN_BATCH
    nbabi.MIN_BATCH = 1 if path == "block" else 1 << 62
    try:
        return mod.integrate(*args, **kw)
    finally:
        nbabi.MIN_BATCH = saved


def test_route_explicit_batches_only(modules):
    """Explicit modules carry a block kernel and take run_block for batches from MIN_BATCH on."""
    cfg = modules["sv2"]._CFG
    assert nbbatch.use_block(cfg, nbabi.MIN_BATCH) and not nbbatch.use_block(cfg, nbabi.MIN_BATCH - 1)
    implicit = cfg.copy()
    implicit[nbruntime.CFG["KIND"]] = 0
    assert not nbbatch.use_block(implicit, 10 ** 6)  # Newton per lane stays on nbruntime.run
    for mod in modules.values():
        assert hasattr(mod, "_py_post_block") and mod._BLOCK_LANES == 128


@pytest.mark.parametrize("label", [c[0] for c in CASES])
def test_block_path_equals_one_trajectory_path_bitwise(modules, label):
    mod = modules[label]
    Y0 = orbits(B)
    info_a, info_b = {}, {}
    a = run(mod, "single", Y0, 0.01, 40, info=info_a)
    b = run(mod, "block", Y0, 0.01, 40, info=info_b)
    assert a.shape == (41, B, 6)
    assert np.array_equal(a, b)  # bitwise, every row and lane (the remainder block too)
    assert np.array_equal(info_a["compensation"], info_b["compensation"])
    # (key, end state, compensation, parameters, ∇U at the end)
    ra, rb = info_a["force"], info_b["force"]
    assert ra[0] == rb[0] and ra[3] == rb[3] and all(np.array_equal(ra[i], rb[i]) for i in (1, 2, 4))
    # not compensated, save_every, out=: the same
    a = run(mod, "single", Y0, 0.01, 40, compensated=False, save_every=7)
    out = np.empty_like(a)
    b = run(mod, "block", Y0, 0.01, 40, compensated=False, save_every=7, out=out)
    assert b is out and np.array_equal(a, b)


def test_bitwise_comparison_detects_a_lane_permutation_and_a_stride_fault(modules, monkeypatch):
    """Negative controls: two lanes of the remainder swapped, or the runtime's lane stride
    disagreeing with the one compiled into the block kernel, are seen by the comparison."""
    mod = modules["sv2"]
    Y0 = orbits(B)
    a = run(mod, "single", Y0, 0.01, 20)
    b = run(mod, "block", Y0, 0.01, 20)
    assert np.array_equal(a, b)
    swapped = b.copy()
    swapped[:, [B - 2, B - 1]] = swapped[:, [B - 1, B - 2]]
    assert not np.array_equal(a, swapped)
    # the runtime's stride 256, the kernel's compiled one 128 (larger, so that the kernel's
    # accesses stay inside the runtime's arrays: numba does not check bounds)
    monkeypatch.setattr(mod, "_BLOCK_LANES", 256)
    c = run(mod, "block", Y0, 0.01, 20, check_resolution=False)
    assert not np.array_equal(a, c)


def _interpreted_block_run(mod, Y0, h, steps):
    """One call of ``run_block`` interpreted (its ``py_func``, the module's block kernel as
    Python): a model of the compiled path in which a fault can be injected."""
    Y = np.array(Y0, dtype=float)
    Bn = Y.shape[0]
    C = np.zeros_like(Y)
    FRC = np.ascontiguousarray(mod._start_force(None, Y, C, np.array([1.0, 1.0])).reshape(Bn, -1))
    traj = np.zeros((steps + 1, Bn, 6))
    traj[0] = Y
    fstat = np.zeros((Bn, 4), dtype=np.int64)
    fval = np.zeros(Bn)
    nbbatch._run_block.py_func(
        mod._py_post_block, mod._nb_hs, nbabi.no_kernel("check"), mod._CFG, mod._FCFG, mod._LERR_INDEX,
        mod._DOMAIN_POSITIVE, mod._STAGE_GAMMAS, mod._STAGE_RATIOS, mod._KICK_A, mod._DRIFT, mod._KICK_B,
        traj, 0, steps, Y, C, FRC, h, np.array([1.0, 1.0]), True, True, fstat, fval, 1, mod._BLOCK_LANES)
    return traj, fstat


def test_block_remainder_fault_is_detected(modules, monkeypatch):
    """Negative control on the remainder: the interpreted run_block agrees with the compiled
    path to round-off; with the remainder block shortened by one lane (``min`` patched)
    the last trajectory is never stepped, which the comparison sees."""
    mod = modules["sv2"]
    Y0 = orbits(B)[:, :]
    ref = run(mod, "block", Y0, 0.01, 3)
    good, _ = _interpreted_block_run(mod, Y0, 0.01, 3)
    assert np.allclose(good, ref, rtol=1e-13, atol=1e-15)
    monkeypatch.setitem(nbbatch._run_block.py_func.__globals__, "min",
                        lambda a, b: b - 1 if b < a else a)
    bad, _ = _interpreted_block_run(mod, Y0, 0.01, 3)
    assert np.allclose(bad[:, :B - 1], ref[:, :B - 1], rtol=1e-13, atol=1e-15)
    assert not np.allclose(bad[:, B - 1], ref[:, B - 1])


@pytest.mark.parametrize("label", ["sv2", "bm-rkn4"])
def test_chunked_block_runs_equal_one_piece(modules, label, monkeypatch):
    mod = modules[label]
    Y0 = orbits(B, seed=1)
    whole = run(mod, "block", Y0, 0.01, 60)
    # in two calls, carried by info (compensation, first-same-as-last force)
    info = {}
    first = run(mod, "block", Y0, 0.01, 25, info=info)
    second = run(mod, "block", first[-1], 0.01, 35, info=info)
    assert np.array_equal(np.concatenate([first, second[1:]]), whole)
    # in one call cut into many run_block calls (the interrupt granularity)
    monkeypatch.setattr(mod, "_CHUNK_WORK", 7 * B)
    assert np.array_equal(run(mod, "block", Y0, 0.01, 60), whole)
    # control: the second call without the carried compensation starts differently
    again = run(mod, "block", first[-1], 0.01, 35)
    assert not np.array_equal(again[-1], whole[-1])


def plunging_batch(bad_lane):
    """Orbits of which one, at ``bad_lane``, falls radially into the singularity r = 0."""
    Y0 = orbits(B, seed=2)
    Y0[bad_lane] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    return Y0


@pytest.mark.parametrize("bad_lane", [37, 200, B - 1])  # first block, second, the remainder
def test_failing_lane_is_named_with_its_step(modules, bad_lane):
    mod = modules["sv2"]
    Y0 = plunging_batch(bad_lane)
    errs = {}
    for path in ("single", "block"):
        with pytest.raises((mod.ResolutionError, mod.NonFiniteError)) as ei:
            run(mod, path, Y0, 0.01, 400)
        errs[path] = ei.value
    a, b = errs["single"], errs["block"]
    assert type(a) is type(b) and str(a) == str(b) and a.step == b.step
    assert f"[{bad_lane}]" in str(b) and f"step {b.step}" in str(b)
    # rows 0 .. step complete for every trajectory, and the same
    assert b.trajectory.shape == (b.step + 1, B, 6)
    assert np.isfinite(b.trajectory).all()
    assert np.array_equal(a.trajectory, b.trajectory)
    # the other lanes alone run past that step
    ok = np.delete(Y0, bad_lane, axis=0)
    assert np.isfinite(run(mod, "block", ok, 0.01, b.step + 5)).all()


def test_unrecorded_lane_failure_would_go_silent(modules, monkeypatch):
    """Negative control: with the scalar pass that names failing lanes disabled (``_lane_status``
    always OK), the plunging lane is not reported and non-finite rows come back."""
    mod = modules["sv2"]
    bad_lane = 200
    Y0 = plunging_batch(bad_lane)
    _, fstat = _interpreted_block_run(mod, Y0, 0.01, 120)
    assert fstat[bad_lane, 0] != 0 and (np.delete(fstat[:, 0], bad_lane) == 0).all()
    monkeypatch.setitem(nbbatch._run_block.py_func.__globals__, "_lane_status",
                        lambda *a: (0, 0, 0.0))
    traj, fstat = _interpreted_block_run(mod, Y0, 0.01, 120)
    assert (fstat[:, 0] == 0).all()  # nothing reported ...
    H = mod.hamiltonian(traj[:, bad_lane])
    assert not (np.abs(H - H[0]) < 0.1).all()  # ... though the lane's energy left its value


# --- a time-transformed module: domain conditions and the time-scale guard in the lanes --------

@pytest.fixture(scope="module")
def logh(tmp_path_factory):
    scene = mg.load_scene("kepler-logh")
    scheme = mg.discretize(scene.run_system, "stormer-verlet")
    path = tmp_path_factory.mktemp("ensemble_logh") / module_filename(scene.name, "sv", "numba")
    mod = mg.generate(scheme, path, backend="numba")
    cfg = mod._CFG
    assert cfg[nbruntime.CFG["NDOMAIN"]] > 0 and cfg[nbruntime.CFG["TT_GUARD"]] == 1 and hasattr(mod, "_py_post_block")
    return mod


def logh_orbits(n, ecc, seed=3):
    """Extended states of n orbits (a = 1) from the apocentre, eccentricities ``ecc``, tilted."""
    rng = np.random.default_rng(seed)
    e = np.broadcast_to(ecc, (n,)).copy()
    ra, va = 1 + e, np.sqrt((1 - e) / (1 + e))
    tilt = rng.uniform(0.0, 0.5, n)
    y = np.stack([-ra, 0 * e, 0 * e, 0 * e, -va * np.cos(tilt), -va * np.sin(tilt)], axis=1)
    return y


def test_log_hamiltonian_lanes_equal_one_trajectory_path_bitwise(logh):
    mod = logh
    rng = np.random.default_rng(4)
    Y0 = mod.initial_state(logh_orbits(B, rng.uniform(0.1, 0.6, B)))
    a = run(mod, "single", Y0, 2 * np.pi / 40, 120)
    b = run(mod, "block", Y0, 2 * np.pi / 40, 120)
    assert np.array_equal(a, b)


def test_log_hamiltonian_failing_lane_named(logh):
    """One lane at e = 0.99 among e = 0.3 orbits: at 30 fictive steps per orbit its pericentre
    passage is refused (local error) by both paths, with the same step, lane and rows."""
    mod = logh
    ecc = np.full(B, 0.3)
    ecc[150] = 0.99
    Y0 = mod.initial_state(logh_orbits(B, ecc))
    errs = {}
    for path in ("single", "block"):
        with pytest.raises(mod.ResolutionError) as ei:
            run(mod, path, Y0, 2 * np.pi / 30, 60)
        errs[path] = ei.value
    a, b = errs["single"], errs["block"]
    assert str(a) == str(b) and a.step == b.step and "[150]" in str(b)
    assert np.array_equal(a.trajectory, b.trajectory) and b.trajectory.shape == (b.step + 1, B, 8)
    # control: without that lane (all e = 0.3) both paths run through, bitwise alike
    Y0[150] = Y0[149]
    assert np.array_equal(run(mod, "single", Y0, 2 * np.pi / 30, 60), run(mod, "block", Y0, 2 * np.pi / 30, 60))


@pytest.mark.skipif(__import__("platform").machine() not in ("x86_64", "AMD64"), reason="x86 instruction names")
def test_block_kernel_is_vectorised_without_contraction(modules):
    """The block kernel's lane loops compile to packed double square roots (SIMD over lanes)
    and no fused multiply-add (which would change the rounding: not bitwise the one-lane
    path).  Control: the one-lane post kernel, compiled the same way, has no packed ones."""
    import re

    import numba

    mod = modules["sv2"]
    block = numba.njit(nbbatch.KERNEL_TYPES["post_block"], error_model="numpy")(mod._py_post_block)
    asm = "\n".join(block.inspect_asm().values())
    assert re.search(r"\bv?sqrtpd\b", asm) and not re.search(r"vfn?m(add|sub)", asm)
    one = numba.njit(nbruntime.KERNEL_TYPES["post"], error_model="numpy")(mod._nb_post.py_func)
    asm1 = "\n".join(one.inspect_asm().values())
    assert re.search(r"\bv?sqrtsd\b", asm1) and not re.search(r"\bv?sqrtpd\b", asm1)
