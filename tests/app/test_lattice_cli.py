"""Lattice scenes on the command line: `methodgen run` / `verify` at any N, and their refusals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from methodgen.app import cli
from methodgen.errors import SceneError
from methodgen.app.lattice_scene import is_lattice_scene, lattice_scene_names, load_lattice_scene


@pytest.fixture(autouse=True)
def _cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path_factory.getbasetemp() / "lattice-cache"))


def _run(capsys, *argv):
    code = cli.main(["run", *argv, "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if out.strip() else None), err


@pytest.mark.parametrize("name", lattice_scene_names())
def test_every_builtin_lattice_scene_runs_and_keeps_what_avf_claims(capsys, name):
    code, rep, err = _run(capsys, name, "--steps", "20", "--param", "N=40")
    assert code == 0, err
    nfields = 1 if rep["traits"]["structure"] == "skew" else 2
    # (a 2-D scene's --param N=40 is the 40 × 40 grid: its second size follows the first)
    assert rep["N"] == 40 and rep["method"] == "avf" and len(rep["y_final"]) == 40 ** rep.get("dims", 1) * nfields
    H = rep["invariants"]["H"]
    assert H["max_abs_error"] <= 1e-13 * max(1.0, abs(H["initial"]))


def test_the_size_is_a_run_time_parameter(capsys):
    """Two sizes from one module: the second run loads the file the first wrote (not rewritten)."""
    import os

    code, a, _ = _run(capsys, "sine-gordon", "--steps", "5", "--param", "N=16")
    stamp = os.stat(a["module_file"]).st_mtime_ns
    code2, b, _ = _run(capsys, "sine-gordon", "--steps", "5", "--param", "N=700")
    assert code == code2 == 0 and (a["N"], b["N"]) == (16, 700)
    assert b["module_file"] == a["module_file"] and os.stat(b["module_file"]).st_mtime_ns == stamp


def test_the_compiled_backend_gives_the_numpy_run(capsys):
    pytest.importorskip("llvmlite")
    _, a, _ = _run(capsys, "fpu-chain", "--steps", "30", "--param", "N=20")
    _, b, _ = _run(capsys, "fpu-chain", "--steps", "30", "--param", "N=20", "--backend", "numba")
    assert (a["backend"], b["backend"]) == ("numpy", "compiled")
    assert np.max(np.abs(np.array(a["y_final"]) - np.array(b["y_final"]))) < 1e-13


def test_parameters_reach_the_module(capsys):
    _, a, _ = _run(capsys, "sine-gordon", "--steps", "2", "--param", "N=16")
    _, b, _ = _run(capsys, "sine-gordon", "--steps", "2", "--param", "N=16", "--param", "L=3")
    assert a["invariants"]["H"]["initial"] != b["invariants"]["H"]["initial"]


@pytest.mark.parametrize("argv,fragment", [
    (["--extended"], "--extended: not available for a lattice scene"),
    (["--param", "N=2.5"], "the size must be an integer"),
    (["--param", "N=2"], "N ≥ 3"),
    (["--param", "c=1"], "unknown parameter; this scene has: N, L"),
    (["--method", "gauss"], "a lattice runs avf or midpoint"),
])
def test_refusals_exit_2_with_one_line(capsys, argv, fragment):
    code = cli.main(["run", "sine-gordon", *argv])
    out, err = capsys.readouterr()
    assert code == 2 and fragment in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_an_unresolved_step_is_refused_and_can_be_accepted(capsys):
    code = cli.main(["run", "sine-gordon", "--h", "80", "--steps", "2"])
    _, err = capsys.readouterr()
    assert code == 3 and "does not resolve the motion" in err
    code, rep, _ = _run(capsys, "sine-gordon", "--h", "80", "--steps", "2", "--no-check-resolution")
    assert code == 0


def test_verify_proves_per_site_term(capsys):
    code = cli.main(["verify", "nls", "--json"])
    rep = json.loads(capsys.readouterr()[0])
    assert code == 0 and rep["all_proved"]
    claims = [c["claim"] for c in rep["certificates"]]
    assert sum(c.startswith("term lemma") for c in claims) == 1      # one term: one lemma for AVF
    assert sum(c.startswith("symmetric") for c in claims) == 2        # AVF and midpoint


def test_scene_files_are_checked_key_by_key(tmp_path):
    good = (tmp_path / "ok.toml")
    good.write_text('[lattice]\nH = "Sum(p[i]**2/2 + q[i]**2/2, i, 1, N)"\n[initial]\nq = "sin(i)"\n'
                    '[run]\nN = 8\nh = 0.1\nsteps = 3\n')
    assert is_lattice_scene(good)
    sc = load_lattice_scene(good)
    assert np.allclose(sc.y0(8)[:8], np.sin(np.arange(1, 9))) and not sc.y0(8)[8:].any()
    for text, fragment in [
        ('[lattice]\nH = "Sum(p[i]**2, i, 1, N)"\nwhat = 1\n[run]\nN = 8\nh = 0.1\nsteps = 3\n', "unknown key 'what'"),
        ('[lattice]\nH = "Sum(p[i]**2, i, 1, N)"\n[run]\nN = 8\nh = 0.1\n', "steps is missing"),
        ('[lattice]\nH = "Sum(p[i]**2, i, 1, N)"\n[initial]\nq = "__import__(1)"\n[run]\nN = 8\nh = 0.1\nsteps = 3\n',
         "unknown function"),
        ('[lattice]\nH = "Sum(p[i]**2, i, 1, N)"\n[initial]\nr = "1"\n[run]\nN = 8\nh = 0.1\nsteps = 3\n',
         "r is not a field"),
        ('[lattice]\nH = "Sum(p[i]**2, i, 1, N)"\n[run]\nmethod = "gauss"\nN = 8\nh = 0.1\nsteps = 3\n',
         "not available for a lattice"),
        ('[lattice]\nH = "Sum(p[j]**2 + i*q[j]**2, j, 1, N)"\n[params]\ni = 3.0\n[run]\nN = 8\nh = 0.1\n'
         'steps = 3\n', "'i' is the site index"),
    ]:
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(SceneError, match=fragment.replace("(", r"\(")):
            load_lattice_scene(bad)


# --- the KdV scene: a skew lattice (u' = S ∇H) ------------------------------------------------

def test_kdv_runs_on_both_backends_and_keeps_energy_and_mass(capsys):
    pytest.importorskip("llvmlite")
    code, a, err = _run(capsys, "kdv", "--steps", "40", "--param", "N=64")
    assert code == 0, err
    code, b, err = _run(capsys, "kdv", "--steps", "40", "--param", "N=64", "--backend", "numba")
    assert code == 0, err
    assert (a["backend"], b["backend"]) == ("numpy", "compiled") and len(a["y_final"]) == 64
    assert np.max(np.abs(np.array(a["y_final"]) - np.array(b["y_final"]))) < 1e-13
    for rep in (a, b):
        for k in ("H", "mass"):
            v = rep["invariants"][k]
            assert v["max_abs_error"] <= 1e-13 * max(1.0, abs(v["initial"]))
    assert a["traits"]["structure"] == "skew" and a["traits"]["energy_preserving"]


def test_kdv_refuses_a_size_below_the_minimum_with_one_line(capsys):
    code = cli.main(["run", "kdv", "--param", "N=4"])
    out, err = capsys.readouterr()
    assert code == 2 and "needs N ≥ 5 sites" in err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_kdv4_runs_at_an_odd_size_on_both_backends_and_keeps_energy_and_mass(capsys):
    """The fourth-order KdV (a skew stencil of half-width 2, terms two sites wide: the Newton matrix
    couples sites 4 apart, grouped 4 sites a block, the last group taking N mod 4 = 3 more)."""
    pytest.importorskip("llvmlite")
    code, a, err = _run(capsys, "kdv4", "--steps", "40", "--param", "N=63")
    assert code == 0, err
    code, b, err = _run(capsys, "kdv4", "--steps", "40", "--param", "N=63", "--backend", "numba")
    assert code == 0, err
    assert len(a["y_final"]) == 63 and np.max(np.abs(np.array(a["y_final"]) - np.array(b["y_final"]))) < 1e-13
    for rep in (a, b):
        for k in ("H", "mass"):
            v = rep["invariants"][k]
            assert v["max_abs_error"] <= 1e-13 * max(1.0, abs(v["initial"]))
    code, mid, err = _run(capsys, "kdv4", "--steps", "40", "--param", "N=63", "--method", "midpoint")
    assert code == 0 and mid["invariants"]["H"]["max_abs_error"] > 1e-9        # the control drifts
    code = cli.main(["run", "kdv4", "--param", "N=8"])
    assert code == 2 and "needs N ≥ 9 sites" in capsys.readouterr()[1]


def test_verify_kdv4_proves_per_template(capsys):
    code = cli.main(["verify", "kdv4", "--json"])
    rep = json.loads(capsys.readouterr()[0])
    assert code == 0 and rep["all_proved"]
    assert rep["proved_invariants"] == {"avf": ["H", "mass"], "midpoint": ["mass"]}


def test_verify_kdv_says_which_invariants_are_proved(capsys):
    code = cli.main(["verify", "kdv", "--json"])
    rep = json.loads(capsys.readouterr()[0])
    assert code == 0 and rep["all_proved"]
    assert rep["proved_invariants"] == {"avf": ["H", "mass"], "midpoint": ["mass"]}
    claims = [c["claim"] for c in rep["certificates"] if c["method"] == "avf"]
    assert any(c.startswith("skew stencil") for c in claims)
    code = cli.main(["verify", "kdv"])
    out = capsys.readouterr()[0]
    assert code == 0 and "avf keeps, proved at every N: H, mass" in out


@pytest.mark.parametrize("table,fragment", [
    ('fields = ["u"]\n', "together"),
    ('skew = "g[i+1] - g[i-1]"\n', "together"),
    ('fields = ["u"]\nskew = "g[i+1] - g[i-1]"\nq = "x"\n', "without q and p"),
    ('fields = [1]\nskew = "g[i+1] - g[i-1]"\n', "list of names"),
    ('fields = ["u"]\nskew = "g[i+1] + g[i-1]"\n', "is not skew"),
])
def test_skew_scene_tables_are_checked(tmp_path, table, fragment):
    bad = tmp_path / "bad.toml"
    bad.write_text(f'[lattice]\nH = "Sum(u[i]**2, i, 1, N)"\n{table}[run]\nN = 8\nh = 0.1\nsteps = 3\n')
    with pytest.raises(SceneError, match=fragment):
        load_lattice_scene(bad)


def test_klein_gordon_2d_runs_at_any_size_and_keeps_energy(capsys):
    """The 2-D scene: --param N=12 is the 12 × 12 grid (its second size follows), M= sets the second;
    AVF keeps H to round-off, the midpoint rule (the control) does not; one module for both sizes."""
    code, a, err = _run(capsys, "klein-gordon-2d", "--steps", "40", "--param", "N=12")
    assert code == 0, err
    assert (a["N"], a["M"], a["dims"], len(a["y_final"])) == (12, 12, 2, 2 * 12 * 12)
    H = a["invariants"]["H"]
    assert H["max_abs_error"] <= 1e-14 * abs(H["initial"])
    code, b, err = _run(capsys, "klein-gordon-2d", "--steps", "40", "--param", "N=12", "--param", "M=16")
    assert code == 0 and (b["N"], b["M"]) == (12, 16) and b["module_file"] == a["module_file"]
    _, c, _ = _run(capsys, "klein-gordon-2d", "--steps", "40", "--param", "N=12", "--method", "midpoint")
    Hm = c["invariants"]["H"]
    assert Hm["max_abs_error"] > 1e-9 * abs(Hm["initial"])


def test_klein_gordon_2d_default_size_and_the_numba_backend(capsys):
    pytest.importorskip("llvmlite")
    scene = load_lattice_scene("klein-gordon-2d")
    assert scene.size == (128, 128) and scene.y0((128, 128)).shape == (2, 128, 128)
    code = cli.main(["run", "klein-gordon-2d", "--steps", "30", "--param", "N=8", "--backend", "numba"])
    out, _ = capsys.readouterr()
    assert code == 0 and "backend compiled" in out and "N × M = 8 × 8" in out
    _, a, _ = _run(capsys, "klein-gordon-2d", "--steps", "30", "--param", "N=8")
    _, b, _ = _run(capsys, "klein-gordon-2d", "--steps", "30", "--param", "N=8", "--backend", "numba")
    assert (a["backend"], b["backend"]) == ("numpy", "compiled")
    assert np.max(np.abs(np.array(a["y_final"]) - np.array(b["y_final"]))) < 1e-13


def test_verify_klein_gordon_2d_decides_per_template(capsys):
    code = cli.main(["verify", "klein-gordon-2d"])
    out, _ = capsys.readouterr()
    assert code == 0 and "[proved] avf: term lemma" in out
    assert "avf keeps, proved at every N × M: H" in out


@pytest.mark.parametrize("table,fragment", [
    ('[lattice]\nH = "Sum(Sum(p[i, j]**2/2 + q[i + 1, j]**2, j, 1, M), i, 1, N)"\nsize = ["N", "M"]\n'
     '[run]\nN = 8\nh = 0.1\nsteps = 2\n', "not a periodic neighbour"),
    ('[lattice]\nH = "Sum(Sum(p[i, j]**2/2 + q[i, j]**2, j, 1, M), i, 1, N)"\nsize = ["N", "M", "K"]\n'
     '[run]\nN = 8\nh = 0.1\nsteps = 2\n', "two names for a 2-D lattice"),
    ('[lattice]\nH = "Sum(Sum(p[i, j]**2/2 + q[i, j]**2, j, 1, M), i, 1, N)"\nsize = ["N", "M"]\n'
     '[run]\nN = 8\nK = 3\nh = 0.1\nsteps = 2\n', "unknown key 'K'"),
    ('[lattice]\nH = "Sum(Sum(p[i, j]**2/2 + q[i, j]**2, j, 1, M), i, 1, N)"\nsize = ["N", "M"]\n'
     '[run]\nN = 8\nM = 2\nh = 0.1\nsteps = 2\n', "needs M ≥ 3"),
])
def test_2d_scene_tables_are_checked(tmp_path, table, fragment):
    path = tmp_path / "s.toml"
    path.write_text(table)
    with pytest.raises(SceneError, match=fragment):
        load_lattice_scene(path)
