"""Numerical extremes, bad input, security and long runs (never silently wrong)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from conftest import ROOT
from methodgen.codegen.emit import emit_source, write_atomic
from methodgen.runtime.runio import load_trajectory

DG = ["avf", "gonzalez", "itoh-abe", "energy-momentum"]


# --- tiny steps and exact 0/0 ------------------------------------------------------

@pytest.mark.parametrize("method", DG)
@pytest.mark.parametrize("h", [1e-8, 1e-6, 1e-4])
def test_tiny_steps_keep_energy_at_roundoff(method, h, modules):
    """A quotient evaluated naively loses ~eps/h per step; the cancelled forms do not."""
    sc = mg.load_scene("simple-pendulum")
    _, mod = modules(sc.system, method)
    traj = mod.integrate(np.array(sc.y0) + [0.0, 0.3], h, 1000)
    H = mod.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 2e-15 * 1000 ** 0.5 * 4
    assert np.max(np.abs(traj[-1] - traj[0])) > 0  # it moved


def test_naive_quotient_fails_the_roundoff_check():
    """Negative control for the removable-singularity checks (tests/test_methods.py): at the
    increments of a step with h = 1e-8 the naive κ∇U of Exercise 1.1 has a relative error
    ~eps/|Δq| against 50-digit arithmetic, which that check's threshold (1e-14) rejects."""
    import mpmath
    mpmath.mp.dps = 50
    q0, q1 = 1.5, 1.5 + 3e-9
    naive = (-np.cos(q1) + np.cos(q0)) / ((q1 - q0) * np.sin(0.5 * (q0 + q1))) * np.sin(0.5 * (q0 + q1))
    a, b = mpmath.mpf(q0), mpmath.mpf(q1)
    exact = (-mpmath.cos(b) + mpmath.cos(a)) / (b - a)
    assert abs(naive - float(exact)) / abs(float(exact)) > 1e-10


@pytest.mark.parametrize("scene", ["simple-pendulum", "double-well"])
@pytest.mark.parametrize("method", DG + ["midpoint"])
def test_equilibrium_hits_every_quotient_exactly(scene, method, modules):
    """At an equilibrium y1 = y0 bitwise: every 0/0 is hit exactly, the state must not move or NaN."""
    sc = mg.load_scene(scene)
    _, mod = modules(sc.system, method)
    y0 = np.array([0.0, 0.0]) if scene == "simple-pendulum" else np.array([1.0, 0.0])
    traj = mod.integrate(y0, 0.1, 20)
    assert np.all(traj == y0)


# --- near-singular and stiff dynamics ------------------------------------------------

@pytest.mark.parametrize("method", ["energy-momentum", "midpoint"])
@pytest.mark.parametrize("e", [0.99, 0.999])
def test_high_eccentricity_kepler_with_fixed_steps_is_refused_clearly(method, e, modules, kepler):
    _, mod = modules(kepler, method)
    y0 = np.array([1 - e, 0, 0, 0, np.sqrt((1 + e) / (1 - e)), 0.0])
    with pytest.raises(mod.ResolutionError) as err:
        mod.integrate(y0, 0.01, int(2 * np.pi / 0.01))
    assert "does not resolve" in str(err.value) and err.value.trajectory is not None
    assert np.all(np.isfinite(err.value.trajectory))


def test_moderate_eccentricity_is_accurate(modules, kepler):
    """Control: e = 0.9 at h = 0.001 passes the guard and returns to its start after one period."""
    _, mod = modules(kepler, "energy-momentum")
    e = 0.9
    y0 = np.array([1 - e, 0, 0, 0, np.sqrt((1 + e) / (1 - e)), 0.0])
    h = 2 * np.pi / 6284
    traj = mod.integrate(y0, h, 6284)
    assert np.max(np.abs(traj[-1] - y0)) < 0.05
    H = mod.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) / abs(H[0]) < 1e-12


