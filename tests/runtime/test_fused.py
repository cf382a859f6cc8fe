"""The stepper compiled with a module's kernels inlined (methodgen.runtime.stepper, methodgen.runtime.fused).

Compared with the same stepper run as Python (its reference, METHODGEN_STEPPER=python) it gives
the same numbers bitwise, failures included: a failing step is recorded
by the stepper itself (status, step, iteration, value, stage), never handed to another
implementation; a resolution verdict that needs eigenvalues stops the loop, which asks its
driver for the spectral radius and resumes at that stage.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import methodgen as mg

pytest.importorskip("llvmlite")


E = 0.99
APO = np.array([1 + E, 0.0, 0.0, 0.0, math.sqrt((1 - E) / (1 + E)), 0.0])


def _counting(monkeypatch):
    """Count the runs of the stepper as Python (the reference the compiled one is compared to)."""
    from methodgen.runtime import fused
    calls = []
    real = fused.python_stepper

    def python_stepper(*args):
        calls.append(1)
        return real(*args)

    monkeypatch.setattr(fused, "python_stepper", python_stepper)
    return calls


def _mode(monkeypatch, fused):
    """"1": the compiled stepper; "0": the same stepper run as Python."""
    monkeypatch.setenv("METHODGEN_STEPPER", "" if fused == "1" else "python")


@pytest.mark.parametrize("case", ["kepler-sv10", "hh-sv8-rkn", "logh-sv6"])
def test_compiled_stepper_is_bitwise_the_python_stepper(monkeypatch, case):
    if case == "logh-sv6":
        L = mg.time_transform(mg.load_scene("kepler").system, form="log")
        mod = mg.build(L, "stormer-verlet", backend="numba", order=6)
        y0 = mod.initial_state(np.array([0.4, 0.0, 0.0, 0.0, 0.8 * 2.0, 0.6 * 2.0]))
        h = 2 * math.pi / 40
    else:
        name, order, comp = {"kepler-sv10": ("kepler", 10, None),
                             "hh-sv8-rkn": ("henon-heiles-2d", 6, "blanes-moan-rkn")}[case]
        scene = mg.load_scene(name)
        mod = mg.build(scene.system, "stormer-verlet", backend="numba", order=order, composition=comp)
        y0, h = np.array(scene.y0, float), scene.h
    Y0 = np.stack([y0, y0 * (1 + 1e-3)])
    runs = {}
    for fused in ("1", "0"):
        _mode(monkeypatch, fused)
        calls = _counting(monkeypatch)
        one = mod.integrate(y0, h, 400)
        batch = mod.integrate(Y0, h, 300, save_every=7)
        # two chunks carry compensation and force as one call does
        info = {}
        first = mod.integrate(y0, h, 150, info=info)
        second = mod.integrate(first[-1], h, 250, info=info)
        runs[fused] = (one, batch, np.concatenate([first, second[1:]]))
        assert (calls == []) == (fused == "1"), (fused, calls)   # the fused path was taken (or not)
    for a, b in zip(runs["1"], runs["0"]):
        assert np.array_equal(a, b)
    assert np.array_equal(runs["1"][0], runs["1"][2])


def test_a_failing_step_is_reported_by_the_stepper_itself(monkeypatch):
    """Kepler at e = 0.99 with a step that jumps over the pericentre: the stepper records the
    failure itself; the error, its step, its check and the rows before it are those of the
    numba runtime."""
    mod = mg.build(mg.load_scene("kepler").system, "stormer-verlet", backend="numba", order=4)
    got = {}
    for fused in ("1", "0"):
        _mode(monkeypatch, fused)
        calls = _counting(monkeypatch)
        with pytest.raises(mod.ResolutionError) as info:
            mod.integrate(APO, 0.2, 200)
        e = info.value
        got[fused] = (e.step, e.check, str(e), e.trajectory.tobytes())
        assert (calls == []) == (fused == "1"), (fused, calls)   # the compiled run never fell back to Python
    assert got["1"] == got["0"]
    # control: resolved, the same run completes on the fused path alone
    _mode(monkeypatch, "1")
    calls = _counting(monkeypatch)
    assert np.all(np.isfinite(mod.integrate(APO, 0.2, 200, check_resolution=False)))
    assert calls == []


def _state_bytes(info):
    """What a chunk leaves for the next: iterations, compensation, solver state (as bytes)."""
    out = [np.asarray(info["newton_iterations"]).tobytes(), np.asarray(info["compensation"]).tobytes()]
    st = info.get("solver_state")
    if st is not None:
        out.append(repr(st[:3]))
        out += [np.asarray(a).tobytes() for a in (st[3] if isinstance(st[3], (tuple, list)) else [st[3]])]
    return out


@pytest.mark.parametrize("case", ["kepler-em2", "hh2d-em8", "hh-kahan", "kepler-gauss3", "hh2d-ec3", "dp-rattle"])
def test_implicit_stages_compiled_are_bitwise_the_python_stepper(monkeypatch, case):
    """Newton's method inlined with the kernels (solvers "newton" and "auto", the carried
    local-error estimate, Gauss' stage system, energy collocation, RATTLE with its scale
    kernel inlined as an expression) and the linearly implicit
    step (Kahan: its resolution verdict from the closed-form 2×2 bound): one trajectory, a batch
    with save_every, and two chunks carrying compensation and solver state -- bitwise the
    runtime's, iterations included, on the fused path alone."""
    name, method, kw = {"kepler-em2": ("kepler", "energy-momentum", {}),
                        "hh2d-em8": ("henon-heiles-2d", "energy-momentum", {"order": 8}),
                        "hh-kahan": ("henon-heiles", "kahan", {}),
                        "kepler-gauss3": ("kepler", "gauss", {"stages": 3}),
                        "hh2d-ec3": ("henon-heiles-2d", "energy-collocation", {"stages": 3}),
                        "dp-rattle": ("double-pendulum", "rattle", {})}[case]
    scene = mg.load_scene(name)
    mod = mg.build(scene.system, method, backend="numba", **kw)
    y0, h = np.array(scene.y0, float), scene.h
    y1 = y0 * (1 + 1e-3)
    Y0 = np.stack([y0, mod.project(y1) if hasattr(mod, "project") else y1])
    runs = {}
    for fused in ("1", "0"):
        _mode(monkeypatch, fused)
        calls = _counting(monkeypatch)
        i1, i2, i3 = {}, {}, {}
        one = mod.integrate(y0, h, 300, info=i1)
        batch = mod.integrate(Y0, h, 200, save_every=7, info=i2)
        first = mod.integrate(y0, h, 120, info=i3)
        mid = _state_bytes(i3)
        second = mod.integrate(first[-1], h, 180, info=i3)
        runs[fused] = ([one, batch, np.concatenate([first, second[1:]])],
                       _state_bytes(i1) + _state_bytes(i2) + mid + _state_bytes(i3))
        assert (calls == []) == (fused == "1"), (fused, calls)
    for a, b in zip(runs["1"][0], runs["0"][0]):
        assert np.array_equal(a, b)
    assert runs["1"][1] == runs["0"][1]
    assert np.array_equal(runs["1"][0][0], runs["1"][0][2])
    assert np.asarray(i1["newton_iterations"]).sum() >= 300          # the stages were solved


