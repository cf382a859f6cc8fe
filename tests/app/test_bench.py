"""methodgen bench: structure of the output and the physics it shows (never timings)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import methodgen as mg
from methodgen.app import bench


@pytest.fixture(scope="module")
def harmonic_quick():
    res = subprocess.run([sys.executable, "-m", "methodgen", "bench", "harmonic", "--quick", "--json"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_bench_json_structure(harmonic_quick):
    rep = harmonic_quick
    wp = rep["work_precision"]
    assert wp["reference"].startswith("exact")
    kinds = {r["kind"] for r in wp["rows"]}
    assert kinds == {"methodgen", "fsolve", "scipy"}
    assert {r["method"] for r in wp["rows"] if r["kind"] == "scipy"} == {"scipy RK45", "scipy DOP853", "scipy Radau"}
    for r in wp["rows"]:
        for key in ("seconds", "error", "energy_error", "invariant_errors"):
            assert key in r
    assert {r["solver"] for r in rep["solvers"]["rows"]} == {"newton", "simplified", "fixed-point", "reuse", "auto"}


def test_bench_rows_show_second_order_and_exact_energy(harmonic_quick):
    rows = [r for r in harmonic_quick["work_precision"]["rows"] if r["method"] == "midpoint"]
    hs = np.array([r["h"] for r in rows])
    errs = np.array([r["error"] for r in rows])
    slope = np.polyfit(np.log(hs), np.log(errs), 1)[0]
    assert 1.8 < slope < 2.2
    assert max(r["energy_error"] for r in rows) < 1e-14      # quadratic H: midpoint preserves it
    rk45 = [r for r in harmonic_quick["work_precision"]["rows"] if r["method"] == "scipy RK45"]
    assert max(r["energy_error"] for r in rk45) > 1e-10       # ... a non-geometric peer does not


def test_geometric_energy_error_is_bounded_where_dop853_drifts():
    sc = mg.load_scene("kepler")
    rep = bench.long_run(sc, ["energy-momentum"], steps=20_000)
    em, dop = rep["rows"]
    assert dop["method"].startswith("scipy DOP853")
    assert em["max_energy_error"] < 1e-13
    assert dop["max_energy_error"] > 10 * em["max_energy_error"]
    assert dop["growth_exponent"] > 0.4          # drifting
    assert em["growth_exponent"] < dop["growth_exponent"]


def test_growth_exponent_fit():
    t = np.linspace(0.01, 1000, 100_000)
    assert bench.growth_exponent(t, 1e-12 * t) == pytest.approx(1.0, abs=0.05)
    assert bench.growth_exponent(t, 1e-12 * np.sqrt(t)) == pytest.approx(0.5, abs=0.05)
    assert abs(bench.growth_exponent(t, 1e-15 * (2 + np.sin(t)))) < 0.1


@pytest.mark.slow   # 12 s; bench --brouwer, the 1e6-step version is slow too
def test_brouwer_stepper_follows_sqrt_t_below_the_plain_stepper():
    """RMS energy error of the exact numerical states (extended precision): √t growth,
    and compensated summation keeps it well below the plain-summation stepper."""
    rep = bench.brouwer(ensemble=100, steps=20_000)
    rows = {("extended" if r["extended"] else "plain" if "plain" in r["stepper"] else "default"): r
            for r in rep["rows"]}
    assert set(rows) == {"extended", "default", "plain"}
    for key in ("extended", "default"):
        good = rows[key]
        assert 0.35 < good["slope"] < 0.65, key
        assert good["rms_energy_error"][-1] < 0.1 * rows["plain"]["rms_energy_error"][-1], key
    # Negative control of the slope fit: a linear drift is not called √t.
    t = np.array(rows["extended"]["t"])
    slope_lin = np.polyfit(np.log(t[t >= t[-1] / 100]), np.log(1e-16 * t[t >= t[-1] / 100]), 1)[0]
    assert not 0.35 < slope_lin < 0.65


def test_reference_is_exact_where_known():
    harm = mg.load_scene("harmonic")
    ref = bench.reference(harm.system, np.array([1.0, 0.0]), 2.0)
    assert ref.kind.startswith("exact") and np.allclose(ref.y, [np.cos(2.0), -np.sin(2.0)], atol=1e-14)
    circ = mg.load_scene("kepler").system
    ref = bench.reference(circ, np.array([1.0, 0, 0, 0, 1.0, 0]), np.pi)
    assert ref.kind == "exact (circular Kepler orbit)"
    assert np.allclose(ref.y, [-1.0, 0, 0, 0, -1.0, 0], atol=1e-14)
    ecc = bench.reference(circ, np.array([0.4, 0, 0, 0, 1.6, 1.2]), 1.0)
    assert ecc.kind.startswith("DOP853")


@pytest.mark.slow
def test_brouwer_law_over_a_million_steps_at_h_001():
    """The issue's acceptance run (about 8 min): 100 phases, h = 0.01, 10⁶ steps.  The refined
    stepper follows √t over the last two decades of t; the default stepper, whose small
    systematic drift takes over after ~10⁵ steps, is the negative control."""
    rep = bench.brouwer(ensemble=100, steps=1_000_000)
    ext = next(r for r in rep["rows"] if r["extended"])
    default = next(r for r in rep["rows"] if not r["extended"] and "plain" not in r["stepper"])
    assert 0.4 < ext["slope"] < 0.6
    assert default["slope"] > 0.6
    assert ext["rms_energy_error"][-1] < default["rms_energy_error"][-1]
