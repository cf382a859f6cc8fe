"""``mod.solve``: a generated module's run as a :class:`Solution` (times, states, status,
statistics, invariant errors), on both backends.

Its rows are :func:`integrate`'s bitwise (the same run); a failed step is reported in the result
(status -1, the message, the rows before it), not raised; the invariant errors are measured on
the rows.  Each property has a control that shows the comparison can fail.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg

BACKENDS = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(
    __import__("importlib").util.find_spec("llvmlite") is None, reason="llvmlite not installed"))]


@pytest.fixture(scope="module", params=BACKENDS)
def em(request, kepler):
    return mg.build(kepler, "energy-momentum", backend=request.param)


Y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])


def test_fields_are_integrates_run(em):
    sol = em.solve(Y0, (0.0, 1.0), 0.03)
    # h shortened to land on t1 in whole steps: 34 steps of 1/34
    assert sol.status == 0 and sol.success and sol.nsteps == 34 and sol.h == 1.0 / 34
    assert sol.t[0] == 0.0 and sol.t[-1] == 1.0 and sol.t.shape == (35,)
    np.testing.assert_allclose(np.diff(sol.t), sol.h, rtol=1e-14)
    info = {}
    ref = em.integrate(Y0, sol.h, 34, info=info)
    assert np.array_equal(sol.y, ref)
    assert np.array_equal(sol.newton_iterations, info["newton_iterations"])
    assert "reached t = 1.0 in 34 steps" in sol.message and "Solution(status=0" in repr(sol)
    # control: another step size is another run
    assert not np.array_equal(em.integrate(Y0, 0.03, 34), sol.y)


def test_backward_batch_and_save_every(em):
    Y = np.stack([Y0, Y0 * 1.01])
    sol = em.solve(Y, (1.0, -1.0), 0.1, save_every=3)
    assert sol.h == -0.1 and sol.nsteps == 20
    # rows after 0, 3, ..., 18 steps and the last (20)
    np.testing.assert_allclose(sol.t, [1.0, 0.7, 0.4, 0.1, -0.2, -0.5, -0.8, -1.0], rtol=0, atol=1e-14)
    assert np.array_equal(sol.y, em.integrate(Y, -0.1, 20, save_every=3))
    assert sol.invariant_errors["H"].shape == (2,)


def test_t_eval_rows(em):
    sol = em.solve(Y0, (0.0, 1.0), 0.1, t_eval=[0.0, 0.5, 1.0])
    full = em.integrate(Y0, 0.1, 10)
    assert np.array_equal(sol.t, [0.0, 0.5, 1.0]) and np.array_equal(sol.y, full[[0, 5, 10]])
    # times from t_span[0]: the same rows from another start time
    later = em.solve(Y0, (2.0, 3.0), 0.1, t_eval=[2.0, 2.5, 3.0])
    assert np.array_equal(later.y, sol.y) and np.array_equal(later.t, [2.0, 2.5, 3.0])


def test_a_failed_step_is_reported_not_raised(em):
    """h = 2 does not resolve Kepler at the pericentre: status -1 with integrate's message and
    the rows before the failing step.  Control: integrate raises the same failure."""
    sol = em.solve(Y0, (0.0, 50.0), 2.0)
    with pytest.raises(em.ResolutionError) as ei:
        em.integrate(Y0, 2.0, 25)
    assert sol.status == -1 and not sol.success and sol.message == str(ei.value)
    assert sol.nsteps == ei.value.step and np.array_equal(sol.y, ei.value.trajectory)
    assert sol.t.shape == (len(sol.y),)


def test_invariant_errors_measure_what_the_method_keeps(kepler):
    """Energy-momentum keeps H and L: their errors at round-off; control: Störmer–Verlet keeps L
    but not H, and the field shows H's error."""
    em = mg.build(kepler, "energy-momentum")
    sv = mg.build(kepler, "stormer-verlet")
    a = em.solve(Y0, (0.0, 5.0), 0.05)
    b = sv.solve(Y0, (0.0, 5.0), 0.05)
    H0 = abs(float(em.hamiltonian(Y0)))
    assert a.invariant_errors["H"] <= 8 * np.finfo(float).eps * H0
    assert b.invariant_errors["H"] > 1e-6 * H0
    assert max(b.invariant_errors[k] for k in ("Lx", "Ly", "Lz")) <= 1e-14


def test_bad_input_is_named(em):
    with pytest.raises(ValueError, match="h must be > 0"):
        em.solve(Y0, (0.0, 1.0), -0.1)
    with pytest.raises(ValueError, match="t_span must be two numbers"):
        em.solve(Y0, 1.0, 0.1)
    with pytest.raises(ValueError, match="t_span must be finite"):
        em.solve(Y0, (0.0, math.inf), 0.1)
    with pytest.raises(TypeError, match="takes no 'steps'"):
        em.solve(Y0, (0.0, 1.0), 0.1, steps=3)
    # an empty span: the initial state alone
    sol = em.solve(Y0, (1.0, 1.0), 0.1)
    assert sol.nsteps == 0 and np.array_equal(sol.y, Y0[None]) and np.array_equal(sol.t, [1.0])