@pytest.mark.parametrize("why", ["not-converged", "unresolved"])
def test_an_implicit_failure_is_reported_by_the_stepper_itself(monkeypatch, why):
    """Newton stopped by maxiter, or a step the Newton matrix says is unresolved: the stepper
    records it, and the error (type, step, message, rows) is the Python stepper's."""
    scene = mg.load_scene("henon-heiles-2d")
    mod = mg.build(scene.system, "energy-momentum", backend="numba")
    y0 = np.array(scene.y0, float)
    h, kw = (scene.h, {"maxiter": 2, "solver": "newton"}) if why == "not-converged" else (2.5, {})
    got = {}
    for fused in ("1", "0"):
        _mode(monkeypatch, fused)
        calls = _counting(monkeypatch)
        with pytest.raises(Exception) as info:
            mod.integrate(y0, h, 100, **kw)
        e = info.value
        got[fused] = (type(e).__name__, getattr(e, "step", None), str(e))
        assert (calls == []) == (fused == "1"), (fused, calls)
    assert got["1"] == got["0"]
    assert got["1"][0] == ("ConvergenceError" if why == "not-converged" else "ResolutionError")


def test_an_undecided_resolution_bound_stops_and_resumes(monkeypatch):
    """Light, soft, non-separable oscillators (midpoint, 4 unknowns): the norms of J - I are
    ~10 while its spectral radius is ~0.15, so the row-sum bound cannot decide the resolution
    check: the stepper stops, its driver takes ρ from the eigenvalues, and the stepper resumes
    at that stage -- bitwise the Python stepper's run, which is never called.  Control: unit
    masses at h = 0.5, where the row sums decide, run in one drive."""
    from methodgen.runtime import fused as fz
    drives = []
    real = fz._drive

    def drive(*args):
        drives.append(1)
        return real(*args)

    monkeypatch.setattr(fz, "_drive", drive)
    H = "(p1**2 + p2**2)/(2*m) + k*(q1**2 + q2**2)/2 + c*q1*p2 + k*q1**4"
    y0 = np.array([0.3, 0.0, 0.0, 0.01])
    for m, h, steps, asks in ((0.01, 0.2, 20, True), (1.0, 0.5, 50, False)):
        mod = mg.build_text(H, ["q1", "q2"], ["p1", "p2"], "midpoint", params={"m": m, "k": m, "c": 0.1 * m},
                            name=f"osc2_{int(m * 100)}", backend="numba")
        _mode(monkeypatch, "0")
        info0 = {}
        ref = mod.integrate(y0, h, steps, info=info0)
        _mode(monkeypatch, "1")
        calls = _counting(monkeypatch)
        del drives[:]
        info1 = {}
        assert np.array_equal(mod.integrate(y0, h, steps, info=info1), ref)
        assert np.array_equal(info1["newton_iterations"], info0["newton_iterations"])
        assert calls == []
        assert (len(drives) > 1) == asks, (m, len(drives))
        if asks:
            assert len(drives) == steps + 1            # one question per step, then the end


