"""Never a crash, bounded time: undecided certificates, the time budget, --timeout, progress."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import pytest

import methodgen as mg
import methodgen.symbolic.verify  # noqa: F401  (loads the package)
from methodgen.app.cli import main as cli_main
from methodgen.symbolic.verify import UNDECIDED, Certificate, Report
from methodgen.symbolic.verify.budget import BudgetExceeded, budget, budget_supported
from methodgen.symbolic.verify.report import STATUSES

V = sys.modules["methodgen.symbolic.verify"]          # the package (``mg.verify`` is the function)

needs_alarm = pytest.mark.skipif(not budget_supported(), reason="SIGALRM budget needs POSIX main thread")


@pytest.fixture(scope="module")
def harmonic_midpoint():
    return mg.discretize(mg.load_scene("harmonic").system, "midpoint")


@pytest.fixture(scope="module")
def kepler_em():
    return mg.discretize(mg.load_scene("kepler").system, "energy-momentum")


def _busy(seconds: float, swallow: bool = False) -> None:
    """Pure-Python work for at most ``seconds``; with ``swallow`` every Exception is eaten,
    wherever in the loop it is raised (as SymPy's ``except Exception:`` blocks do)."""
    stop, n = time.monotonic() + seconds, 0
    while True:
        try:
            while True:
                if time.monotonic() >= stop:
                    return
                n += sum(range(200)) % 7
                if swallow and n % 1001 == 0:
                    raise ValueError("an ordinary failure, eaten")
        except Exception:
            if not swallow:
                raise


# --- (a) exceptions become undecided ---------------------------------------------------

def test_undecided_status_and_report():
    assert UNDECIDED == "undecided" and UNDECIDED in STATUSES
    c = Certificate("some claim", UNDECIDED, details={"reason": "time budget of 1 s exceeded"})
    assert c.passed
    rep = Report("t", [c, Certificate("other", "proved")])
    # undecided is not a failure, but not "ok" either (issue 28.6c)
    assert not rep.ok and not rep.refuted and rep.verdict == "undecided"
    assert rep.all_passed and not rep.decided and rep.undecided == [c]
    assert str(rep).startswith("t: UNDECIDED (1 undecided)")
    assert "[undecided] some claim  (time budget of 1 s exceeded)" in str(rep)
    assert "undecided" in rep.markdown() and "time budget of 1 s exceeded" in rep.markdown()
    assert r"\item[undecided]" in rep.latex()
    d = json.loads(rep.to_json())
    assert set(d) == {"ok", "verdict", "title", "seconds", "certificates"}
    assert d["ok"] is False and d["verdict"] == "undecided"
    assert d["certificates"][0]["status"] == UNDECIDED
    assert Report("t", [Certificate("x", "proved")]).decided
    assert Report("t", [Certificate("x", "proved")]).ok          # positive control of the verdict


def test_no_certificate_is_never_ok():
    """Issue 27.6: a report with nothing verified is not "ok" (a scheme always has claims)."""
    rep = Report("t", [])
    assert not rep.ok and not rep.refuted and rep.verdict == "nothing verified"
    assert str(rep).startswith("t: NOTHING VERIFIED")
    assert "NOTHING VERIFIED" in rep.markdown()


def test_raising_claim_is_undecided(monkeypatch, harmonic_midpoint):
    def boom(scheme):
        raise ZeroDivisionError("division by zero in the reduction")

    monkeypatch.setattr(V, "invariant_certificates", boom)
    rep = mg.verify(harmonic_midpoint)                    # no exception escapes
    assert not rep.refuted and rep.verdict == "undecided" and rep.all_passed and not rep.decided
    [c] = rep.undecided
    assert c.claim == "invariants kept by the step (midpoint)"
    assert c.details["reason"] == "reduction failed: ZeroDivisionError: division by zero in the reduction"
    assert "\n" not in c.details["reason"]
    assert rep.find("symplectic")[0].status == "proved"    # the other claims still ran


def test_failing_applicability_check_is_undecided(monkeypatch, kepler_em):
    def boom(system):
        raise RuntimeError("radial_profile choked\nsecond line")

    monkeypatch.setattr(V, "radial_profile", boom)
    rep = mg.verify(kepler_em)
    assert not rep.refuted and not rep.ok
    und = rep.undecided
    assert [c.claim for c in und] == ["q × p first integrals for every radial potential V (3D)",
                                      "q × p first integrals of this H"]
    for c in und:
        assert c.details["reason"].startswith("could not decide whether the claim applies")
        assert "RuntimeError: radial_profile choked" in c.details["reason"]
        assert "\n" not in c.details["reason"]
    assert rep.find("discrete-gradient identity")[0].status == "proved"


def test_broken_scheme_is_undecided_not_a_crash():
    rep = mg.verify(object())
    assert not rep.refuted and not rep.ok and not rep.decided and len(rep) == 1
    assert rep[0].details["reason"].startswith("reduction failed: AttributeError")


def test_timeout_argument_validation(harmonic_midpoint):
    assert V._claim_seconds(None) == V._claim_seconds(0) == V.DEFAULT_TIMEOUT == 60
    assert V._claim_seconds(2.5) == 2.5
    for bad in (-1, float("nan"), float("inf"), "abc"):
        with pytest.raises(ValueError, match="timeout"):
            mg.verify(harmonic_midpoint, timeout=bad)


# --- (b) the budget interrupts pure-Python loops ----------------------------------------

@needs_alarm
def test_budget_interrupts_pure_python_loop():
    t0 = time.monotonic()
    with pytest.raises(BudgetExceeded) as info:
        with budget(0.3) as b:
            _busy(10)
    assert info.value.budget is b and b.expired and b.enforced
    assert time.monotonic() - t0 < 1.5
    assert not issubclass(BudgetExceeded, Exception)


@needs_alarm
def test_budget_interrupts_loop_that_catches_exception():
    t0 = time.monotonic()
    with pytest.raises(BudgetExceeded):
        with budget(0.3):
            _busy(10, swallow=True)
    assert time.monotonic() - t0 < 1.5


@needs_alarm
def test_negative_control_an_exception_alarm_would_be_swallowed():
    """Why BudgetExceeded is a BaseException: an Exception raised by the alarm is eaten."""
    class Alarm(Exception):
        pass

    def handler(signum, frame):
        raise Alarm

    old = signal.signal(signal.SIGALRM, handler)
    try:
        # An alarm handled between two swallowing blocks (at the loop's jump back, outside the
        # try) escapes: rare, but it happens on a loaded machine.  Such a run proves nothing
        # either way, so it is repeated; the control holds if one run swallows every alarm.
        for _attempt in range(5):
            try:
                signal.setitimer(signal.ITIMER_REAL, 0.1, 0.1)
                t0 = time.monotonic()
                try:
                    _busy(0.6, swallow=True)      # runs to its own end: the alarms were swallowed
                finally:
                    signal.setitimer(signal.ITIMER_REAL, 0, 0)
                elapsed = time.monotonic() - t0
            except Alarm:
                # (also one delivered late, at the timer's switch-off: it escaped no block of _busy)
                continue
            assert elapsed >= 0.55
            break
        else:
            pytest.fail("every run let an alarm escape: Exception alarms were not swallowed")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0, 0)
        signal.signal(signal.SIGALRM, old)


