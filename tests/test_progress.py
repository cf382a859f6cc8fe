"""Progress of long work (issue 25, item 4; issue 28, 8b): phases reported in order, never timed here."""

from __future__ import annotations

import io
import warnings

import pytest

import methodgen as mg
import methodgen.cli as cli
from methodgen import progress
from methodgen.progress import StderrReporter, phase


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)
    previous = progress.install(None)
    yield
    progress.install(previous)


def recorder():
    calls = []

    def report(name, elapsed, done):
        assert elapsed >= 0.0
        calls.append((name, done))

    return calls, report


def test_a_cold_build_reports_its_phases_in_order():
    calls, report = recorder()
    system = mg.Hamiltonian("p**2/2 + q**4/4", ["q"], ["p"], name="quartic")
    mod = mg.build(system, "midpoint", progress=report)
    assert callable(mod.step)
    phases = ["derive", "lower", "render", "write", "load"]
    assert calls == [(p, d) for p in phases for d in (False, True)]
    # Negative control: the warm build (module up to date) derives nothing and says so.
    calls.clear()
    mg.build(system, "midpoint", progress=report)
    assert calls == [("load", False), ("load", True)]


def test_the_api_is_silent_by_default(capsys):
    mg.build(mg.Hamiltonian("p**2/2 + q**6/6", ["q"], ["p"], name="sextic"), "midpoint")
    assert capsys.readouterr().err == ""


def test_build_text_reports_too():
    calls, report = recorder()
    mg.build_text("p**2/2 + q**4/4", ["q"], ["p"], "midpoint", name="q4", progress=report)
    assert [p for p, d in calls if d] == ["derive", "lower", "render", "write", "load"]
    calls.clear()
    mg.build_text("p**2/2 + q**4/4", ["q"], ["p"], "midpoint", name="q4", progress=report)
    assert calls == [("load", False), ("load", True)]     # the warm path


def test_a_phase_that_fails_still_ends():
    calls, report = recorder()
    with pytest.raises(ZeroDivisionError):
        with phase("derive", report):
            1 / 0
    assert calls == [("derive", False), ("derive", True)]


def test_stderr_reporter_threshold():
    out = io.StringIO()
    rep = StderrReporter(threshold=0, stream=out)
    rep("derive", 0.0, False)
    rep("derive", 0.25, True)
    assert out.getvalue() == "methodgen: derive …\nmethodgen: derive done in 0.2 s\n"
    # Negative control: a phase shorter than the threshold prints nothing (the timer is cancelled).
    quiet = io.StringIO()
    rep = StderrReporter(threshold=60, stream=quiet)
    rep("render", 0.0, False)
    rep("render", 0.1, True)
    assert quiet.getvalue() == ""


def test_the_running_line_comes_while_the_phase_runs():
    import threading

    out = io.StringIO()
    rep = StderrReporter(threshold=0.05, stream=out)
    seen = threading.Event()
    rep("derive", 0.0, False)
    for _ in range(200):            # wait for the timer's line (a condition, not a time assertion)
        if "still running" in out.getvalue():
            seen.set()
            break
        threading.Event().wait(0.01)
    rep("derive", 0.3, True)
    assert seen.is_set() and out.getvalue().endswith("methodgen: derive done in 0.3 s\n")


def _osc(tmp_path):
    f = tmp_path / "osc.toml"
    f.write_text('name = "osc"\n[system]\nH = "p**2/2 + q**2/2"\nq = ["q"]\np = ["p"]\n'
                 '[run]\nmethod = "midpoint"\nh = 0.01\nsteps = 10\ny0 = [1.0, 0.0]\n')
    return str(f)


def test_cli_prints_the_phases_on_stderr_when_forced(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("METHODGEN_PROGRESS_SECONDS", "0")
    assert cli.main(["run", _osc(tmp_path), "--steps", "5"]) == 0
    err = capsys.readouterr().err
    done = [ln.split()[1] for ln in err.splitlines() if ln.startswith("methodgen: ") and " done in " in ln]
    assert done == ["derive", "lower", "render", "write", "load"], err
    assert progress.installed() is None     # the CLI's reporter is gone after the command


def test_cli_is_quiet_under_the_threshold(tmp_path, capsys, monkeypatch):
    """Negative control: the default threshold (2 s) and a build well under it: no progress lines."""
    monkeypatch.setenv("METHODGEN_PROGRESS_SECONDS", "600")
    assert cli.main(["run", _osc(tmp_path), "--steps", "5"]) == 0
    assert " done in " not in capsys.readouterr().err


def test_tqdm_reporter_when_installed():
    pytest.importorskip("tqdm")
    out = io.StringIO()
    report = progress.tqdm_reporter(file=out)
    with phase("derive", report):
        pass
    assert "derive" in out.getvalue()


def test_the_running_line_gives_the_last_time_as_an_estimate(tmp_path):
    history = tmp_path / "times.json"
    first = io.StringIO()
    rep = StderrReporter(threshold=0, stream=first, history=history)
    with progress.about("big_0123456789ab_energy_momentum.py"):
        rep("derive", 0.0, False)
        rep("derive", 472.0, True)
    assert "last time" not in first.getvalue()          # nothing known the first time
    again = io.StringIO()
    rep = StderrReporter(threshold=0, stream=again, history=history)
    # The same module after a generator change: another signature, the same phase and module.
    with progress.about("big_fedcba987654_energy_momentum.py"):
        rep("derive", 0.0, False)
    assert again.getvalue() == "methodgen: derive big_fedcba987654_energy_momentum.py … (472.0 s last time)\n"
    # Negative control: another module (or another phase) has no estimate.
    other = io.StringIO()
    rep = StderrReporter(threshold=0, stream=other, history=history)
    with progress.about("small_0123456789ab_midpoint.py"):
        rep("derive", 0.0, False)
        rep("lower", 0.0, False)
    assert "last time" not in other.getvalue()
