"""The command line's failures: one line, the right exit status, the limit named (issues 27 and 28).

Each guard has a negative control: with the guard switched off, the old failure (a traceback, a
NaN reported as 0, a folder created) is observed.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

import methodgen.app.cli as cli
import methodgen.app.cli.bench as cli_bench
import methodgen.app.cli.run as cli_run
import methodgen.codegen.emit as emit
import methodgen.app.limits as limits
import methodgen.problem.parse as parse
import methodgen.app.sweep as sw
from methodgen.app import bench
from methodgen.app.cli.common import fmt, join_negative_values
from methodgen.errors import InputError
from methodgen.app.stats import ErrorMax, max_abs_error, max_value

from helpers import FORCED_SCENE, cli_main as _main, one_line as _one_line, strict_json as _no_nan_json


# --- 27.7: a run beyond the limits is one line, exit 2, naming the limit --------------------------

@pytest.mark.parametrize("argv, fragment", [
    (["--steps", "10000000000000"], "beyond the limit of 1e+12 steps"),
    (["--steps", "99999999999999999999999"], "beyond the limit of 1e+12 steps"),
    (["--t-final", "1e300"], "--t-final 1e+300 with h = 0.1 asks for 1e+301 steps"),
])
def test_run_beyond_the_step_limit_is_one_line_exit_2(capsys, argv, fragment):
    code, out, err = _main(capsys, "run", "harmonic", *argv)
    assert code == cli.EXIT_INPUT and out == ""
    assert fragment in _one_line(err)


def test_time_dependent_scene_with_a_huge_t_final(tmp_path, capsys):
    f = tmp_path / "forced.toml"
    f.write_text(FORCED_SCENE)
    code, out, err = _main(capsys, "run", f, "--t-final", "1e300")
    assert code == cli.EXIT_INPUT and "beyond the limit of 1e+12 steps" in _one_line(err)


def test_step_limit_negative_control(capsys, monkeypatch):
    """Without the guard the same command ends in numpy's allocation error (the old traceback)."""
    monkeypatch.setattr(cli_run, "check_steps", lambda steps, what: None)
    monkeypatch.setattr(cli_run, "check_memory", lambda *a, **k: None)
    with pytest.raises((ValueError, MemoryError)):
        cli.main(["run", "harmonic", "--steps", "99999999999999999999999"])


def test_states_that_do_not_fit_in_memory_are_refused(capsys, monkeypatch):
    # A machine of 4 kB: 100 steps of 2 values (and 100 Newton counts) need about 2.4 kB > half.
    monkeypatch.setattr(limits, "memory_limit", lambda: 4000)
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "100")
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and "more than half of this machine's 4.0 kB" in line
    assert "--save FILE.npz --chunk N" in line and "--save-every K" in line
    # The way out the message names works: in chunks of 10 steps the same run fits.
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "100", "--save-every", "50", "--chunk", "10",
                           "--json")
    assert code == 0, err


def test_memory_limit_negative_control(capsys, monkeypatch):
    """The same 100 steps on a machine with memory to spare: not refused."""
    monkeypatch.setattr(limits, "memory_limit", lambda: 10 ** 9)
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "100", "--json")
    assert code == 0 and _no_nan_json(out)["steps_done"] == 100


def test_newton_counts_are_summarised_per_chunk():
    its = cli_run._Iterations()
    its.add(np.array([2, 3, 2]))
    its.add(np.array([], dtype=int))
    its.add(np.array([5]))
    assert (its.count, its.max) == (4, 5) and its.mean == pytest.approx(3.0)


# --- 27.11: --t-final T --steps N is h = T/N -------------------------------------------------------

def test_t_final_with_steps_takes_h_as_t_over_n(capsys):
    code, out, _ = _main(capsys, "run", "harmonic", "--t-final", "10", "--steps", "50", "--json")
    rep = _no_nan_json(out)
    assert code == 0 and rep["h"] == 0.2 and rep["steps"] == 50 and rep["t_final"] == pytest.approx(10.0)
    code, out, _ = _main(capsys, "run", "harmonic", "--h", "0.2", "--steps", "50", "--json")
    assert _no_nan_json(out)["y_final"] == rep["y_final"]
    # With --h 0.3 (10/0.3 is not whole): ceil -> 34 steps of 10/34, still ending at 10.
    code, out, _ = _main(capsys, "run", "harmonic", "--t-final", "10", "--h", "0.3", "--json")
    rep = _no_nan_json(out)
    assert rep["t_final"] == pytest.approx(10.0) and rep["steps"] == 34 and rep["h_requested"] == 0.3