@needs_alarm
def test_budget_refires_after_a_swallowed_alarm():
    caught = 0
    t0 = time.monotonic()
    with pytest.raises(BudgetExceeded):
        with budget(0.2):
            while time.monotonic() - t0 < 5:
                try:
                    _busy(5)
                except BudgetExceeded:            # a bare ``except:`` somewhere deep in SymPy
                    caught += 1
                    if caught >= 3:
                        raise
    assert caught == 3 and time.monotonic() - t0 < 2


@needs_alarm
def test_verify_claim_over_budget_is_undecided(monkeypatch, harmonic_midpoint):
    monkeypatch.setattr(V, "symplectic_certificate", lambda scheme: _busy(30, swallow=True))
    t0 = time.monotonic()
    rep = mg.verify(harmonic_midpoint, timeout=0.5)
    assert time.monotonic() - t0 < 4
    assert not rep.refuted and not rep.ok and not rep.decided
    [c] = rep.undecided
    assert c.claim == "the step map is symplectic (midpoint)"
    assert "budget" in c.details["reason"] and c.details["timeout"] == 0.5
    assert 0.4 < c.seconds < 2


# --- (e) the budget restores the previous handler and timer ------------------------------

@needs_alarm
def test_budget_restores_previous_handler_and_timer():
    calls = []

    def handler(signum, frame):
        calls.append(time.monotonic())

    old = signal.signal(signal.SIGALRM, handler)
    try:
        signal.setitimer(signal.ITIMER_REAL, 100, 0)
        with budget(5):
            assert signal.getsignal(signal.SIGALRM) is not handler
            assert 0 < signal.getitimer(signal.ITIMER_REAL)[0] <= 5     # the earlier deadline
        assert signal.getsignal(signal.SIGALRM) is handler
        delay, interval = signal.getitimer(signal.ITIMER_REAL)
        assert 98 < delay <= 100 and interval == 0
        # An earlier foreign timer still fires inside the budget, through its own handler.
        signal.setitimer(signal.ITIMER_REAL, 0.1, 0)
        with budget(5):
            _busy(0.4)
        assert len(calls) == 1
        assert signal.getsignal(signal.SIGALRM) is handler
        assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0, 0)
        signal.signal(signal.SIGALRM, old)
    assert signal.getsignal(signal.SIGALRM) is old


