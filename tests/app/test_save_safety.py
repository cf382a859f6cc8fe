"""``--save`` never loses data (issue 28, items 4 and 5), on a real file system (tmp_path).

* A failing or interrupted run never replaces an existing file: its states go to
  ``NAME.partial.npz`` and a warning says so; a complete run does replace it.
* A file rebuilt after ``kill -9`` (and any other file) records what its rows cover:
  ``steps_done = (rows - 1) * save_every`` and ``t_final`` — checked against the
  module itself (the last row is the state after ``steps_done`` steps).

Each guard has a negative control: with the guard replaced by the old behaviour,
the loss or the wrong metadata is observed.
"""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
import warnings

import numpy as np
import pytest

import methodgen.app.cli as cli
import methodgen.runtime.runio as runio
from methodgen.runtime.runio import ChunkWriter, extent, load_trajectory, recover_orphans


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)


@pytest.fixture
def osc(tmp_path):
    """A harmonic oscillator with a mass parameter (m = 0 fails at step 0), as a user scene."""
    f = tmp_path / "osc.toml"
    f.write_text('name = "osc"\n[system]\nH = "p**2/(2*m) + q**2/2"\nq = ["q"]\np = ["p"]\n'
                 '[params]\nm = 1.0\n'
                 '[run]\nmethod = "midpoint"\nh = 0.01\nsteps = 1000\ny0 = [1.0, 0.0]\n')
    return f


def run(capsys, *args):
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# --- 28.4: a failing run never overwrites a good file -------------------------------------------

def _good_then_failing(osc, tmp_path, capsys):
    g = tmp_path / "g.npz"
    assert run(capsys, "run", osc, "--steps", "100", "--save", g)[0] == 0
    good = g.read_bytes()
    code, _, err = run(capsys, "run", osc, "--param", "m=0", "--steps", "100", "--save", g)
    # m = 0: H is not defined at the initial state -- bad input (exit 2), the run fails at step 0
    assert code == cli.EXIT_INPUT and "Traceback" not in err
    return g, good, err


def test_failing_run_keeps_the_complete_file_and_saves_beside_it(osc, tmp_path, capsys):
    g, good, err = _good_then_failing(osc, tmp_path, capsys)
    assert g.read_bytes() == good                      # not one byte of the complete run changed
    states, meta = load_trajectory(g)
    assert states.shape == (101, 2) and bool(meta["complete"])
    partial = tmp_path / "g.partial.npz"
    assert f"saved 1 states to {partial}" in err and f"{g} exists" in err and "kept" in err
    p_states, p_meta = load_trajectory(partial)
    assert p_states.shape == (1, 2) and not bool(p_meta["complete"]) and int(p_meta["steps_done"]) == 0
    # A second failing run keeps the first partial file too.
    assert run(capsys, "run", osc, "--param", "m=0", "--save", g)[0] == cli.EXIT_INPUT
    assert (tmp_path / "g.partial-2.npz").is_file() and partial.is_file() and g.read_bytes() == good
    assert not list(tmp_path.glob(".*.tmp"))


def test_failing_run_overwrite_negative_control(osc, tmp_path, capsys, monkeypatch):
    """The guard replaced by the old move (os.replace over the target): the good file is lost."""
    def old_move(self):
        os.replace(self._tmp, self.path)
        return self.path

    monkeypatch.setattr(ChunkWriter, "_place_incomplete", old_move)
    g, good, _ = _good_then_failing(osc, tmp_path, capsys)
    assert g.read_bytes() != good and load_trajectory(g)[0].shape == (1, 2)


def test_a_complete_run_does_replace_the_file(osc, tmp_path, capsys):
    g = tmp_path / "g.npz"
    assert run(capsys, "run", osc, "--steps", "5", "--save", g)[0] == 0
    assert run(capsys, "run", osc, "--steps", "7", "--save", g)[0] == 0
    assert load_trajectory(g)[0].shape == (8, 2) and not list(tmp_path.glob("g.partial*"))


