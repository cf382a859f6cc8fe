"""Lock-step batches of explicit methods on the numba backend (methodgen.runtime.stepper.lockstep).

A batch of at least ``nbabi.MIN_BATCH`` trajectories of an explicit method runs in
blocks of ``_BLOCK_LANES`` lanes, stepped together through the module's block kernel
inlined into the lock-step loop (vectorised by LLVM); smaller batches and implicit
methods take the one-trajectory stepper.  These tests check that both paths give
*bitwise* the same rows (no fastmath: the block kernel is the same arithmetic),
including a batch that is not a multiple of the block, chunked runs, ``save_every`` and
``out=``, that a failing lane is reported with its index and step, and that the
lock-step loop compiled and run as Python agree.  Each has a negative control showing
that the comparison can fail.
"""

from __future__ import annotations

import os
import textwrap
import inspect

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen.emit import module_filename

pytest.importorskip("llvmlite")

from methodgen.codegen import abi, llvmkernels  # noqa: E402
from methodgen.runtime import fused, nbabi, stepper  # noqa: E402

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
    """``mod.integrate`` on the lock-step path (``path="block"``; ``"python"``: the lock-step
    loop run as Python) or the one-trajectory one."""
    saved = nbabi.MIN_BATCH
    nbabi.MIN_BATCH = 1 if path in ("block", "python") else 1 << 62
    env = os.environ.get("METHODGEN_STEPPER")
    os.environ["METHODGEN_STEPPER"] = "python" if path == "python" else ""
    try:
        return mod.integrate(*args, **kw)
    finally:
        nbabi.MIN_BATCH = saved
        if env is None:
            del os.environ["METHODGEN_STEPPER"]
        else:
            os.environ["METHODGEN_STEPPER"] = env


def test_route_explicit_batches_only(modules, hh):
    """Explicit modules carry a block kernel and run in lock-step from MIN_BATCH trajectories on;
    not implicit ones, nor projected ones (a projected step is the one-trajectory stepper's)."""
    cfg = modules["sv2"]._CFG
    assert nbabi.use_block(cfg, nbabi.MIN_BATCH) and not nbabi.use_block(cfg, nbabi.MIN_BATCH - 1)
    implicit = cfg.copy()
    implicit[abi.CFG["KIND"]] = 0
    assert not nbabi.use_block(implicit, 10 ** 6)  # Newton per lane stays on the stepper
    projected = cfg.copy()
    projected[abi.CFG["PROJ"]] = 1
    assert not nbabi.use_block(projected, 10 ** 6)
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


def test_bitwise_comparison_detects_a_lane_permutation(modules):
    """Negative control: two lanes of the remainder swapped are seen by the comparison.  (The
    lane stride is one constant: the block kernel is inlined into the lock-step loop, both
    compiled with the module's ``_BLOCK_LANES``.)"""
    mod = modules["sv2"]
    Y0 = orbits(B)
    a = run(mod, "single", Y0, 0.01, 20)
    b = run(mod, "block", Y0, 0.01, 20)
    assert np.array_equal(a, b)
    swapped = b.copy()
    swapped[:, [B - 2, B - 1]] = swapped[:, [B - 1, B - 2]]
    assert not np.array_equal(a, swapped)


def test_lockstep_compiled_and_as_python_agree_bitwise(modules, logh):
    """The lock-step loop, one source run two ways: compiled (the block kernel inlined) and as
    Python, the same bits -- a batch with a remainder block, save_every, not compensated, a
    time-transformed module with its domain conditions and guard."""
    for mod, h, Y0 in ((modules["sv2"], 0.01, orbits(150)), (modules["bm-rkn4"], 0.01, orbits(40)),
                       (logh, 2 * np.pi / 40, logh.initial_state(logh_orbits(40, 0.5)))):
        for kw in ({}, {"compensated": False, "save_every": 3}):
            assert np.array_equal(run(mod, "block", Y0, h, 12, **kw), run(mod, "python", Y0, h, 12, **kw))


def _edited_lockstep(monkeypatch, line, replacement):
    """:func:`methodgen.runtime.stepper.lockstep` with one line of its source replaced (a fault)."""
    src = textwrap.dedent(inspect.getsource(stepper.lockstep))
    assert src.count(line) == 1
    namespace = {}
    exec(compile(src.replace(line, replacement), "edited_lockstep", "exec"), namespace)
    monkeypatch.setattr(stepper, "lockstep", namespace["lockstep"])


