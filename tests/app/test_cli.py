"""The command line: the main job, JSON contract, clean errors."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest


def run(*args, **kw):
    return subprocess.run([sys.executable, "-m", "methodgen", *args], capture_output=True, text=True, **kw)


def test_run_kepler_json_contract():
    res = run("run", "kepler", "--steps", "2000", "--json")
    assert res.returncode == 0, res.stderr
    rep = json.loads(res.stdout)  # exactly one JSON object on stdout
    for key in ("scene", "method", "h", "steps", "y_final", "invariants", "newton", "seconds", "us_per_step"):
        assert key in rep
    assert rep["scene"] == "kepler" and rep["method"] == "energy-momentum" and rep["steps"] == 2000
    assert len(rep["y_final"]) == 6
    assert set(rep["invariants"]) == {"H", "Lx", "Ly", "Lz"}
    for v in rep["invariants"].values():
        assert set(v) >= {"initial", "max_abs_error", "max_rel_error"}
    assert rep["invariants"]["H"]["max_rel_error"] < 1e-13
    assert 1 <= rep["newton"]["mean_iterations"] <= rep["newton"]["max_iterations"] <= 10
    assert rep["seconds"] > 0 and rep["us_per_step"] > 0


def test_run_text_report_and_overrides():
    res = run("run", "harmonic", "--method", "energy-momentum", "--h", "0.05", "--steps", "100")
    assert res.returncode == 0, res.stderr
    assert "energy-momentum" in res.stdout and "µs/step" in res.stdout and "Newton" in res.stdout


def test_run_scene_file(tmp_path):
    f = tmp_path / "duffing.toml"
    f.write_text('name = "duffing"\n[system]\nH = "p**2/2 + q**4/4 - q**2/2"\nq = ["q"]\np = ["p"]\n'
                 '[run]\nmethod = "energy-momentum"\nh = 0.05\nsteps = 200\ny0 = [0.1, 0.5]\n')
    res = run("run", str(f), "--json", env=None)
    assert res.returncode == 0, res.stderr
    rep = json.loads(res.stdout)
    assert rep["invariants"]["H"]["max_abs_error"] < 1e-14


@pytest.mark.parametrize("args, fragment", [
    (("run", "nosuchscene"), "no built-in scene or file"),
    (("run", "kepler", "--method", "nosuch"), "unknown method"),
    (("run", "kepler", "--h", "0"), "non-zero"),
    (("run", "kepler", "--steps", "-3"), "non-negative"),
    (("run", "kepler", "--h", "nan"), "finite"),
    (("frobnicate",), "invalid choice"),
])
def test_bad_input_exits_nonzero_without_traceback(args, fragment):
    res = run(*args)
    assert res.returncode == 2
    assert fragment in res.stderr
    assert "Traceback" not in res.stderr and res.stdout == ""


def test_numerical_failure_exits_3_with_step(tmp_path):
    f = tmp_path / "tight.toml"
    f.write_text('name = "tight"\n[system]\nH = "(px**2+py**2)/2 - 1/sqrt(x**2+y**2)"\nq = ["x", "y"]\n'
                 'p = ["px", "py"]\n[run]\nmethod = "energy-momentum"\nh = 0.5\nsteps = 50\n'
                 'y0 = [0.05, 0.0, 0.0, 0.1]\n')
    res = run("run", str(f))
    assert res.returncode == 3
    assert "at step 0" in res.stderr and "use h <=" in res.stderr and "Traceback" not in res.stderr


def test_listings():
    res = run("scenes", "--json")
    names = {s["name"] for s in json.loads(res.stdout)["scenes"]}
    assert {"kepler", "harmonic"} <= names
    res = run("methods", "--json")
    assert {"midpoint", "energy-momentum"} <= {m["name"] for m in json.loads(res.stdout)["methods"]}


def test_a_quantity_that_starts_at_zero_has_no_relative_error(tmp_path):
    """K of a time-transformed run starts at 0: its relative error is "—" (null in --json), not
    inf or a ratio of round-off; a quantity that does not start at 0 keeps its relative error."""
    res = run("run", "kepler-eccentric", "--steps", "314", "--json")
    assert res.returncode == 0, res.stderr
    inv = json.loads(res.stdout)["invariants"]
    assert abs(inv["H"]["initial"]) < 1e-15 and inv["H"]["max_rel_error"] is None
    assert inv["H"]["max_abs_error"] is not None
    assert inv["H_phys"]["max_rel_error"] is not None and inv["H_phys"]["max_rel_error"] < 1e-12
    text = run("run", "kepler-eccentric", "--steps", "314").stdout
    row = next(line for line in text.splitlines() if line.split() and line.split()[0] == "H")
    assert row.rstrip().endswith("—")


def test_json_says_what_the_method_promises_for_each_invariant():
    """energy-momentum keeps H and q × p (claim "exact"); the midpoint rule keeps q × p but H only
    to its error ("monitored"); AVF with quadrature keeps H "approximate"."""
    em = json.loads(run("run", "kepler", "--steps", "50", "--json").stdout)["invariants"]
    mp = json.loads(run("run", "kepler", "--steps", "50", "--method", "midpoint", "--json").stdout)["invariants"]
    assert {k: v["claim"] for k, v in em.items()} == dict.fromkeys(("H", "Lx", "Ly", "Lz"), "exact")
    assert mp["H"]["claim"] == "monitored" and mp["Lz"]["claim"] == "exact"
    avf = json.loads(run("run", "kepler", "--steps", "50", "--method", "avf", "--json").stdout)["invariants"]
    assert avf["H"]["claim"] == "approximate"
