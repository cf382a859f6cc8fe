"""Open, versioned trajectory files (``methodgen-trajectory`` 1, HDF5): :mod:`methodgen.runtime.trajfile`.

* What is written reads back bitwise, by methodgen and by h5py, netCDF4 and xarray in a
  process that cannot import methodgen; the dimensions are netCDF dimensions.
* The same run saved as ``.npz`` and ``.h5`` gives the same states and metadata.
* Crash safety as the ``.npz``: a killed writer's temporary file is rebuilt from its flushed
  chunks (a damaged chunk, caught by its checksum, and the rows after it are dropped; a file
  h5py cannot open is kept); a write error keeps the complete chunks; an incomplete run goes
  beside an existing file (``NAME.partial.h5``).
* Without h5py, ``--save x.h5`` is refused before any work (exit 2, how to install it); any
  suffix but ``.npz``/``.h5`` is refused.

Each guard has a negative control.
"""

from __future__ import annotations

import errno
import json
import os
import signal
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

h5py = pytest.importorskip("h5py")

import methodgen as mg  # noqa: E402
import methodgen.app.cli as cli  # noqa: E402
import methodgen.runtime.runio as runio  # noqa: E402
import methodgen.runtime.trajfile as tf  # noqa: E402
from methodgen.errors import InputError, StorageError  # noqa: E402
from methodgen.runtime.trajfile import (H5ChunkWriter, load_trajectory, read_trajectory, recover_orphans,  # noqa: E402
                                row_times, save_trajectory)


@pytest.fixture(scope="module")
def shared_cache(tmp_path_factory):
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(autouse=True)
def private_cache(shared_cache, monkeypatch):
    monkeypatch.setenv("METHODGEN_CACHE", str(shared_cache))
    monkeypatch.setattr(warnings, "showwarning", warnings.showwarning)


@pytest.fixture(scope="module")
def osc(tmp_path_factory):
    """A harmonic oscillator with a mass parameter (m = 0 fails at step 0), as a user scene."""
    f = tmp_path_factory.mktemp("scene") / "osc.toml"
    f.write_text('name = "osc"\n[system]\nH = "p**2/(2*m) + q**2/2"\nq = ["q"]\np = ["p"]\n'
                 '[params]\nm = 1.0\n'
                 '[run]\nmethod = "midpoint"\nh = 0.01\nsteps = 1000\ny0 = [1.0, 0.0]\n')
    return f


def run(capsys, *args):
    code = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


META = {"scene": "s", "method": "midpoint", "order": 2, "h": 0.25, "steps": 95, "save_every": 10,
        "state_names": ["q", "p"], "time_transform": "", "time_column": "", "claims": {"symplectic": True}}


def _write(path, chunks, meta=META, **close):
    w = H5ChunkWriter(path, meta=dict(meta))
    for c in chunks:
        w.append(c)
    return w.close(**close)


# --- round trip -----------------------------------------------------------------------------------

def test_round_trip_and_a_truncated_dataset_is_detected(tmp_path):
    rng = np.random.default_rng(1)
    chunks = [rng.standard_normal((4, 2)), rng.standard_normal((4, 2)), rng.standard_normal((3, 2))]
    where = _write(tmp_path / "r.h5", chunks, complete=True, reason="complete")
    assert where == tmp_path / "r.h5" and sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]
    t, y, meta = read_trajectory(where)
    np.testing.assert_array_equal(y, np.concatenate(chunks))                 # bitwise
    # row i: min(10 i, 95) steps of h = 0.25; the last row is the state after all 95
    np.testing.assert_array_equal(t, 0.25 * np.minimum(10 * np.arange(11), 95))
    assert int(meta["steps_done"]) == 95 and float(meta["t_final"]) == t[-1] == 23.75
    assert meta["complete"] is True and meta["reason"] == "complete"      # plain values
    assert list(meta["state_names"]) == ["q", "p"] and meta["claims"] == {"symplectic": True}
    assert str(meta["format"]) == "methodgen-trajectory" and int(meta["format_version"]) == 1
    assert {"created", "methodgen_version", "scene", "method", "order", "h", "steps", "save_every"} <= set(meta)

    # Negative control: a file whose y lost rows (truncated) is refused, not read short.
    cut = tmp_path / "cut.h5"
    cut.write_bytes(where.read_bytes())
    with h5py.File(cut, "r+") as f:
        f["y"].resize(7, axis=0)
    with pytest.raises(StorageError, match="damaged: y has 7 rows and t 11, but 11 were saved"):
        read_trajectory(cut)