@needs_alarm
def test_nested_budgets_keep_the_earlier_deadline():
    with pytest.raises(BudgetExceeded) as info:
        with budget(0.3) as outer:
            with budget(10) as inner:
                _busy(5)
    assert info.value.budget is outer and not inner.expired
    with budget(10):
        with pytest.raises(BudgetExceeded) as info:
            with budget(0.2) as inner:
                _busy(5)
        assert info.value.budget is inner
        assert 9 < signal.getitimer(signal.ITIMER_REAL)[0] <= 10      # the outer deadline again
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


@needs_alarm
def test_enclosing_budget_is_not_swallowed_by_verify(monkeypatch, harmonic_midpoint):
    monkeypatch.setattr(V, "symplectic_certificate", lambda scheme: _busy(30))
    with pytest.raises(BudgetExceeded):
        with budget(0.3):
            mg.verify(harmonic_midpoint, timeout=20)


def test_budget_rejects_bad_seconds():
    for bad in (0, -1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="positive finite"):
            budget(bad)


# --- (c) the command line ------------------------------------------------------------------

def _cli(*args):
    return subprocess.run([sys.executable, "-m", "methodgen", *args], capture_output=True, text=True,
                          timeout=120)


@needs_alarm
def test_cli_tiny_timeout_is_undecided_not_a_crash():
    r = _cli("verify", "kepler", "--method", "energy-momentum", "--timeout", "0.001", "--json")
    assert r.returncode == 3, r.stderr            # undecided: neither ok (0) nor refuted (1)
    assert "Traceback" not in r.stderr
    d = json.loads(r.stdout)
    assert d["ok"] is False and d["verdict"] == "undecided"
    statuses = {c["status"] for c in d["certificates"]}
    assert "undecided" in statuses and statuses <= set(STATUSES)
    for c in d["certificates"]:
        if c["status"] == "undecided":
            assert "budget of 0.001 s exceeded" in c["details"]["reason"]


@pytest.mark.parametrize("value", ["-1", "abc", "0", "nan", "inf"])
def test_cli_bad_timeout(value, capsys):
    with pytest.raises(SystemExit) as info:
        cli_main(["verify", "harmonic", f"--timeout={value}"])
    assert info.value.code == 2
    out, err = capsys.readouterr()
    assert out == "" and "Traceback" not in err
    assert err.strip().splitlines()[-1] == (f"methodgen: error: argument --timeout: "
                                            f"expected a positive number of seconds, got {value!r}")


def test_cli_text_shows_undecided(monkeypatch, capsys):
    monkeypatch.setattr(V, "invariant_certificates", lambda scheme: 1 / 0)
    assert cli_main(["verify", "harmonic", "--method", "midpoint"]) == 3
    out, _ = capsys.readouterr()
    assert "midpoint on harmonic: UNDECIDED (1 undecided)" in out
    assert "[undecided] invariants kept by the step (midpoint)  (reduction failed: ZeroDivisionError" in out


@needs_alarm
def test_cli_tiny_timeout_text_is_not_ok(capsys):
    """Issue 28.6c: ``--timeout 1e-9`` decides nothing; the text must not say ok."""
    assert cli_main(["verify", "harmonic", "--method", "midpoint", "--timeout", "1e-9"]) == 3
    out, _ = capsys.readouterr()
    assert "midpoint on harmonic: UNDECIDED" in out and ": ok" not in out
    # positive control: with the default budget the same verification is ok, exit 0
    assert cli_main(["verify", "harmonic", "--method", "midpoint"]) == 0
    assert "midpoint on harmonic: ok" in capsys.readouterr()[0]


# --- (d) progress -----------------------------------------------------------------------------

def test_progress_only_after_threshold_and_never_on_stdout(monkeypatch, capsys):
    assert cli_main(["verify", "harmonic", "--method", "midpoint", "--json"]) == 0
    out, err = capsys.readouterr()
    json.loads(out)
    assert err == ""                                   # fast run: nothing printed
    monkeypatch.setattr(V, "PROGRESS_AFTER", 0.0)
    assert cli_main(["verify", "harmonic", "--method", "midpoint", "--json"]) == 0
    out, err = capsys.readouterr()
    assert json.loads(out)["ok"] is True               # stdout: exactly one JSON object
    assert "verify:" not in out
    assert "verify: [1/4] invariants kept by the step (midpoint)" in err
    assert "verify: [4/4] the step is symmetric (midpoint)" in err


def test_progress_tqdm_on_a_terminal(monkeypatch, capsys, harmonic_midpoint):
    pytest.importorskip("tqdm")
    monkeypatch.setattr(V, "PROGRESS_AFTER", 0.0)
    monkeypatch.setattr(V._Progress, "_tty", lambda self: True)
    rep = mg.verify(harmonic_midpoint, progress=True)
    out, err = capsys.readouterr()
    assert rep.ok and out == ""
    assert "\rverify: [4/4] the step is symmetric (midpoint) …" in err


def test_progress_off_by_default_in_the_api(monkeypatch, capsys, harmonic_midpoint):
    monkeypatch.setattr(V, "PROGRESS_AFTER", 0.0)
    mg.verify(harmonic_midpoint)
    assert capsys.readouterr() == ("", "")