def test_t_final_with_steps_on_a_time_dependent_scene(tmp_path, capsys):
    f = tmp_path / "forced.toml"
    f.write_text(FORCED_SCENE)
    code, out, err = _main(capsys, "run", f, "--t-final", "2.5", "--steps", "40", "--json")
    rep = _no_nan_json(out)
    assert code == 0, err
    assert rep["h"] == pytest.approx(2.0 / 40) and rep["t_final"] == pytest.approx(2.5)


def test_h_with_t_final_and_steps_is_refused(capsys):
    code, _, err = _main(capsys, "run", "harmonic", "--t-final", "10", "--steps", "50", "--h", "0.2")
    assert code == cli.EXIT_INPUT and "not all three" in _one_line(err)


# --- 27.4: --no-check-resolution ----------------------------------------------------------------------

def test_no_check_resolution_on_run(capsys):
    # Negative control first: h = 1 on Kepler is refused by the resolution check (exit 3).
    # (At h = 2 whether Newton still converges on the unresolved orbit depends on the last
    # bits of the iterates: it did before powers were printed as the compiled kernels round
    # them, and stops at step 3 since.  h = 1 is unresolved and Newton converges.)
    code, _, err = _main(capsys, "run", "kepler", "--h", "1", "--steps", "10")
    assert code == cli.EXIT_NUMERICAL and "does not resolve" in _one_line(err)
    code, out, err = _main(capsys, "run", "kepler", "--h", "1", "--steps", "10", "--no-check-resolution", "--json")
    assert code == 0 and _no_nan_json(out)["steps_done"] == 10, err


def test_no_check_resolution_on_sweep(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('scene = "kepler"\nmethods = ["midpoint"]\nh = [2.0]\nsteps = 10\n')
    code, out, _ = _main(capsys, "sweep", spec, "--json")
    assert code == 0 and _no_nan_json(out)["rows"][0]["status"] == "numerical-error"   # the control
    code, out, _ = _main(capsys, "sweep", spec, "--json", "--no-check-resolution")
    rep = _no_nan_json(out)
    assert code == 0 and rep["rows"][0]["status"] == "ok" and rep["spec"]["check_resolution"] is False


# --- 28.3: a NaN is never reported as 0 (run, sweep, bench) ---------------------------------------

def test_error_max_keeps_nan():
    e = ErrorMax().update(np.array([1e-9, 2e-9]))
    assert e.finite and e.value == pytest.approx(2e-9)
    e.update(np.array([np.nan, 5.0]), offset=2)
    assert e.nonfinite_step == 2 and math.isnan(e.value) and e.finite_max == 5.0
    assert math.isnan(max_abs_error([0.0, np.inf])) and max_abs_error([1.0, -3.0]) == 3.0
    assert math.isnan(max_value(0.0, math.nan)) and math.isnan(max_value(math.nan, 0.0))
    # Negative control: the builtin maximum loses the NaN when it comes second.
    assert max(0.0, math.nan) == 0.0


class _NaNModule:
    """A module whose energy stops being a number after two steps (no error raised)."""
    INVARIANT_NAMES = ("H",)
    ConvergenceError = NonFiniteError = ResolutionError = type("E", (RuntimeError,), {})

    @staticmethod
    def invariants(Y, params=None):
        Y = np.asarray(Y)
        return {"H": Y[..., 0] ** 2 / 2 + Y[..., 1] ** 2 / 2}

    @staticmethod
    def integrate(y0, h, steps, params=None, info=None, check_resolution=True):
        y0 = np.asarray(y0, dtype=float)
        out = np.repeat(y0[None], steps + 1, axis=0)
        out[3:] = np.nan
        if info is not None:
            info["newton_iterations"] = np.ones(steps, dtype=int)
        return out


def _sweep_row(monkeypatch, stats_cls=None):
    monkeypatch.setattr(sw, "load_shipped_module", lambda src: _NaNModule)
    if stats_cls is not None:
        monkeypatch.setattr(sw, "ErrorMax", stats_cls)
    task = sw.Task(key=(0,), name="t", method="midpoint", h=0.1, h_used=0.1, steps=10, params=(), swept=(),
                   batch=0, y0=np.array([[1.0, 0.0]]))
    return sw.run_task(task, None)


def test_sweep_reports_a_nan_energy_as_null_never_0(monkeypatch):
    row = _sweep_row(monkeypatch)
    assert row["status"] == "numerical-error" and row["energy_error"] is None
    assert row["nonfinite"] == {"H": 3} and "H is not finite at step 3" in row["error"]


def test_sweep_nan_negative_control(monkeypatch):
    """With the old running maximum (builtin max) the same run is "ok" with an energy error of 0."""
    class OldMax(ErrorMax):
        def update(self, errors, offset=0, stride=1):
            self.finite_max = max(self.finite_max, float(np.max(np.abs(errors))))
            return self

    row = _sweep_row(monkeypatch, OldMax)
    assert row["status"] == "ok" and row["energy_error"] == 0.0


def test_sweep_table_prints_non_finite(tmp_path, capsys):
    # Harmonic with m = -1 grows like e^t; from step ~3550 H = inf - inf.
    spec = tmp_path / "neg.toml"
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.1]\nsteps = 8000\n[params]\nm = [-1.0]\n')
    code, out, _ = _main(capsys, "sweep", spec)
    row = [line for line in out.splitlines() if line.startswith("midpoint")][0]
    assert "non-finite" in row and "0.00e+00" not in row
    code, out, _ = _main(capsys, "sweep", spec, "--json")
    r = _no_nan_json(out)["rows"][0]
    assert r["energy_error"] is None and r["status"] != "ok" and r["nonfinite"]["H"] > 0