def test_block_remainder_fault_is_detected(modules, monkeypatch):
    """Negative control on the remainder: the lock-step loop as Python agrees with the compiled
    one; with the remainder block shortened by one lane the last trajectory is never stepped,
    which the comparison sees."""
    mod = modules["sv2"]
    Y0 = orbits(B)
    ref = run(mod, "block", Y0, 0.01, 3)
    assert np.array_equal(run(mod, "python", Y0, 0.01, 3), ref)
    _edited_lockstep(monkeypatch, "_nl = min(_L, _nbt - _b0)", "_nl = min(_L, _nbt - _b0) - (1 if _nbt - _b0 < _L else 0)")
    # (into rows of NaN: a row left unwritten must not show a freed array's old values)
    bad = run(mod, "python", Y0, 0.01, 3, out=np.full_like(ref, np.nan))
    assert np.array_equal(bad[:, :B - 1], ref[:, :B - 1])
    assert not np.array_equal(bad[:, B - 1], ref[:, B - 1])


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
    """Negative control: with the scalar pass that names failing lanes disabled (``lane_status``
    always OK), the plunging lane is not reported and non-finite rows come back."""
    mod = modules["sv2"]
    bad_lane = 200
    Y0 = plunging_batch(bad_lane)
    with pytest.raises((mod.ResolutionError, mod.NonFiniteError)) as ei:
        run(mod, "python", Y0, 0.01, 120)
    assert f"[{bad_lane}]" in str(ei.value)

    def always_ok(PS, YS, NE2, ND2, EJS, l, out):
        out[0] = 0.0
        out[1] = 0.0
        out[2] = 0.0

    monkeypatch.setattr(stepper, "lane_status", always_ok)
    traj = run(mod, "python", Y0, 0.01, 120)     # nothing reported ...
    H = mod.hamiltonian(traj[:, bad_lane])
    assert not (np.abs(H - H[0]) < 0.1).all()    # ... though the lane's energy left its value


# --- a time-transformed module: domain conditions and the time-scale guard in the lanes --------

@pytest.fixture(scope="module")
def logh(tmp_path_factory):
    scene = mg.load_scene("kepler-logh")
    scheme = mg.discretize(scene.run_system, "stormer-verlet")
    path = tmp_path_factory.mktemp("ensemble_logh") / module_filename(scene.name, "sv", "numba")
    mod = mg.generate(scheme, path, backend="numba")
    cfg = mod._CFG
    assert cfg[abi.CFG["NDOMAIN"]] > 0 and cfg[abi.CFG["TT_GUARD"]] == 1 and hasattr(mod, "_py_post_block")
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


def _loop_function(mod, block):
    """The lock-step (``block``) or one-trajectory loop of an explicit module, as compiled."""
    by = {"post": mod._nb_post, "hs": getattr(mod, "_nb_hs", None), "check": getattr(mod, "_nb_check", None)}
    kernels = tuple(by.get(n) or nbabi.no_kernel(n) for n in fused.KERNEL_NAMES)
    return fused.loop_function(kernels, mod._CFG, mod._FCFG, mod._LERR_INDEX, mod._DOMAIN_POSITIVE,
                               mod._STAGE_GAMMAS, mod._STAGE_RATIOS, (0, 0, 1, 1),
                               (mod._block_kernel(), mod._BLOCK_LANES) if block else None)


@pytest.mark.skipif(__import__("platform").machine() not in ("x86_64", "AMD64"), reason="x86 instruction names")
def test_lockstep_loop_is_vectorised_without_contraction(modules):
    """The lock-step loop's lane loops compile to packed double square roots (SIMD over lanes:
    the block kernel inlined, its rows distinct stack buffers) and no fused multiply-add (which
    would change the rounding: not bitwise the one-lane path).  Control: the one-trajectory
    stepper of the same module, compiled the same way, has no packed ones."""
    import re

    mod = modules["sv2"]
    fn, sig = _loop_function(mod, True)
    asm = llvmkernels.assembly(fn, sig, fn.__globals__)
    assert re.search(r"\bv?sqrtpd\b", asm) and not re.search(r"vfn?m(add|sub)", asm)
    fn1, sig1 = _loop_function(mod, False)
    asm1 = llvmkernels.assembly(fn1, sig1, fn1.__globals__)
    assert re.search(r"\bv?sqrtsd\b", asm1) and not re.search(r"\bv?sqrtpd\b", asm1)