def test_stiff_linear_system_is_accurate_where_resolved(tmp_path):
    """Eigenvalue ratio 1e8 (ω = 1 and 1e4), midpoint with h = 0.01: the fast mode is not
    resolved but stays bounded with its energy exact (A-stability, quadratic H); the slow
    mode is accurate to O(h²)."""
    sys_ = mg.Hamiltonian("(p1**2 + p2**2)/2 + (q1**2 + w**2*q2**2)/2", q=["q1", "q2"],
                          p=["p1", "p2"], params={"w": 1e4}, name="stiff")
    mod = mg.generate(mg.discretize(sys_, "midpoint"), tmp_path / "stiff.py")
    y0 = np.array([1.0, 1e-4, 0.0, 0.0])
    with pytest.warns(mod.ResolutionWarning, match="h\\*omega = 100"):   # the fast mode is aliased
        traj = mod.integrate(y0, 0.01, 100)
    assert abs(traj[-1, 0] - np.cos(1.0)) < 1e-4
    assert np.max(np.abs(traj[:, 1])) <= 1e-4 * (1 + 1e-12)
    H = mod.hamiltonian(traj)
    assert np.max(np.abs(H - H[0])) / H[0] < 1e-13


def test_overflow_mid_run_stops_with_the_step_and_keeps_the_states(tmp_path):
    sys_ = mg.Hamiltonian("p**2/2 - q**4", q=["q"], p=["p"], name="blowup")
    mod = mg.generate(mg.discretize(sys_, "stormer-verlet"), tmp_path / "blowup.py")
    # check_resolution=False: the local error estimate would (rightly) stop the unresolved
    # h = 0.5 at step 0; this test is about the overflow itself.
    with pytest.raises(mod.NonFiniteError) as err:
        mod.integrate(np.array([1.0, 0.0]), 0.5, 200, check_resolution=False)
    e = err.value
    assert "step" in str(e) and e.trajectory.shape[0] == e.step + 1
    assert np.all(np.isfinite(e.trajectory))
    with pytest.raises(mod.NonFiniteError):  # the batch path too
        mod.integrate(np.array([[1.0, 0.0], [0.1, 0.0]]), 0.5, 200, check_resolution=False)


def test_rank_loss_of_the_constraints_is_a_clear_error(tmp_path):
    dup = mg.Hamiltonian("(px**2+py**2+pz**2)/2 + z", q=["x", "y", "z"], p=["px", "py", "pz"],
                         constraints=["x**2+y**2+z**2-1", "2*x**2+2*y**2+2*z**2-2"])
    with pytest.raises(mg.MethodNotApplicable, match="dependent"):
        mg.discretize(dup, "rattle")
    circle = mg.Hamiltonian("(px**2+py**2)/2 + y", q=["x", "y"], p=["px", "py"], constraints=["x**2+y**2-1"])
    mod = mg.generate(mg.discretize(circle, "rattle"), tmp_path / "circle.py")
    with pytest.raises(ValueError, match="rank-deficient"):
        mod.integrate(np.zeros(4), 0.01, 5)


# --- names and bad input -----------------------------------------------------------

def test_names_colliding_with_python_and_printer_names_generate_working_code(tmp_path):
    params = {n: 1.0 + i / 10 for i, n in enumerate(["sum", "np", "e", "E", "I", "N", "S", "beta", "gamma", "abs"])}
    H = ("(max**2 + numpy**2)/2 + sum*print**2/2 + np*math**2 + e*print*math + E*print**4/4 + "
         "I*math**4/8 + N + S*print**2*math**2 + beta*exp(-gamma*print**2) + abs*cos(math)")
    sys_ = mg.Hamiltonian(H, q=["print", "math"], p=["max", "numpy"], params=params, name="names")
    for method in ("midpoint", "itoh-abe"):
        scheme = mg.discretize(sys_, method)
        mod = mg.generate(scheme, tmp_path / f"names_{method.replace('-', '_')}.py")
        y0 = np.array([0.3, -0.2, 0.1, 0.4])
        traj = mod.integrate(y0, 0.01, 100)
        Hs = mod.hamiltonian(traj)
        assert np.all(np.isfinite(traj))
        assert mod.hamiltonian(y0) == pytest.approx(float(sys_.H.subs(dict(zip(sys_.y, y0)))
                                                          .subs({sys_.symbol(k): v for k, v in params.items()})))
        if method == "itoh-abe":
            assert np.max(np.abs(Hs - Hs[0])) < 1e-13


@pytest.mark.parametrize("name", ['x; import os', 'x)', '__class__', 'a.b', 'x\n', 'lambda'])
def test_hostile_symbol_names_are_refused(name):
    with pytest.raises(mg.InputError):
        mg.Hamiltonian(sp.Symbol("p") ** 2, q=[sp.Symbol(name)], p=["p"])
    with pytest.raises(mg.InputError):
        mg.Hamiltonian("p**2 + k", q=["q"], p=["p"], params={name: 1.0})