def test_a_newer_format_version_and_a_foreign_hdf5_file_are_refused(tmp_path):
    where = _write(tmp_path / "v.h5", [np.zeros((2, 2))])
    with h5py.File(where, "r+") as f:
        f.attrs["format_version"] = 2
    with pytest.raises(InputError, match="version 2, newer than this methodgen reads"):
        read_trajectory(where)
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["y"] = np.zeros(3)
    with pytest.raises(InputError, match="not a methodgen-trajectory file"):
        read_trajectory(tmp_path / "other.h5")
    # runio's reader (the .npz one) points to this module instead of failing obscurely
    with pytest.raises(InputError, match="methodgen.runtime.trajfile.load_trajectory"):
        runio.load_trajectory(where)


READER = textwrap.dedent('''
    import json, sys

    class Block:
        def find_spec(self, name, path=None, target=None):
            if name == "methodgen" or name.startswith("methodgen."):
                raise ImportError("methodgen is blocked in this process")

    sys.meta_path.insert(0, Block())
    try:
        import methodgen
        blocked = False
    except ImportError:
        blocked = True
    import h5py, netCDF4, xarray

    path, out = sys.argv[1], {"blocked": blocked}
    with h5py.File(path, "r") as f:
        out["format"] = str(f.attrs["format"])
        out["version"] = int(f.attrs["format_version"])
        out["complete"] = int(f.attrs["complete"])
        out["y"] = f["y"][()].tolist()
        out["t"] = f["t"][()].tolist()
    with netCDF4.Dataset(path) as d:
        out["nc_dims"] = {k: len(v) for k, v in d.dimensions.items()}
        out["nc_unlimited"] = [k for k, v in d.dimensions.items() if v.isunlimited()]
        out["nc_y"] = list(d["y"].dimensions)
    with xarray.open_dataset(path, engine="netcdf4") as ds:
        out["xr_dims"] = list(ds["y"].dims)
        out["xr_coords"] = sorted(ds["y"].coords)
        out["xr_y"] = ds["y"].values.tolist()
        out["xr_t"] = ds["t"].values.tolist()
        out["xr_state"] = [str(s) for s in ds["state"].values] if "state" in ds.coords else None
        out["xr_attrs"] = {k: str(v) for k, v in ds.attrs.items()}
    out["methodgen_loaded"] = sorted(m for m in sys.modules if m.split(".")[0] == "methodgen")
    print(json.dumps(out))
''')


