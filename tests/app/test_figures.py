"""The lecture notes' Figures 1 and 2: captions as checked claims, each with a negative control,
and the plots rendered on shortened runs (the full figures come from ``methodgen figures``)."""

from __future__ import annotations

import json
import math
import struct
import sys

import numpy as np
import pytest

from methodgen.app import figures as F
from methodgen.app.cli.figures import _summary as _figures_summary
from methodgen.errors import InputError

A = F.LINEAR_A
OMEGA = math.sqrt(26.0)


def png_size(path) -> tuple[int, int]:
    """(width, height) from the PNG header (signature, then the IHDR chunk)."""
    with open(path, "rb") as fh:
        head = fh.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG file"
    assert head[12:16] == b"IHDR"
    return struct.unpack(">II", head[16:24])


# --- Figure 1 -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def fig1():
    return F.figure1_data()


def test_exact_solution_closed_form_matches_expm():
    from scipy.linalg import expm

    t = np.array([0.0, 0.3, 1.0, 7.5])
    JA = np.array([[0.0, 1.0], [-1.0, 0.0]]) @ A
    ref = np.array([expm(s * JA) @ [1.0, 0.0] for s in t])
    assert np.allclose(F.linear_exact(A, [1.0, 0.0], t), ref, rtol=0, atol=1e-12)


def test_figure1_caption(fig1):
    c = F.figure1_checks(fig1)
    assert c["passed"], c
    for panel, h, steps in (("left", 1.0, 4), ("right", 0.5, 400)):
        p = c[panel]
        assert p["steps"] == steps
        assert p["energy_max_rel_error"] <= 1e-13           # same ellipse, to round-off
        assert p["angle"]["max_deviation"] <= 1e-13        # closed-form speed, every step
        assert abs(p["angle"]["expected"]) == pytest.approx(2 * math.atan(h * OMEGA / 2), abs=1e-15)
        assert abs(p["angle"]["expected"]) < h * OMEGA     # slower than the exact flow


def test_figure1_speed_check_rejects_wrong_speeds(fig1):
    traj, h = fig1["right"]["midpoint"], fig1["right"]["h"]
    # The exact flow's angle and two plausible-looking wrong formulas are all rejected ...
    for wrong in (-h * OMEGA, -math.atan(h * OMEGA), -2 * math.atan(h * OMEGA / 2) * (1 + 1e-9)):
        assert not F.check_angular_speed(traj, A, wrong)["passed"]
    # ... and the exact solution (same ellipse, other speed) fails the midpoint formula,
    exact = F.linear_exact(A, fig1["y0"], h * np.arange(len(traj)))
    assert not F.check_angular_speed(exact, A, F.midpoint_angle(A, h))["passed"]
    # while the measurement itself recovers the exact flow's own angle −hω (< π here).
    assert F.check_angular_speed(exact, A, -h * OMEGA, tol=1e-12)["passed"]


def test_figure1_energy_check_rejects_off_ellipse():
    # Explicit Euler on the same linear system leaves the ellipse: the caption check must fail.
    h, n = 0.5, 20
    M = np.eye(2) + h * (np.array([[0.0, 1.0], [-1.0, 0.0]]) @ A)
    traj = [np.array([1.0, 0.0])]
    for _ in range(n):
        traj.append(M @ traj[-1])
    data = {"A": A, "omega": OMEGA, "H": lambda y: 0.5 * np.einsum("...i,ij,...j->...", y, A, y),
            "left": {"h": h, "midpoint": np.array(traj)}, "right": {"h": h, "midpoint": np.array(traj)}}
    c = F.figure1_checks(data)
    assert not c["passed"]
    assert c["right"]["energy_max_rel_error"] > 1.0


# --- Figure 2 -------------------------------------------------------------------------

@pytest.fixture(scope="module")
def fig2():
    # Shortened: [0, 500] instead of [0, 10 000]; still 100 periods per tenth.
    return F.figure2_data(t_final=500.0)


def test_figure2_caption(fig2):
    c = F.figure2_checks(fig2)
    assert c["passed"], c
    assert set(c["drift"]) == {"midpoint", "trapezoidal", "kahan"}
    for d in c["drift"].values():
        assert d["bounded"] and d["ratio"] <= F.DRIFT_FACTOR
        assert 1e-5 < d["max"] < 1e-2  # an O(h²) error, neither zero nor large
    assert c["kahan_largest"]
    assert c["modified_energy"]["max_rel_drift"] <= 1e-12


