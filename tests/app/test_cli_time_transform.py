"""Time transformations and collocation stages on the command line and in scenes:
``--time-transform G``, ``[run] time_transform``, ``--stages S``, ``[run] stages`` (issue 14, item 4)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import methodgen as mg
from methodgen.app import cli
from methodgen.codegen.emit import load_module
from methodgen.errors import SceneError
from methodgen.runtime.runio import load_trajectory

ROOT = Path(__file__).resolve().parents[2]
R = "sqrt(x**2 + y**2 + z**2)"


@pytest.fixture(scope="module", autouse=True)
def cache(tmp_path_factory):
    """A private module cache: undeclared variants of built-in scenes go there, not to generated/."""
    root = tmp_path_factory.mktemp("tt") / "cache"
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("METHODGEN_CACHE", str(root))
        yield root


def _main(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def _run_json(capsys, *argv):
    code, out, err = _main(capsys, "run", *argv, "--json")
    assert code == 0, err
    return json.loads(out)


def _one_line_error(code, out, err, *fragments):
    assert code == cli.EXIT_INPUT, (code, out, err)
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert all(f in err for f in fragments), err


# --- the built-in scene -------------------------------------------------------------------

def test_scene_declares_the_transformation():
    sc = mg.load_scene("kepler-eccentric")
    assert sc.time_transform == R and sc.methods == ("avf", "midpoint", "gauss")
    assert sc.run_system.name == "kepler-eccentric-tt" and sc.run_system.time_transform is not None
    assert len(sc.y0) == 2 * sc.system.dim == 6           # y0 in the original variables
    assert sc.y0[4] == pytest.approx(-math.sqrt(0.01 / 1.99), rel=1e-15)
    plain = mg.load_scene("kepler")
    assert plain.transformed is None and plain.run_system is plain.system


def test_run_kepler_eccentric_reaches_ten_orbits_with_avf(capsys):
    rep = _run_json(capsys, "kepler-eccentric")
    tt = rep["time_transform"]
    assert rep["method"] == "avf" and tt["g"] == R
    # h and steps are fictive; the physical time reached is ten periods (2π each).
    assert tt["tau_final"] == pytest.approx(0.02 * 3142) and rep["steps_done"] == 3142
    assert tt["t_final"] == rep["t_final"] == pytest.approx(20 * math.pi, abs=0.1)
    # The original energy: kept by AVF to round-off (and reported under H_phys).
    assert tt["H_phys_max_abs_error"] == rep["invariants"]["H_phys"]["max_abs_error"] < 1e-10
    assert rep["invariants"]["H_phys"]["initial"] == pytest.approx(-0.5, abs=1e-12)
    assert rep["state_names"] == ["x", "y", "z", "t", "px", "py", "pz", "e"]
    assert rep["y0"] == list(mg.load_scene("kepler-eccentric").y0)
    # The scene's own modules are the committed ones of K.
    assert Path(rep["module"]) == ROOT / "generated" / "kepler_eccentric_tt_avf.py"


def test_text_report_says_the_transformation_is_on(capsys):
    code, out, err = _main(capsys, "run", "kepler-eccentric", "--steps", "200")
    assert code == 0, err
    first, second = out.splitlines()[:2]
    assert "fictive τ = 0 .. 4" in first and "physical t = 0 .." in first
    assert second.startswith(f"time transformation on: g = {R}")
    assert "max |ΔH_phys| =" in out and "H_phys" in out


def test_midpoint_reports_the_magnified_energy_error(capsys):
    """Negative control: H_phys = K/g − e; midpoint keeps K only to O(h²), and 1/g = 100 at
    pericentre — the report shows it (measured 0.50), it is not hidden behind K."""
    rep = _run_json(capsys, "kepler-eccentric", "--method", "midpoint", "--steps", "400")
    assert rep["time_transform"]["H_phys_max_abs_error"] > 1e-2
    assert rep["invariants"]["H"]["max_abs_error"] < 1e-2   # K itself stays small


def test_time_transform_on_the_command_line(capsys, cache):
    rep = _run_json(capsys, "kepler", "--time-transform", "sqrt(x**2+y**2+z**2)", "--method", "avf",
                    "--h", "0.02", "--steps", "314")
    tt = rep["time_transform"]
    assert tt["g"] == "sqrt(x**2+y**2+z**2)" and rep["steps"] == 314
    assert tt["t_final"] == pytest.approx(2 * math.pi, abs=0.02)     # one orbit of kepler (period 2π)
    assert tt["H_phys_max_abs_error"] < 1e-12
    # Not declared by the kepler scene: its module is the cache's, named after K (kepler-tt).
    path = Path(rep["module"])
    assert path.parent == cache and path.name.startswith("kepler_tt_") and path.name.endswith("_avf.py")
    assert load_module(path).TIME_TRANSFORM["g"] == "sqrt(x**2+y**2+z**2)"
    # The same scene without the flag: no transformation in the report.
    plain = _run_json(capsys, "kepler", "--steps", "3")
    assert plain["time_transform"] is None and plain["stages"] is None


@pytest.mark.parametrize("g, fragments", [
    ("sqrt(px**2 + x**2)", ["--time-transform", "depends on momenta"]),
    ("2", ["--time-transform", "does not depend on q"]),
    ("foo(x)", ["--time-transform", "unknown function 'foo'", "allowed functions"]),
    ("r", ["--time-transform", "unknown symbol 'r'", "declared symbols"]),
    ("Abs(x)", ["--time-transform", "not smooth"]),
    ("sqrt(x**2)", ["--time-transform", "not smooth"]),
    ("__import__('os').system('true')", ["--time-transform", "only direct calls of", "are allowed"]),
    ("x - 1", ["g = x - 1 is -0.6 at y0", "positive"]),
    ("", ["--time-transform must be a function g(q)"]),
])
def test_bad_g_is_a_one_line_error(capsys, g, fragments):
    code, out, err = _main(capsys, "run", "kepler", "--method", "midpoint", "--time-transform", g,
                           "--steps", "3")
    _one_line_error(code, out, err, *fragments)
    assert not out


def test_t_final_is_refused_with_a_transformation(capsys):
    code, out, err = _main(capsys, "run", "kepler-eccentric", "--t-final", "10")
    _one_line_error(code, out, err, "--t-final is a physical time", "fictive time", "--steps")


def test_a_method_that_does_not_apply_to_K_says_so(capsys):
    code, out, err = _main(capsys, "run", "kepler", "--time-transform", R, "--steps", "3")
    _one_line_error(code, out, err, f"with the time transformation g = {R}", "energy-momentum needs a separable")


def test_save_records_the_transformation(tmp_path, capsys):
    target = tmp_path / "ecc.npz"
    rep = _run_json(capsys, "kepler-eccentric", "--steps", "60", "--save", str(target), "--chunk", "25")
    states, meta = load_trajectory(target)
    assert states.shape == (61, 8) and str(meta["time_transform"]) == R
    assert list(meta["state_names"])[3] == "t"
    assert states[-1, 3] == pytest.approx(rep["time_transform"]["t_final"], rel=1e-15)
    assert states[0, 3] == 0.0 and states[0, 7] == pytest.approx(0.5, abs=1e-12)   # e = -H(y0)


def test_none_switches_the_transformation_off_and_shows_why_it_is_there(capsys, cache):
    """Without the transformation the same fixed step is refused at the first pericentre."""
    code, out, err = _main(capsys, "run", "kepler-eccentric", "--time-transform", "none", "--steps", "200",
                           "--json")
    rep = json.loads(out)
    assert code == cli.EXIT_NUMERICAL and "does not resolve" in rep["error"] and rep["time_transform"] is None
    assert Path(rep["module"]).parent == cache   # the untransformed system is not the scene's module


def test_verify_takes_the_transformation(capsys):
    code, out, err = _main(capsys, "verify", "kepler-eccentric", "--method", "midpoint", "--json")
    rep = json.loads(out)
    assert code == 0 and rep["ok"], err
    assert rep["time_transform"] == {"g": R, "system": "kepler-eccentric-tt"}
    assert any("K = g" in c["claim"] or "∂K/∂t" in c["claim"] for c in rep["certificates"])
    code, out, err = _main(capsys, "verify", "kepler", "--time-transform", "p", "--method", "midpoint")
    _one_line_error(code, out, err, "--time-transform", "unknown symbol 'p'")


# --- stages -----------------------------------------------------------------------------------

def test_stages_3_is_order_6(capsys, cache):
    rep = _run_json(capsys, "harmonic", "--method", "gauss", "--stages", "3", "--steps", "50")
    assert rep["order"] == 6 and rep["stages"] == 3 and rep["method"] == "gauss"
    module = load_module(rep["module"])
    assert module.ORDER == 6 and Path(rep["module"]).parent == cache
    assert Path(rep["module"]).name.endswith("_gauss_stages3.py")
    code, out, err = _main(capsys, "run", "harmonic", "--method", "gauss", "--stages", "3", "--steps", "5")
    assert code == 0 and "method gauss (3 stages)  order 6" in out.splitlines()[0], err
    # The default number of stages is reported too (and keeps the plain module name).
    rep = _run_json(capsys, "harmonic", "--method", "gauss", "--steps", "5")
    assert rep["order"] == 4 and rep["stages"] == 2 and Path(rep["module"]).name.endswith("_gauss.py")


@pytest.mark.parametrize("argv, fragments", [
    (["--method", "energy-momentum", "--stages", "3"],
     ["--stages", "energy-momentum takes no stages", "gauss (stages 1..6", "energy-collocation (stages 1..4"]),
    (["--stages", "2"], ["midpoint takes no stages"]),                            # the scene's method
    (["--method", "gauss", "--stages", "7"], ["--stages = 7", "gauss takes stages 1, 2, 3, 4, 5, 6"]),
    (["--method", "energy-collocation", "--stages", "5"], ["energy-collocation takes stages 1, 2, 3, 4"]),
    (["--method", "gauss", "--stages", "0"], ["gauss takes stages"]),
    (["--method", "gauss", "--stages", "three"], ["--stages must be a whole number", "'three'", "gauss"]),
    (["--method", "gauss", "--stages", "2.5"], ["--stages must be a whole number", "'2.5'"]),
])
def test_bad_stages_are_one_line_errors(capsys, argv, fragments):
    code, out, err = _main(capsys, "run", "harmonic", *argv, "--steps", "3")
    _one_line_error(code, out, err, *fragments)


@pytest.mark.parametrize("command", [["verify", "harmonic"], ["generate", "harmonic", "--check"]])
def test_stages_on_verify_and_generate_name_what_is_valid(capsys, command):
    code, out, err = _main(capsys, *command, "--stages", "3")
    _one_line_error(code, out, err, "--stages", "midpoint, energy-momentum take no stages", "gauss")


SCENE = """
name = "osc"
[system]
H = "p**2/2 + q**2/2 + q**4/4"
q = ["q"]
p = ["p"]
[run]
method = {methods}
h = 0.1
steps = 20
y0 = [0.5, 0.0]
{extra}
"""


def _scene(tmp_path, methods='["gauss", "midpoint"]', extra=""):
    path = tmp_path / "osc.toml"
    path.write_text(SCENE.format(methods=methods, extra=extra))
    return path


def test_scene_stages_apply_to_the_methods_that_take_them(tmp_path, capsys):
    path = _scene(tmp_path, extra="stages = 3")
    assert mg.load_scene(path).stages == 3
    rep = _run_json(capsys, str(path))
    assert rep["method"] == "gauss" and rep["order"] == 6 and rep["stages"] == 3
    rep = _run_json(capsys, str(path), "--method", "midpoint")
    assert rep["order"] == 2 and rep["stages"] is None
    rep = _run_json(capsys, str(path), "--stages", "1")   # the command line wins
    assert rep["order"] == 2 and rep["stages"] == 1


@pytest.mark.parametrize("methods, extra, fragments", [
    ('"midpoint"', "stages = 3", ["[run].stages", "midpoint takes no stages", "gauss (stages 1..6"]),
    ('["gauss"]', "stages = 9", ["[run].stages = 9", "gauss takes stages 1, 2, 3, 4, 5, 6"]),
    ('["gauss"]', 'stages = "3"', ["[run].stages must be a whole number", "'3'"]),
    ('["energy-collocation"]', "stages = 5", ["energy-collocation takes stages 1, 2, 3, 4"]),
    ('["avf"]', 'time_transform = "p"', ["[run].time_transform", "depends on momenta"]),
    ('["avf"]', 'time_transform = "1"', ["[run].time_transform", "does not depend on q"]),
    ('["avf"]', 'time_transform = "sqrt(q**2)"', ["[run].time_transform", "not smooth"]),
    ('["avf"]', 'time_transform = "-q"', ["[run].time_transform", "is -0.5 at y0", "positive"]),
    ('["avf"]', 'time_transform = 2', ["[run].time_transform must be a str"]),
])
def test_bad_scene_values(tmp_path, capsys, methods, extra, fragments):
    path = _scene(tmp_path, methods, extra)
    with pytest.raises(SceneError) as exc:
        mg.load_scene(path)
    assert all(f in str(exc.value) for f in fragments), str(exc.value)
    code, out, err = _main(capsys, "run", str(path))
    _one_line_error(code, out, err, *fragments)


def test_scene_time_transform_runs_from_the_original_y0(tmp_path, capsys):
    path = _scene(tmp_path, '["avf"]', 'time_transform = "1 + q**2"')
    rep = _run_json(capsys, str(path))
    assert rep["time_transform"]["g"] == "1 + q**2" and rep["state_names"] == ["q", "t", "p", "e"]
    # t' = g ≥ 1: the physical time runs ahead of the fictive one.
    assert rep["t_final"] > rep["time_transform"]["tau_final"] == pytest.approx(2.0)
    assert rep["time_transform"]["H_phys_max_abs_error"] < 1e-13   # polynomial K: AVF exact
    assert np.isclose(rep["y_final"][3], -rep["invariants"]["H_phys"]["initial"])  # e = -H(y0)
