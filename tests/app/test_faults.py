"""Faults without tracebacks or loss (issue 13, items 2 and 4): NaN on the command line,
full disks, bad paths, killed runs, impossible sweep sizes, non-smooth scenes."""

from __future__ import annotations

import errno
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import methodgen.app.cli as cli
import methodgen.app.cli.run as cli_run
import methodgen.app.cli.scenes as cli_scenes
from methodgen.app.cli.common import dump_json
import methodgen.runtime.runio as runio
import methodgen.app.sweep as sw
from methodgen.errors import StorageError
from methodgen.runtime.runio import ChunkWriter, load_trajectory, recover_orphans

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    """Every test gets its own cache; the CLI's warning hook is put back afterwards."""
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)


@pytest.fixture
def osc(tmp_path):
    """A harmonic oscillator as a user scene: its module goes to the test's cache, never to generated/."""
    f = tmp_path / "osc.toml"
    f.write_text('name = "osc"\n[system]\nH = "p**2/2 + q**2/2"\nq = ["q"]\np = ["p"]\n'
                 '[run]\nmethod = "midpoint"\nh = 0.01\nsteps = 1000\ny0 = [1.0, 0.0]\n')
    return f


def main(capsys, *args):
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def strict_json(text: str):
    """json.loads that refuses NaN / Infinity (which the standard module accepts)."""
    def bad(name):
        raise AssertionError(f"{name} in JSON output")
    return json.loads(text, parse_constant=bad)


def one_error_line(err: str) -> str:
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if not ln.startswith("methodgen: warning:")
             and not ln.startswith("methodgen: note:")]
    assert len(lines) == 1, err
    return lines[0]


def scene_file(tmp_path, H, y0, name="s", method="midpoint", steps=10, h=0.1):
    f = tmp_path / f"{name}.toml"
    f.write_text(f'name = "{name}"\n[system]\nH = "{H}"\nq = ["q"]\np = ["p"]\n'
                 f'[run]\nmethod = "{method}"\nh = {h}\nsteps = {steps}\ny0 = {list(y0)}\n')
    return f


# --- item 2, CLI side: a NaN is never an error of 0 ---------------------------------------------

def test_nan_hamiltonian_is_not_shown_as_zero_error(tmp_path, capsys):
    """The issue's reproduction: H = p²/2 + log(q) from q = -1 printed 'max abs error 0.000e+00', exit 0."""
    # Either the stepper raises NonFiniteError at step 0 (then there is no table) or the CLI's
    # own monitoring finds H(y0) = nan: one line in both cases, never a 0 error.  H undefined at
    # the initial state is bad input (exit 2), not a failure of the run (3).
    f = scene_file(tmp_path, "p**2/2 + log(q)", (-1.0, 0.3), name="logq")
    code, out, err = main(capsys, "run", f)
    assert code == cli.EXIT_INPUT
    one_error_line(err)
    for row in (ln for ln in out.splitlines() if ln.split()[:1] == ["H"]):
        assert "0.000e+00" not in row and "non-finite" in row

    code, out, err = main(capsys, "run", f, "--json")
    assert code == cli.EXIT_INPUT
    rep = strict_json(out)
    assert rep["status"] == "non-finite"
    H = rep["invariants"]["H"]
    assert H["status"] == "non-finite" and H["first_nonfinite_step"] == 0
    assert H["initial"] is None and H["max_abs_error"] is None and H["max_rel_error"] is None


def test_finite_run_is_ok_negative_control(tmp_path, capsys):
    f = scene_file(tmp_path, "p**2/2 + log(q)", (1.0, 0.3), name="logq_ok")
    code, out, err = main(capsys, "run", f, "--json")
    assert code == 0, err
    rep = strict_json(out)
    assert rep["status"] == "ok" and rep["invariants"]["H"]["status"] == "ok"
    assert 0 < rep["invariants"]["H"]["max_abs_error"] < 1e-3  # midpoint: a real, finite error


def test_monitor_records_the_first_nonfinite_step_whatever_the_module_does():
    """Belt and braces: the CLI's own monitoring sees NaN even if the stepper raised nothing."""
    class Mod:
        INVARIANT_NAMES = ("H",)

        @staticmethod
        def invariants(traj):
            return {"H": traj[:, 0] ** 2}

    good = np.array([[1.0], [1.0 + 1e-9], [1.0]])
    acc = cli_run._invariant_stats(Mod, good, None, offset=0)
    assert acc["H"]["error"].nonfinite_step is None and 0 < acc["H"]["error"].value < 1e-8
    bad = np.array([[1.0], [np.nan], [5.0]])
    acc = cli_run._invariant_stats(Mod, bad, acc, offset=2)
    assert acc["H"]["error"].nonfinite_step == 3 and math.isnan(acc["H"]["error"].value)
    assert acc["H"]["error"].finite_max == pytest.approx(24.0)  # over the finite values; reported as null


