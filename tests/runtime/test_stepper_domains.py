"""States leaving the real domain of H (issue 13, item 2, the generated steppers).

A state where H is not real -- the argument of a log at or below 0, of a square root
or fractional power below 0 -- raises NonFiniteError at the first such step, in both
backends, for one trajectory and for a batch; so does an initial state (or a
parameter such as a zero mass) where H or its gradient is not defined.  Before, the
midpoint rule stepped on into q < 0 for H = p²/2 + log(q) (the vector field -1/q is
real there) and returned H = NaN without a word.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg

LOG = mg.Hamiltonian("p**2/2 + log(q)", q=["q"], p=["p"], name="logq")
ROOT = mg.Hamiltonian("p**2/2 + c*q**(3/2)", q=["q"], p=["p"], params={"c": 1.0}, name="root")
MASS = mg.Hamiltonian("p**2/(2*m) + q**4/4", q=["q"], p=["p"], params={"m": 1.0}, name="quartic_m")


@pytest.fixture(scope="module")
def numba_log(modules, tmp_path_factory):
    pytest.importorskip("llvmlite")
    scheme, _ = modules(LOG, "midpoint")
    return mg.generate(scheme, tmp_path_factory.mktemp("numba_domain") / "logq_midpoint_numba.py",
                       backend="numba")


def _log_modules(modules, numba_log=None):
    mods = [modules(LOG, m)[1] for m in ("midpoint", "energy-momentum", "stormer-verlet")]
    return mods + ([numba_log] if numba_log is not None else [])


def test_domain_conditions_are_only_those_that_can_fail(modules, kepler):
    assert modules(LOG, "midpoint")[1].DOMAIN_CONDITIONS == (("positive", "q"),)
    assert modules(ROOT, "midpoint")[1].DOMAIN_CONDITIONS == (("nonnegative", "q"),)
    # sqrt(x**2 + y**2 + z**2) >= 0 is proved: Kepler checks nothing per step
    assert modules(kepler, "energy-momentum")[1].DOMAIN_CONDITIONS == ()


def test_initial_state_outside_the_domain(modules, numba_log):
    """The issue's reproduction: H = p²/2 + log(q) from y0 = (-1, 0.3)."""
    for mod in _log_modules(modules, numba_log):
        for Y, where in [(np.array([-1.0, 0.3]), "y0 = [-1.0, 0.3]"),
                         (np.array([[1.0, 0.3], [-1.0, 0.3]]), "(trajectories [1])")]:
            with pytest.raises(mod.NonFiniteError) as err:
                mod.integrate(Y, 0.01, 10)
            e = err.value
            assert e.step == 0 and e.trajectory.shape == (1,) + Y.shape
            assert "initial state" in str(e) and "q > 0" in str(e) and where in str(e)
            assert "does not help" in str(e)  # no advice to shrink h
        # Negative control: from inside the domain, moving away from q = 0, no error.
        traj = mod.integrate(np.array([1.0, 0.3]), 0.01, 100)
        assert np.all(np.isfinite(mod.hamiltonian(traj)))


def test_state_leaving_the_domain_at_the_first_such_step(modules, numba_log):
    """From q = 1 towards q = 0 with a large step: the step that jumps to q < 0 raises
    (check_resolution=False: the domain check, not the resolution guards, which refuse
    the run earlier by default)."""
    y0 = np.array([1.0, -2.0])
    for mod in _log_modules(modules, numba_log):
        if mod.METHOD == "energy-momentum":
            continue  # its discrete gradient log[q0, q1] is NaN for q1 < 0: Newton reports it
        for Y in (y0, np.stack([np.array([1.0, 0.3]), y0])):
            with pytest.raises(mod.NonFiniteError) as err:
                mod.integrate(Y, 0.2, 100, check_resolution=False)
            e = err.value
            assert "left the real domain of H" in str(e) and "q > 0 is violated" in str(e)
            assert e.step > 0 and e.trajectory.shape[0] == e.step + 1
            rows = e.trajectory if Y.ndim == 1 else e.trajectory[:, 1]
            assert np.all(rows[:, 0] > 0) and np.all(np.isfinite(mod.hamiltonian(rows)))
            # Negative control: the state the step produced is where H is NaN -- what the
            # run used to return silently.
            state = e.state if Y.ndim == 1 else e.state[0]
            assert state[0] <= 0
            with np.errstate(invalid="ignore"):
                assert np.isnan(mod.hamiltonian(state))
            if Y.ndim == 2:
                assert "(trajectories [1])" in str(e)
        with pytest.raises(mod.ResolutionError):
            mod.integrate(y0, 0.2, 100)