def test_cli_json_carries_the_solution_names(capsys, kepler):
    """``methodgen run --json`` reports ``success``, ``message``, ``nsteps`` and
    ``invariant_errors`` as a Solution names them, with the same values as ``mod.solve`` on the
    same run; a failed run says ``success`` false with the failure's message."""
    import json

    from methodgen.app.cli import main

    assert main(["run", "kepler", "--steps", "50", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    sc = mg.load_scene("kepler")
    mod = mg.build(kepler, "energy-momentum")
    sol = mod.solve(np.array(sc.y0), (0.0, 50 * sc.h), sc.h)
    assert rep["success"] is True and rep["nsteps"] == sol.nsteps == 50
    assert set(rep["invariant_errors"]) == set(sol.invariant_errors)
    for name, v in sol.invariant_errors.items():
        assert abs(rep["invariant_errors"][name] - v) <= 4e-16
    assert main(["run", "kepler", "--steps", "50", "--h", "2", "--json"]) != 0
    out = capsys.readouterr()
    bad = json.loads(out.out)
    assert bad["success"] is False and "does not resolve the dynamics" in bad["message"]


APO = np.array([-1.6, 0.0, 0.0, 0.0, -0.4, -0.3])     # the apocentre of Y0's orbit (e = 0.6)


@pytest.mark.parametrize("every", [1, 3])
def test_progress_reports_and_keeps_the_run(em, every):
    """progress= runs in chunks that continue each other: the same rows, times and iterations
    bitwise, with a report at the start and after each chunk (about 1 % of the steps)."""
    calls = []
    ref = em.solve(Y0, (0.0, 20.0), 0.01, save_every=every)
    sol = em.solve(Y0, (0.0, 20.0), 0.01, save_every=every, progress=lambda d, t: calls.append((d, t)))
    assert np.array_equal(sol.y, ref.y) and np.array_equal(sol.t, ref.t)
    assert np.array_equal(sol.newton_iterations, ref.newton_iterations) and sol.message == ref.message
    done = [d for d, _ in calls]
    assert calls[0] == (0, 2000) and calls[-1] == (2000, 2000) and {t for _, t in calls} == {2000}
    assert done == sorted(done) and 50 <= len(calls) <= 202
    assert all((b - a) % every == 0 for a, b in zip(done[:-2], done[1:-1]))   # chunks of whole save_every
    # control: chunks that do not continue each other (a fresh start per chunk) are another run
    y, rows = Y0, [Y0[None]]
    for _ in range(10):
        part = em.integrate(y, 0.01, 200)
        rows.append(part[1:])
        y = part[-1]
    assert not np.array_equal(np.concatenate(rows), em.solve(Y0, (0.0, 20.0), 0.01).y)


def test_progress_on_a_failed_run_ends_at_the_step_made(em):
    """A step that fails mid-run (the pericentre from the apocentre at h = 0.2): the same status,
    message, rows and step as without progress; the last report is (step, step)."""
    calls = []
    ref = em.solve(APO, (0.0, 40.0), 0.2, save_every=3)
    sol = em.solve(APO, (0.0, 40.0), 0.2, save_every=3, progress=lambda d, t: calls.append((d, t)))
    assert ref.status == -1 and 0 < ref.nsteps < 200      # fails mid-run, not at the first step
    assert sol.status == -1 and sol.message == ref.message and sol.nsteps == ref.nsteps
    assert np.array_equal(sol.y, ref.y) and np.array_equal(sol.t, ref.t)
    assert np.array_equal(sol.newton_iterations, ref.newton_iterations)
    assert calls[-1] == (ref.nsteps, ref.nsteps) and calls[-2][1] == 200


def test_progress_with_events_and_text_line(em, capsys):
    calls = []
    peri = mg.event(em, "x*px + y*py + z*pz", direction=1, terminal=2)
    ref = em.solve(Y0, (0.0, 1e3), 0.01, events=peri)
    sol = em.solve(Y0, (0.0, 1e3), 0.01, events=peri, progress=lambda d, t: calls.append((d, t)))
    assert np.array_equal(sol.y, ref.y) and np.array_equal(sol.t_events[0], ref.t_events[0])
    assert calls[0] == (0, 100_000) and calls[-1] == (sol.nsteps, sol.nsteps) and sol.status == 1
    em.solve(Y0, (0.0, 1.0), 0.01, progress=True)
    err = capsys.readouterr().err
    assert err.startswith("\renergy-momentum: 0/100 steps (0 %)") and err.endswith("100/100 steps (100 %)\n")
    with pytest.raises(ValueError, match="progress must be"):
        em.solve(Y0, (0.0, 1.0), 0.01, progress="yes")


def test_tqdm_steps_bar(em):
    pytest.importorskip("tqdm")
    import io

    from methodgen.codegen.progress import tqdm_steps
    out = io.StringIO()
    em.solve(Y0, (0.0, 1.0), 0.01, progress=tqdm_steps(file=out, mininterval=0))
    assert "100/100" in out.getvalue()
    out = io.StringIO()
    em.solve(APO, (0.0, 40.0), 0.2, progress=tqdm_steps(file=out, mininterval=0))
    assert "14/14" in out.getvalue()         # ended early: the bar closes at the step made
