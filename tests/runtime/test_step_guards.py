"""Per-step guards of the runtimes (both backends), with their negative controls.

* A time transformation whose g reaches 0: g = q on the harmonic oscillator from
  (q, p) = (1, -1); the physical trajectory reaches q = 0 at t = π/4, the flow of
  K = g(H + e) only creeps towards it (K's error divided by a vanishing g outgrows the
  energy: the level-set guard), and a coarse midpoint step lands beyond it (g < 0).
* ``initial_state`` refuses g(y0) <= 0.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg

Y0_TT = np.array([1.0, -1.0])          # (q, p): H = 1, q reaches 0 at t = π/4


@pytest.fixture(scope="module")
def tt_modules(tmp_path_factory):
    root = tmp_path_factory.mktemp("guards")
    K = mg.time_transform(mg.load_scene("harmonic").system, "q")
    cache = {}

    def get(method, backend="numpy"):
        if (method, backend) not in cache:
            cache[method, backend] = mg.generate(mg.discretize(K, method), root / f"ttq_{method}_{backend}.py",
                                                 backend=backend)
        return cache[method, backend]

    return get


def _h_phys_error(mod, tr):
    Hp = mod.invariants(tr)["H_phys"]
    return float(np.max(np.abs(Hp - Hp[0])))


def _check_g_guards(mod):
    """The checks of one module (either backend)."""
    Y0 = mod.initial_state(Y0_TT)
    # The level-set guard stops the run where g has collapsed (before H_phys is wrong by 100%).
    with pytest.raises(mod.ResolutionError, match=r"g = q has fallen to .* at step \d+ .*state \{'q'") as ei:
        mod.integrate(Y0, 0.3, 400)
    assert ei.value.check == "time_scale" and 0 < ei.value.trajectory[-1, 0] < 0.1
    assert ei.value.step == len(ei.value.trajectory) - 1
    # the rows before the failure are an honest run: physical energy within its midpoint error
    # (each row has |H + e| <= MAX_LEVEL_DEFECT (|e| + |T| + |U|) <= 0.1 (1 + 2 |e|))
    assert _h_phys_error(mod, ei.value.trajectory) < 0.3
    # negative control: without the guard the run ends with 0 and H_phys wrong by ~100 %
    tr = mod.integrate(Y0, 0.3, 400, check_resolution=False)
    assert _h_phys_error(mod, tr) > 0.9
    # A coarse step lands at g < 0: refused always (also without check_resolution), naming g.
    for cr in (True, False):
        with pytest.raises(mod.NonFiniteError, match=r"g = q is -0\.24\d* <= 0 at step 0 \(state") as ei:
            mod.integrate(Y0, 1.6, 10, check_resolution=cr)
        assert ei.value.state[0] < 0
    # an extended state with g <= 0 is refused at the start
    with pytest.raises(mod.NonFiniteError, match=r"g = q is -1, not > 0"):
        mod.integrate(np.array([-1.0, 0.0, 1.0, -1.0]), 0.1, 3)
    with pytest.raises(mod.NonFiniteError, match=r"g = q is -1, not > 0.*trajectories \[1\]"):
        mod.integrate(np.array([[1.0, 0.0, -1.0, -1.0], [-1.0, 0.0, 1.0, -1.0]]), 0.1, 3)


def test_g_guards_numpy(tt_modules):
    mod = tt_modules("midpoint")
    _check_g_guards(mod)
    # batch path: the same failure, named by trajectory
    Y = mod.initial_state(np.array([[1.0, 1.0], [1.0, -1.0]]))
    with pytest.raises(mod.ResolutionError, match=r"trajectories \[1\]"):
        mod.integrate(Y, 0.3, 400)


def test_g_crossing_negative_control(tt_modules):
    """Without the g guard the midpoint step at h = 1.6 is an ordinary converged step to q < 0:
    the state the NonFiniteError names solves the step equations (the unknowns are the
    increments), so an unguarded runtime returns it -- physical time then runs backwards."""
    mod = tt_modules("midpoint")
    assert all(name.startswith("_d_") for name in mod.UNKNOWN_NAMES)
    Y0 = mod.initial_state(Y0_TT)
    with pytest.raises(mod.NonFiniteError) as ei:
        mod.integrate(Y0, 1.6, 1)
    y1 = ei.value.state
    assert np.max(np.abs(mod.residual(y1 - Y0, Y0, 1.6))) < 1e-14
    assert y1[0] < 0 and y1[1] < Y0[1] + 1.6 * 1.0   # g < 0; dt = g dτ: t advanced less than g(y0) h


def test_avf_stops_on_the_guard_not_on_newton(tt_modules):
    """AVF keeps K to round-off, yet g = q shrinks geometrically: the level-set guard names the
    cause (it used to end in a Newton failure at g ~ 1e-18)."""
    mod = tt_modules("avf")
    with pytest.raises(mod.ResolutionError, match="has fallen to") as ei:
        mod.integrate(mod.initial_state(Y0_TT), 0.3, 400)
    assert ei.value.trajectory[-1, 1] == pytest.approx(np.pi / 4, abs=0.01)   # physical time stalls at π/4
    # negative control: unguarded, the run ends in Newton's method failing (or in nonsense)
    try:
        tr = mod.integrate(mod.initial_state(Y0_TT), 0.3, 400, check_resolution=False)
    except mod.ConvergenceError:
        pass
    else:
        assert _h_phys_error(mod, tr) > 0.5


def _check_roundoff_residual_message(mod):
    """Unguarded, g = q creeps to 0 and the increments become far smaller than the state: a
    simplified-Newton residual at the state's round-off is not a failure of h (it used to say
    "try a smaller step size h" with a residual of 5e-17); a real divergence still is."""
    Y0 = mod.initial_state(Y0_TT)
    with pytest.raises(mod.ConvergenceError) as ei:
        mod.integrate(Y0, 0.3, 400, solver="simplified", check_resolution=False)
    y = ei.value.trajectory[-1]
    assert ei.value.residual_norm <= 4 * 2.2e-16 * np.abs(y).max()
    assert ei.value.converging and "raise maxiter" in str(ei.value) and "smaller step" not in str(ei.value)
    # negative control: Newton's method failing with a residual of O(1) keeps the advice on h
    with pytest.raises(mod.ConvergenceError) as ei:
        mod.integrate(Y0, 0.3, 400, solver="newton", check_resolution=False)
    assert ei.value.residual_norm > 1 and not ei.value.converging and "smaller step size h" in str(ei.value)


def test_roundoff_residual_is_not_called_a_step_size_failure(tt_modules):
    _check_roundoff_residual_message(tt_modules("avf"))


def test_initial_state_refuses_g_not_positive(tt_modules):
    mod = tt_modules("midpoint")
    with pytest.raises(ValueError, match=r"g = q is -1 at y0; it must be > 0"):
        mod.initial_state(np.array([-1.0, 1.0]))
    with pytest.raises(ValueError, match=r"g = q is 0 at y0\[1\]"):
        mod.initial_state(np.array([[1.0, 1.0], [0.0, 1.0]]))
    assert mod.initial_state(np.array([0.5, 1.0]))[0] == 0.5        # positive g: accepted


def test_g_guards_numba(tt_modules):
    pytest.importorskip("llvmlite")
    _check_g_guards(tt_modules("midpoint", "numba"))


# --- linear fields: exempt from the resolution guard, but an unresolved h is warned of ---------

@pytest.fixture(scope="module")
def linear_modules(tmp_path_factory):
    root = tmp_path_factory.mktemp("linear")
    system = mg.load_scene("harmonic").system
    cache = {}

    def get(backend="numpy", method="midpoint"):
        if (backend, method) not in cache:
            cache[backend, method] = mg.generate(mg.discretize(system, method), root / f"harm_{method}_{backend}.py",
                                                 backend=backend)
        return cache[backend, method]

    return get


def _check_linear_warning(mod):
    import warnings

    with pytest.warns(mod.ResolutionWarning, match=r"h\*omega = 1e\+04 > pi.*aliased.*use h <= 2e-06"):
        mod.integrate([1.0, 0.0], 0.01, 10, {"k": 1e12})
    # negative controls: a resolved h (h·ω = 0.1), and check_resolution=False, are silent
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mod.integrate([1.0, 0.0], 0.1, 10)
        mod.integrate([1.0, 0.0], 0.01, 10, {"k": 1e12}, check_resolution=False)
        mod.integrate([1.0, 0.0], 3.1, 10)            # h·ω = 3.1: two steps per period and more
    with pytest.warns(mod.ResolutionWarning, match=r"h\*omega = 3\.2"):
        mod.integrate([1.0, 0.0], 3.2, 10)            # just below two


def test_linear_warning_numpy(linear_modules):
    mod = linear_modules()
    assert mod.MAX_RESOLUTION is None and mod.MAX_LOCAL_ERROR is None    # exempt from the guard
    _check_linear_warning(mod)
    _check_linear_warning(linear_modules(method="energy-momentum"))


def test_linear_warning_numba(linear_modules):
    pytest.importorskip("llvmlite")
    _check_linear_warning(linear_modules("numba"))


def test_linear_warning_cli_one_line(tmp_path):
    import subprocess
    import sys

    scene = tmp_path / "stiff.toml"
    scene.write_text('name = "stiff"\n[system]\nH = "p**2/(2*m) + k*q**2/2"\nq = ["q"]\np = ["p"]\n'
                     '[params]\nm = 1.0\nk = 1e12\n[run]\nmethod = ["midpoint"]\nh = 0.01\nsteps = 100\n'
                     'y0 = [1.0, 0.0]\n')
    res = subprocess.run([sys.executable, "-m", "methodgen", "run", str(scene)], capture_output=True, text=True,
                         cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("methodgen: warning: step size h = 0.01 does not resolve")
    assert "Traceback" not in res.stderr


# --- a step landing inside a thin barrier ------------------------------------------------------

BARRIER = "p**2/2 + 10*exp(-(q/0.005)**2)"      # energy 2 < 10: the exact motion is reflected


@pytest.fixture(scope="module")
def barrier_modules(tmp_path_factory):
    root = tmp_path_factory.mktemp("barrier")
    system = mg.Hamiltonian(BARRIER, q=["q"], p=["p"], name="barrier")
    cache = {}

    def get(method, backend="numpy"):
        if (method, backend) not in cache:
            cache[method, backend] = mg.generate(mg.discretize(system, method),
                                                 root / f"bar_{method.replace('-', '_')}_{backend}.py", backend=backend)
        return cache[method, backend]

    return get


def _check_barrier(mod):
    # from q = -1 at h = 0.1 the fifth step ends at q = 0, the barrier's top: H jumps 2 -> 12
    with pytest.raises(mod.ResolutionError, match=r"at step 4: H changed by 5 times its own size") as ei:
        mod.integrate([-1.0, 2.0], 0.1, 20)
    assert ei.value.check == "energy_jump" and ei.value.suggested_h < 0.1
    assert len(ei.value.trajectory) == 5
    # negative control: without the guard the step is accepted, H jumps by 10 and back, and
    # the particle is transmitted (the exact one is reflected)
    tr = mod.integrate([-1.0, 2.0], 0.1, 20, check_resolution=False)
    H = mod.hamiltonian(tr)
    assert np.abs(H - 2.0).max() == pytest.approx(10.0, rel=1e-6) and tr[-1, 0] > 2.5
    # batch: the trajectory that lands in the barrier is named
    with pytest.raises(mod.ResolutionError, match=r"trajectories \[1\]"):
        mod.integrate([[-1.1, 2.0], [-1.0, 2.0]], 0.1, 20)


@pytest.mark.parametrize("method", ["stormer-verlet", "midpoint"])
def test_barrier_energy_jump_numpy(barrier_modules, method):
    _check_barrier(barrier_modules(method))


def test_barrier_energy_jump_numba(barrier_modules):
    pytest.importorskip("llvmlite")
    _check_barrier(barrier_modules("stormer-verlet", "numba"))


@pytest.fixture(scope="module")
def barrier_o4(tmp_path_factory):
    """Störmer–Verlet composed to order 4 (triple jump) on the barrier, numpy and compiled."""
    root = tmp_path_factory.mktemp("barrier4")
    scheme = mg.discretize(mg.Hamiltonian(BARRIER, q=["q"], p=["p"], name="barrier"), "stormer-verlet", order=4,
                           composition="triple-jump")
    return {b: mg.generate(scheme, root / f"bar4_{b}.py", backend=b) for b in ("numpy", "numba")}


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_composition_tests_the_energy_jump_once_per_composed_step(barrier_o4, backend):
    """The triple jump's fifth step from q = -1 (h = 0.1) drifts over the barrier and back, and its
    last stage ends on the barrier's top: H jumps at the composed step's end.  The composition tests
    H there, once per composed step (its post kernel gives no H: the configuration says EJUMP 2);
    the error is the composed step's, with no stage named.  Control: without the guard the step is
    accepted and H jumps by 10."""
    if backend == "numba":
        pytest.importorskip("llvmlite")
    mod = barrier_o4[backend]
    assert mod._STAGES == 3
    if backend == "numba":
        from methodgen.codegen.abi import CFG
        assert int(mod._CFG[CFG["EJUMP"]]) == 2 and int(mod._CFG[CFG["POST_LEN"]]) == int(mod._CFG[CFG["POST_EJ"]])
    with pytest.raises(mod.ResolutionError, match=r"at step 4: H changed by [0-9.]+ times its own size") as ei:
        mod.integrate([-1.0, 2.0], 0.1, 20)
    assert ei.value.check == "energy_jump" and "[stage" not in str(ei.value)
    assert len(ei.value.trajectory) == 5
    tr = mod.integrate([-1.0, 2.0], 0.1, 20, check_resolution=False)
    assert np.abs(mod.hamiltonian(tr) - 2.0).max() > 5.0
    # a batch names the trajectory
    with pytest.raises(mod.ResolutionError, match=r"trajectories \[1\]"):
        mod.integrate([[-1.1, 2.0], [-1.0, 2.0]], 0.1, 20)


def test_a_lockstep_batch_names_the_lane_whose_composed_step_jumps(barrier_o4):
    """The compiled lock-step loop (a batch of at least MIN_BATCH trajectories) makes the same
    per-step test lane by lane: of 20 lanes, the one started at q = -1 lands on the barrier's top
    at step 4 and is named; the numpy batch names the same lane and step.  Control: the other
    lanes alone run through."""
    pytest.importorskip("llvmlite")
    from methodgen.runtime.nbabi import MIN_BATCH
    starts = np.array([[-5.0 - 0.01 * k, 2.0] for k in range(20)])     # (never near the barrier in 20 steps)
    starts[7] = [-1.0, 2.0]
    assert len(starts) >= MIN_BATCH
    for backend in ("numba", "numpy"):
        mod = barrier_o4[backend]
        with pytest.raises(mod.ResolutionError, match=r"at step 4.*trajectories \[7\]") as ei:
            mod.integrate(starts, 0.1, 20)
        assert ei.value.check == "energy_jump"
        mod.integrate(np.delete(starts, 7, axis=0), 0.1, 20)


def test_a_composition_reports_a_non_finite_state_at_the_same_step_on_both_backends(tmp_path):
    """The compiled loop checks an explicit composition's state for inf/NaN at the composed step's
    end (a stage's inf or NaN stays in the state); the numpy module at every stage.  A Hénon–Heiles
    orbit above the escape energy blows up: both name the same step (control: the runs do fail)."""
    pytest.importorskip("llvmlite")
    scheme = mg.discretize(mg.load_scene("henon-heiles-2d").run_system, "stormer-verlet", order=4)
    a = mg.generate(scheme, tmp_path / "hh4_numpy.py")
    b = mg.generate(scheme, tmp_path / "hh4_numba.py", backend="numba")
    for y0 in ([0.0, 0.0, 3.0, 3.0], [0.5, -2.0, 1.0, 1.0]):
        steps = []
        for mod in (a, b):
            with pytest.raises(mod.NonFiniteError) as ei:
                mod.integrate(np.array(y0), 0.1, 200, check_resolution=False)
            steps.append(ei.value.step)
        assert steps[0] == steps[1] and steps[0] > 5


def test_barrier_thinner_than_a_step_is_invisible(barrier_modules):
    """The documented limit (README): from q = -1.1 no step end touches the barrier and the
    force is ~0 wherever a step evaluates it -- no fixed-step method can see it.  A step that
    resolves the barrier reflects the particle, as the exact motion is."""
    mod = barrier_modules("stormer-verlet")
    tr = mod.integrate([-1.1, 2.0], 0.1, 20)                 # silently transmitted
    assert tr[-1, 0] > 2.5 and np.abs(mod.hamiltonian(tr) - 2.0).max() < 1e-12
    tr = mod.integrate([-1.1, 2.0], 0.001, 1200)             # resolved: reflected
    assert tr[-1, 0] < -1.0


def test_roundoff_residual_message_numba(tt_modules):
    pytest.importorskip("llvmlite")
    _check_roundoff_residual_message(tt_modules("avf", "numba"))
