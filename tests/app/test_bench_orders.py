"""methodgen bench --peers --orders: composed methods in the peers table (structure, never timings)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import methodgen as mg
from methodgen.app import bench
from methodgen.app.cli import main
from methodgen.errors import InputError


def _slope(rows):
    hs = np.array([r["h"] for r in rows])
    errs = np.array([r["error"] for r in rows])
    return float(np.polyfit(np.log(hs), np.log(errs), 1)[0])


@pytest.fixture(scope="module")
def kepler_orders():
    # heyoka/REBOUND may be installed or not: either way the methodgen rows are the subject here.
    return bench.work_precision(mg.load_scene("kepler"), ["energy-momentum"], quick=True, T=3.0, peers=True,
                                orders=(2, 4))


def test_every_order_has_rows_and_order_4_converges_faster(kepler_orders):
    wp = kepler_orders
    assert wp["orders"] == [2, 4]
    ours = [r for r in wp["rows"] if r["kind"] == "methodgen"]
    by_order = {k: [r for r in ours if r["order"] == k] for k in (2, 4)}
    assert {r["method"] for r in by_order[2]} == {"energy-momentum"}
    assert {r["method"] for r in by_order[4]} == {"energy-momentum o4 (suzuki)"}
    for k, rows in by_order.items():
        assert len(rows) == 2, k
        for r in rows:
            assert r["base_method"] == "energy-momentum" and r["seconds"] >= 0 and np.isfinite(r["error"])
    assert by_order[4][0]["composition"] == "suzuki" and by_order[4][0]["stages"] == 5
    assert by_order[2][0]["composition"] is None and by_order[2][0]["stages"] == 1
    s2, s4 = _slope(by_order[2]), _slope(by_order[4])
    assert 1.5 < s2 < 2.5, s2
    assert s4 > 3.3 and s4 > s2 + 1.3, (s2, s4)
    # The composition keeps the base method's exact energy.
    assert max(r["energy_rel_error"] for r in by_order[4]) < 1e-13
    assert set(wp["targets"]) >= {"error", "energy_rel_error", "best", "heyoka", "ias15"}


def test_composed_ladder_reaches_small_steps_only_where_needed():
    h = 0.01
    assert bench.composed_steps(h, 2, quick=True) == [h * f for f in bench.QUICK_PEER_FACTORS]
    for order, stages in ((4, 5), (8, 17), (10, 35)):
        hs = bench.composed_steps(h, order, stages)
        assert hs[0] == pytest.approx(4 * stages * h) and hs[-1] >= h * bench.PEER_FACTORS[-1] * (1 - 1e-12)
        ratios = np.array(hs[:-1]) / np.array(hs[1:])
        np.testing.assert_allclose(ratios, 10 ** (1 / order))   # a decade of error per point
        assert len(hs) <= bench.PEER_MAX_POINTS
    assert bench.row_label("midpoint", 8, "kahan-li") == "midpoint o8 (kahan-li)"
    assert bench.row_label("midpoint") == "midpoint"


def test_targets_picks_the_cheapest_row_that_meets_both():
    rows = [{"method": "a", "kind": "methodgen", "seconds": 1.0, "error": 1e-11, "energy_rel_error": 1e-15},
            {"method": "a", "kind": "methodgen", "seconds": 0.5, "error": 1e-11, "energy_rel_error": 1e-13},
            {"method": "a", "kind": "methodgen", "seconds": 0.2, "error": 1e-9, "energy_rel_error": 1e-15},
            {"method": "heyoka (Taylor)", "kind": "heyoka", "tol": 1e-15, "seconds": 0.01, "error": 1e-12,
             "energy_rel_error": 1e-15},
            {"method": "x", "kind": "methodgen", "h": 1.0}]                      # a run without numbers
    tg = bench.targets(rows)
    assert [(r["method"], r["seconds"]) for r in tg["best"]] == [("heyoka (Taylor)", 0.01), ("a", 1.0)]
    assert tg["heyoka"]["seconds"] == 0.01 and tg["ias15"] is None


def test_frontier_cheapest_per_tool_and_level():
    rows = [{"method": "sv o10", "kind": "methodgen", "h": 0.1, "seconds": 0.04, "error": 5e-11,
             "energy_rel_error": 3e-13},
            {"method": "sv o4", "kind": "methodgen", "h": 0.1, "seconds": 0.01, "error": 1e-7,
             "energy_rel_error": 1e-9},
            {"method": "em o8", "kind": "methodgen", "h": 0.2, "seconds": 0.09, "error": 8e-11,
             "energy_rel_error": 2e-15},
            {"method": "em o8", "kind": "methodgen", "h": 0.1, "seconds": 0.001, "error": float("nan"),
             "energy_rel_error": 2e-15},                                       # failed numerically
            {"method": "heyoka (Taylor)", "kind": "heyoka", "tol": 1e-15, "seconds": 0.02, "error": 2e-11,
             "energy_rel_error": 1e-15},
            {"method": "REBOUND IAS15", "kind": "rebound", "tol": 1e-9, "seconds": 0.05, "error": 3e-7,
             "energy_rel_error": 1e-15},
            {"method": "scipy DOP853", "kind": "scipy", "tol": 1e-9, "seconds": 1e-6, "error": 1e-12},
            {"method": "x", "kind": "methodgen", "h": 1.0}]                      # a run without numbers
    fr = bench.frontier(rows, levels=(1e-6, 1e-10, 1e-12))
    assert fr["tools"] == ["methodgen", "methodgen, energy kept", "REBOUND IAS15", "heyoka"]
    at = {e["level"]: e for e in fr["table"]}
    # 1e-6: the cheap o4 run qualifies for "methodgen" but not for "energy kept" (rel. dE 1e-9)
    assert at[1e-6]["best"]["methodgen"]["method"] == "sv o4"
    assert at[1e-6]["best"]["methodgen, energy kept"]["method"] == "em o8"
    assert at[1e-6]["best"]["REBOUND IAS15"]["seconds"] == 0.05
    assert at[1e-6]["ratio"]["heyoka"] == pytest.approx(0.01 / 0.02)
    # 1e-10: IAS15 (3e-7) does not qualify; the NaN row never counts, scipy rows are not compared
    assert at[1e-10]["best"]["methodgen"]["method"] == "sv o10"
    assert at[1e-10]["best"]["REBOUND IAS15"] is None and at[1e-10]["ratio"]["REBOUND IAS15"] is None
    assert at[1e-10]["ratio"]["heyoka"] == pytest.approx(2.0)
    # 1e-12: nobody of ours gets there
    assert at[1e-12]["best"]["methodgen"] is None and at[1e-12]["ratio"]["heyoka"] is None


def test_cli_json_has_the_composed_rows(capsys, tmp_path):
    pytest.importorskip("matplotlib")
    png = tmp_path / "wp.png"
    assert main(["bench", "kepler", "--peers", "--quick", "--t-final", "2", "--methods", "energy-momentum",
                 "--orders", "2,4", "--json", "--plot", str(png)]) == 0
    rep = json.loads(capsys.readouterr().out)
    wp = rep["work_precision"]
    assert wp["orders"] == [2, 4]
    labels = {r["method"] for r in wp["rows"] if r["kind"] == "methodgen"}
    assert labels == {"energy-momentum", "energy-momentum o4 (suzuki)"}
    assert all(r["order"] in (2, 4) for r in wp["rows"] if r["kind"] == "methodgen")
    assert png.stat().st_size > 0 and rep["plot"] == str(png)


def test_cli_table_names_the_orders(capsys):
    assert main(["bench", "kepler", "--peers", "--quick", "--t-final", "2", "--methods", "energy-momentum",
                 "--orders", "4"]) == 0
    out = capsys.readouterr().out
    assert "energy-momentum o4 (suzuki)" in out
    assert "cheapest run with final error <= 1e-10" in out
    assert "frontier: the cheapest run of each tool" in out


@pytest.mark.parametrize("value, fragment", [
    ("3", "order 3 is not available"),
    ("x", "expected comma-separated orders"),
    ("2,12", "order 12 is not available"),
    ("", "expected comma-separated orders"),
])
def test_bad_orders_exit_2_without_traceback(capsys, value, fragment):
    with pytest.raises(SystemExit) as exc:
        main(["bench", "kepler", "--peers", "--quick", "--orders", value])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--orders" in err and fragment in err and "Traceback" not in err


def test_orders_above_2_need_peers(capsys):
    assert main(["bench", "kepler", "--quick", "--orders", "2,4"]) == 2
    err = capsys.readouterr().err
    assert "--peers" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_non_symmetric_methods_are_a_note_not_a_crash():
    sc = mg.load_scene("kepler")
    wp = bench.work_precision(sc, ["itoh-abe"], quick=True, T=1.0, peers=True, orders=(2, 4))
    ours = [r for r in wp["rows"] if r["kind"] == "methodgen"]
    assert ours and {r["order"] for r in ours} == {2}
    assert any(n.startswith("itoh-abe: not symmetric") for n in wp["notes"])
    with pytest.raises(InputError, match="orders"):
        bench.work_precision(sc, ["midpoint"], quick=True, T=1.0, peers=True, orders=(3,))