def test_newton_iterates_outside_the_domain(modules):
    """Energy-momentum: log[q0, q1] is NaN for q1 < 0, so Newton has no solution to offer
    (a named error, never a NaN state)."""
    _, mod = modules(LOG, "energy-momentum")
    with pytest.raises((mod.ConvergenceError, mod.ResolutionError, mod.NonFiniteError)) as err:
        mod.integrate(np.array([1.0, -2.0]), 0.1, 100, check_resolution=False)
    assert np.all(np.isfinite(err.value.trajectory))


def test_fractional_power(modules):
    _, mod = modules(ROOT, "midpoint")
    with pytest.raises(mod.NonFiniteError, match="q >= 0"):
        mod.integrate(np.array([-0.5, 0.0]), 0.01, 10)
    with pytest.raises(mod.NonFiniteError) as err:  # (the field -1.5 c q^(1/2) is NaN there too)
        mod.integrate(np.array([1.0, -3.0]), 0.2, 100, check_resolution=False)
    assert np.all(err.value.trajectory[:, 0] >= 0)


def test_zero_mass_is_not_a_step_size_problem(modules):
    for method in ("midpoint", "stormer-verlet"):
        _, mod = modules(MASS, method)
        for Y in (np.array([1.0, 0.5]), np.array([[1.0, 0.5], [0.5, 0.0]])):
            with pytest.raises(mod.NonFiniteError) as err:
                mod.integrate(Y, 0.01, 10, {"m": 0.0})
            msg = str(err.value)
            assert err.value.step == 0 and "initial state" in msg and "'m': 0.0" in msg
            assert "does not help" in msg and "try a smaller step size" not in msg
        # Negative control: the same module with m = 1.
        mod.integrate(np.array([1.0, 0.5]), 0.01, 10, {"m": 1.0})


def test_numba_initial_zero_mass(modules, tmp_path):
    pytest.importorskip("llvmlite")
    scheme, _ = modules(MASS, "stormer-verlet")
    mod = mg.generate(scheme, tmp_path / "quartic_m_stormer_verlet_numba.py", backend="numba")
    with pytest.raises(mod.NonFiniteError, match="initial state") as err:  # raised before compiling
        mod.integrate(np.array([1.0, 0.5]), 0.01, 10, {"m": 0.0})
    assert "try a smaller step size" not in str(err.value)


def test_numba_local_error_and_advice(modules, numba_log):
    """The compiled loop's local error estimate and Newton advice agree with numpy's
    (the same module as above: compiled once)."""
    _, np_mod = modules(LOG, "midpoint")
    for Y in (np.array([1.0, -2.0]), np.array([[1.0, 0.3], [1.0, -2.0]])):
        errs = []
        for mod in (np_mod, numba_log):
            with pytest.raises(mod.ResolutionError) as err:
                mod.integrate(Y, 0.2, 100)
            errs.append(err.value)
        a, b = errs
        assert a.check == b.check == "local_error" and a.step == b.step > 0
        assert b.resolution == pytest.approx(a.resolution, rel=1e-9) and b.suggested_h < 0.2
        np.testing.assert_allclose(b.trajectory, a.trajectory, rtol=0, atol=1e-13)
    # maxiter too small, the residual already at round-off: "raise maxiter", not a smaller h
    for mod in (np_mod, numba_log):
        with pytest.raises(mod.ConvergenceError) as err:
            mod.integrate(np.array([1.0, 0.3]), 0.01, 5, maxiter=1)
        assert "raise maxiter" in str(err.value) and "smaller step size" not in str(err.value)