def _read_elsewhere(path) -> dict:
    """Read ``path`` with h5py, netCDF4 and xarray in a process that cannot import methodgen."""
    pytest.importorskip("netCDF4")
    pytest.importorskip("xarray")
    res = subprocess.run([sys.executable, "-I", "-c", READER, str(path)], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_read_by_h5py_netcdf4_and_xarray_without_methodgen(tmp_path):
    chunks = [np.arange(8.0).reshape(4, 2) / 3, np.arange(14.0).reshape(7, 2) / 7]
    where = _write(tmp_path / "x.h5", chunks, complete=True, reason="complete")
    got = _read_elsewhere(where)
    assert got["blocked"] and got["methodgen_loaded"] == []     # the control: methodgen is not importable
    y = np.concatenate(chunks)
    assert got["format"] == "methodgen-trajectory" and got["version"] == 1 and got["complete"] == 1
    assert np.array_equal(got["y"], y) and np.array_equal(got["xr_y"], y)        # bitwise (JSON round-trips)
    assert got["t"] == got["xr_t"] == list(0.25 * np.minimum(10 * np.arange(11), 95))
    assert got["nc_dims"] == {"time": 11, "state": 2} and got["nc_unlimited"] == ["time"]
    assert got["nc_y"] == ["time", "state"] and got["xr_dims"] == ["time", "state"]
    assert got["xr_coords"] == ["state", "t"] and got["xr_state"] == ["q", "p"]
    assert got["xr_attrs"]["scene"] == "s" and got["xr_attrs"]["steps_done"] == "95"


def test_multi_axis_states_get_named_netcdf_dimensions(tmp_path):
    rng = np.random.default_rng(2)
    body = rng.standard_normal((5, 3, 2))
    w = H5ChunkWriter(tmp_path / "b.h5", meta={"h": 0.1})
    w.append(body[:2])
    w.append(body[2:])
    got = _read_elsewhere(w.close())
    assert got["xr_dims"] == ["time", "body", "coordinate"] and np.array_equal(got["xr_y"], body)
    assert got["nc_dims"] == {"time": 5, "body": 3, "coordinate": 2}
    # A batch of trajectories, named: the state axis carries the names.
    w = H5ChunkWriter(tmp_path / "batch.h5", meta={"h": 0.1, "state_names": ["x", "px"]},
                      dims=("trajectory", "state"))
    w.append(body)
    got = _read_elsewhere(w.close())
    assert got["xr_dims"] == ["time", "trajectory", "state"] and got["xr_state"] == ["x", "px"]
    # Negative control: names for the wrong number of axes are refused (nothing left behind).
    w = H5ChunkWriter(tmp_path / "bad.h5", dims=("state",))
    with pytest.raises(InputError, match="name 1 axes; the states have 2"):
        w.append(body)
    w.abort()
    assert not list(tmp_path.glob("*bad*"))


def test_the_time_of_each_row():
    rows = np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 0.3, 0.0, 1.0], [2.0, 0.7, 0.0, 1.0]])
    tt = {"h": 0.5, "state_names": ["q", "t", "p", "e"], "time_column": "t", "time_transform": "r"}
    np.testing.assert_array_equal(row_times(4, rows, tt), [0.0, 0.3, 0.7])   # the physical-time column
    assert np.isnan(row_times(0, rows, {**tt, "time_column": ""})).all()     # fictive h: no time
    plain = {"h": 0.5, "t0": 1.0, "save_every": 3, "steps": 7}
    np.testing.assert_array_equal(row_times(2, rows, plain), [1.0 + 0.5 * 6, 1.0 + 0.5 * 7, 1.0 + 0.5 * 7])
    # t_final (runio.extent) and the last row's time are the same number
    assert runio.extent(4, plain)["t_final"] == row_times(0, np.zeros((4, 1)), plain)[-1]


# --- the same run as .npz and .h5 -------------------------------------------------------------------

def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype.kind == b.dtype.kind and bool(np.all(a == b))


def test_npz_and_h5_of_the_same_run_agree(osc, tmp_path, capsys):
    args = ["run", osc, "--steps", "100", "--chunk", "30", "--save-every", "3", "--json", "--save"]
    assert run(capsys, *args, tmp_path / "a.npz")[0] == 0
    code, out, _ = run(capsys, *args, tmp_path / "a.h5")
    assert code == 0 and json.loads(out)["saved"] == str(tmp_path / "a.h5")
    y_npz, m_npz = runio.load_trajectory(tmp_path / "a.npz")
    y_h5, m_h5 = load_trajectory(tmp_path / "a.h5")
    assert y_h5.shape == (35, 2) and y_npz.dtype == y_h5.dtype == np.float64
    assert np.array_equal(y_npz, y_h5)                                     # bitwise
    shared = set(m_npz) & set(m_h5)
    assert {"scene", "method", "h", "steps", "save_every", "steps_done", "t_final", "complete", "reason",
            "state_names", "signature", "hamiltonian", "claims", "methodgen_version"} <= shared
    assert [k for k in sorted(shared) if not _same(m_npz[k], m_h5[k])] == []
    assert load_trajectory(tmp_path / "a.npz")[1].keys() == m_npz.keys()  # the front reads .npz as runio does
    t = read_trajectory(tmp_path / "a.h5").t
    assert t[-1] == float(m_h5["t_final"]) == 1.0 and t[1] == 0.03
    # Negative control: a run one step shorter is told apart (last row, steps_done, t_final).
    assert run(capsys, "run", osc, "--steps", "99", "--chunk", "30", "--save-every", "3", "--save",
               tmp_path / "b.h5")[0] == 0
    y_b, m_b = load_trajectory(tmp_path / "b.h5")
    assert not np.array_equal(y_b, y_npz)
    assert {k for k in shared if not _same(m_npz[k], m_b[k])} == {"steps", "steps_done", "t_final"}


