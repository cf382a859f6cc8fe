"""The stepper (methodgen.runtime.stepper): one source, run two ways -- compiled with a module's
kernels inlined (LLVM, methodgen.runtime.fused) and executed as plain Python -- bitwise the same.

The Python execution calls the same kernels (compiled), so what is compared is the stepper
itself: stages, every Newton solver, the linearly implicit solve, compensated sums,
first-same-as-last, every check and the failures' status, step, value and stage, and the
question it asks its driver where a resolution verdict needs eigenvalues.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg

pytest.importorskip("llvmlite")

E = 0.99
APO = np.array([1 + E, 0.0, 0.0, 0.0, math.sqrt((1 - E) / (1 + E)), 0.0])
OSC = "(p1**2 + p2**2)/(2*m) + k*(q1**2 + q2**2)/2 + c*q1*p2 + k*q1**4"


def _module(case):
    if case == "osc-undecided":
        return mg.build_text(OSC, ["q1", "q2"], ["p1", "p2"], "midpoint", params={"m": 0.01, "k": 0.01, "c": 0.001},
                             name="osc2_1", backend="numba"), np.array([0.3, 0.0, 0.0, 0.01]), 0.2
    if case == "logh-sv4":
        L = mg.time_transform(mg.load_scene("kepler").system, form="log")
        mod = mg.build(L, "stormer-verlet", backend="numba", order=4)
        return mod, mod.initial_state(np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])), 2 * math.pi / 40
    scene, method, kw = {
        "kepler-sv4": ("kepler", "stormer-verlet", {"order": 4}),
        "kepler-em2": ("kepler", "energy-momentum", {}),
        "hh2d-em4": ("henon-heiles-2d", "energy-momentum", {"order": 4}),
        "hh-kahan": ("henon-heiles", "kahan", {}),
        "kepler-gauss2": ("kepler", "gauss", {"stages": 2}),
        "dp-rattle": ("double-pendulum", "rattle", {}),
        # projected steps (methodgen.symbolic.projection): symmetric onto H, a first-same-as-last
        # splitting, the standard projection onto four invariants
        "hh-proj": ("henon-heiles-2d", "stormer-verlet", {"project": "energy"}),
        "hh-bm-proj": ("henon-heiles-2d", "stormer-verlet", {"order": 4, "composition": "blanes-moan-rkn",
                                                             "project": "energy"}),
        "kepler-proj-std": ("kepler", "stormer-verlet", {"project": "invariants-standard"}),
    }[case]
    sc = mg.load_scene(scene)
    return mg.build(sc.system, method, backend="numba", **kw), np.array(sc.y0, float), sc.h


def _run(monkeypatch, mod, y0, h, steps, mode, **kw):
    """(rows, iterations, error) of a run on the compiled stepper or the stepper as Python."""
    monkeypatch.setenv("METHODGEN_STEPPER", "python" if mode == "python" else "")
    info = {}
    try:
        rows = mod.integrate(np.stack([y0, y0 * (1 + 1e-4)]), h, steps, save_every=3, info=info, **kw)
        err = None
    except Exception as e:        # a failure: its type, step and message, and the rows before it
        rows, err = getattr(e, "trajectory", None), (type(e).__name__, getattr(e, "step", None), str(e))
    return rows, np.asarray(info.get("newton_iterations", [])), err


CASES = [("kepler-sv4", 40, {}), ("logh-sv4", 40, {}), ("kepler-em2", 30, {}), ("hh2d-em4", 20, {}),
         ("hh2d-em4", 20, {"solver": "auto"}), ("hh2d-em4", 20, {"solver": "fixed-point"}),
         ("hh2d-em4", 20, {"solver": "simplified"}), ("hh2d-em4", 20, {"solver": "reuse"}),
         ("kepler-gauss2", 20, {"solver": "reuse"}), ("hh-kahan", 30, {}), ("kepler-gauss2", 20, {}),
         ("dp-rattle", 20, {}), ("osc-undecided", 10, {}),
         ("hh-proj", 30, {}), ("hh-proj", 30, {"compensated": False}), ("hh-bm-proj", 20, {}),
         ("kepler-proj-std", 30, {}),
         # a projected step's failures: the base step's local error, maxiter
         ("hh-proj", 5, {"h": 1.0}), ("hh-proj", 5, {"maxiter": 1}),
         # failures: a step over the pericentre (local error), maxiter, an unresolved Newton matrix
         ("kepler-sv4", 200, {"y0": APO, "h": 0.2}), ("hh2d-em4", 20, {"maxiter": 2, "solver": "newton"}),
         ("hh2d-em4", 20, {"h": 2.5})]


@pytest.mark.parametrize("case, steps, kw", CASES,
                         ids=[f"{c}-{i}" for i, (c, _, _) in enumerate(CASES)])
def test_python_and_compiled_steppers_agree_bitwise(monkeypatch, case, steps, kw):
    mod, y0, h = _module(case)
    kw = dict(kw)
    y0 = kw.pop("y0", y0)
    h = kw.pop("h", h)
    compiled = _run(monkeypatch, mod, y0, h, steps, "compiled", **kw)
    python = _run(monkeypatch, mod, y0, h, steps, "python", **kw)
    assert compiled[2] == python[2]
    for a, b in zip(compiled[:2], python[:2]):
        assert (a is None and b is None) or np.array_equal(a, b)
    if case == "kepler-sv4" and "y0" not in kw and steps == 40:
        assert compiled[2] is None
    if steps == 200 or kw.get("maxiter") in (1, 2) or kw.get("h") in (1.0, 2.5):
        assert compiled[2] is not None               # the failure cases fail


def test_negative_control_an_edited_stepper_is_caught(monkeypatch):
    """The comparison can fail: a Python stepper whose compensated update drops the rounding
    error it should carry (one statement of the source edited: the composed step's sum, the
    module running merged kicks) gives other bits."""
    import inspect
    import textwrap

    from methodgen.runtime import stepper
    mod, y0, h = _module("kepler-sv4")
    compiled = _run(monkeypatch, mod, y0, h, 40, "compiled")
    src = textwrap.dedent(inspect.getsource(stepper.stepper))
    assert mod._MERGED_KICKS
    line = "_cl[_i] = _a - (_s - _yl[_i])"
    assert src.count(line) == 1
    namespace = {"math": math}
    exec(compile(src.replace(line, "_cl[_i] = 0.0"), "edited_stepper", "exec"), namespace)
    monkeypatch.setattr(stepper, "stepper", namespace["stepper"])
    python = _run(monkeypatch, mod, y0, h, 40, "python")
    assert not np.array_equal(compiled[0], python[0])


@pytest.mark.parametrize("solver", ["newton", "simplified", "fixed-point", "reuse", "auto"])
def test_every_option_combination_compiled_is_the_python_stepper(monkeypatch, solver):
    """The options that select code (solver, check_resolution, compensated, a tolerance) are
    constants of each compiled loop: every combination, compiled, gives the bits of the same
    source run as Python (one module, a batch of two, rows kept every 3 steps, two chunks)."""
    mod, y0, h = _module("hh2d-em4")
    for chk in (True, False):
        for comp in (True, False):
            for tol in (None, 1e-12):
                kw = dict(solver=solver, check_resolution=chk, compensated=comp)
                if tol is not None:
                    kw["tol"] = tol
                runs = {}
                for mode in ("compiled", "python"):
                    monkeypatch.setenv("METHODGEN_STEPPER", "python" if mode == "python" else "")
                    info = {}
                    Y0 = np.stack([y0, y0 * (1 + 1e-4)])
                    first = mod.integrate(Y0, h, 12, save_every=3, info=info, **kw)
                    second = mod.integrate(first[-1], h, 9, info=info, **kw)
                    runs[mode] = (first, second, np.asarray(info["newton_iterations"]))
                for a, b in zip(runs["compiled"], runs["python"]):
                    assert np.array_equal(a, b), (solver, chk, comp, tol)
