"""Particle scenes on the command line: `methodgen run` / `verify` / `scenes` at any N, and refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from methodgen.app import cli
from methodgen.app.particles_scene import is_particles_scene, load_particles_scene, particles_scene_names


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path_factory.getbasetemp() / "particles-cache"))


def _run(capsys, *argv):
    code = cli.main(["run", *argv, "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if out.strip() else None), err


def test_the_ring_is_listed_and_loads():
    assert "nbody-ring" in particles_scene_names() and is_particles_scene("nbody-ring")
    s = load_particles_scene("nbody-ring")
    y0, arrays = s.state(7)
    assert y0.shape == (28,) and arrays["m"][0] == 1.0
    m = arrays["m"]
    assert np.allclose(y0[14:].reshape(7, 2).sum(axis=0), 0, atol=1e-18)          # barycentric: P = 0
    assert np.allclose(m @ y0[:14].reshape(7, 2), 0, atol=1e-15)                  # centre of mass at 0


@pytest.mark.parametrize("method", ["stormer-verlet", "energy-momentum"])
def test_run_at_two_sizes_from_one_module(capsys, method):
    code, a, err = _run(capsys, "nbody-ring", "--method", method, "--steps", "20", "--param", "N=5")
    assert code == 0, err
    code, b, err = _run(capsys, "nbody-ring", "--method", method, "--steps", "20", "--param", "N=9")
    assert code == 0, err
    assert (a["N"], b["N"]) == (5, 9) and a["module_file"] == b["module_file"] and len(b["y_final"]) == 36
    if method == "energy-momentum":
        H = b["invariants"]["H"]
        assert H["max_abs_error"] <= 1e-14 * abs(H["initial"])


def test_compiled_backend_gives_the_numpy_run(capsys):
    pytest.importorskip("llvmlite")
    _, a, _ = _run(capsys, "nbody-ring", "--steps", "10", "--param", "N=6", "--order", "4")
    _, b, _ = _run(capsys, "nbody-ring", "--steps", "10", "--param", "N=6", "--order", "4", "--backend", "numba")
    assert (a["backend"], b["backend"], b["order"]) == ("numpy", "compiled", 4)
    assert np.max(np.abs(np.array(a["y_final"]) - np.array(b["y_final"]))) < 1e-13


def test_verify_and_scenes(capsys):
    assert cli.main(["verify", "nbody-ring", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["all_proved"] and set(rep["proved_invariants"]["energy-momentum"]) == {"H", "P", "L"}
    assert cli.main(["scenes", "--json"]) == 0
    assert "nbody-ring" in [r["name"] for r in json.loads(capsys.readouterr().out)["particles"]]


@pytest.mark.parametrize("argv,words", [
    (["--param", "N=1"], "N ≥ 2"),
    (["--param", "N=2.5"], "must be an integer"),
    (["--param", "Q=1"], "unknown parameter"),
    (["--order", "3"], "composed to order"),
    (["--method", "gauss"], "particles run"),
    (["--save", "x.npz"], "not available for a particle scene"),
])
def test_cli_errors_are_one_line(capsys, argv, words):
    code = cli.main(["run", "nbody-ring", *argv])
    out, err = capsys.readouterr()
    assert code != 0 and words in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_the_trap_runs_and_verifies_energy_momentum_above_order_2(capsys):
    """The trap scene (a central W): energy-momentum at order 4 keeps H and L to round-off at N = 6, and
    its certificates claim H and L (not P, the trap pulls); Störmer–Verlet, the control, does not keep H."""
    assert "trap" in particles_scene_names() and load_particles_scene("trap").orders == {
        "energy-momentum": 2, "stormer-verlet": 4}
    code, em, err = _run(capsys, "trap", "--method", "energy-momentum", "--order", "4", "--steps", "200",
                         "--param", "N=6")
    assert code == 0, err
    assert em["order"] == 4 and em["traits"]["stages"] == 5 and em["traits"]["external_discrete_gradient"] == "central"
    H, L = em["invariants"]["H"], em["invariants"]["L"]
    assert H["max_abs_error"] <= 1e-13 * abs(H["initial"]) and L["max_abs_error"] <= 1e-13 * abs(L["initial"])
    code, sv, err = _run(capsys, "trap", "--method", "stormer-verlet", "--order", "2", "--steps", "200",
                         "--param", "N=6")
    assert code == 0, err
    assert sv["invariants"]["H"]["max_abs_error"] > 1e-8 * abs(sv["invariants"]["H"]["initial"])
    assert cli.main(["verify", "trap", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["all_proved"] and set(rep["proved_invariants"]["energy-momentum"]) == {"H", "L"}


def test_a_scene_order_table_names_what_is_valid(tmp_path):
    from pathlib import Path

    from methodgen.errors import SceneError

    text = Path(load_particles_scene("trap").source).read_text(encoding="utf-8")
    for bad, words in (('order = {gauss = 4}', "does not run"), ('order = {energy-momentum = 5}', "2, 4, 6, 8"),
                       ('order = 3', "2, 4, 6, 8")):
        path = tmp_path / "bad.toml"
        path.write_text(text.replace('order = {energy-momentum = 2, stormer-verlet = 4}', bad))
        with pytest.raises(SceneError, match=words):
            load_particles_scene(path)
    path.write_text(text.replace('order = {energy-momentum = 2, stormer-verlet = 4}', "order = 6"))
    assert load_particles_scene(path).orders == {"energy-momentum": 6, "stormer-verlet": 6}