def test_json_never_contains_nan_or_infinity():
    text = dump_json({"a": math.nan, "b": [1.0, -math.inf], "c": {"d": np.float64(np.inf)},
                          "e": np.array([1.0, np.nan])})
    assert strict_json(text) == {"a": None, "b": [1.0, None], "c": {"d": None}, "e": [1.0, None]}


class NonFiniteError(FloatingPointError):
    """Stands in for the generated module's own class (matched by name, like the others)."""

    def __init__(self, msg, step, trajectory):
        super().__init__(msg)
        self.step, self.trajectory = step, trajectory


def test_nonfinite_error_from_the_stepper_is_one_line_exit_3(osc, tmp_path, capsys, monkeypatch):
    real_build = cli_run.build

    class Wrapped:
        def __init__(self, mod):
            self._mod = mod

        def __getattr__(self, name):
            return getattr(self._mod, name)

        def integrate(self, y0, h, steps, *a, **k):
            traj = self._mod.integrate(y0, h, 3)
            traj = np.vstack([traj, np.full((1, traj.shape[1]), np.nan)])
            raise NonFiniteError("state is not finite at step 4 (q = nan)\nsecond line", 4, traj)

    monkeypatch.setattr(cli_run, "build", lambda *a, **k: Wrapped(real_build(*a, **k)))
    out_file = tmp_path / "nf.npz"
    code, out, err = main(capsys, "run", osc, "--json", "--save", out_file)
    assert code == cli.EXIT_NUMERICAL
    line = one_error_line(err)
    assert "not finite at step 4" in line and "second line" in line and str(out_file) in line
    rep = strict_json(out)
    assert rep["status"] == "non-finite" and rep["y_final"] == [None, None]
    states, meta = load_trajectory(out_file)
    assert len(states) == 5 and not bool(meta["complete"])


def test_nonfinite_error_at_step_0_without_trajectory(osc, capsys, monkeypatch):
    """y0 outside the domain: the error may come before any state; the report still has H(y0)."""
    real_build = cli_run.build

    class Wrapped:
        def __init__(self, mod):
            self._mod = mod

        def __getattr__(self, name):
            return getattr(self._mod, name)

        def integrate(self, *a, **k):
            raise NonFiniteError("H is not defined at the initial state", 0, None)

    monkeypatch.setattr(cli_run, "build", lambda *a, **k: Wrapped(real_build(*a, **k)))
    code, out, err = main(capsys, "run", osc, "--json")
    assert code == cli.EXIT_NUMERICAL and "at step 0" in one_error_line(err)
    rep = strict_json(out)
    assert rep["status"] == "non-finite" and rep["steps_done"] == 0
    assert rep["invariants"]["H"]["initial"] == 0.5


# --- item 4: full disks ---------------------------------------------------------------------------

def _full_disk_from_call(monkeypatch, n_ok: int, n_fail: int = 1):
    """np.lib.format.write_array fails like a full disk after ``n_ok`` calls (having written part).

    It fails ``n_fail`` times: cutting off the partial chunk frees its space again.
    """
    real = np.lib.format.write_array
    calls = {"n": 0}

    def write_array(fh, array, *a, **k):
        calls["n"] += 1
        ok = n_ok() if callable(n_ok) else n_ok
        if ok < calls["n"] <= ok + n_fail:
            fh.write(b"\x93NUMPY partial")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fh, array, *a, **k)

    monkeypatch.setattr(np.lib.format, "write_array", write_array)


def test_disk_full_during_save_keeps_every_written_chunk(osc, tmp_path, capsys, monkeypatch):
    """Was: chained tracebacks and nothing saved.  The metadata entries, then chunks 0..2 fit."""
    written = {}
    real_init = runio.ChunkWriter.__init__

    def init(self, path, meta=None):      # count the metadata entries the run writes first
        written["meta"] = len(meta or {})
        real_init(self, path, meta)

    monkeypatch.setattr(runio.ChunkWriter, "__init__", init)
    _full_disk_from_call(monkeypatch, n_ok=lambda: written["meta"] + 3)
    target = tmp_path / "out" / "F.npz"
    target.parent.mkdir()
    code, out, err = main(capsys, "run", osc, "--steps", "1000", "--save", target, "--chunk", "100")
    assert code == cli.EXIT_NUMERICAL
    line = one_error_line(err)
    assert "No space left on device" in line and f"saved 301 states to {target}" in line
    states, meta = load_trajectory(target)
    assert states.shape == (301, 2) and np.all(np.isfinite(states))
    assert not bool(meta["complete"]) and str(meta["reason"]) == "write-error"
    assert int(meta["steps_done"]) == 300 and str(meta["scene"]) == "osc"
    assert [p.name for p in target.parent.iterdir()] == ["F.npz"]  # no temporary file left
    monkeypatch.undo()
    # The chunks are the run's states: a complete run from the same start agrees.
    ok = tmp_path / "ok.npz"
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    assert main(capsys, "run", osc, "--steps", "300", "--save", ok, "--chunk", "100")[0] == 0
    np.testing.assert_array_equal(load_trajectory(ok)[0], states)