def test_run_report_prints_non_finite(capsys):
    code, out, err = _main(capsys, "run", "harmonic", "--param", "m=-1", "--steps", "8000", "--json")
    rep = _no_nan_json(out)
    assert code == cli.EXIT_NUMERICAL and rep["invariants"]["H"]["max_abs_error"] is None
    assert rep["invariants"]["H"]["status"] == "non-finite"
    # 5000 steps: H = inf - inf from step 3553 while the state is still finite (no error raised).
    code, out, err = _main(capsys, "run", "harmonic", "--param", "m=-1", "--steps", "5000")
    h_row = [line for line in out.splitlines() if line.split()[:1] == ["H"]][0]
    assert code == cli.EXIT_NUMERICAL and "non-finite" in h_row and "0.000e+00" not in h_row


def test_bench_table_prints_non_finite(capsys):
    nan = math.nan
    row = {"method": "midpoint", "h": 0.1, "steps": 10, "seconds": 0.1, "error": nan, "energy_error": nan,
           "energy_rel_error": nan, "invariant_errors": {"H": nan, "L": 1e-16}, "newton_mean": 2.0}
    cli_bench._print_bench({"work_precision": {"scene": "s", "T": 1.0, "reference": "r", "rows": [row]}})
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("midpoint")][0]
    assert line.count("non-finite") == 3 and "e+00" not in line
    # Negative control: a finite row prints its numbers.
    cli_bench._print_bench({"work_precision": {"scene": "s", "T": 1.0, "reference": "r", "rows": [
        {**row, "error": 0.0, "energy_error": 0.0, "energy_rel_error": 0.0, "invariant_errors": {"H": 0.0}}]}})
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("midpoint")][0]
    assert "non-finite" not in line and "0.00e+00" in line


def test_bench_errors_keep_nan_and_the_table_says_so():
    traj = np.array([[1.0, 0.0], [0.5, 0.5], [np.nan, np.inf]])
    out = bench._errors(_NaNModule, traj, np.zeros(2))
    assert math.isnan(out["energy_error"]) and math.isnan(out["error"])
    assert fmt(out["energy_error"]) == "non-finite" and fmt(None) == "-" and fmt(0.0) == "0.00e+00"
    assert '"energy_error": null' in cli.common.dump_json(out)