def test_hostile_scene_file_via_cli_has_no_side_effect(tmp_path):
    marker = tmp_path / "pwned"
    f = tmp_path / "evil.toml"
    f.write_text(f'name = "evil"\n[system]\nH = "__import__(\'os\').system(\'touch {marker}\')"\n'
                 'q = ["q"]\np = ["p"]\n[run]\nmethod = "midpoint"\nh = 0.1\nsteps = 1\ny0 = [0.0, 0.0]\n')
    res = subprocess.run([sys.executable, "-m", "methodgen", "run", str(f)], capture_output=True, text=True)
    assert res.returncode == 2 and "Traceback" not in res.stderr and "only direct calls" in res.stderr
    assert not marker.exists()


@pytest.mark.parametrize("text, fragment", [
    ('name = "x"\n[system\nH = "p**2"', "invalid TOML"),
    ('name = "x"\n[system]\nH = 3\nq = ["q"]\np = ["p"]', "[system].H must be a str"),
    ('name = "x"\nbogus = 1\n[system]\nH = "p**2"\nq = ["q"]\np = ["p"]', "unknown key(s) ['bogus']"),
])
def test_bad_scene_files_via_cli(tmp_path, text, fragment):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    res = subprocess.run([sys.executable, "-m", "methodgen", "run", str(f)], capture_output=True, text=True)
    assert res.returncode == 2 and fragment in res.stderr and "Traceback" not in res.stderr


def test_interrupted_generation_leaves_nothing_that_imports(tmp_path, monkeypatch, harmonic):
    path = tmp_path / "h.py"
    src = emit_source(mg.discretize(harmonic, "midpoint"))

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(KeyboardInterrupt):
        write_atomic(path, src)
    assert not path.exists() and list(tmp_path.iterdir()) == []


# --- long runs -------------------------------------------------------------------------

def test_stream_into_a_memmap_and_iterate_in_chunks(tmp_path, modules, kepler):
    _, mod = modules(kepler, "energy-momentum")
    y0 = np.array([0.4, 0, 0, 0, 1.6, 1.2])
    mm = np.lib.format.open_memmap(tmp_path / "traj.npy", mode="w+", shape=(1001, 6))
    mod.integrate(y0, 0.01, 1000, out=mm)
    mm.flush()
    full = np.load(tmp_path / "traj.npy")
    chunks = list(mod.iterate(y0, 0.01, 1000, chunk=128))
    assert sum(len(c) for c in chunks) == 1001 and max(len(c) for c in chunks) <= 129  # y0 + 128 steps
    np.testing.assert_allclose(np.concatenate(chunks), full, rtol=1e-13, atol=1e-14)


def test_cli_save_in_chunks(tmp_path):
    out = tmp_path / "k.npz"
    res = subprocess.run([sys.executable, "-m", "methodgen", "run", "kepler", "--steps", "2500",
                          "--save", str(out), "--chunk", "1000", "--json"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    rep = json.loads(res.stdout)
    states, meta = load_trajectory(out)
    assert states.shape == (2501, 6) and int(meta["steps_done"]) == 2500 and bool(meta["complete"])
    np.testing.assert_allclose(states[-1], rep["y_final"])


def test_ctrl_c_keeps_the_trajectory(tmp_path):
    # The interrupt must land in the integration, not in the imports: a fixed sleep did not
    # (at a load of 12 on 2 cores the child was still importing after 4 s: exit -2, a traceback).
    # With every phase reported (threshold 0) the child says when its module is loaded; the run
    # starts right after it.
    env = {**os.environ, "METHODGEN_PROGRESS_SECONDS": "0"}
    proc = subprocess.Popen([sys.executable, "-m", "methodgen", "run", "kepler", "--steps", "100000000"],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    head = []
    while not (head and head[-1].startswith("methodgen: load ") and " done in " in head[-1]):
        line = proc.stderr.readline()
        assert line, "".join(head)          # the child ended before loading its module
        head.append(line)
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    err = "".join(head) + err
    assert proc.returncode == 130, err
    assert "interrupted at step" in err and "saved" in err and "Traceback" not in err
    saved = tmp_path / "kepler_energy_momentum_partial.npz"
    states, meta = load_trajectory(saved)
    assert len(states) == int(meta["steps_done"]) + 1 > 10 and not bool(meta["complete"])
    assert np.all(np.isfinite(states))