@pytest.mark.parametrize("method, kw", [("energy-momentum", {"order": 4}), ("stormer-verlet", {"order": 6})])
def test_a_batch_of_any_size_runs_fused(monkeypatch, method, kw):
    """The number of trajectories is a run-time bound of the loop: a batch of 12 (implicit; and
    explicit below the lock-step batch size) runs fused, bitwise the Python stepper's, iterations
    included (counted in place, in the caller's zeroed array)."""
    scene = mg.load_scene("henon-heiles-2d")
    mod = mg.build(scene.system, method, backend="numba", **kw)
    y0 = np.array(scene.y0, float)
    Y = y0 * (1 + 1e-3 * np.arange(12)[:, None])
    got = {}
    for fused in ("1", "0"):
        _mode(monkeypatch, fused)
        calls = _counting(monkeypatch)
        info = {}
        a = mod.integrate(Y, scene.h, 200, save_every=3, info=info)
        got[fused] = (a, np.asarray(info["newton_iterations"]))
        assert (calls == []) == (fused == "1")
    assert np.array_equal(got["1"][0], got["0"][0])
    assert np.array_equal(got["1"][1], got["0"][1])


@pytest.mark.parametrize("solver", ["newton", "simplified", "fixed-point", "reuse", "auto"])
@pytest.mark.parametrize("tol", [None, 1e-12])
def test_every_solver_and_stopping_rule_compiled_and_as_python(monkeypatch, solver, tol):
    """Each solver with the round-off stopping rule and with a tolerance: bitwise the Python stepper's
    trajectory and iterations, on the compiled stepper alone (no Python fallback)."""
    scene = mg.load_scene("henon-heiles-2d")
    mod = mg.build(scene.system, "energy-momentum", backend="numba", order=4)
    y0 = np.array(scene.y0, float)
    got = {}
    for fused in ("1", "0"):
        _mode(monkeypatch, fused)
        calls = _counting(monkeypatch)
        info = {}
        got[fused] = (mod.integrate(y0, scene.h, 150, solver=solver, tol=tol, info=info),
                      np.asarray(info["newton_iterations"]))
        assert (calls == []) == (fused == "1"), (fused, calls)
    assert np.array_equal(got["1"][0], got["0"][0])
    assert np.array_equal(got["1"][1], got["0"][1])


def test_the_asked_spectral_radius_decides(monkeypatch):
    """Hénon–Heiles energy-momentum at h = 2.5: the stepper asks for ρ, and the answer decides
    the run -- the error (its h·ω) is the Python stepper's.  Negative control: a driver that
    answers half the spectral radius lets the unresolved step pass (the error changes), so the
    answer is what the stepper used."""
    from methodgen.runtime import fused as fz
    scene = mg.load_scene("henon-heiles-2d")
    mod = mg.build(scene.system, "energy-momentum", backend="numba")
    y0 = np.array(scene.y0, float)

    def error():
        with pytest.raises(Exception) as info:
            mod.integrate(y0, 2.5, 100)
        return type(info.value).__name__, info.value.step, str(info.value)

    _mode(monkeypatch, "0")
    ref = error()
    _mode(monkeypatch, "1")
    asked = []
    real = fz.spectral_h_omega

    def spectral(J, resol):
        asked.append(1)
        return real(J, resol)

    monkeypatch.setattr(fz, "spectral_h_omega", spectral)
    assert error() == ref and asked
    monkeypatch.setattr(fz, "spectral_h_omega", lambda J, resol: 0.5 * real(J, resol))
    try:
        wrong = error()
    except BaseException as exc:   # (no error at all: the run passed)
        wrong = repr(exc)
    assert wrong != ref