def test_bench_constraint_error_keeps_nan():
    """bench._errors itself (not a copy of its formula): a NaN velocity residual is kept
    (tests/test_cli_mends.py has the constrained module, the table's cell and the negative control
    with the builtin max)."""
    class Constrained(_NaNModule):
        @staticmethod
        def constraint_residuals(Y):
            return np.full(len(Y), 1e-12), np.where(np.arange(len(Y)) == 1, np.nan, 0.0)
    traj = np.array([[1.0, 0.0], [1.0, 0.0]])
    out = bench._errors(Constrained, traj, traj[-1])
    assert math.isnan(out["constraint_error"]) and out["nulls"]["constraint_error"]
    # Negative control: the builtin max(np.max(g), np.max(gv)) drops the NaN of gv.
    g, gv = Constrained.constraint_residuals(traj)
    assert max(np.max(np.abs(g)), np.max(np.abs(gv))) == 1e-12


# --- 28.7: overflowing coefficients, a y0 at a singularity ---------------------------------------

def _scene_file(tmp_path, H):
    f = tmp_path / "big.toml"
    f.write_text(f'name = "big"\n[system]\nH = "{H}"\nq = ["q"]\np = ["p"]\n[run]\nmethod = "midpoint"\n'
                 'h = 0.1\nsteps = 5\ny0 = [1.0, 0.0]\n')
    return f


@pytest.mark.parametrize("H, fragment", [
    ("p**2/2 + 1e200*1e200*q**2", "the number 1.000E+400"),
    ("p**2/2 + 1e308*10*q**2", "the number 1.000E+309"),
    ("p**2/2 + 1e-320*q**2", "the denominator of 1.000E-320"),
])
def test_a_coefficient_beyond_a_double_is_one_line_exit_2(tmp_path, capsys, H, fragment):
    code, out, err = _main(capsys, "run", _scene_file(tmp_path, H))
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and fragment in line and "beyond the range of a double" in line


def test_coefficient_negative_control(tmp_path, monkeypatch):
    """Without the check the module is generated and fails at run time with an OverflowError."""
    monkeypatch.setattr(parse, "_check_double_range", lambda expr, what: None)
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    with pytest.raises(OverflowError):
        cli.main(["run", str(_scene_file(tmp_path, "p**2/2 + 1e200*1e200*q**2"))])


def test_bench_y0_at_a_singularity_is_one_line_exit_2(capsys):
    code, out, err = _main(capsys, "bench", "kepler", "--quick", "--y0=0,0,0,0,0,0")
    assert code == cli.EXIT_INPUT and out == ""
    assert "the vector field is not finite at the initial state" in _one_line(err)


def test_bench_y0_negative_control(capsys, monkeypatch):
    """Without the check the reference solution fails: still one line (exit 3), no RuntimeError traceback."""
    monkeypatch.setattr(bench, "check_initial_state", lambda scene, own=None: None)
    code, out, err = _main(capsys, "bench", "kepler", "--quick", "--y0=0,0,0,0,0,0")
    # (numpy's warnings of the division by r = 0 come first, one line each)
    assert code == cli.EXIT_NUMERICAL and "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("methodgen: error: the DOP853 reference solution failed")


# --- 28.8a: bench --t-final beyond a bound -------------------------------------------------------

def test_bench_t_final_beyond_the_bound(capsys):
    code, out, err = _main(capsys, "bench", "harmonic", "--t-final", "1e9")
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and "beyond the bench's limit of 1e+07" in line and "at most 62500" in line


def test_bench_length_bound_is_where_it_says():
    bench.check_length(62500.0, 0.00625)             # negative control: at the bound, accepted
    with pytest.raises(InputError, match="at most 62500"):
        bench.check_length(62500.0 * 1.01, 0.00625)


