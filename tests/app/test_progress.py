"""Progress of long work (issue 25, item 4; issue 28, 8b): phases reported in order, never timed here."""

from __future__ import annotations

import io
import warnings

import pytest

import methodgen as mg
import methodgen.app.cli as cli
from methodgen.codegen import progress
from methodgen.codegen.progress import StderrReporter, phase


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


# --- the threshold: inf reports nothing, nonsense is refused (review item 10) ---------------------

class FakeTimer:
    """threading.Timer that never runs by itself: the test fires the timers left uncancelled."""

    made: list = []

    def __init__(self, interval, function, args=()):
        self.interval, self.function, self.args, self.cancelled = interval, function, args, False
        FakeTimer.made.append(self)

    def start(self):
        pass

    def cancel(self):
        self.cancelled = True

    @classmethod
    def fire(cls):
        for t in cls.made:
            if not t.cancelled:
                t.function(*t.args)


@pytest.fixture
def fake_timer(monkeypatch):
    import threading

    FakeTimer.made = []
    monkeypatch.setattr(threading, "Timer", FakeTimer)
    return FakeTimer


@pytest.mark.parametrize("value", ["inf", "1e300"])
def test_an_infinite_threshold_starts_no_timer(tmp_path, capsys, monkeypatch, fake_timer, value):
    monkeypatch.setenv("METHODGEN_PROGRESS_SECONDS", value)
    assert cli.main(["run", _osc(tmp_path), "--steps", "5"]) == 0
    err = capsys.readouterr().err
    assert fake_timer.made == [] and "Traceback" not in err and "methodgen: derive" not in err
    rep = StderrReporter(threshold=3.0, stream=io.StringIO())
    rep("derive", 0.0, False)
    assert len(fake_timer.made) == 1          # control: a finite threshold does start one


def test_a_timer_of_infinite_length_fails_in_its_thread():
    """Why: the negative control of the guard above — threading.Timer(inf) raises in its thread."""
    import threading

    seen = []
    previous, threading.excepthook = threading.excepthook, lambda args: seen.append(args.exc_type)
    try:
        t = threading.Timer(float("inf"), lambda: None)
        t.start()
        t.join(5)
    finally:
        threading.excepthook = previous
    assert seen == [OverflowError]


@pytest.mark.parametrize("value", ["-1", "nan", "two", "-inf"])
def test_a_threshold_that_is_not_seconds_is_refused(tmp_path, capsys, monkeypatch, value):
    monkeypatch.setenv("METHODGEN_PROGRESS_SECONDS", value)
    assert cli.main(["run", _osc(tmp_path), "--steps", "5"]) == cli.EXIT_INPUT
    err = capsys.readouterr().err
    assert err.startswith("methodgen: error: METHODGEN_PROGRESS_SECONDS must be a number of seconds >= 0")
    assert "Traceback" not in err and len(err.splitlines()) == 1
    with pytest.raises(mg.InputError):
        StderrReporter(threshold=float(value) if value != "two" else -2.0)
    # Control: a valid value runs.
    monkeypatch.setenv("METHODGEN_PROGRESS_SECONDS", "0.5")
    assert cli.main(["run", _osc(tmp_path), "--steps", "5"]) == 0


# --- timers by thread and module, estimates of unnamed systems, the compile phase (item 11) -------

def _two_threads(rep, fake_timer):
    """Thread 1 starts derive on a.py; thread 2 starts derive on b.py; thread 1 ends a.py; timers fire."""
    import threading

    go_on = threading.Event()

    def thread_a():                       # a long-lived worker: a starts, b starts elsewhere, a ends
        with progress.about("a.py"):
            rep("derive", 0.0, False)
            go_on.wait(30)
            rep("derive", 0.1, True)

    def thread_b():
        with progress.about("b.py"):
            rep("derive", 0.0, False)     # b still runs

    a = threading.Thread(target=thread_a)
    a.start()
    while len(fake_timer.made) < 1:       # a's timer is made (a condition, not a time)
        threading.Event().wait(0.001)
    b = threading.Thread(target=thread_b)
    b.start()
    b.join()
    go_on.set()
    a.join()
    fake_timer.fire()


