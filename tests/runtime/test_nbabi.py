"""The compiled backend's runtime interface (methodgen.runtime.nbabi).

A compiled module (backend="numba") holds its kernels only and runs on the stepper
(methodgen.runtime.stepper).  These tests check that every step structure takes it, that it
reads its per-stage coefficients from the module, and that a module refuses a runtime it was
not generated for.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen import emit
from methodgen.codegen.emit import emit_source, module_filename

pytest.importorskip("llvmlite")

from methodgen.codegen import abi  # noqa: E402
from methodgen.codegen import llvmkernels as lk  # noqa: E402
from methodgen.runtime import nbabi  # noqa: E402


def _module(tmp_path, scene_name, method, order=2, **options):
    scene = mg.load_scene(scene_name)
    scheme = mg.discretize(scene.system, method, order=order, **options)
    path = tmp_path / module_filename(scene.name, f"{method}_o{order}", "numba")
    return scene, mg.generate(scheme, path, backend="numba")


# --- route ---------------------------------------------------------------------------

def test_every_step_structure_takes_the_stepper(kepler, hh):
    """Explicit, Newton-solved, linearly implicit and projected steps all run on the stepper
    (methodgen.runtime.stepper through methodgen.runtime.nbabi.run); the module holds kernels only (no
    compiled loop of its own)."""
    schemes = [mg.discretize(kepler, "energy-momentum"), mg.discretize(kepler, "stormer-verlet"),
               mg.discretize(mg.load_scene("henon-heiles").system, "kahan"),
               mg.discretize(hh, "stormer-verlet", project="energy")]
    for scheme in schemes:
        src = emit_source(scheme, backend="numba")
        assert "_rt.run(" in src and "def _nb_run(" not in src and "def _nb_solve_step(" not in src
        # a projected step is the stepper's too: the module's _nb_proj_run only calls it
        assert ("def _nb_proj_run(" in src) == bool(scheme.projection)
        assert "@_jit\ndef _nb_proj_run" not in src


@pytest.mark.slow
@pytest.mark.parametrize("scene_name,method,order", [
    ("kepler", "energy-momentum", 4), ("kepler", "stormer-verlet", 4), ("henon-heiles", "kahan", 2),
    ("henon-heiles-2d", "energy-momentum", 2), ("kepler-eccentric", "gauss", 2),
    ("spherical-pendulum", "shake", 2), ("rigid-body", "avf", 2)])
def test_compiled_and_python_stepper_agree_bitwise_on_every_kind(tmp_path, monkeypatch, scene_name, method, order):
    """Compositions, first-same-as-last, linearly implicit, domain conditions, constraints
    (banded elimination), a Poisson system: the compiled stepper and the stepper run as
    Python give the same exception (or none) with the same message, rows and iterations
    (fast siblings: tests/test_stepper.py)."""
    scene = mg.load_scene(scene_name)
    scheme = mg.discretize(scene.system, method, order=order)
    mod = mg.generate(scheme, tmp_path / "mod_numba.py", backend="numba")
    y0 = np.array(scene.y0)
    if mod.TIME_TRANSFORM:
        y0 = mod.initial_state(y0)
    compiled = _outcome(mod, y0, scene.h)
    monkeypatch.setenv("METHODGEN_STEPPER", "python")
    python = _outcome(mod, y0, scene.h)
    assert compiled[0] == python[0] and compiled[1] == python[1]
    assert np.array_equal(compiled[2], python[2]) and np.array_equal(compiled[3], python[3])


def _outcome(mod, y0, h, steps=300):
    """(exception type, its message without the module name, trajectory, iterations)."""
    info = {}
    try:
        traj = mod.integrate(y0, h, steps, info=info)
        return None, "", traj, info["newton_iterations"]
    except (mod.ResolutionError, mod.ConvergenceError, mod.NonFiniteError) as exc:
        return type(exc).__name__, str(exc), exc.trajectory, info.get("newton_iterations")


# --- per-stage coefficients ----------------------------------------------------------

def test_explicit_stage_reads_its_steps_from_the_stage_coefficients(tmp_path):
    """The runtime hands the first-same-as-last post kernel h·KICK_A[k], h·DRIFT[k],
    h·KICK_B[k].  Doubling all three is one step of 2h, bitwise; controls: restored, the
    step of h again; doubling DRIFT alone is neither (the kicks are read separately)."""
    scene, mod = _module(tmp_path, "simple-pendulum", "stormer-verlet")
    y0 = np.array(scene.y0)
    h = scene.h
    np.testing.assert_array_equal(mod._KICK_A, 0.5 * np.array(mod.GAMMAS))
    np.testing.assert_array_equal(mod._DRIFT, np.array(mod.GAMMAS))
    ref_h = mod.integrate(y0, h, 1)
    ref_2h = mod.integrate(y0, 2 * h, 1)
    saved = [a.copy() for a in (mod._KICK_A, mod._DRIFT, mod._KICK_B)]
    try:
        for arr, old in zip((mod._KICK_A, mod._DRIFT, mod._KICK_B), saved):
            arr[:] = 2 * old
        doubled = mod.integrate(y0, h, 1)
        mod._KICK_A[:], mod._KICK_B[:] = saved[0], saved[2]
        drift_only = mod.integrate(y0, h, 1)
    finally:
        for arr, old in zip((mod._KICK_A, mod._DRIFT, mod._KICK_B), saved):
            arr[:] = old
    np.testing.assert_array_equal(doubled, ref_2h)
    np.testing.assert_array_equal(mod.integrate(y0, h, 1), ref_h)
    assert not np.array_equal(ref_h, ref_2h)
    assert not np.array_equal(drift_only, ref_2h) and not np.array_equal(drift_only, ref_h)


def test_configuration_is_checked_by_name():
    with pytest.raises(ValueError, match="missing .*'N'"):
        nbabi.int_config(**{k: 0 for k in abi.CFG if k != "N"})
    with pytest.raises(ValueError, match="unknown .*'BOGUS'"):
        nbabi.float_config(**{k: 0.0 for k in abi.FCFG}, BOGUS=1.0)
    cfg = nbabi.int_config(**{k: i for k, i in abi.CFG.items()})
    assert cfg.tolist() == list(range(len(abi.CFG)))


def test_status_codes_match_the_modules(tmp_path):
    _, mod = _module(tmp_path, "simple-pendulum", "midpoint")
    for name, code in abi.STATUS.items():
        assert getattr(mod, "_" + name) == code, name


# --- cache stamp -------------------------------------------------------------------------

def test_the_runtime_is_stamped_with_its_content_hash():
    # the stamp covers the runtime's interface and the contract whose layout it compiles in
    import hashlib
    h = hashlib.sha256()
    package = os.path.dirname(os.path.dirname(nbabi.__file__))
    for name in ("codegen/abi.py", "runtime/nbabi.py"):
        with open(os.path.join(package, name), "rb") as f:
            h.update(hashlib.sha256(f.read()).digest())
    assert h.hexdigest() == nbabi.SOURCE_SHA256 == abi.RUNTIME_SHA256


def test_a_compiled_module_runs_without_numba(tmp_path):
    """In a fresh process where ``import numba`` fails, a compiled module is built and its steps
    run on its compiled stepper.  Control: the stepper's machine code is there (fused._LOOPS)."""
    scene = mg.load_scene("double-well")
    path = tmp_path / module_filename("dw", "midpoint", "numba")
    mg.generate(mg.discretize(scene.system, "midpoint"), path, backend="numba")
    code = textwrap.dedent(f"""
        import sys, numpy as np
        sys.modules["numba"] = None
        from methodgen.runtime import fused
        from methodgen.codegen.emit import load_module
        m = load_module({str(path)!r})
        m.integrate(np.array({list(scene.y0)!r}), {scene.h!r}, 3)
        assert fused._LOOPS
        print("ran", sys.modules["numba"])
    """)
    env = {k: v for k, v in os.environ.items() if k != "METHODGEN_STEPPER"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split() == ["ran", "None"]


# --- the runtime a module was generated for ----------------------------------------------

def _import_fresh(path, name):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_module_refuses_a_runtime_it_was_not_generated_for(tmp_path, monkeypatch):
    """A numba module generated by one methodgen and imported under another (upgraded or
    edited runtime: the configuration, the kernels' outputs or the status codes may mean
    something else) was run on it silently; it now raises ImportError naming the remedy.
    Control: under the runtime it was generated for it imports and runs."""
    scene, mod = _module(tmp_path, "simple-pendulum", "midpoint")
    assert mod._RUNTIME_SHA256 == nbabi.SOURCE_SHA256 == emit.runtime_sha256()
    path = mod.__file__
    ok = _import_fresh(path, "rt_same")
    assert ok.integrate(np.array(scene.y0), scene.h, 3).shape == (4, 2)
    monkeypatch.setattr(nbabi, "SOURCE_SHA256", "0" * 64)   # (what a module checks)
    with pytest.raises(ImportError, match=r"generated for another methodgen runtime .*installed 0{16}.*regenerate"):
        _import_fresh(path, "rt_other")


def test_residual_and_jacobian_of_one_state(tmp_path):
    """``residual(z, y0, h)`` and ``jacobian`` of one z and one y0 (no broadcasting) on the
    shared runtime raised numba's 'No matching definition ... readonly array' (the rows are
    read-only views of numpy.broadcast_to; the runtime's explicit signatures take writable
    arrays).  Now they equal the numpy module's to round-off; control: the numpy module's
    values differ at another h, so the comparison sees a wrong step size."""
    scene = mg.load_scene("simple-pendulum")
    scheme = mg.discretize(scene.system, "midpoint")
    nb = mg.generate(scheme, tmp_path / "one_state_numba.py", backend="numba")
    ref = mg.generate(scheme, tmp_path / "one_state.py", backend="numpy")
    assert "_rt.run(" in open(nb.__file__).read()
    y0 = np.array(scene.y0)
    z = np.full(len(nb.UNKNOWN_NAMES), 0.01)
    for fn in ("residual", "jacobian"):
        got = getattr(nb, fn)(z, y0, 0.1)
        np.testing.assert_allclose(got, getattr(ref, fn)(z, y0, 0.1), rtol=1e-14, atol=1e-16)
        assert not np.allclose(got, getattr(ref, fn)(z, y0, 0.2), rtol=1e-14, atol=1e-16)
    np.testing.assert_allclose(nb.residual(z[None], y0[None], 0.1)[0], nb.residual(z, y0, 0.1), rtol=0, atol=0)


def test_batches_in_any_memory_order(tmp_path):
    """A Fortran-ordered or broadcast batch y0 (and a Fortran-ordered compensation in info)
    raised numba's 'No matching definition' on the shared runtime (its signatures take
    C-contiguous rows; the batch was copied keeping its order).  Now each equals the batch
    in C order bitwise (first-same-as-last and Newton); control: a batch whose rows differ in
    the last bit gives another trajectory."""
    scene = mg.load_scene("simple-pendulum")
    y0 = np.array(scene.y0)
    Y = np.array([y0, 1.1 * y0, 0.9 * y0])
    for method in ("stormer-verlet", "midpoint"):
        mod = mg.generate(mg.discretize(scene.system, method), tmp_path / f"order_{method}_numba.py".replace("-", "_"),
                          backend="numba")
        assert "_rt.run(" in open(mod.__file__).read()
        ref = mod.integrate(Y, scene.h, 20)
        np.testing.assert_array_equal(mod.integrate(np.asfortranarray(Y), scene.h, 20), ref)
        np.testing.assert_array_equal(mod.integrate(np.broadcast_to(y0, (3, 2)), scene.h, 20)[:, 1],
                                      ref[:, 0])
        info = {"compensation": np.asfortranarray(np.zeros_like(Y))}
        np.testing.assert_array_equal(mod.integrate(Y, scene.h, 20, info=info), ref)
        assert not np.array_equal(mod.integrate(np.nextafter(Y, 2.0), scene.h, 20), ref)


def test_stage_systems_by_structure_run_on_the_shared_runtime(tmp_path, monkeypatch):
    """Gauss (and energy collocation) emit their stage system by structure (loops over the
    stages, calling f and f'); on the shared route those loops are compiled for the runtime's
    kernel types.  Before, the shared route's kernels took ``ir.scalar.res``, which is not that
    residual: residual and Jacobian differed from the numpy module's (by 1.0 in the Jacobian)
    and every step was wrong (Kepler e = 0.6: 5e-5 per step, Newton 'converged' in 1
    iteration).  Now residual, Jacobian and 50 steps agree with the numpy module to
    round-off.  Control: without the stage system in the
    module's description (the straight-line kernels of ``ir.scalar``), the residual is wrong."""
    from methodgen.codegen import lower

    scene = mg.load_scene("simple-pendulum")
    scheme = mg.discretize(scene.system, "gauss")
    ref = mg.generate(scheme, tmp_path / "gauss4.py", backend="numpy")
    nb = mg.generate(scheme, tmp_path / "gauss4_numba.py", backend="numba")
    src = open(nb.__file__).read()
    assert "_rt.run(" in src and "_nb_fieldjac(" in src
    y0 = np.array(scene.y0)
    z = 0.01 * np.sin(np.arange(len(ref.UNKNOWN_NAMES)) + 1.0)
    for fn in ("residual", "jacobian"):
        np.testing.assert_allclose(getattr(nb, fn)(z, y0, 0.1), getattr(ref, fn)(z, y0, 0.1), rtol=1e-13, atol=1e-15)
    traj = nb.integrate(y0, scene.h, 50)
    np.testing.assert_allclose(traj, ref.integrate(y0, scene.h, 50), rtol=0, atol=1e-13)
    monkeypatch.setattr(lower, "stage_tables", lambda st: None)
    forced = mg.generate(scheme, tmp_path / "gauss4_forced_numba.py", backend="numba")
    assert "_rt.run(" in open(forced.__file__).read() and "_nb_fieldjac(" not in open(forced.__file__).read()
    assert not np.allclose(forced.residual(z, y0, 0.1), ref.residual(z, y0, 0.1), rtol=1e-6, atol=1e-9)


# --- per-step cost: work arrays on the stack ----------------------------------------------

_TWO = """
def two(_z, _y, _c, _h, _p, _r):
    a = stack_array((3,))
    b = stack_array((3,))
    for i in range(3):
        a[i] = _y[0]
        b[i] = -_y[0]
    _r[0] = a[0] + a[1] + a[2]


def alias(_z, _y, _c, _h, _p, _r):
    a = stack_array((3,))
    b = a
    for i in range(3):
        a[i] = _y[0]
        b[i] = -_y[0]
    _r[0] = a[0] + a[1] + a[2]
"""


def test_stack_arrays_are_distinct_and_writable(tmp_path):
    """``stack_array(shape)`` (the stepper's work arrays): each is its own buffer in the
    compiled function's frame.  Control: two names of one buffer (what a shared buffer would
    be) fail the same check."""
    path = tmp_path / "two_buffers.py"
    path.write_text(_TWO)
    mod = _import_fresh(path, "two_buffers")
    res = abi.KERNEL_TYPES["res"]
    out = {}
    for name in ("two", "alias"):
        r = np.zeros(1)
        lk.compile_kernel(getattr(mod, name), res)(np.zeros(1), np.array([1.5]), np.zeros(1), 0.1, np.zeros(1), r)
        out[name] = r[0]
    assert out == {"two": 4.5, "alias": -4.5}


def test_stage_kernels_keep_their_work_arrays_on_the_stack(tmp_path):
    """Gauss's stage kernels take their work arrays (f, f' at the stage points) from the stack
    (``stack_array``) instead of allocating them per call (a fifth of Kepler gauss s = 3's step
    when they were numpy arrays).  Control: energy collocation's kernels, printed by the same
    code, have them too, and no stage kernel allocates."""
    scene = mg.load_scene("kepler")
    for method in ("gauss", "energy-collocation"):
        nb = mg.generate(mg.discretize(scene.system, method, stages=2), tmp_path / f"stack_{method}_numba.py".replace("-", "_"),
                         backend="numba")
        src = open(nb.__file__).read()
        stage = src[src.index("def _nb_resjac("):src.index("def _nb_post(")]
        assert stage.count("stack_array(") == 6 and "numpy.empty(" not in stage and "numpy.zeros(" not in stage, method


def test_a_continued_run_skips_the_initial_check_and_control(kepler, monkeypatch):
    """A call continuing from the exact end state (and parameters) of this module's last call,
    through ``info`` or as the module's last run, does not check its initial state again: the
    loop checked it as a step's state.  Controls: without ``info``, from another state, or with other parameters the check
    runs; and the continued run is bitwise the run in one piece."""
    mod = mg.build(kepler, "stormer-verlet", backend="numba")
    y0 = np.array(mg.load_scene("kepler").y0)
    calls = []
    check = mod._check_initial_rows

    def counted(Y, p):
        calls.append(1)
        return check(Y, p)

    monkeypatch.setattr(mod, "_check_initial_rows", counted)
    whole = mod.integrate(y0, 0.01, 40)
    info = {}
    a = mod.integrate(y0, 0.01, 20, info=info)
    b = mod.integrate(a[-1], 0.01, 20, info=info)
    assert len(calls) == 2 and np.array_equal(b[-1], whole[-1])     # whole, then a; not b
    mod.integrate(a[-1], 0.01, 5)                                       # no info
    mod.integrate(a[-2], 0.01, 5, info=dict(info))                      # another state
    mod.integrate(b[-1], 0.01, 5, params={"m": 1.0, "k": 2.0}, info=dict(info))
    assert len(calls) == 5
    # stepping in a loop: a step from the state the module's last run ended on skips it too
    y1 = mod.step(y0, 0.01)
    y2 = mod.step(y1, 0.01)
    assert len(calls) == 6
    again = mod.step(y1, 0.01)               # control: y1 is no longer the last end state
    assert len(calls) == 7 and np.array_equal(again, y2)