def test_save_trajectory_after_solve(osc, tmp_path):
    import methodgen as mg

    mod = mg.build(mg.load_scene(str(osc)).system, "midpoint")
    sol = mod.solve(np.array([1.0, 0.0]), (0.0, 1.0), 0.1)
    where = tf.save(tmp_path / "s.h5", sol, module=mod)
    t, y, meta = tf.load(where)
    assert np.array_equal(t, sol.t) and np.array_equal(y, sol.y)
    assert str(meta["method"]) == "midpoint" and int(meta["order"]) == 2 and bool(meta["complete"])
    assert meta["claims"]["symplectic"] is True and int(meta["steps_done"]) == sol.nsteps
    assert meta["save_every"] == 1
    # a batch: the axes are (time, trajectory, state)
    batch = mod.solve(np.array([[1.0, 0.0], [0.5, 0.0]]), (0.0, 1.0), 0.1)
    got = _read_elsewhere(save_trajectory(tmp_path / "batch.h5", batch, module=mod))
    assert got["xr_dims"] == ["time", "trajectory", "state"] and np.array_equal(got["xr_y"], batch.y)
    # the same to an .npz: t is kept with it
    t2, y2, _ = tf.load(save_trajectory(tmp_path / "s.npz", sol, module=mod))
    assert np.array_equal(t2, sol.t) and np.array_equal(y2, sol.y)
    with pytest.raises(InputError, match="ends in .npz .* or .h5"):
        save_trajectory(tmp_path / "s.csv", sol)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["batch.h5", "s.h5", "s.npz"]


# --- crash safety ----------------------------------------------------------------------------------

KILLED = textwrap.dedent('''
    import sys, time
    import numpy as np
    from methodgen.runtime.trajfile import H5ChunkWriter

    w = H5ChunkWriter(sys.argv[1], meta={"h": 0.25, "save_every": 10, "steps": 10000,
                                         "state_names": ["q", "p"], "time_transform": "", "scene": "k"})
    w.append(np.arange(402.0).reshape(201, 2))
    w.append(-np.arange(400.0).reshape(200, 2))
    print("flushed", flush=True)
    time.sleep(120)
''')


