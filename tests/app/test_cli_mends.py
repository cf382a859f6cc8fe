"""The command line's mends after a third red-team review: each finding one line on stderr, no
traceback, exit 2 for bad input / 3 for a numerical failure / 0 ok.

Every guard has a negative control: with the guard switched off (or the input fixed) the old
behaviour or the accepted run is observed.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest
import sympy as sp

import methodgen.app.cli as cli
import methodgen.app.cli.bench as cli_bench
import methodgen.app.cli.run as cli_run
import methodgen.codegen.emit as emit
import methodgen.app.limits as limits
import methodgen.problem.parse as parse
import methodgen.app.sweep as sw
from methodgen.app import bench
from methodgen.app.cli.common import check_output_file, cli_advice, join_negative_values
from methodgen.errors import InputError, ParseError, StorageError
from methodgen.app.stats import ErrorMax

from helpers import FORCED_SCENE, cli_main as _main, one_line as _one_line, strict_json as _json


# --- 1: bench --h must be > 0 ----------------------------------------------------------------------

def test_bench_negative_h_is_one_line_exit_2(capsys):
    code, out, err = _main(capsys, "bench", "harmonic", "--quick", "--peers", "--h", "-0.1")
    assert code == cli.EXIT_INPUT and out == ""
    assert "--h must be positive for bench" in _one_line(err)


def test_bench_negative_h_negative_control():
    """Without the CLI's check a negative h reaches the peers' bench: T = h*steps < 0 (it was a
    ValueError traceback; now an InputError of bench itself)."""
    import dataclasses
    scene = dataclasses.replace(cli_bench.load_scene("harmonic"), h=-0.1)
    with pytest.raises(InputError, match="needs a positive final time, got T = -100"):
        bench.work_precision(scene, ["midpoint"], quick=True, peers=True)


# --- 2 and 13: parameters making the field undefined or overflow ------------------------------------

@pytest.mark.parametrize("scene, value", [("harmonic", "m=0"), ("pendulum", "m=1e-300")])
def test_bench_parameters_that_break_the_field_are_named(capsys, scene, value):
    code, out, err = _main(capsys, "bench", scene, "--quick", "--param", value)
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and f"the parameters {value.replace('1e-300', '1e-300')}" in line
    assert "give other --param values" in line and "--y0" not in line


def test_bench_zoo_field_negative_control(monkeypatch):
    """The old check built ode_rhs outside its try: lambdify cannot print zoo (KeyError)."""
    scene = cli_bench._bench_overrides(cli_bench.load_scene("harmonic"),
                                       argparse.Namespace(y0=None, param=["m=0"], h=None))
    with pytest.raises(KeyError):
        bench.ode_rhs(scene.system)
    assert not bench.field_is_finite(scene)
    # and the scene's own m = 1 is finite at the same y0
    assert bench.field_is_finite(cli_bench.load_scene("harmonic"))


def test_bench_y0_and_parameters_both_named(capsys):
    code, out, err = _main(capsys, "bench", "kepler", "--quick", "--y0=0,0,0,0,1,0", "--param", "k=2")
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and "the parameters k=2" in line and "give another --y0, and check --param" in line


# --- 3: ~user that cannot be expanded ----------------------------------------------------------------

@pytest.mark.parametrize("argv, option", [
    (["run", "harmonic", "--steps", "2", "--save", "~nosuchuser_mg/x.npz"], "--save"),
    (["run", "harmonic", "--steps", "2", "--plot", "~nosuchuser_mg/x.png"], "--plot"),
])
def test_unknown_home_folder_is_one_line_exit_2(capsys, argv, option):
    code, out, err = _main(capsys, *argv)
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and f"{option} ~nosuchuser_mg/" in line and "cannot expand ~" in line


def test_unknown_home_folder_in_sweep_csv(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.1]\nsteps = 2\n')
    code, out, err = _main(capsys, "sweep", spec, "--csv", "~nosuchuser_mg/x.csv")
    assert code == cli.EXIT_INPUT and "--csv ~nosuchuser_mg/x.csv: cannot expand ~" in _one_line(err)


def test_unknown_home_folder_in_the_cache(capsys, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", "~nosuchuser_mg/x")
    with pytest.raises(StorageError) as info:
        emit.cache_dir()
    assert info.value.bad_path
    code, out, err = _main(capsys, "run", "harmonic", "--method", "gauss", "--steps", "2")
    assert code == cli.EXIT_INPUT and "METHODGEN_CACHE=~nosuchuser_mg/x: cannot expand ~" in _one_line(err)


def test_unknown_home_folder_negative_control():
    """pathlib itself raises RuntimeError (the old traceback) for the same text."""
    from pathlib import Path
    with pytest.raises(RuntimeError):
        Path("~nosuchuser_mg/x").expanduser()


# --- 4 and 8: --t-final and the sign of h; one rule for run and sweep --------------------------------

def test_negative_h_against_a_later_t_final_is_refused(capsys):
    code, out, err = _main(capsys, "run", "harmonic", "--h", "-0.1", "--t-final", "1", "--json")
    assert code == cli.EXIT_INPUT and out == ""
    assert "h = -0.1 runs backward in time but T - t0 = 1" in _one_line(err)


def test_time_dependent_scene_negative_h_is_refused(tmp_path, capsys):
    f = tmp_path / "forced.toml"
    f.write_text(FORCED_SCENE)
    code, out, err = _main(capsys, "run", f, "--h", "-0.05", "--t-final", "2.5")
    assert code == cli.EXIT_INPUT and "from t0 = 0.5" in _one_line(err)


def test_backward_run_to_an_earlier_t_final(capsys):
    # Negative control of the two above: the signs agree, the run goes back to T.
    code, out, err = _main(capsys, "run", "harmonic", "--h", "-0.1", "--t-final", "-1", "--json")
    rep = _json(out)
    assert code == 0 and rep["steps"] == 10 and rep["t_final"] == pytest.approx(-1.0), err


def test_t_final_not_a_whole_number_of_steps_ends_at_t(capsys):
    code, out, err = _main(capsys, "run", "harmonic", "--t-final", "10", "--h", "0.3", "--json")
    rep = _json(out)
    assert code == 0 and rep["steps"] == 34 and rep["t_final"] == pytest.approx(10.0, abs=1e-12)
    assert rep["h"] == pytest.approx(10 / 34) and rep["h"] <= 0.3 and rep["h_requested"] == 0.3
    # a whole number of steps: h unchanged, no h_requested
    code, out, err = _main(capsys, "run", "harmonic", "--t-final", "1", "--h", "0.1", "--json")
    rep = _json(out)
    assert rep["steps"] == 10 and rep["h"] == 0.1 and "h_requested" not in rep


def test_run_and_sweep_share_the_rule(capsys, tmp_path):
    assert limits.steps_for_time(1.0, 0.3) == (4, 0.25)
    assert limits.steps_for_time(10.0, 0.3)[0] == 34
    assert limits.steps_for_time(1.0, 0.1) == (10, 0.1)      # 1/0.1 = 9.999999999999998: whole
    assert limits.steps_for_time(-1.0, -0.1) == (10, -0.1)
    with pytest.raises(InputError, match="sign of T - t0"):
        limits.steps_for_time(1.0, -0.1)
    spec = sw.parse_spec({"scene": "harmonic", "methods": ["midpoint"], "h": [0.3], "t_final": 1.0})
    task = sw.plan_sweep(spec).tasks[0]
    assert (task.steps, task.h_used) == (4, 0.25)
    code, out, err = _main(capsys, "run", "harmonic", "--t-final", "1", "--h", "0.3", "--json")
    rep = _json(out)
    assert (rep["steps"], rep["h"]) == (task.steps, task.h_used)


def test_sweep_table_shows_the_h_used(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.3]\nt_final = 1.0\n')
    code, out, err = _main(capsys, "sweep", spec)
    row = [x for x in out.splitlines() if x.startswith("midpoint")][0]
    assert code == 0 and row.split()[1] == "0.25" and "h: the step used" in out
    # Negative control: a whole number of steps prints the spec's h and no note.
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.25]\nt_final = 1.0\n')
    code, out, err = _main(capsys, "sweep", spec)
    assert "h: the step used" not in out


# --- 5: --save-every never reports a step past the end ----------------------------------------------

def test_save_every_nonfinite_step_is_within_the_run(capsys):
    code, out, err = _main(capsys, "run", "harmonic", "--param", "m=-1", "--steps", "3600", "--save-every",
                           "1000", "--json")
    rep = _json(out)
    H = rep["invariants"]["H"]
    assert code == cli.EXIT_NUMERICAL
    assert H["first_nonfinite_step"] == 3600 and H["last_finite_step"] == 3000
    assert "step 4000" not in err and "finite at step 3000" in err
    # Every step seen: the true first step (inside (3000, 3600]).
    code, out, err = _main(capsys, "run", "harmonic", "--param", "m=-1", "--steps", "3600", "--json")
    H1 = _json(out)["invariants"]["H"]
    assert 3000 < H1["first_nonfinite_step"] <= 3600 and "last_finite_step" not in H1


def test_error_max_caps_the_step():
    err = np.array([0.0, 0.0, 0.0, 0.0, np.nan])   # rows at 0, 1000, 2000, 3000 and the last, 3600
    e = ErrorMax().update(err, offset=0, stride=1000, last=3600)
    assert (e.nonfinite_step, e.finite_before) == (3600, 3000)
    # Negative control: without last, the row index times the stride (the old report).
    assert ErrorMax().update(err, offset=0, stride=1000).nonfinite_step == 4000


# --- 6, 9, 16: bench's NaNs: the table, the reasons, the real constraint path ------------------------

class _ConstrainedNaN:
    """A module with a non-H invariant and constraint residuals that stop being numbers."""
    INVARIANT_NAMES = ("H", "L")

    @staticmethod
    def invariants(Y):
        Y = np.asarray(Y)
        return {"H": Y[:, 0] ** 2 / 2 + Y[:, 1] ** 2 / 2, "L": np.where(np.arange(len(Y)) == 2, np.nan, 1.0)}

    @staticmethod
    def constraint_residuals(Y):
        n = len(Y)
        return np.full(n, 1e-12), np.where(np.arange(n) == 1, np.nan, 1e-13)


def test_bench_constraint_error_keeps_nan():
    """bench._errors on a module whose velocity constraint residual is NaN at one step."""
    traj = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0]])
    out = bench._errors(_ConstrainedNaN, traj, traj[-1])
    assert math.isnan(out["constraint_error"]) and math.isnan(out["invariant_errors"]["L"])
    assert out["energy_error"] == 0.0 and out["status"] == "non-finite"
    assert set(out["nulls"]) == {"invariant_errors.L", "constraint_error"}


def test_bench_constraint_error_negative_control(monkeypatch):
    """With the builtin max in place of stats.max_value the NaN residual disappears."""
    monkeypatch.setattr(bench, "max_value", lambda *v: max(v))
    traj = np.array([[1.0, 0.0], [1.0, 0.0], [1.0, 0.0]])
    assert bench._errors(_ConstrainedNaN, traj, traj[-1])["constraint_error"] == 1e-12


def _bench_row(**kw):
    row = {"method": "rattle", "h": 0.1, "steps": 10, "seconds": 0.1, "error": 1e-3, "energy_error": 1e-9,
           "energy_rel_error": 1e-9, "invariant_errors": {"H": 1e-9, "L": math.nan, "M": 1e-12},
           "constraint_error": 1e-11, "newton_mean": 2.0}
    row.update(kw)
    return row


def _table_cell(capsys, row):
    cli_bench._print_bench({"work_precision": {"scene": "s", "T": 1.0, "reference": "r", "rows": [row]}})
    line = [x for x in capsys.readouterr().out.splitlines() if x.startswith("rattle")][0]
    return line.split()[-2]   # inv/constr, before Newton


def test_bench_table_keeps_a_nan_among_invariants_and_constraints(capsys):
    assert _table_cell(capsys, _bench_row()) == "non-finite"                      # NaN first of the others
    row = _bench_row(invariant_errors={"H": 1e-9, "M": 1e-12}, constraint_error=math.nan)
    assert _table_cell(capsys, row) == "non-finite"                               # NaN last
    # Negative control: all finite, the maximum is printed.
    assert _table_cell(capsys, _bench_row(invariant_errors={"H": 1e-9, "M": 1e-12})) == "1.00e-11"


def test_bench_table_builtin_max_negative_control(capsys, monkeypatch):
    monkeypatch.setattr(cli_bench, "max_value", lambda *v: max(v))
    row = _bench_row(invariant_errors={"H": 1e-9, "M": 1e-12}, constraint_error=math.nan)
    # builtin max(1e-12, nan) keeps 1e-12: the NaN constraint error vanished from the table
    assert _table_cell(capsys, row) == "1.00e-12"


def test_bench_json_nulls_say_why():
    traj = np.array([[0.0, 0.0], [0.0, 0.0]])             # H(y0) = 0: no relative error
    out = bench._errors(_ConstrainedNaN, traj, traj[-1])
    assert out["nulls"]["energy_rel_error"] == "H(y0) = 0: no relative error"
    doc = json.loads(cli.common.dump_json(out))
    assert doc["energy_rel_error"] is None and "energy_rel_error" in doc["nulls"]
    traj = np.array([[1.0, 0.0], [np.nan, 0.0]])
    out = bench._errors(_ConstrainedNaN, traj, np.zeros(2))
    assert out["nulls"]["energy_error"] == "H is not finite along the run" and out["status"] == "non-finite"


# --- 7: bench --no-check-resolution ----------------------------------------------------------------

def test_bench_resolution_refusal_names_the_flag(capsys):
    code, out, err = _main(capsys, "bench", "kepler", "--only-extras", "--long", "--long-steps", "100", "--h", "2")
    line = _one_line(err)
    assert code == cli.EXIT_NUMERICAL and "pass --no-check-resolution" in line
    assert "check_resolution=False" not in line


def test_bench_no_check_resolution(monkeypatch):
    """The flag reaches every integrate call of the solver table, the long run and Brouwer."""
    seen = []

    def spy(fn):
        def wrapped(*a, **k):
            seen.append((fn.__name__, k.get("check_resolution")))
            return {"rows": [], "steps": 1, "h": 0.1, "T": 1.0, "scene": "s", "ensemble": 2}
        wrapped.__name__ = fn.__name__
        return wrapped

    for name in ("solver_variants", "long_run", "brouwer", "work_precision"):
        monkeypatch.setattr(bench, name, spy(getattr(bench, name)))
    cli.main(["bench", "harmonic", "--quick", "--long", "--brouwer", "--json", "--no-check-resolution"])
    assert ("solver_variants", False) in seen and ("long_run", False) in seen and ("brouwer", False) in seen
    seen.clear()
    cli.main(["bench", "harmonic", "--quick", "--long", "--brouwer", "--json"])   # negative control
    assert ("long_run", True) in seen and ("solver_variants", True) in seen and ("brouwer", True) in seen


def test_solver_variants_passes_check_resolution():
    scene = cli_bench.load_scene("kepler")
    import dataclasses
    scene = dataclasses.replace(scene, h=2.0)
    rows = bench.solver_variants(scene, ["midpoint"], steps=3)["rows"]
    assert all("does not resolve" in r.get("failed", "") for r in rows)
    rows = bench.solver_variants(scene, ["midpoint"], steps=3, check_resolution=False)["rows"]
    assert not any("does not resolve" in r.get("failed", "") for r in rows)


def test_cli_advice():
    assert cli_advice("use h <= 0.5, or pass check_resolution=False to accept") == \
        "use h <= 0.5, or pass --no-check-resolution to accept"


# --- 10: counts of 0 ------------------------------------------------------------------------------

@pytest.mark.parametrize("argv, fragment", [
    (["--brouwer", "--brouwer-steps", "0"], "--brouwer-steps must be at least 1, got 0"),
    (["--long", "--long-steps", "0"], "--long-steps must be at least 1, got 0"),
    (["--brouwer", "--ensemble", "0"], "--ensemble must be at least 2, got 0"),
    (["--brouwer", "--ensemble", "1"], "--ensemble must be at least 2, got 1"),
])
def test_bench_counts_of_zero_are_refused(capsys, argv, fragment):
    code, out, err = _main(capsys, "bench", "harmonic", "--quick", "--only-extras", *argv)
    assert code == cli.EXIT_INPUT and fragment in _one_line(err)


def test_bench_small_counts_run(capsys):
    # Negative control: 1 step, an ensemble of 2 are run as given (not replaced by the defaults).
    code, out, err = _main(capsys, "bench", "harmonic", "--quick", "--only-extras", "--long", "--long-steps", "1",
                           "--brouwer", "--brouwer-steps", "20", "--ensemble", "2", "--json")
    rep = _json(out)
    assert code == 0 and rep["long"]["steps"] == 1 and rep["brouwer"]["steps"] == 20, err
    assert rep["brouwer"]["ensemble"] == 2


# --- 11: --plot, --csv, --out checked before any work -------------------------------------------------

@pytest.mark.parametrize("plot, fragment", [
    ("nope/x.png", "the folder nope does not exist"),
    ("d/", "is a folder; give a file name in it, e.g. d/run.png"),
    ("", "--plot needs a file name"),
])
def test_bad_plot_paths_before_the_run(tmp_path, capsys, monkeypatch, plot, fragment):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "d").mkdir()
    ran = []
    monkeypatch.setattr(cli_run, "build", lambda *a, **k: ran.append(1))
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "3", "--plot", plot)
    assert code == cli.EXIT_INPUT and fragment in _one_line(err) and not ran
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d"]


def test_bench_plot_checked_before_the_runs(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(bench, "work_precision", lambda *a, **k: pytest.fail("ran before the check"))
    code, out, err = _main(capsys, "bench", "harmonic", "--quick", "--plot", tmp_path / "nope" / "x.png")
    assert code == cli.EXIT_INPUT and "does not exist" in _one_line(err)


def test_empty_csv_and_out(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nh = [0.1]\nsteps = 2\n')
    code, out, err = _main(capsys, "sweep", spec, "--csv", "")
    assert code == cli.EXIT_INPUT and "--csv needs a file name" in _one_line(err)
    code, out, err = _main(capsys, "generate", "--out", "")
    assert code == cli.EXIT_INPUT and "--out needs a folder name" in _one_line(err)


def test_a_good_plot_path_is_accepted(tmp_path):
    # Negative control of the checks: a file name in an existing folder passes.
    assert check_output_file(str(tmp_path / "x.png"), "--plot") == tmp_path / "x.png"


# --- 12: values starting with "-", no abbreviations -------------------------------------------------

def test_negative_inf_nan_and_time_transform_values():
    assert join_negative_values(["--y0", "-inf,0", "--steps", "3"]) == ["--y0=-inf,0", "--steps", "3"]
    assert join_negative_values(["--y0", "-nan,0"]) == ["--y0=-nan,0"]
    assert join_negative_values(["--time-transform", "-x"]) == ["--time-transform=-x"]
    # Negative control: an option after an option is left alone.
    assert join_negative_values(["--y0", "--json"]) == ["--y0", "--json"]
    assert join_negative_values(["--time-transform", "--json"]) == ["--time-transform", "--json"]


@pytest.mark.parametrize("value, fragment", [("-inf,0", "is not finite"), ("-nan,0", "is not finite")])
def test_non_finite_y0_is_one_line(capsys, value, fragment):
    code, out, err = _main(capsys, "run", "harmonic", "--steps", "3", "--y0", value)
    assert code == cli.EXIT_INPUT and fragment in _one_line(err)


def test_abbreviations_are_refused(capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(["run", "harmonic", "--steps", "3", "--y", "1,0"])
    assert info.value.code == cli.EXIT_INPUT and "unrecognized arguments: --y 1,0" in capsys.readouterr().err
    # Negative control: argparse's default would take --y for --y0.
    p = argparse.ArgumentParser(allow_abbrev=True)
    p.add_argument("--y0")
    assert p.parse_args(["--y", "1,0"]).y0 == "1,0"


# --- 14: number-valued subexpressions beyond a double -------------------------------------------------

@pytest.mark.parametrize("H, fragment", [
    ("p**2/2 + exp(1000)*q**2", "exp(1000) = 1.970E+434"),
    ("p**2/2 + cosh(800)*q**2", "cosh(800)"),
    ("p**2/2 + exp(-1000)*q**2", "exp(-1000)"),
])
def test_number_subexpressions_beyond_a_double(tmp_path, capsys, H, fragment):
    f = tmp_path / "big.toml"
    f.write_text(f'name = "big"\n[system]\nH = "{H}"\nq = ["q"]\np = ["p"]\n[run]\nmethod = "midpoint"\n'
                 'h = 0.1\nsteps = 5\ny0 = [1.0, 0.0]\n')
    code, out, err = _main(capsys, "run", f)
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and fragment in line and "beyond the range of a double" in line


def test_number_subexpressions_within_a_double_pass():
    q, p = sp.symbols("q p")
    expr = parse.parse_expr("p**2/2 + exp(700)*q**2 + sqrt(2)*sin(1)*q + exp(-700)*q", {"q": q, "p": p})
    assert expr.has(sp.exp(700))   # negative control: within range, accepted unchanged


def test_number_subexpression_negative_control(monkeypatch):
    """Without the check, exp(1000) passes parsing and becomes inf in doubles (the old exit 3)."""
    monkeypatch.setattr(parse, "_check_double_range", lambda expr, what: None)
    q, p = sp.symbols("q p")
    expr = parse.parse_expr("p**2/2 + exp(1000)*q**2", {"q": q, "p": p})
    with np.errstate(over="ignore"):
        assert not math.isfinite(float(sp.lambdify([q, p], expr, "numpy")(np.float64(1.0), 0.0)))
    with pytest.raises(ParseError):
        monkeypatch.undo()
        parse.parse_expr("p**2/2 + exp(1000)*q**2", {"q": q, "p": p})


# --- 15: the bench's total work; --plot's memory -------------------------------------------------------

def test_bench_total_work_is_bounded(capsys):
    code, out, err = _main(capsys, "bench", "harmonic", "--quick", "--t-final", "62500")
    line = _one_line(err)
    assert code == cli.EXIT_INPUT and "beyond the bench's limit" in line and "at most 1.54e+04" in line


def test_bench_total_work_bound_is_where_it_says():
    hs = [0.1, 0.05, 0.025]
    bench.check_work(15000.0, 2, hs, hs[:2], 9)           # negative control: below the bound, accepted
    with pytest.raises(InputError, match="at most 1.54e"):
        bench.check_work(15500.0, 2, hs, hs[:2], 9)


def test_plot_of_a_saved_run_checks_memory(tmp_path, capsys, monkeypatch):
    # 1000 steps saved in chunks of 10 fit a 20 kB machine; plotted, all 1001 states come back (16 kB).
    monkeypatch.setattr(limits, "memory_limit", lambda: 20_000)
    argv = ["run", "harmonic", "--steps", "1000", "--save", tmp_path / "x.npz", "--chunk", "10"]
    code, out, err = _main(capsys, *argv, "--plot", tmp_path / "x.png")
    assert code == cli.EXIT_INPUT and "--plot draws every kept state" in _one_line(err)
    assert not (tmp_path / "x.npz").exists()
    code, out, err = _main(capsys, *argv, "--json")        # negative control: without --plot it fits
    assert code == 0, err


def test_peers_say_their_work_before_they_start(capsys):
    wp = bench.work_precision(cli_bench.load_scene("harmonic"), ["midpoint"], quick=True, peers=True,
                              progress=True, orders=(2, 4))
    done = sum(r["steps"] * r.get("stages", 1) for r in wp["rows"] if r.get("kind") == "methodgen")
    assert 0 < done <= wp["estimated_steps"] <= 2 * done   # an upper bound, and not a loose one here
    assert "run at most about" in capsys.readouterr().err
    # Negative control: without progress nothing is printed.
    bench.work_precision(cli_bench.load_scene("harmonic"), ["midpoint"], quick=True, peers=True, orders=(2,))
    assert "run at most about" not in capsys.readouterr().err