def test_two_threads_in_the_same_phase_keep_their_own_timers(fake_timer):
    out = io.StringIO()
    _two_threads(StderrReporter(threshold=1.0, stream=out), fake_timer)
    assert out.getvalue() == "methodgen: derive b.py … (still running after 1 s)\n"
    # Negative control: timers keyed by the phase only (the old reporter) report a, which ended, not b.
    out = io.StringIO()
    rep = StderrReporter(threshold=1.0, stream=out)
    rep._slot = lambda name: name
    fake_timer.made = []
    _two_threads(rep, fake_timer)
    assert out.getvalue() == "methodgen: derive a.py … (still running after 1 s)\n"


def test_unnamed_systems_keep_their_own_estimates(tmp_path):
    history = tmp_path / "times.json"
    rep = StderrReporter(threshold=0, stream=io.StringIO(), history=history)
    with progress.about("system_0123456789ab_midpoint.py"):
        rep("derive", 0.0, False)
        rep("derive", 300.0, True)
    out = io.StringIO()
    rep = StderrReporter(threshold=0, stream=out, history=history)
    with progress.about("system_fedcba987654_midpoint.py"):      # another unnamed system
        rep("derive", 0.0, False)
    with progress.about("system_0123456789ab_midpoint.py"):      # the same one again
        rep("derive", 0.0, False)
    assert out.getvalue().splitlines() == [
        "methodgen: derive system_fedcba987654_midpoint.py …",
        "methodgen: derive system_0123456789ab_midpoint.py … (300.0 s last time)"]
    # Control: a named system keeps its estimate across signatures (the test above), the old
    # key gave the unnamed ones one shared key.
    assert progress._history_key("derive", "system_0123456789ab_midpoint.py") != \
        progress._history_key("derive", "system_fedcba987654_midpoint.py")
    assert progress._history_key("derive", "osc_0123456789ab_midpoint.py") == \
        progress._history_key("derive", "osc_fedcba987654_midpoint.py") == "derive:osc_midpoint.py"


def test_the_cli_compile_phase_names_its_module(tmp_path, capsys, monkeypatch):
    """The numba branch of ``run`` on a numpy module marked numba (no compile: fast); lines name the module."""
    import methodgen.app.cli.run as cli_run

    real, built = cli_run.build, []

    def build_marked(*args, **kwargs):
        module = real(*args, **kwargs)
        module.BACKEND = "numba"           # takes the compile branch; step() is the numpy one
        built.append(module)
        return module

    monkeypatch.setattr(cli_run, "build", build_marked)
    monkeypatch.setenv("METHODGEN_PROGRESS_SECONDS", "0")
    assert cli.main(["run", _osc(tmp_path), "--steps", "5"]) == 0
    err = capsys.readouterr().err
    name = built[0].__file__.rsplit("/", 1)[-1]
    lines = [ln for ln in err.splitlines() if ln.startswith("methodgen: compile")]
    assert lines[0] == f"methodgen: compile {name} …" and lines[1].startswith(f"methodgen: compile {name} done in")
    # Negative control: a phase outside about() names no module (the old compile line).
    out = io.StringIO()
    StderrReporter(threshold=0, stream=out)("compile", 0.0, False)
    assert out.getvalue() == "methodgen: compile …\n"


def test_build_progress_true_writes_a_line_per_phase(tmp_path, capsys):
    """``mg.build(..., progress=True)`` as ``solve(progress=True)``: lines on stderr (it raised
    TypeError: 'bool' object is not callable); a progress that is neither is refused by name."""
    mod = mg.build_text("p**2/2 + q**4/4", ["q"], ["p"], "midpoint", name="quartp", path=tmp_path / "a.py",
                        progress=True)
    err = capsys.readouterr().err
    assert mod.METHOD == "midpoint" and "methodgen: derive" in err and "methodgen: load" in err
    mg.build_text("p**2/2 + q**4/4", ["q"], ["p"], "midpoint", name="quartp", path=tmp_path / "b.py", progress=False)
    assert capsys.readouterr().err == ""                 # control: silent
    with pytest.raises(mg.InputError, match="progress must be True, False, None or a callable"):
        mg.build_text("p**2/2 + q**4/4", ["q"], ["p"], "midpoint", name="quartp", path=tmp_path / "c.py",
                      progress="yes")
