"""Nonlinear solvers that pay only for what they need (issue 16 item 2): "auto" and "reuse".

"auto" iterates the fixed point z <- F(z) (one residual per iteration, no Jacobian, no
linear solve) while it contracts fast and switches to Newton's method where it does not;
"reuse" keeps the factorised Newton matrix over iterations and steps.  Both stop with the
same round-off rule as Newton's method, so they must give the same steps to round-off —
and the guards (local error, h·ω, predictor) must still fire.
"""
from pathlib import Path

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen.emit import load_module, module_filename

GENERATED = Path(__file__).resolve().parents[2] / "generated"


def load_generated(name):
    """A committed module of generated/ (their sync with the generator is tested elsewhere)."""
    return load_module(GENERATED / f"{name}.py")


@pytest.fixture(scope="module")
def tt_avf(tmp_path_factory):
    """Kepler e = 0.99 under the time transformation g = |q| (8 unknowns): numpy, numba."""
    sc = mg.load_scene("kepler-eccentric")
    np_mod = load_generated("kepler_eccentric_tt_avf")
    pytest.importorskip("llvmlite")
    scheme = mg.discretize(sc.run_system, "avf")
    path = tmp_path_factory.mktemp("solvers") / module_filename(sc.run_system.name, "avf", "numba")
    nb_mod = mg.generate(scheme, path, backend="numba")
    y0 = np_mod.initial_state(np.array(sc.y0, dtype=float))
    return np_mod, nb_mod, y0, sc.h


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def test_default_solver_by_size(tt_avf):
    np_mod, nb_mod, y0, h = tt_avf
    assert np_mod.DEFAULT_SOLVER == nb_mod.DEFAULT_SOLVER == "auto"
    assert {"auto", "reuse"} <= set(np_mod.SOLVERS)
    small = load_generated("kepler_energy_momentum")  # 3 unknowns: the Jacobian is cheap
    assert small.DEFAULT_SOLVER == "newton" and small.SOLVERS[0] == "newton"
    a = np_mod.integrate(y0, h, 50)
    assert np.array_equal(a, np_mod.integrate(y0, h, 50, solver="auto"))


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=pytest.mark.slow)])
@pytest.mark.parametrize("solver", ["auto", "reuse", "fixed-point"])
def test_same_steps_as_newton(tt_avf, solver, backend):
    # numba only with -m slow: compiling this 8-unknown module costs ~40 s of the default
    # run, and its kernels are the numpy module's expressions (tests/test_numba.py checks
    # the backends agree, Gaussian elimination included)
    np_mod, nb_mod, y0, h = tt_avf
    mod = np_mod if backend == "numpy" else nb_mod
    steps = 400  # beyond the first pericentre passage (fictive step, |q| down to 0.01)
    ref = np_mod.integrate(y0, h, steps, solver="newton")
    info = {}
    y = mod.integrate(y0, h, steps, solver=solver, info=info)
    assert _rel(y, ref) < 1e-12, (mod.BACKEND, solver)
    assert info["newton_iterations"].min() >= 1
    # batches: every row as its single run, to round-off
    Y0 = np.array([y0, y0 + 1e-4 * np.eye(len(y0))[0]])
    Y = mod.integrate(Y0, h, 100, solver=solver)
    assert _rel(Y[:, 0], mod.integrate(y0, h, 100, solver=solver)) < 1e-12


def test_auto_switches_to_newton_where_the_fixed_point_is_slow():
    # Hénon–Heiles midpoint at h = 0.5: the fixed point contracts by about h·ω/2 per
    # iteration, too slowly for _AUTO_RATE, so "auto" runs Newton's method.
    mod = load_generated("henon_heiles_midpoint")
    y0 = np.array(mg.load_scene("henon-heiles").y0, dtype=float)
    its = {}
    for solver in ("newton", "fixed-point", "auto"):
        info = {}
        mod.integrate(y0, 0.5, 200, solver=solver, info=info)
        its[solver] = info["newton_iterations"].sum()
    assert its["auto"] < 0.8 * its["fixed-point"], its
    # Negative control: a module whose rate threshold never triggers behaves as the fixed point.
    rate = mod._AUTO_RATE
    try:
        mod._AUTO_RATE = 1e9
        info = {}
        mod.integrate(y0, 0.5, 200, solver="auto", info=info)
        assert info["newton_iterations"].sum() == its["fixed-point"]
    finally:
        mod._AUTO_RATE = rate