def test_a_failing_run_with_no_file_there_saves_under_the_name(osc, tmp_path, capsys):
    g = tmp_path / "new.npz"
    code, _, err = run(capsys, "run", osc, "--param", "m=0", "--save", g)
    assert code == cli.EXIT_INPUT and f"saved 1 states to {g}" in err and "exists" not in err


def test_interrupt_and_disk_full_never_replace_a_file(tmp_path, monkeypatch):
    """The writer's own rule, whatever the caller: complete=False and rescue() place beside."""
    target = tmp_path / "t.npz"
    target.write_bytes(b"a good file")
    w = ChunkWriter(target, meta={"h": 0.5})
    w.append(np.ones((3, 2)))
    with pytest.warns(RuntimeWarning, match="kept as it was"):
        where = w.close(complete=False, reason="KeyboardInterrupt")
    assert where == tmp_path / "t.partial.npz" and target.read_bytes() == b"a good file"
    assert float(load_trajectory(where)[1]["t_final"]) == 1.0

    w = ChunkWriter(target)
    w.append(np.ones((4, 2)))
    real = np.lib.format.write_array

    def full(fh, array, *a, **k):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np.lib.format, "write_array", full)
    with pytest.raises(OSError):
        w.append(np.ones((4, 2)))
    monkeypatch.setattr(np.lib.format, "write_array", real)
    with pytest.warns(RuntimeWarning):
        where = w.close(steps_done=7, complete=True)   # the caller's claim cannot hold: rescued
    states, meta = load_trajectory(where)
    assert where == tmp_path / "t.partial-2.npz" and target.read_bytes() == b"a good file"
    assert states.shape == (4, 2) and not bool(meta["complete"]) and int(meta["steps_done"]) == 3


# --- 28.5: the metadata matches the rows --------------------------------------------------------

def test_extent_counts_kept_steps():
    meta = {"save_every": np.array(10), "steps": np.array(95), "h": np.array(0.5),
            "state_names": np.array(["q", "t", "p", "e"]), "time_transform": np.array("")}
    assert extent(1, meta) == {"steps_done": 0, "t_final": 0.0}
    assert extent(5, meta) == {"steps_done": 40, "t_final": 20.0}
    assert extent(11, meta)["steps_done"] == 95            # the last row: after all the steps
    tt = {**meta, "time_column": np.array("t"), "time_transform": np.array("r")}
    assert extent(5, tt, np.array([0.0, 3.25, 0.0, 0.0])) == {"steps_done": 40, "t_final": 3.25}
    assert extent(5, tt) == {"steps_done": 40}            # no physical time without the row


def _orphan(folder, meta, chunks):
    """What ``kill -9`` leaves: chunks on disk, the lock released, no directory, no close."""
    w = ChunkWriter(folder / "long.npz", meta=meta)
    for c in chunks:
        w.append(c)
    w._release()   # the process is gone: its lock goes, its temporary file stays
    return w


def test_recovered_metadata_matches_the_rows_in_process(tmp_path):
    meta = {"h": 0.25, "save_every": 10, "steps": 10_000, "state_names": ["q", "p"], "time_transform": ""}
    _orphan(tmp_path, meta, [np.zeros((201, 2)), np.ones((200, 2))])
    (note,) = recover_orphans(tmp_path)
    states, got = load_trajectory(tmp_path / "long.recovered.npz")
    assert len(states) == 401 and "401 states" in note
    assert int(got["steps_done"]) == 4000 and float(got["t_final"]) == 1000.0
    assert str(got["reason"]) == "killed" and not bool(got["complete"])


def _rows_match_steps(module, y0, h, states, meta) -> bool:
    """The last row is the module's state after ``steps_done`` steps, and t_final is h·steps_done."""
    n = int(meta["steps_done"])
    ref = module.integrate(np.array(y0), h, n)[-1]
    return bool(np.allclose(states[-1], ref, rtol=0, atol=1e-12)
                and np.isclose(float(meta["t_final"]), h * n, rtol=1e-15))