def test_bench_long_steps_beyond_memory(capsys, monkeypatch):
    monkeypatch.setattr(limits, "memory_limit", lambda: 10 ** 6)
    code, out, err = _main(capsys, "bench", "harmonic", "--only-extras", "--long", "--long-steps", "100000")
    assert code == cli.EXIT_INPUT and "--long-steps 100000 keeps the energy error" in _one_line(err)
    # Negative control: 1000 steps fit in the same (pretended) 1 MB.
    code, out, err = _main(capsys, "bench", "harmonic", "--only-extras", "--long", "--long-steps", "1000",
                           "--json")
    assert code == 0 and json.loads(out)["long"]["steps"] == 1000, err


def test_sweep_step_limit(tmp_path, capsys):
    spec = tmp_path / "big.toml"
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.1]\nsteps = 100000000000000\n')
    code, out, err = _main(capsys, "sweep", spec)
    assert code == cli.EXIT_INPUT and "1e+14 steps per trajectory, beyond the limit" in _one_line(err)
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.1]\nsteps = 1000000000000\n')
    sw.load_spec(spec)   # negative control: at the limit the spec is accepted


# --- 28.9: small interface defects ----------------------------------------------------------------

@pytest.mark.parametrize("save, fragment", [
    ("missing/x.npz", "does not exist (it is not created"),
    ("dir/", "is a folder; give a file name in it"),
    ("dir", "is a folder; give a file name in it"),
    ("", "--save needs a file name"),
])
def test_bad_save_paths(tmp_path, capsys, monkeypatch, save, fragment):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "dir").mkdir()
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "5", "--save", save)
    assert code == cli.EXIT_INPUT and fragment in _one_line(err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir"] and not list((tmp_path / "dir").iterdir())


def test_save_into_an_existing_folder_works(tmp_path, capsys):
    # Negative control of the above: a file name in a folder that exists is saved.
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "5", "--save", tmp_path / "x.npz")
    assert code == 0 and (tmp_path / "x.npz").is_file(), err


def test_negative_y0_without_equals(capsys):
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "3", "--y0", "-1,0", "--json")
    assert code == 0 and _no_nan_json(out)["y0"] == [-1.0, 0.0], err
    assert join_negative_values(["--y0", "-1,0", "--h", "-1e-2", "--steps", "3"]) == \
        ["--y0=-1,0", "--h=-1e-2", "--steps", "3"]
    # Negative control: argparse alone takes "-1,0" for an option.
    with pytest.raises(SystemExit):
        cli.make_parser().parse_args(["run", "harmonic", "--y0", "-1,0"])
    capsys.readouterr()


def test_cache_path_with_tilde_is_the_home_folder(tmp_path, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("METHODGEN_CACHE", "~/mgc")
    assert emit.cache_dir() == tmp_path / "mgc"
    assert Path(os.path.expanduser("~")) == tmp_path   # the control: HOME is where ~ points


@pytest.mark.parametrize("extra", [[], ["--json"]])
def test_run_with_parameters_outside_the_domain_of_H_is_bad_input(capsys, extra):
    """`run --param m=0`: H is not defined at the initial state; the input is at fault (exit 2,
    one line), not the run (3)."""
    code, out, err = _main(capsys, "run", "kepler", "--steps", "10", "--param", "m=0", *extra)
    assert code == cli.EXIT_INPUT, err
    assert "at the initial state" in _one_line(err) and "Traceback" not in err


def test_run_failure_after_the_start_is_still_exit_3(capsys):
    """Control: a run that fails at a later step (h far too large for the eccentric orbit) keeps exit 3."""
    code, out, err = _main(capsys, "run", "kepler-eccentric", "--time-transform", "none")
    assert code == cli.EXIT_NUMERICAL, err
    assert "initial state" not in err


def test_a_chunked_run_names_the_runs_step(capsys):
    """--chunk runs the module in pieces; a failure names the step of the run, as one piece would
    (the apocentre of the e = 0.6 orbit at h = 0.2: the pericentre is not resolved at step 14)."""
    args = ("run", "kepler", "--y0", "-1.6,0,0,0,-0.4,-0.3", "--h", "0.2", "--steps", "200")
    code1, _, whole = _main(capsys, *args)
    code2, _, chunked = _main(capsys, *args, "--chunk", "5")
    assert code1 == code2 == 3
    assert "at step 14: step size h = 0.2 does not resolve the dynamics at step 14:" in whole
    assert chunked == whole