def test_disk_full_while_closing_keeps_all_chunks(tmp_path, monkeypatch):
    w = ChunkWriter(tmp_path / "c.npz", meta={"scene": "x"})
    for i in range(3):
        w.append(np.full((4, 2), float(i)))
    _full_disk_from_call(monkeypatch, n_ok=0)  # the metadata written at close fails
    path = w.close(steps_done=11, complete=True)
    states, meta = load_trajectory(path)
    assert states.shape == (12, 2) and str(meta["scene"]) == "x"


def test_when_not_even_the_directory_fits_the_next_save_rebuilds_it(tmp_path, monkeypatch):
    w = ChunkWriter(tmp_path / "d.npz")
    w.append(np.ones((5, 2)))
    w.append(np.ones((5, 2)))

    def no_space(*a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(runio, "_finish_zip", no_space)
    _full_disk_from_call(monkeypatch, n_ok=0, n_fail=100)
    with pytest.raises(StorageError) as info:
        w.append(np.ones((5, 2)))
    with pytest.raises(StorageError, match=r"complete entries are in .*\.d\.npz\..*\.tmp") as info:
        w.close()
    assert not info.value.bad_path
    monkeypatch.undo()
    notes = recover_orphans(tmp_path)
    assert len(notes) == 1 and "recovered 2 complete chunks (10 states)" in notes[0]
    states, meta = load_trajectory(tmp_path / "d.recovered.npz")
    assert states.shape == (10, 2) and str(meta["reason"]) == "killed"


def test_disk_full_while_generating_the_module(tmp_path, capsys, monkeypatch):
    """Was: an 18-line OSError traceback.  The write goes to /dev/full: a real ENOSPC."""
    if not os.path.exists("/dev/full"):
        pytest.skip("needs /dev/full")
    import methodgen.codegen.store as store

    real = store.make_temp

    def make_temp(folder, name):
        fd, tmp = real(folder, name)
        if not name.endswith(".py"):  # the cache key still fits
            return fd, tmp
        full = os.open("/dev/full", os.O_WRONLY)
        os.dup2(full, fd)
        os.close(full)
        return fd, tmp

    monkeypatch.setattr(store, "make_temp", make_temp)
    f = scene_file(tmp_path, "p**2/2 + q**4/4", (0.5, 0.1), name="quartic")
    code, out, err = main(capsys, "run", f)
    assert code == cli.EXIT_NUMERICAL and out == ""
    line = one_error_line(err)
    assert "No space left on device" in line and "cannot write" in line and "quartic" in line
    assert not [p for p in (tmp_path / "cache").iterdir() if p.suffix in (".py", ".tmp")]


# --- item 4: bad paths are exit 2, one line -------------------------------------------------------

def test_cache_path_through_a_file(tmp_path, capsys, monkeypatch):
    (tmp_path / "afile").write_text("x")
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "afile" / "x"))
    f = scene_file(tmp_path, "p**2/2 + q**4/4", (0.5, 0.1), name="quartic")
    code, out, err = main(capsys, "run", f)
    assert code == cli.EXIT_INPUT
    assert f"{tmp_path / 'afile'} is a file, not a folder" in one_error_line(err)


def test_save_path_through_a_file_and_no_permission(osc, tmp_path, capsys, monkeypatch):
    (tmp_path / "afile").write_text("x")
    code, out, err = main(capsys, "run", osc, "--steps", "5", "--save", tmp_path / "afile" / "F.npz")
    assert code == cli.EXIT_INPUT and "is a file, not a folder" in one_error_line(err)

    # A folder that cannot be written (as root every folder can: the check is what is tested).
    (tmp_path / "ro").mkdir()
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != tmp_path / "ro")
    code, out, err = main(capsys, "run", osc, "--steps", "5", "--save", tmp_path / "ro" / "F.npz")
    assert code == cli.EXIT_INPUT
    line = one_error_line(err)
    assert str(tmp_path / "ro" / "F.npz") in line and "is not a writable folder" in line
    assert not list((tmp_path / "ro").iterdir())