def test_reuse_refreshes_the_kept_matrix():
    mod = load_generated("henon_heiles_midpoint")
    y0 = np.array(mg.load_scene("henon-heiles").y0, dtype=float)
    ref = mod.integrate(y0, 0.3, 300, solver="newton")
    info = {}
    y = mod.integrate(y0, 0.3, 300, solver="reuse", info=info)
    assert _rel(y, ref) < 1e-12
    # Negative control: never refreshed for slow contraction (only on divergence), the
    # matrix of the first step serves the whole orbit and costs many more iterations.
    rate = mod._REUSE_RATE
    try:
        mod._REUSE_RATE = 1e9
        info_stale = {}
        y_stale = mod.integrate(y0, 0.3, 300, solver="reuse", info=info_stale)
    finally:
        mod._REUSE_RATE = rate
    assert _rel(y_stale, ref) < 1e-12  # still converged: the same stopping rule
    assert info_stale["newton_iterations"].sum() > 1.3 * info["newton_iterations"].sum()


@pytest.mark.parametrize("backend", ["numpy", pytest.param("numba", marks=pytest.mark.slow)])
@pytest.mark.parametrize("solver", ["auto", "reuse"])
def test_guards_still_fire(tt_avf, solver, backend):
    # Plain Kepler from pericentre with a step that does not resolve it: refused, with a
    # ResolutionError, whatever the solver.
    mod = load_generated("kepler_energy_momentum")
    y0 = np.array(mg.load_scene("kepler").y0, dtype=float)
    with pytest.raises(mod.ResolutionError):
        mod.integrate(y0, 0.5, 20, solver=solver)
    # Through the pericentre of e = 0.99 at 40x the fictive step: a named error, never an
    # orbit (a linearly converging iteration may give up before the estimate sees the step).
    np_mod, nb_mod, y0t, h = tt_avf
    m = np_mod if backend == "numpy" else nb_mod
    with pytest.raises((m.ResolutionError, m.ConvergenceError)):
        m.integrate(y0t, 40 * h, 400, solver=solver)


@pytest.mark.parametrize("solver", ["auto", "reuse"])
def test_chunks_equal_one_piece(pair, solver):
    # The solver state (auto's Newton hold, reuse's kept matrix) continues from chunk to
    # chunk through info, like the compensation: iterate() in chunks of 7 steps is bitwise
    # the run in one piece, on both backends.  h = 0.5 makes "auto" switch back and forth.
    pytest.importorskip("llvmlite")
    np_mod, nb_mod = pair("henon-heiles", "midpoint")
    y0 = np.array(mg.load_scene("henon-heiles").y0, dtype=float)
    for mod in (np_mod, nb_mod):
        whole = mod.integrate(y0, 0.5, 200, solver=solver)
        parts, info, y = [], {}, y0
        for k in range(0, 200, 7):
            n = min(7, 200 - k)
            part = mod.integrate(y, 0.5, n, solver=solver, info=info)
            parts.append(part if k == 0 else part[1:])
            y = part[-1]
        assert np.array_equal(np.concatenate(parts), whole), mod.BACKEND
        # Negative control: dropping the solver state between chunks changes the bits.
        if solver == "auto":
            parts, info, y = [], {}, y0
            for k in range(0, 200, 7):
                n = min(7, 200 - k)
                info.pop("solver_state", None)
                part = mod.integrate(y, 0.5, n, solver=solver, info=info)
                parts.append(part if k == 0 else part[1:])
                y = part[-1]
            assert not np.array_equal(np.concatenate(parts), whole), mod.BACKEND


def test_solver_state_is_not_taken_across_backends_or_solvers(pair):
    # One info dict handed from a numpy run to a numba run (or to another solver): the
    # state that does not belong to it is ignored, never misread.
    pytest.importorskip("llvmlite")
    np_mod, nb_mod = pair("henon-heiles", "midpoint")
    y0 = np.array(mg.load_scene("henon-heiles").y0, dtype=float)
    info = {}
    np_mod.integrate(y0, 0.5, 20, solver="reuse", info=info)
    info.pop("compensation")
    a = nb_mod.integrate(y0, 0.5, 20, solver="reuse", info=info)
    assert np.array_equal(a, nb_mod.integrate(y0, 0.5, 20, solver="reuse"))
    info.pop("compensation")
    b = nb_mod.integrate(y0, 0.5, 20, solver="auto", info=info)
    assert np.array_equal(b, nb_mod.integrate(y0, 0.5, 20, solver="auto"))