def _kill_during_save(osc, folder, tmp_path):
    env = {**os.environ, "METHODGEN_CACHE": str(tmp_path / "cache")}
    proc = subprocess.Popen([sys.executable, "-m", "methodgen", "run", str(osc), "--steps", "100000000",
                             "--save-every", "10", "--chunk", "2000", "--save", str(folder / "long.npz")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=tmp_path)
    try:
        deadline = time.time() + 90
        tmp = []
        while time.time() < deadline:
            tmp = list(folder.glob(".long.npz.*.tmp")) if folder.is_dir() else []
            if tmp and tmp[0].stat().st_size > 20_000:   # several chunks of 200 rows are on disk
                break
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.05)
        assert tmp, "the run never started writing"
    finally:
        proc.send_signal(signal.SIGKILL)   # kill -9
        proc.wait()


def test_kill_9_recovery_records_the_steps_its_rows_cover(osc, tmp_path, capsys, monkeypatch):
    """Was: 82001 rows of --save-every 10 recorded as steps_done = 82000 (they cover 820000)."""
    folder = tmp_path / "D"
    folder.mkdir()   # --save never creates a folder
    _kill_during_save(osc, folder, tmp_path)
    (orphan,) = folder.glob(".long.npz.*.tmp")
    kept = tmp_path / "orphan.tmp"
    kept.write_bytes(orphan.read_bytes())          # for the negative control below
    code, _, err = run(capsys, "run", osc, "--steps", "10", "--save", folder / "next.npz")
    assert code == 0 and "long.recovered.npz" in err
    states, meta = load_trajectory(folder / "long.recovered.npz")
    assert len(states) > 201 and (len(states) - 1) % 200 == 0
    assert int(meta["steps_done"]) == (len(states) - 1) * 10 and int(meta["save_every"]) == 10
    from methodgen.symbolic.scene import load_scene
    from methodgen.codegen.build import build
    module = build(load_scene(str(osc)).system, "midpoint")
    assert _rows_match_steps(module, [1.0, 0.0], 0.01, states, meta)

    # Negative control: the old rebuild (steps_done = rows - 1) on the same orphan is caught.
    def old(fd, entries, chunks, rows):
        return {"steps_done": max(rows - 1, 0), "t_final": 0.01 * max(rows - 1, 0),
                "complete": False, "reason": "killed"}

    monkeypatch.setattr(runio, "_rebuilt_meta", old)
    fd, again = runio.make_temp(folder, "long.npz")
    os.write(fd, kept.read_bytes())
    os.close(fd)
    recover_orphans(folder)
    states2, meta2 = load_trajectory(folder / "long.recovered-2.npz")
    np.testing.assert_array_equal(states2, states)
    assert not _rows_match_steps(module, [1.0, 0.0], 0.01, states2, meta2)


# --- without hard links: never a rename onto the name (review items 5 and 6) ---------------------

def _old_place_new(tmp, candidates):
    """The old fallback: check the name, then rename onto it (the race), and errors it gave up on."""
    for target in candidates:
        try:
            os.link(tmp, target)
        except FileExistsError:
            continue
        except OSError as exc:
            if exc.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
                raise
            if os.path.lexists(target):
                continue
            os.replace(tmp, target)
            return target
        os.unlink(tmp)
        return target
    raise AssertionError("no free name")


def _no_link(code):
    def link(src, dst, *a, **k):
        raise OSError(code, os.strerror(code))
    return link


def _complete_run(target):
    g = ChunkWriter(target, meta={"h": 0.1})
    g.append(np.ones((1000, 2)))
    return g.close(complete=True)