def test_drift_check_rejects_explicit_euler():
    """Explicit Euler's energy grows steadily: the "no drift" check must say so."""
    from methodgen.symbolic.scene import load_scene
    from methodgen.codegen.build import build, scene_module_path

    scene = load_scene("henon-heiles")
    mod = build(scene.system, "midpoint", path=scene_module_path(scene, "midpoint"))
    h, n = 0.05, 2000

    def f(y):
        q, p = y
        return np.array([p + q * q - p * p, -(q + 2 * q * p)])  # (∂H/∂p, −∂H/∂q)

    y = np.array(scene.y0)
    traj = [y]
    for _ in range(n):
        y = y + h * f(y)
        traj.append(y)
    Hs = mod.hamiltonian(np.array(traj))
    d = F.energy_drift(Hs - Hs[0])
    assert not d["bounded"] and d["ratio"] > 2 * F.DRIFT_FACTOR


def test_modified_energy_check_rejects_wrong_formulas(fig2):
    Ht, _ = F.modified_energy_function()
    kahan, h = fig2["runs"]["kahan"], fig2["h"]
    good = Ht(kahan, h)
    assert np.max(np.abs(good - good[0])) / abs(good[0]) <= 1e-12
    # Not a control: H̃ with h → −h is conserved too (Kahan is symmetric, so Φ₋ₕ = Φₕ⁻¹
    # conserves it and hence so does Φₕ).  Wrong coefficient h/2 instead of h/3; plain H.
    H = fig2["H"](kahan)
    assert np.max(np.abs(Ht(kahan, -h) - Ht(kahan, -h)[0])) / abs(good[0]) <= 1e-12
    for wrong in (H + 1.5 * (good - H), H):
        data = dict(fig2, modified_energy=wrong)
        c = F.figure2_checks(data)
        assert not c["modified_energy"]["passed"] and c["modified_energy"]["max_rel_drift"] > 1e-6
    # Kahan's modified energy is not conserved by the midpoint rule either.
    mid = Ht(fig2["runs"]["midpoint"], h)
    assert np.max(np.abs(mid - mid[0])) / abs(mid[0]) > 1e-6


def test_modified_energy_matches_verification_layer():
    import sympy as sp

    from methodgen.symbolic.scene import load_scene

    system = load_scene("henon-heiles").system
    _, expr = F.modified_energy_function(system)
    assert sp.cancel(expr - F._modified_energy_expr_local(system)) == 0


def test_kahan_largest_can_fail(fig2):
    errs = dict(fig2["energy_error"])
    errs["midpoint"] = 10 * errs["kahan"]
    assert not F.figure2_checks(dict(fig2, energy_error=errs))["kahan_largest"]


# --- rendering ------------------------------------------------------------------------

SHORT = {"fig1": {"t_right": 20.0}, "fig2": {"t_final": 50.0}}


def test_figures_render_png(tmp_path):
    from methodgen.app.plots import plot_figure1, write_figures

    res = write_figures(tmp_path, "png", **SHORT)
    f1, f2 = res["files"]
    assert png_size(f1) == (1000, 450)
    assert png_size(f2) == (1000, 800)
    import matplotlib.image

    assert matplotlib.image.imread(f2).shape[:2] == (800, 1000)
    # Reproducible bytes: drawing again gives the same file (no dates/versions embedded).
    again = plot_figure1(F.figure1_data(**SHORT["fig1"]), tmp_path / "again.png",
                         checks=res["checks"]["figure1"])
    assert again.read_bytes() == f1.read_bytes()


@pytest.mark.parametrize("fmt,magic", [("svg", b"<?xml"), ("pdf", b"%PDF")])
def test_figure1_renders_svg_pdf(tmp_path, fmt, magic):
    from methodgen.app.plots import plot_figure1

    data = F.figure1_data(**SHORT["fig1"])
    f = plot_figure1(data, tmp_path / f"f.{fmt}")
    assert f.read_bytes()[:5].startswith(magic)
    if fmt == "svg":
        assert 'width="720pt" height="324pt"' in f.read_text(encoding="utf-8")  # 10 × 4.5 in
        assert plot_figure1(data, tmp_path / "g.svg").read_bytes() == f.read_bytes()