def test_any_other_oserror_is_one_line(capsys, monkeypatch):
    def boom(args):
        raise OSError(errno.EIO, os.strerror(errno.EIO), "/some/file")

    monkeypatch.setattr(cli_scenes, "cmd_scenes", boom)
    code, out, err = main(capsys, "scenes")
    assert code == cli.EXIT_NUMERICAL and one_error_line(err) == "methodgen: error: /some/file: Input/output error"


# --- item 4: a killed --save ----------------------------------------------------------------------

def test_killed_save_is_recovered_by_the_next_run(osc, tmp_path, capsys):
    """Was: an 8 MB unreadable .kill.npz.*.tmp left behind for good."""
    folder = tmp_path / "runs"
    folder.mkdir()
    env = {**os.environ, "METHODGEN_CACHE": str(tmp_path / "cache")}
    proc = subprocess.Popen([sys.executable, "-m", "methodgen", "run", str(osc), "--steps", "100000000",
                             "--save", str(folder / "kill.npz"), "--chunk", "2000"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=tmp_path)
    try:
        deadline = time.time() + 60
        tmp = []
        while time.time() < deadline:
            tmp = list(folder.glob(".kill.npz.*.tmp")) if folder.is_dir() else []
            if tmp and tmp[0].stat().st_size > 200_000:  # a few chunks are on disk
                break
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.05)
        assert tmp, "the run never started writing"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    (orphan,) = folder.glob(".kill.npz.*.tmp")
    with pytest.raises(Exception):
        np.load(orphan)  # what a killed run leaves is not readable as it is
    code, out, err = main(capsys, "run", osc, "--steps", "10", "--save", folder / "next.npz")
    assert code == 0, err
    assert "recovered" in err and "kill.recovered.npz" in err and "Traceback" not in err
    assert not list(folder.glob("*.tmp"))
    states, meta = load_trajectory(folder / "kill.recovered.npz")
    assert len(states) >= 2001 and (len(states) - 1) % 2000 == 0 and np.all(np.isfinite(states))
    assert str(meta["reason"]) == "killed" and not bool(meta["complete"])
    assert str(meta["scene"]) == "osc"
    assert load_trajectory(folder / "next.npz")[0].shape == (11, 2)


def test_a_live_writer_is_never_taken_for_an_orphan(tmp_path):
    """Negative control: the lock tells a running save from a dead one."""
    w = ChunkWriter(tmp_path / "live.npz")
    w.append(np.ones((3, 2)))
    assert recover_orphans(tmp_path) == []
    assert list(tmp_path.glob(".live.npz.*.tmp"))
    assert w.close().is_file()
    # An orphan without a complete chunk is just removed.
    fd, tmp = runio.make_temp(tmp_path, "empty.npz")
    os.write(fd, b"PK\x03\x04 cut")
    os.close(fd)
    (notes,) = [recover_orphans(tmp_path)]
    assert len(notes) == 1 and "removed" in notes[0] and not os.path.exists(tmp)


# --- item 4: sweeps that cannot fit ---------------------------------------------------------------

def test_sweep_larger_than_the_machine_is_refused(tmp_path, capsys, monkeypatch):
    spec = tmp_path / "big.toml"
    spec.write_text('scene = "harmonic"\nmethods = ["midpoint"]\nsteps = 10\n'
                    '[initial]\ncount = 1000000000000\nspread = 1e-3\n')
    code, out, err = main(capsys, "sweep", spec)
    assert code == cli.EXIT_INPUT and out == ""
    line = one_error_line(err)
    assert "needs about" in line and "TB of memory" in line and "more than this machine has" in line
    # Control: a normal size passes, and the same check fires for it on a tiny machine.
    small = {"scene": "harmonic", "methods": ["midpoint"], "steps": 10, "initial": {"count": 1000}}
    sw.parse_spec(small)
    monkeypatch.setattr(sw, "memory_limit", lambda: 10_000)
    with pytest.raises(sw.SpecError, match="more than this machine has"):
        sw.parse_spec(small)


# --- non-smooth scenes: one line (parse.check_smooth) ---------------------------------------------

@pytest.mark.parametrize("H, fragment", [("p**2/2 + sqrt(q**2)", "Abs(q) is not smooth"),
                                         ("p**2/2 + Max(q, 0)", "Max(q, 0) is not smooth")])
def test_non_smooth_scene_is_one_line(tmp_path, capsys, H, fragment):
    f = scene_file(tmp_path, H, (1.0, 0.3), name="ns")
    code, out, err = main(capsys, "run", f)
    assert code == cli.EXIT_INPUT and out == ""
    assert fragment in one_error_line(err)