def _killed_writer(folder):
    """A writer that flushed two chunks and was then killed (SIGKILL): its temporary file."""
    proc = subprocess.Popen([sys.executable, "-c", KILLED, str(folder / "long.h5")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "flushed", proc.stderr.read()
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    (tmp,) = folder.glob(".long.h5.*.tmp")
    return tmp


EXPECTED = np.concatenate([np.arange(402.0).reshape(201, 2), -np.arange(400.0).reshape(200, 2)])


def _corrupt_last_chunk(path) -> None:
    """Overwrite bytes inside the last stored chunk of y (as a torn write would leave it)."""
    with h5py.File(path, "r", locking=False) as f:
        dsid = f["y"].id
        info = dsid.get_chunk_info(dsid.get_num_chunks() - 1)
    with open(path, "r+b") as fh:
        fh.seek(info.byte_offset + 8)
        fh.write(b"\xff" * 16)


def test_a_killed_writer_is_recovered_with_its_flushed_chunks(osc, tmp_path, capsys):
    tmp = _killed_writer(tmp_path)
    orphan = tmp.read_bytes()
    # h5py opens what the kill left: the flushed rows and the count that says so
    with h5py.File(tmp, "r", locking=False) as f:
        assert f["y"].shape == (401, 2) and int(f.attrs["saved_rows"]) == 401 and int(f.attrs["complete"]) == 0
    # The next --save into the folder (an .npz one: both formats are rebuilt) recovers it.
    code, _, err = run(capsys, "run", osc, "--steps", "10", "--save", tmp_path / "next.npz")
    assert code == 0 and "recovered 401 states" in err and "long.recovered.h5" in err
    t, y, meta = read_trajectory(tmp_path / "long.recovered.h5")
    np.testing.assert_array_equal(y, EXPECTED)
    assert not bool(meta["complete"]) and str(meta["reason"]) == "killed" and str(meta["scene"]) == "k"
    assert int(meta["steps_done"]) == 4000 and float(meta["t_final"]) == 1000.0 == t[-1]
    assert not list(tmp_path.glob(".*.tmp"))

    # Negative control: a chunk damaged on disk fails its checksum, and is dropped with what follows.
    fd, again = runio.make_temp(tmp_path, "long.h5")
    os.write(fd, orphan)
    os.close(fd)
    _corrupt_last_chunk(again)
    with h5py.File(again, "r", locking=False) as f, pytest.raises(OSError):
        f["y"][201:]                                    # the checksum is what catches it
    (note,) = recover_orphans(tmp_path)
    assert "recovered 201 states" in note
    np.testing.assert_array_equal(read_trajectory(tmp_path / "long.recovered-2.h5").y, EXPECTED[:201])


def test_an_orphan_h5py_cannot_open_is_kept(tmp_path):
    fd, bad = runio.make_temp(tmp_path, "bad.h5")
    os.write(fd, b"\x89HDF\r\n\x1a\n" + b"\0" * 600)     # a superblock cut short: not an HDF5 file
    os.close(fd)
    good = _killed_writer(tmp_path)
    notes = recover_orphans(tmp_path)
    assert any("h5py cannot open it" in n and str(bad) in n and "kept" in n for n in notes), notes
    assert os.path.exists(bad)                                           # never deleted
    # Negative control: the good orphan beside it was recovered in the same pass.
    assert any("recovered 401 states" in n for n in notes) and not good.exists()
    # Without h5py an orphan is kept too, with the way to install it.
    fd, other = runio.make_temp(tmp_path, "other.h5")
    os.write(fd, good.parent.joinpath("long.recovered.h5").read_bytes())
    os.close(fd)
    with pytest.MonkeyPatch.context() as mp:
        mp.setitem(sys.modules, "h5py", None)
        notes = recover_orphans(tmp_path)
    assert any('pip install "methodgen[hdf5]"' in n and "kept" in n for n in notes) and os.path.exists(other)


def _arm_disk_full(monkeypatch):
    real, armed = h5py.Dataset.__setitem__, []

    def setitem(self, key, value):
        if armed:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(self, key, value)

    monkeypatch.setattr(h5py.Dataset, "__setitem__", setitem)
    return armed


def test_a_write_error_keeps_the_complete_chunks(tmp_path, monkeypatch):
    armed = _arm_disk_full(monkeypatch)
    w = H5ChunkWriter(tmp_path / "d.h5", meta={"h": 0.5, "state_names": ["q", "p"]})
    w.append(np.ones((5, 2)))
    w.append(2 * np.ones((5, 2)))
    armed.append(True)
    with pytest.raises(StorageError, match="No space left on device"):
        w.append(3 * np.ones((5, 2)))
    armed.clear()
    where = w.close(steps_done=99, complete=True)      # the caller's claim cannot hold: rescued
    t, y, meta = read_trajectory(where)
    assert where == tmp_path / "d.h5" and y.shape == (10, 2) and np.all(y[5:] == 2)
    assert not bool(meta["complete"]) and str(meta["reason"]) == "write-error" and int(meta["steps_done"]) == 9
    assert float(meta["t_final"]) == 4.5 and sorted(p.name for p in tmp_path.iterdir()) == ["d.h5"]

    # Negative control: without cutting the rows back, the file is inconsistent -- and the reader says so.
    real_finish = H5ChunkWriter._finish_on_disk

    def no_cut(self, attrs):
        good, self._good_rows = self._good_rows, self._good_rows + 5
        try:
            real_finish(self, attrs)
        finally:
            self._good_rows = good

    monkeypatch.setattr(H5ChunkWriter, "_finish_on_disk", no_cut)
    w = H5ChunkWriter(tmp_path / "e.h5", meta={"h": 0.5})
    w.append(np.ones((5, 2)))
    armed.append(True)
    with pytest.raises(StorageError):
        w.append(np.ones((5, 2)))
    armed.clear()
    bad = w.close()
    with h5py.File(bad, "r") as f:          # 10 rows on disk, of which 5 were written completely
        assert f["y"].shape[0] == 10 and int(f.attrs["saved_rows"]) == 5
    with pytest.raises(StorageError, match="damaged: y has 10 rows and t 10, but 5 were saved"):
        read_trajectory(bad)


def test_when_even_the_rescue_fails_the_next_save_rebuilds_the_file(tmp_path, monkeypatch):
    armed = _arm_disk_full(monkeypatch)
    w = H5ChunkWriter(tmp_path / "f.h5", meta={"h": 0.5})
    w.append(np.ones((5, 2)))
    w.append(2 * np.ones((5, 2)))
    armed.append(True)
    with pytest.raises(StorageError):
        w.append(np.ones((5, 2)))

    def fail(self, attrs):
        self._abandon_file()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(H5ChunkWriter, "_finish_on_disk", fail)
    with pytest.raises(StorageError, match=r"the 10 complete rows are in .*\.f\.h5\..*\.tmp"):
        w.close()
    monkeypatch.undo()
    (note,) = recover_orphans(tmp_path)
    assert "recovered 10 states" in note
    y = read_trajectory(tmp_path / "f.recovered.h5").y
    assert y.shape == (10, 2) and np.all(y[5:] == 2)


def test_an_incomplete_run_never_replaces_a_file(osc, tmp_path, capsys):
    g = tmp_path / "g.h5"
    assert run(capsys, "run", osc, "--steps", "50", "--save", g)[0] == 0
    good = g.read_bytes()
    code, _, err = run(capsys, "run", osc, "--param", "m=0", "--save", g)   # fails at step 0
    assert code == cli.EXIT_INPUT and "Traceback" not in err
    partial = tmp_path / "g.partial.h5"
    assert f"saved 1 states to {partial}" in err and f"{g} exists" in err
    assert g.read_bytes() == good and read_trajectory(g).y.shape == (51, 2)
    t, y, meta = read_trajectory(partial)
    assert y.shape == (1, 2) and not bool(meta["complete"]) and int(meta["steps_done"]) == 0
    assert run(capsys, "run", osc, "--param", "m=0", "--save", g)[0] == cli.EXIT_INPUT
    assert (tmp_path / "g.partial-2.h5").is_file() and g.read_bytes() == good
    # Negative control: a complete run does replace the file.
    assert run(capsys, "run", osc, "--steps", "7", "--save", g)[0] == 0
    assert read_trajectory(g).y.shape == (8, 2) and not list(tmp_path.glob(".*.tmp"))


# --- refused before any work -----------------------------------------------------------------------

def test_without_h5py_save_h5_is_refused_before_any_work(osc, tmp_path, capsys, monkeypatch):
    cache = tmp_path / "fresh-cache"
    monkeypatch.setenv("METHODGEN_CACHE", str(cache))
    folder = tmp_path / "out"
    folder.mkdir()
    with monkeypatch.context() as mp:
        mp.setitem(sys.modules, "h5py", None)          # import h5py fails
        code, out, err = run(capsys, "run", osc, "--steps", "10", "--save", folder / "x.h5")
        assert code == cli.EXIT_INPUT and "Traceback" not in err and len(err.strip().splitlines()) == 1
        assert 'pip install "methodgen[hdf5]"' in err and "h5py" in err
        assert not cache.exists() and list(folder.iterdir()) == []      # nothing built, nothing written
        with pytest.raises(InputError, match=r'pip install "methodgen\[hdf5\]"'):
            save_trajectory(folder / "y.h5", [0.0], [[1.0, 2.0]])
        with pytest.raises(InputError, match="h5py"):
            read_trajectory(tmp_path / "nothing.h5")
        # an .npz needs no h5py
        assert run(capsys, "run", osc, "--steps", "10", "--save", folder / "x.npz")[0] == 0
    # Negative control: with h5py the same command works.
    assert run(capsys, "run", osc, "--steps", "10", "--save", folder / "x.h5")[0] == 0
    assert read_trajectory(folder / "x.h5").y.shape == (11, 2)


@pytest.mark.parametrize("name", ["x.txt", "x", "x.hdf"])
def test_a_bad_suffix_is_refused(osc, tmp_path, capsys, name):
    code, out, err = run(capsys, "run", osc, "--steps", "5", "--save", tmp_path / name)
    assert code == cli.EXIT_INPUT and "Traceback" not in err
    assert ".npz" in err and ".h5" in err and "a trajectory file ends in" in err
    assert list(tmp_path.iterdir()) == []


def test_a_solutions_stride_is_recorded(tmp_path):
    """save_every of a saved Solution: its stride (rows after min(i·k, nsteps) steps), or 0 for
    rows at chosen times that are no stride's (t holds them); control: a stride read off the
    first two rows alone would say 30 for t_eval = [0, 0.3, 0.5]."""
    mod = mg.build(mg.load_scene("harmonic").system, "midpoint")
    y0 = np.array([1.0, 0.0])
    for kw, want in ((dict(save_every=7), 7), (dict(), 1), (dict(t_eval=[0.0, 0.3, 0.5]), 0)):
        sol = mod.solve(y0, (0.0, 1.0), 0.01, **kw)
        t, y, meta = read_trajectory(tf.save(tmp_path / f"s{want}.h5", sol, module=mod))
        assert meta["save_every"] == want and np.array_equal(t, sol.t) and np.array_equal(y, sol.y)
    assert round((0.3 - 0.0) / 0.01) == 30
