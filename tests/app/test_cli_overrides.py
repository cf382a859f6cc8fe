"""`methodgen run` overrides: --y0, --param NAME=VALUE (repeatable), --t-final (issue 15, item 2)."""

from __future__ import annotations

import json

import pytest

from methodgen.app import cli


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
    (["--steps", "10", "--t-final", "1", "--h", "0.1"], "not all three"),
    (["--steps", "0", "--t-final", "1"], "--steps must be at least 1 with --t-final"),
    (["--t-final", "-1"], "runs forward in time but T - t0 = -1"),
])
def test_bad_overrides_are_one_line_errors(capsys, argv, fragment):
    code, _, err = _run(capsys, *argv)
    assert code == cli.EXIT_INPUT
    assert fragment in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


# --- bench: the same overrides (issue 15, item 2: "and the same where bench needs them") ---------

def _bench(capsys, *argv):
    code = cli.main(["bench", "harmonic", "--quick", "--methods", "midpoint", "--json", *argv])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if out.strip() else None), err


def _midpoint_error(k, q0, h, T):
    """Max-norm final error of the midpoint rule on H = p²/2 + k q²/2 from (q0, 0), independently:
    each step is a rotation by θ = 2 atan(ωh/2) of (q, p/ω) (the Cayley transform)."""
    import math
    w = math.sqrt(k)
    n = round(T / h)
    theta = 2 * math.atan(w * h / 2)
    num = (q0 * math.cos(n * theta), -q0 * w * math.sin(n * theta))
    ex = (q0 * math.cos(w * T), -q0 * w * math.sin(w * T))
    return max(abs(a - b) for a, b in zip(num, ex))


def test_bench_overrides_reach_the_work_precision_rows(capsys):
    code, rep, _ = _bench(capsys, "--param", "k=4", "--y0", "0.5,0")
    assert code == 0
    wp = rep["work_precision"]
    rows = [r for r in wp["rows"] if r["kind"] == "methodgen"]
    assert rows
    for r in rows:
        assert r["error"] == pytest.approx(_midpoint_error(4.0, 0.5, r["h"], wp["T"]), rel=1e-6)
    # Negative control: the scene's own k = 1, y0 = (1, 0) give other errors.
    code, rep0, _ = _bench(capsys)
    r0 = [r for r in rep0["work_precision"]["rows"] if r["kind"] == "methodgen"][0]
    assert r0["error"] == pytest.approx(_midpoint_error(1.0, 1.0, r0["h"], wp["T"]), rel=1e-6)
    assert abs(r0["error"] - rows[0]["error"]) > 1e-3


@pytest.mark.parametrize("argv, fragment", [
    (["--param", "omega=2"], "unknown parameter; this scene has: m, k"),
    (["--y0", "1,2,3"], "needs 2 comma-separated values"),
    (["--param", "k=nan"], "is not finite"),
])
def test_bad_bench_overrides_are_one_line_errors(capsys, argv, fragment):
    code, _, err = _bench(capsys, *argv)
    assert code == 2 and fragment in err and "Traceback" not in err
