"""`methodgen run SCENE --section TEXT` on scenes of symbolic size (particles, 1-D lattices): the
crossings are the module API's (one event location), on the method's own map, and bad input is
one line and exit 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

import methodgen as mg
from methodgen.app import cli
from methodgen.app.particles_scene import load_particles_scene

SECTION = "y[2] = 0, py[2] > 0"


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path_factory.getbasetemp() / "family-section-cache"))


def _run(capsys, *argv):
    code = cli.main(["run", *argv, "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if out.strip() else None), err


def test_particle_section_is_the_apis_and_on_the_methods_map(capsys):
    code, rep, err = _run(capsys, "nbody-ring", "--param", "N=3", "--method", "energy-momentum", "--steps", "2500",
                          "--section", SECTION)
    assert code == 0, err
    assert rep["crossings"] >= 2 and rep["success"] and rep["N"] == 3
    pts = np.array(rep["y_events"])
    names = rep["state_names"]
    y2, py2 = names.index("y[2]"), names.index("py[2]")
    assert names[:2] == ["x[1]", "y[1]"] and names[6] == "px[1]"
    # on the surface to round-off, on the condition's side
    assert np.max(np.abs(pts[:, y2])) <= 1e-15 and np.all(pts[:, py2] > 0)
    # the located states keep what energy-momentum keeps (H to round-off of its size)
    H0 = abs(rep["invariant_errors_at_crossings"]["H"])
    sc = load_particles_scene("nbody-ring")
    mod = mg.build_particles(sc.family, "energy-momentum", order=2)
    y0, arrays = sc.state(3)
    assert H0 <= 1e-13 * abs(mod.hamiltonian(y0, None, arrays))
    # the same source run two ways: the API's section gives bitwise the CLI's crossings
    t, y, _ = mg.poincare(mod, y0, rep["h"], SECTION, crossings=None, t_max=2500 * rep["h"], arrays=arrays)
    assert np.array_equal(t, np.array(rep["t_events"])) and np.array_equal(y, pts)
    # control: the other side of the section crosses at other times
    code, other, err = _run(capsys, "nbody-ring", "--param", "N=3", "--method", "energy-momentum", "--steps", "2500",
                            "--section", "y[2] = 0, py[2] < 0")
    assert code == 0, err
    assert other["crossings"] >= 1 and not set(other["t_events"]) & set(rep["t_events"])
    assert np.all(np.array(other["y_events"])[:, py2] < 0)


def test_lattice_section_numpy_and_compiled_agree(capsys):
    args = ["sine-gordon", "--param", "N=16", "--steps", "1500", "--section", "q[1] = 0, p[1] > 0"]
    code, a, err = _run(capsys, *args)
    assert code == 0, err
    code, b, err = _run(capsys, *args, "--backend", "numba")
    assert code == 0, err
    assert a["crossings"] == b["crossings"] >= 2
    # the rows are the same bits on both backends; the located sub-steps agree to round-off
    np.testing.assert_allclose(a["t_events"], b["t_events"], rtol=0, atol=1e-12)
    assert a["max_abs_g"] <= 1e-15 and b["max_abs_g"] <= 1e-15
    assert a["state_names"][:2] == ["q[1]", "q[2]"] and a["state_names"][16] == "p[1]"


def test_section_plot_is_written(capsys, tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "section.png"
    code = cli.main(["run", "sine-gordon", "--param", "N=8", "--steps", "600", "--section", "q[1] = 0",
                     "--plot", str(out)])
    text, err = capsys.readouterr()
    assert code == 0, err
    assert out.stat().st_size > 1000 and "crossings of 'q[1] = 0'" in text and "plot written" in text


@pytest.mark.parametrize("argv, says", [
    (["nbody-ring", "--param", "N=3", "--section", "vx[1] = 0"], "'vx' is not a field"),
    (["sine-gordon", "--section", "z[1] = 0"], "its fields are q, p"),
    (["sine-gordon", "--section", "q = 0"], "write q[k]"),
    (["nbody-ring", "--plot", "out.png"], "--plot: a particle run draws a Poincaré section only"),
    (["sine-gordon", "--plot", "out.png"], "--plot: a lattice run draws a Poincaré section only"),
    (["klein-gordon-2d", "--param", "N=8", "--section", "q[1] = 0"], "a 2-D lattice takes no text sections"),
])
def test_bad_sections_are_one_line_and_exit_2(capsys, argv, says):
    code = cli.main(["run", *argv])
    out, err = capsys.readouterr()
    assert code == 2 and says in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