def test_without_hard_links_a_complete_run_finishing_meanwhile_is_kept(tmp_path, monkeypatch):
    target = tmp_path / "run.npz"
    monkeypatch.setattr(runio.os, "link", _no_link(errno.EPERM))
    real_fdopen, raced = os.fdopen, []

    def fdopen_racing(fd, *a, **k):   # the copy into the reserved name starts: a complete run lands
        if not raced and target.exists():
            raced.append(_complete_run(target))
        return real_fdopen(fd, *a, **k)

    w = ChunkWriter(target, meta={"h": 0.1})
    w.append(np.zeros((3, 2)))
    monkeypatch.setattr(runio.os, "fdopen", fdopen_racing)
    with pytest.warns(RuntimeWarning, match="kept as it was"):
        where = w.close(complete=False, reason="KeyboardInterrupt")
    monkeypatch.setattr(runio.os, "fdopen", real_fdopen)
    assert raced == [target]
    states, meta = load_trajectory(target)
    assert states.shape == (1000, 2) and bool(meta["complete"])            # the complete run is kept
    assert where == tmp_path / "run.partial.npz" and load_trajectory(where)[0].shape == (3, 2)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz", "run.partial.npz"]   # no temporary left

    # Negative control: the old fallback (check, then rename) loses the complete run.
    for p in tmp_path.iterdir():
        p.unlink()
    monkeypatch.setattr(runio, "_place_new", _old_place_new)
    real_lexists = os.path.lexists

    def lexists_racing(p):
        seen = real_lexists(p)
        if str(p) == str(target) and not seen:
            _complete_run(target)
        return seen

    w = ChunkWriter(target, meta={"h": 0.1})
    w.append(np.zeros((3, 2)))
    monkeypatch.setattr(runio.os.path, "lexists", lexists_racing)
    w.close(complete=False, reason="KeyboardInterrupt")
    monkeypatch.setattr(runio.os.path, "lexists", real_lexists)
    assert load_trajectory(target)[0].shape == (3, 2)                      # overwritten by the incomplete run


def test_without_hard_links_an_existing_file_is_taken_and_the_copy_goes_beside(tmp_path, monkeypatch):
    target = tmp_path / "run.npz"
    target.write_bytes(b"a good file")
    monkeypatch.setattr(runio.os, "link", _no_link(errno.EOPNOTSUPP))
    w = ChunkWriter(target, meta={"h": 0.1})
    w.append(np.zeros((3, 2)))
    with pytest.warns(RuntimeWarning, match="kept as it was"):
        where = w.close(complete=False, reason="KeyboardInterrupt")
    assert target.read_bytes() == b"a good file" and load_trajectory(where)[0].shape == (3, 2)


@pytest.mark.parametrize("code", ["ENOSYS", "EPERM", "EXDEV"])
def test_link_failing_with_any_error_falls_back_to_the_safe_copy(tmp_path, monkeypatch, code):
    """FUSE mounts without link() say ENOSYS: incomplete runs and killed saves are still saved."""
    code = getattr(errno, code)
    monkeypatch.setattr(runio.os, "link", _no_link(code))
    w = ChunkWriter(tmp_path / "run.npz", meta={"h": 0.1})
    w.append(np.zeros((3, 2)))
    assert w.close(complete=False, reason="KeyboardInterrupt") == tmp_path / "run.npz"
    # A killed save (its temporary file left unlocked) is rebuilt the same way.
    k = ChunkWriter(tmp_path / "killed.npz", meta={"h": 0.1})
    k.append(np.ones((2, 2)))
    k._abandon_zip()
    os.close(k._lock)
    k._lock = None
    notes = recover_orphans(tmp_path)
    assert any("recovered 1 complete chunks" in n for n in notes), notes
    assert load_trajectory(tmp_path / "killed.recovered.npz")[0].shape == (2, 2)
    # Negative control: the old rule gave up on ENOSYS (a StorageError for the user), took the others.
    tmp = tmp_path / "x.tmp"
    tmp.write_bytes(b"x")
    if code == errno.ENOSYS:
        with pytest.raises(OSError):
            _old_place_new(str(tmp), [tmp_path / "x.npz"])
    else:
        assert _old_place_new(str(tmp), [tmp_path / "x.npz"]) == tmp_path / "x.npz"