@pytest.mark.parametrize("case", ["hh2d-em4", "kepler-gauss2", "nbody3-em2",
                                  # the same kernels' shape (pair loops, a dense 18×18 LU) at
                                  # six bodies: its Python-stepper reference costs ~25 s of CPU
                                  pytest.param("oss-em2", marks=pytest.mark.slow)])
def test_solver_reuse_runs_on_the_stepper(monkeypatch, case):
    """Solver "reuse" (LU factors kept over steps and calls, refreshed when an iteration
    contracts slowly or diverges): on the compiled stepper, bitwise the Python stepper's --
    rows, iterations and the kept factors, permutations and flags -- in two chunks.  The
    N-body cases have kernels that loop over the pair terms (methodgen.lower_loops) and a
    dense LU of more than three unknowns."""
    if case == "nbody3-em2":
        from methodgen.app.bench import nbody_initial, nbody_system

        scene = SimpleNamespace(system=nbody_system(3), y0=nbody_initial(3), h=0.01)
        method, kw = "energy-momentum", {}
    else:
        name, method, kw = {"hh2d-em4": ("henon-heiles-2d", "energy-momentum", {"order": 4}),
                            "kepler-gauss2": ("kepler", "gauss", {"stages": 2}),
                            "oss-em2": ("outer-solar-system", "energy-momentum", {})}[case]
        scene = mg.load_scene(name)
    mod = mg.build(scene.system, method, backend="numba", **kw)
    if case.startswith(("nbody", "oss")):
        assert np.size(mod._IDX0), "the N-body module loops over its pairs"
    y0 = np.array(scene.y0, float)
    runs = {}
    for fused in ("1", "0"):
        _mode(monkeypatch, fused)
        calls = _counting(monkeypatch)
        info = {}
        first = mod.integrate(y0, scene.h, 150, solver="reuse", info=info)
        second = mod.integrate(first[-1], scene.h, 100, solver="reuse", info=info)
        st = info["solver_state"][3]
        runs[fused] = [first, second, np.asarray(info["newton_iterations"])] + [np.asarray(a) for a in st]
        assert (calls == []) == (fused == "1"), (fused, calls)
    for a, b in zip(runs["1"], runs["0"]):
        assert np.array_equal(a, b)
    assert runs["1"][4].all() and runs["1"][5].any()      # factors were kept, and valid


def test_a_strided_out_runs_on_the_stepper(monkeypatch):
    """A caller's ``out`` that is not contiguous (every other column of a larger array): the
    stepper writes a contiguous copy of the rows a call reaches and copies them back -- the
    numba runtime is not called, and the rows are those of a run into a fresh array."""
    scene = mg.load_scene("kepler")
    mod = mg.build(scene.system, "energy-momentum", backend="numba")
    y0 = np.array(scene.y0, float)
    _mode(monkeypatch, "1")
    ref = mod.integrate(y0, scene.h, 300, save_every=3)
    calls = _counting(monkeypatch)
    big = np.full((ref.shape[0], 12), -7.0)
    out = big[:, ::2]
    assert mod.integrate(y0, scene.h, 300, save_every=3, out=out) is out
    assert np.array_equal(out, ref) and calls == []
    assert np.all(big[:, 1::2] == -7.0)              # the other columns untouched


def test_work_arrays_kept_between_calls_carry_nothing_over():
    """The compiled loop keeps its work arrays between calls (per loop, size and thread): a run
    after a failed one, after other batch sizes and from other threads gives the rows it gives
    first in a fresh process-state.  Control: the failing run does fail (a stale failure record
    would then be the only way the next run could go wrong)."""
    import threading

    kep = mg.load_scene("kepler").system
    mod = mg.build(kep, "energy-momentum", backend="numba")
    y0 = APO.copy()
    first = mod.integrate(y0, 0.05, 40)
    one = mod.integrate(y0, 0.05, 1)
    with pytest.raises(mod.ResolutionError):          # h = 2 does not resolve the pericentre
        mod.integrate(y0, 2.0, 40)
    assert np.array_equal(mod.integrate(y0, 0.05, 40), first)
    Y = np.stack([y0, y0 * 1.01, y0 * 0.99])
    batch = mod.integrate(Y, 0.05, 40)
    assert np.array_equal(batch[:, 0], first) and np.array_equal(mod.integrate(y0, 0.05, 1), one)
    out = {}

    def run(k):
        out[k] = [mod.integrate(Y if k % 2 else y0, 0.05, 40) for _ in range(5)]

    threads = [threading.Thread(target=run, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k, runs in out.items():
        for r in runs:
            assert np.array_equal(r, batch if k % 2 else first)