def test_plot_run(tmp_path):
    from methodgen.codegen.build import build, scene_module_path
    from methodgen.app.plots import plot_run
    from methodgen.symbolic.scene import load_scene

    s = load_scene("henon-heiles")
    mod = build(s.system, "kahan", path=scene_module_path(s, "kahan"))
    traj = mod.integrate(np.array(s.y0), 0.5, 200)
    out = plot_run(mod, traj, tmp_path / "hh.png", scene_name=s.name, method="kahan", h=0.5)
    assert png_size(out) == (400, 750)  # one phase portrait, one error panel
    with pytest.raises(InputError, match="unknown coordinate"):
        plot_run(mod, traj, tmp_path / "x.png", scene_name="x", method="x", h=1.0, pairs=[("nope", "p")])
    with pytest.raises(InputError, match="format"):
        plot_run(mod, traj, tmp_path / "x.jpg", scene_name="x", method="x", h=1.0)


def test_plots_return_figures_without_a_path(tmp_path):
    """Without a path every plot function returns the Figure and writes nothing; saved, it is
    the same picture as the file written with a path (control: another run is another picture)."""
    from matplotlib.figure import Figure

    from methodgen.codegen.build import build, scene_module_path
    from methodgen.app.plots import plot_run, plot_scene, plot_work_precision
    from methodgen.symbolic.scene import load_scene

    s = load_scene("henon-heiles")
    mod = build(s.system, "kahan", path=scene_module_path(s, "kahan"))
    traj = mod.integrate(np.array(s.y0), 0.5, 200)
    fig = plot_run(mod, traj, scene_name=s.name, method="kahan", h=0.5)
    assert isinstance(fig, Figure) and list(tmp_path.iterdir()) == []
    fig.savefig(tmp_path / "a.png", dpi=100, metadata={"Software": None})
    written = plot_run(mod, traj, tmp_path / "b.png", scene_name=s.name, method="kahan", h=0.5)
    assert (tmp_path / "a.png").read_bytes() == written.read_bytes()
    other = plot_run(mod, traj[:100], tmp_path / "c.png", scene_name=s.name, method="kahan", h=0.5)
    assert other.read_bytes() != written.read_bytes()
    assert isinstance(plot_scene("henon-heiles", steps=20), Figure)
    rows = [{"method": "midpoint", "seconds": 1e-3 * k, "error": 1e-2 / k ** 2} for k in (1, 2, 4)]
    assert isinstance(plot_work_precision(rows), Figure)


def test_plot_scene_constrained(tmp_path):
    from methodgen.app.plots import plot_scene

    out = plot_scene("double-pendulum", tmp_path / "dp.png", steps=30)  # with the residual panel
    assert png_size(out) == (1200, 750)  # (x1, y1), (x1, p1x), (y1, p1y) on top, two panels below


def test_plot_work_precision(tmp_path):
    from methodgen.app.plots import plot_work_precision

    rows = [{"method": m, "seconds": s * k, "error": e / k ** 2}
            for m, s, e in (("midpoint", 1e-3, 1e-2), ("kahan", 5e-4, 3e-2)) for k in (1, 2, 4, 8)]
    rows.append({"method": "kahan", "seconds": 1.0, "error": 0.0})  # not drawable on log axes: skipped
    rows.append({"method": "kahan", "h": 0.1, "failed": "ConvergenceError"})  # bench's failed rows
    rows.append({"method": "kahan", "seconds": 1.0, "error": None})
    assert png_size(plot_work_precision(rows, tmp_path / "wp.png")) == (800, 600)
    with pytest.raises(InputError):
        plot_work_precision([{"method": "m", "seconds": 0.0, "error": 1.0}], tmp_path / "wp2.png")


def test_missing_matplotlib_message(tmp_path, monkeypatch, capsys):
    from methodgen.app.cli import main
    from methodgen.app.plots import PlotUnavailable, plot_work_precision

    monkeypatch.setitem(sys.modules, "matplotlib.backends.backend_agg", None)
    with pytest.raises(PlotUnavailable, match=r'pip install "methodgen\[plot\]"'):
        plot_work_precision([{"method": "m", "seconds": 1.0, "error": 1.0}], tmp_path / "wp.png")
    assert main(["figures", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.strip().count("\n") == 0 and 'pip install "methodgen[plot]"' in err
    assert not list(tmp_path.iterdir())


def test_cli_figures(tmp_path, monkeypatch, capsys):
    import methodgen.app.plots as plots
    from methodgen.app.cli import main

    full = plots.write_figures
    monkeypatch.setattr(plots, "write_figures", lambda out, fmt="png": full(out, fmt, **SHORT))
    assert main(["figures", "--out", str(tmp_path), "--format", "svg", "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["ok"] and rep["checks"]["figure2"]["drift"]["kahan"]["bounded"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure1_linear.svg", "figure2_henon_heiles.svg"]
    assert "2·arctan(hω/2)" in "\n".join(_figures_summary(rep["checks"]))
