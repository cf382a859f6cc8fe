"""`methodgen run` overrides: --y0, --param NAME=VALUE (repeatable), --t-final (issue 15, item 2)."""

from __future__ import annotations

import json

import pytest

from methodgen import cli


def _run(capsys, *argv):
    code = cli.main(["run", "kepler", "--json", *argv])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if out.strip() else None), err


def test_overrides_reach_the_run(capsys):
    code, rep, _ = _run(capsys, "--y0", "0.5,0,0,0,1.2,0.9", "--param", "k=2", "--t-final", "0.5")
    assert code == 0
    assert rep["y0"] == [0.5, 0, 0, 0, 1.2, 0.9] and rep["params"] == {"m": 1.0, "k": 2.0}
    assert rep["steps"] == 50 and rep["t_final"] == pytest.approx(0.5)
    # H(y0) = |p|²/2 - k/|q| with the overridden k and y0: the parameter reached the module.
    assert rep["invariants"]["H"]["initial"] == pytest.approx(1.125 - 2 / 0.5)
    assert rep["invariants"]["H"]["max_rel_error"] < 1e-13


def test_without_overrides_the_scene_values_are_used(capsys):
    """Negative control for the test above: the defaults give a different H(y0)."""
    code, rep, _ = _run(capsys, "--steps", "10")
    assert code == 0 and rep["params"] == {"m": 1.0, "k": 1.0}
    assert rep["invariants"]["H"]["initial"] == pytest.approx((1.6**2 + 1.2**2) / 2 - 1 / 0.4)


@pytest.mark.parametrize("argv, fragment", [
    (["--param", "q=1"], "unknown parameter; this scene has: m, k"),
    (["--param", "k"], "expected NAME=VALUE"),
    (["--param", "k=inf"], "is not finite"),
    (["--param", "k=abc"], "is not a number"),
    (["--y0", "1,2"], "needs 6 comma-separated values"),
    (["--y0", "0.5,0,0,0,1.2,nan"], "entry 6: 'nan' is not finite"),
    (["--steps", "10", "--t-final", "1"], "either --steps or --t-final"),
    (["--t-final", "-1"], "positive finite time"),
])
def test_bad_overrides_are_one_line_errors(capsys, argv, fragment):
    code, _, err = _run(capsys, *argv)
    assert code == cli.EXIT_INPUT
    assert fragment in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
