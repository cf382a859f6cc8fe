"""Open, versioned trajectory files: ``methodgen-trajectory 1`` (HDF5), and the front for both formats.

``methodgen run --save FILE.h5`` (and :func:`save_trajectory`) write an HDF5 file
that h5py, netCDF4 and xarray read without methodgen; ``--save FILE.npz`` writes
the chunked ``.npz`` of :mod:`methodgen.runtime.runio` as before.  The suffix chooses
(:data:`SUFFIXES`); :func:`load_trajectory` and :func:`read_trajectory` read
both, :func:`recover_orphans` rebuilds the temporary files of killed runs of both.

Format ``methodgen-trajectory``, version 1
------------------------------------------
An HDF5 file (also a valid netCDF-4 file: dimensions are HDF5 dimension scales)::

    /                     root attributes (below)
    /y      float64 (time, *state axes)   the saved states, row i after
                                          min(i * save_every, steps) steps;
                                          chunked, unlimited along time, Fletcher-32
                                          checksums (a damaged chunk fails to read)
    /t      float64 (time,)               the time of each row: the state's
                                          ``time_column`` (physical time of a time
                                          transformation or a time-dependent H), else
                                          t0 + h * step index (t0 = 0 when absent);
                                          NaN where not known; CF ``coordinates``
                                          attribute of y, so xarray shows t as a
                                          coordinate of y
    /time                                 the unlimited dimension of the rows (a
                                          netCDF dimension without a variable)
    /state  str (state,)                  the state names: the coordinate of y's state
                                          axis (1-D states with ``state_names``)

For states of more than one axis the axes are named by ``dims`` (default
``body``, ``coordinate`` for two axes, ``axis_1``, … for more; a batch
:class:`Solution` saved with :func:`save_trajectory`: ``trajectory``, ``state``).

Root attributes (plain HDF5 types: text, integers, floats and arrays of them):

* ``format = "methodgen-trajectory"``, ``format_version = 1`` — a reader refuses a
  higher version; ``methodgen_version``, ``created`` (ISO 8601, UTC);
* what the run was: ``scene``, ``method``, ``order``, ``composition``, ``h``,
  ``steps`` (planned), ``save_every`` (1 unless given; 0: rows at chosen times, as
  ``solve(t_eval=...)``'s — ``t`` says which), ``state_names``,
  ``time_transform``, ``time_column``, ``stages``, and the provenance the caller
  gives (``hamiltonian``, ``signature``, ``claims`` …);
* what the rows cover: ``complete`` (0 while writing and for an incomplete run),
  ``reason``, ``steps_done``, ``t_final`` (when known), ``saved_rows`` (the rows
  written completely; a reader checks it against ``y`` and ``t``);
* ``boolean_attributes``, ``json_attributes``: the names of the attributes that
  hold a boolean (as 0/1) or a mapping (as JSON text), so that they read back as such.

Crash safety is that of the ``.npz`` (:mod:`methodgen.runtime.runio`): the file is
written to a locked temporary file ``.NAME.h5.HOST-PID.XXXXXXXX.tmp`` in the same
folder, flushed after each chunk, and renamed into place when closed; an
incomplete run never replaces a file (``NAME.partial.h5``); a write error keeps
the complete chunks (:meth:`H5ChunkWriter.rescue`); the temporary file of a
killed run is rebuilt into ``NAME.recovered.h5`` by :func:`recover_orphans` from
the rows its last flush recorded (``saved_rows``), checked against their
checksums — and kept as it is, with a note, when h5py cannot open it.

h5py is optional (``pip install "methodgen[hdf5]"``); this module imports it only
when an ``.h5`` file is written or read.
"""

from __future__ import annotations

import datetime as _dt
import errno as _errno
import json
import os
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._version import __version__
from ..codegen.store import find_orphans, make_temp, storage_error
from ..errors import InputError, StorageError
from .runio import ChunkWriter, _LockedTemp, _fmt_size, _free_name, _place_new, _scalar, extent
from .runio import load_trajectory as _load_npz
from .runio import recover_orphans as _recover_npz

__all__ = ["FORMAT", "FORMAT_VERSION", "SUFFIXES", "H5ChunkWriter", "Trajectory", "check_suffix",
           "require_h5py", "open_writer", "save_trajectory", "read_trajectory", "load_trajectory",
           "recover_orphans", "row_times", "save", "load"]

FORMAT = "methodgen-trajectory"
FORMAT_VERSION = 1
#: The suffixes of trajectory files and their formats.
SUFFIXES = {".npz": "npz", ".h5": "hdf5"}
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
HDF5_INSTALL = 'pip install "methodgen[hdf5]"'

#: The NAME of a dimension scale that is a netCDF dimension without a variable (netCDF-C, h5netcdf).
_NOT_A_VARIABLE = "This is a netCDF dimension but not a netCDF variable."
#: Root attributes of the format itself, not metadata of the run.
_INTERNAL = frozenset({"boolean_attributes", "json_attributes", "saved_rows"})
#: Written by the writer itself (a meta value for them is ignored).
_FORMAT_KEYS = frozenset({"format", "format_version"})
#: Rows per HDF5 chunk at most: 256 KiB of float64.
_CHUNK_BYTES = 1 << 18


def require_h5py():
    """The ``h5py`` module, or a one-line :class:`InputError` saying how to install it."""
    try:
        import h5py
    except ImportError as exc:
        raise InputError(f"writing or reading .h5 trajectory files needs h5py, which is not installed "
                         f"({exc}): {HDF5_INSTALL} (or save to FILE.npz)") from None
    return h5py


def check_suffix(path, option: str = "--save") -> str:
    """The format of the trajectory file ``path`` by its suffix: ``"npz"`` or ``"hdf5"``.

    Raises
    ------
    InputError
        Any other suffix (the message names the valid ones).
    """
    suffix = Path(str(path)).suffix.lower()
    kind = SUFFIXES.get(suffix)
    if kind is None:
        raise InputError(f"{option} {path}: a trajectory file ends in .npz (numpy, in chunks) or .h5 (HDF5, "
                         f"{FORMAT} {FORMAT_VERSION}), not {suffix or 'no suffix'}")
    return kind


def _is_hdf5(path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(8) == HDF5_SIGNATURE
    except OSError:
        return Path(str(path)).suffix.lower() == ".h5"


# --- attributes: plain HDF5 types, read back as written ------------------------------------------

_SKIP = object()


def _encode(key: str, value):
    """``(attribute value, kind)`` of a metadata value; kind is "bool", "json" or None."""
    import h5py

    if value is None:
        return _SKIP, None
    if isinstance(value, Mapping):
        return json.dumps(value, default=str), "json"
    if isinstance(value, (bool, np.bool_)):
        return np.int8(bool(value)), "bool"
    if isinstance(value, (str, np.str_)):
        return str(value), None
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace"), None
    arr = np.asarray(value)
    if arr.ndim == 0:
        if arr.dtype.kind in "iu":
            return np.int64(arr), None
        if arr.dtype.kind == "f":
            return np.float64(arr), None
        if arr.dtype.kind in "bUSO" and not isinstance(arr.item(), np.ndarray):
            item = arr.item()
            if isinstance(item, (bool, str, bytes, Mapping, type(None))):
                return _encode(key, item)
    if arr.dtype.kind == "b":
        return arr.astype(np.int8), "bool"
    if arr.dtype.kind in "iu":
        return arr.astype(np.int64), None
    if arr.dtype.kind == "f":
        return arr.astype(np.float64), None
    if arr.dtype.kind in "US" or (arr.dtype.kind == "O" and all(isinstance(v, str) for v in arr.ravel())):
        return np.array([str(v) for v in arr.ravel()], dtype=h5py.string_dtype()).reshape(arr.shape), None
    try:
        return json.dumps(value.tolist() if isinstance(value, np.ndarray) else value), "json"
    except (TypeError, ValueError):
        raise InputError(f"metadata {key!r}: a {type(value).__name__} cannot be stored; give text, "
                         "numbers, booleans, arrays of them or a mapping") from None


def _decode(value, kind):
    """A root attribute as :func:`load_trajectory` returns it (0-d arrays, like an ``.npz``'s)."""
    if kind == "json":
        return json.loads(value)
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray) and value.dtype.kind in "OS":
        value = np.array([v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)
                          for v in value.ravel()]).reshape(value.shape)
    out = np.asarray(value)
    return out.astype(bool) if kind == "bool" else out


def _kinds(attrs) -> dict:
    out = {}
    for kind, key in (("bool", "boolean_attributes"), ("json", "json_attributes")):
        for name in np.atleast_1d(attrs.get(key, np.array([], dtype=object))).ravel():
            out[name.decode() if isinstance(name, bytes) else str(name)] = kind
    return out


def _read_meta(attrs) -> dict:
    kinds = _kinds(attrs)
    return {k: _decode(attrs[k], kinds.get(k)) for k in attrs if k not in _INTERNAL}


def _names(meta: dict) -> list[str]:
    return [str(n) for n in np.atleast_1d(_scalar(meta, "state_names", []) or [])]


def row_times(first_row: int, states, meta: dict) -> np.ndarray:
    """The times of ``states``, rows ``first_row, first_row + 1, …`` of a saved run.

    The state's ``time_column`` (a time transformation's or a time-dependent H's
    physical time) when the rows have one axis; else ``t0 + h * step`` with row i
    after ``min(i * save_every, steps)`` steps (as :func:`methodgen.runtime.runio.extent`
    counts), for a run without a time transformation; NaN where neither applies.
    """
    states = np.asarray(states)
    n = len(states)
    column = str(_scalar(meta, "time_column", "") or "")
    names = _names(meta)
    if column:
        if column in names and states.ndim == 2:
            return np.array(states[:, names.index(column)], dtype=np.float64)
        return np.full(n, np.nan)
    if "h" not in meta or str(_scalar(meta, "time_transform", "") or ""):
        return np.full(n, np.nan)
    every = int(_scalar(meta, "save_every", 1) or 1)
    step = (int(first_row) + np.arange(n, dtype=np.int64)) * every
    planned = _scalar(meta, "steps")
    if planned is not None:
        step = np.minimum(step, int(planned))
    return float(_scalar(meta, "t0", 0.0)) + float(_scalar(meta, "h")) * step.astype(np.float64)


def _default_dims(shape: tuple, names: list[str]) -> tuple[str, ...]:
    if len(shape) == 1:
        return ("state",)
    if len(shape) == 2:
        return ("body", "coordinate")
    return tuple(f"axis_{i}" for i in range(1, len(shape) + 1))


# --- the HDF5 writer ------------------------------------------------------------------------------

class H5ChunkWriter(_LockedTemp):
    """Write a trajectory chunk by chunk into ``path`` (a ``.h5``), as :class:`~methodgen.runtime.runio.ChunkWriter`.

    The same interface and the same guarantees: :meth:`append`, :meth:`close`,
    :meth:`rescue`, :meth:`abort`, :attr:`saved_rows`, :attr:`failed`,
    :attr:`recovered` (notes about killed saves rebuilt in the folder).

    Parameters
    ----------
    path : path-like
        Final file name, ending in ``.h5``.
    meta : dict, optional
        Metadata written at once as root attributes (a file rebuilt after a kill
        has them); ``save_every``, ``steps``, ``h``, ``t0``, ``time_column`` and
        ``state_names`` give the times of the rows (:func:`row_times`) and what they
        cover (:func:`~methodgen.runtime.runio.extent`).
    dims : sequence of str, optional
        Names of the state axes (default: :func:`_default_dims`).

    Raises
    ------
    InputError
        h5py is missing, or the suffix is not ``.h5``.
    StorageError
        The folder cannot be written, or the disk is full.
    """

    def __init__(self, path, meta: dict | None = None, *, dims=None, _recover: bool = True):
        self._h5py = require_h5py()
        path = Path(path)
        if path.suffix.lower() != ".h5":
            raise InputError(f"an HDF5 trajectory file ends in .h5, got {path}")
        self.path = path
        self.chunks = 0
        self.rows = 0
        self._start_meta = dict(meta or {})
        self._dims = None if dims is None else tuple(str(d) for d in dims)
        self._last_row = None
        self.failed: StorageError | None = None
        self._good_rows = 0
        self._kinds: dict[str, str] = {}
        self._f = self._y = self._t = self._time = None
        self._lock = None
        self._tmp = None
        self._candidates = None   # where an incomplete file goes (default: NAME, NAME.partial.h5, …)
        self.recovered: list[str] = []
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            if _recover:
                self.recovered = recover_orphans(path.parent)
            self._lock, self._tmp = make_temp(path.parent, path.name)
            self._f = self._h5py.File(self._tmp, "w", locking=False, track_order=True)
            head = {k: v for k, v in self._start_meta.items() if k not in _FORMAT_KEYS}
            head.setdefault("methodgen_version", __version__)
            head.setdefault("created", _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
            head.setdefault("save_every", 1)
            head["complete"] = False    # until closed as complete: also what a killed file says
            self._set_attrs({"format": FORMAT, "format_version": FORMAT_VERSION, **head, "saved_rows": 0})
            self._f.flush()
        except OSError as exc:
            self._discard()
            raise storage_error(exc, "write", path) from None
        except BaseException:
            self._discard()
            raise

    # attributes ---------------------------------------------------------------------------------

    def _set_attrs(self, meta: dict) -> None:
        attrs = self._f.attrs
        changed = False
        for key, value in meta.items():
            value, kind = _encode(key, value)
            if value is _SKIP:
                continue
            if self._kinds.get(key) != kind:
                changed = True
                if kind is None:
                    self._kinds.pop(key, None)
                else:
                    self._kinds[key] = kind
            attrs[key] = value
        if changed:
            for kind, name in (("bool", "boolean_attributes"), ("json", "json_attributes")):
                keys = [k for k, v in self._kinds.items() if v == kind]
                if keys:
                    attrs[name] = np.array(keys, dtype=self._h5py.string_dtype())
                elif name in attrs:
                    del attrs[name]

    # datasets -----------------------------------------------------------------------------------

    def _create(self, shape: tuple, first: int) -> None:
        h5py, f = self._h5py, self._f
        names = _names(self._start_meta)
        dims = self._dims if self._dims is not None else _default_dims(shape, names)
        if len(dims) != len(shape):
            raise InputError(f"dims {dims} name {len(dims)} axes; the states have {len(shape)}: {shape}")
        clash = {"time", "t", "y"} & set(dims)
        if clash:
            raise InputError(f"dims: {', '.join(sorted(clash))} is a name of the file's own datasets")
        if any(n == 0 for n in shape):
            raise InputError(f"states of shape {shape} have no values")
        width = int(np.prod(shape, dtype=np.int64)) if shape else 1
        rows = max(1, min(max(int(first), 1), _CHUNK_BYTES // (8 * width)))
        time = f.create_dataset("time", shape=(0,), maxshape=(None,), dtype="f4", chunks=(rows,))
        time.make_scale(_NOT_A_VARIABLE)
        scales = []
        for name, size in zip(dims, shape):
            if name in f:
                if f[name].shape != (size,):
                    raise InputError(f"dims: {name!r} names axes of different lengths")
                scales.append(f[name])
                continue
            if name == "state" and len(names) == size:
                d = f.create_dataset("state", data=np.array(names, dtype=h5py.string_dtype()))
                d.attrs["long_name"] = "state variable"
                d.make_scale("state")
            else:
                d = f.create_dataset(name, shape=(size,), dtype="f4")
                d.make_scale(_NOT_A_VARIABLE)
            scales.append(d)
        y = f.create_dataset("y", shape=(0, *shape), maxshape=(None, *shape), dtype="f8",
                             chunks=(rows, *shape), fletcher32=True)
        y.attrs["long_name"] = "saved states"
        y.attrs["coordinates"] = "t"   # CF: xarray makes t a coordinate of y
        t = f.create_dataset("t", shape=(0,), maxshape=(None,), dtype="f8", chunks=(rows,), fletcher32=True)
        t.attrs["long_name"] = "time of the row (physical time; NaN where not known)"
        y.dims[0].attach_scale(time)
        t.dims[0].attach_scale(time)
        for axis, scale in enumerate(scales, start=1):
            y.dims[axis].attach_scale(scale)
        self._y, self._t, self._time = y, t, time

    def append(self, states, t=None) -> None:
        """Append consecutive states, shape (n, ...); ``t``: their times (default :func:`row_times`).

        Raises
        ------
        StorageError
            The write failed (e.g. disk full); :meth:`rescue` keeps the chunks before it.
        """
        if self.failed is not None:
            raise self.failed
        states = np.asarray(states)
        if states.ndim < 1:
            raise InputError(f"states must have a row axis, got shape {states.shape}")
        if states.dtype.kind not in "fiub":
            raise InputError(f"states must be real numbers, got dtype {states.dtype}")
        n = len(states)
        times = (row_times(self._good_rows, states, self._start_meta) if t is None
                 else np.asarray(t, dtype=np.float64).reshape(-1))
        if len(times) != n:
            raise InputError(f"t has {len(times)} times for {n} states")
        if self._y is not None and states.shape[1:] != self._y.shape[1:]:
            raise InputError(f"states of shape {states.shape[1:]} appended to a file of {self._y.shape[1:]}")
        last = np.array(states[-1], dtype=np.float64, copy=True) if n else self._last_row
        try:
            if self._y is None:
                self._create(states.shape[1:], n)
            n0 = self._good_rows
            for d in (self._y, self._t, self._time):
                d.resize(n0 + n, axis=0)
            if n:
                self._y[n0:] = states
                self._t[n0:] = times
            self._f.flush()   # the rows, then the count that says they are there
            self._set_attrs({"saved_rows": n0 + n, **extent(n0 + n, self._start_meta, last)})
            self._f.flush()
        except InputError:
            raise
        except OSError as exc:
            self.failed = storage_error(exc, "write", self.path)
            raise self.failed from None
        except BaseException:
            self.failed = StorageError(f"writing {self.path} was interrupted", self.path, _errno.EINTR)
            raise
        self._good_rows += n
        self.chunks += 1
        self.rows += n
        self._last_row = last

    @property
    def saved_rows(self) -> int:
        """Rows of the chunks written completely."""
        return self._good_rows

    def close(self, **meta) -> Path:
        """Write metadata, close, and move the file into place; returns where it went.

        As :meth:`methodgen.runtime.runio.ChunkWriter.close`: ``steps_done``/``t_final`` default
        to what the rows cover; ``complete=False`` replaces no file (``NAME.partial.h5``,
        with a RuntimeWarning); after a failed write this is :meth:`rescue`.
        """
        if self.failed is not None:
            return self.rescue(**meta)
        meta = {**extent(self._good_rows, self._start_meta, self._last_row), **meta}
        complete = bool(meta.get("complete", True))
        try:
            self._set_attrs({**meta, "complete": complete, "saved_rows": self._good_rows})
            self._close_file()
            os.fsync(self._lock)
            if complete:
                os.replace(self._tmp, self.path)
                where = self.path
            else:
                where = self._place_incomplete()
        except OSError as exc:
            if self.failed is None:
                self.failed = storage_error(exc, "write", self.path)
            return self.rescue(**meta)
        self._release()
        return where

    def _close_file(self) -> None:
        f, self._f = self._f, None
        self._y = self._t = self._time = None
        if f is not None:
            f.close()

    def _place_incomplete(self) -> Path:
        where = _place_new(self._tmp, self._candidates or [self.path, *_free_name(self.path, "partial")])
        if self._candidates is None and where != self.path:
            warnings.warn(f"{self.path} exists and this run did not complete, so it is kept as it was; "
                          f"the {self._good_rows} states of this run are saved to {where}",
                          RuntimeWarning, stacklevel=4)
        return where

    def rescue(self, **meta) -> Path:
        """Keep every complete chunk after a failed write: cut the rows back, finish, move into place.

        The file is marked ``complete = 0``, ``reason = "write-error"``, with what its
        rows cover; it replaces no existing file.  When even that cannot be
        written, :class:`StorageError` names the temporary file (the next
        ``--save`` into the folder rebuilds it: :func:`recover_orphans`).
        """
        meta = {**meta, **extent(self._good_rows, self._start_meta, self._last_row),
                "complete": False, "reason": "write-error", "saved_rows": self._good_rows}
        last = None
        for extra in (meta, {k: meta[k] for k in ("complete", "reason", "saved_rows")}):
            try:
                self._finish_on_disk(extra)
                where = self._place_incomplete()
            except OSError as exc:
                last = exc
                continue
            self._release()
            return where
        tmp = self._tmp
        self._release()   # unlocked: a later run sees an orphan and rebuilds it
        raise StorageError(f"cannot finish {self.path}: {getattr(last, 'strerror', None) or last}; the "
                           f"{self._good_rows} complete rows are in {tmp} (the next --save into "
                           f"{self.path.parent} rebuilds them)", self.path, getattr(last, "errno", None))

    def _finish_on_disk(self, attrs: dict) -> None:
        """Cut the datasets to the complete rows, write ``attrs`` and close (reopening if needed)."""
        try:
            if self._f is None:
                self._f = self._h5py.File(self._tmp, "r+", locking=False)
                self._kinds = _kinds(self._f.attrs)
            for name in ("y", "t", "time"):
                if name in self._f and self._f[name].shape[0] != self._good_rows:
                    self._f[name].resize(self._good_rows, axis=0)
            self._set_attrs(attrs)
            self._close_file()
            os.fsync(self._lock)
        except BaseException:
            self._abandon_file()
            raise

    def abort(self) -> None:
        """Drop the file (nothing is kept)."""
        self._discard()

    def _abandon_file(self) -> None:
        try:
            self._close_file()
        except Exception:  # noqa: BLE001 - after a failure: the file is finished or rebuilt later
            pass



# --- both formats ----------------------------------------------------------------------------------

def open_writer(path, meta: dict | None = None, *, dims=None):
    """A chunk writer for ``path`` by its suffix: :class:`~methodgen.runtime.runio.ChunkWriter` (``.npz``) or
    :class:`H5ChunkWriter` (``.h5``); both rebuild the killed saves of either format in the folder
    first (their notes in ``.recovered``).

    Raises
    ------
    InputError
        Another suffix, or ``.h5`` without h5py.
    """
    if check_suffix(path) == "hdf5":
        return H5ChunkWriter(path, meta, dims=dims)
    writer = ChunkWriter(path, meta=meta)
    writer.recovered = list(writer.recovered) + _recover_h5(Path(path).parent)
    return writer


class Trajectory(NamedTuple):
    """A saved trajectory: times ``t`` (rows,), states ``y`` (rows, ...), metadata ``meta``."""

    t: np.ndarray
    y: np.ndarray
    meta: dict


def read_trajectory(path) -> Trajectory:
    """Read a trajectory file of either format: ``Trajectory(t, y, meta)``.

    ``meta`` holds the root attributes as plain Python values (text, numbers,
    booleans; arrays stay arrays; ``claims``, JSON text in the file, as a dict).
    For an ``.npz``, ``t`` is its ``t`` entry (written by :func:`save_trajectory`)
    or else :func:`row_times` of its metadata.  (:func:`load_trajectory` returns
    the metadata as 0-d arrays, as :func:`methodgen.runtime.runio.load_trajectory` does.)

    Raises
    ------
    InputError
        Not a trajectory file, a newer format version, or an ``.h5`` without h5py.
    StorageError
        The file cannot be read, is damaged (a checksum fails) or truncated
        (fewer rows than ``saved_rows``).
    """
    t, y, meta = _read_arrays(path)
    return Trajectory(t, y, {k: _plain(k, v) for k, v in meta.items()})


def _plain(key: str, value):
    """A metadata value as a plain Python value: 0-d arrays as their item, ``claims`` (JSON
    text) as a dict."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()
    if key == "claims" and isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return value
    return value


def _read_arrays(path) -> Trajectory:
    """:func:`read_trajectory` with the metadata as written (0-d arrays)."""
    if not _is_hdf5(path):
        y, meta = _load_npz(path)
        t = meta.pop("t", None)
        return Trajectory(row_times(0, y, meta) if t is None else np.asarray(t), y, meta)
    h5py = require_h5py()
    try:
        with h5py.File(path, "r", locking=False) as f:
            fmt = f.attrs.get("format")
            fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
            if fmt != FORMAT:
                raise InputError(f"{path} is an HDF5 file but not a {FORMAT} file (its format attribute is "
                                 f"{fmt!r})")
            version = int(f.attrs.get("format_version", 0))
            if version > FORMAT_VERSION:
                raise InputError(f"{path} is {FORMAT} version {version}, newer than this methodgen reads "
                                 f"({FORMAT_VERSION}): upgrade methodgen")
            meta = _read_meta(f.attrs)
            if "y" not in f:
                return Trajectory(np.zeros((0,)), np.zeros((0,)), meta)
            saved = int(f.attrs.get("saved_rows", f["y"].shape[0]))
            rows = (f["y"].shape[0], f["t"].shape[0] if "t" in f else f["y"].shape[0])
            if rows != (saved, saved):
                raise StorageError(f"{path} is damaged: y has {rows[0]} rows and t {rows[1]}, but "
                                   f"{saved} were saved (truncated?)", path, _errno.EIO)
            y = f["y"][()]
            t = f["t"][()] if "t" in f else row_times(0, y, meta)
    except (InputError, StorageError):
        raise
    except OSError as exc:
        raise storage_error(exc, "read", path) from None
    return Trajectory(t, y, meta)


def load_trajectory(path) -> tuple[np.ndarray, dict]:
    """``(states, metadata)`` of a trajectory file of either format (as :func:`methodgen.runtime.runio.load_trajectory`
    for an ``.npz``); the same run saved as ``.npz`` and ``.h5`` gives equal arrays and values."""
    traj = _read_arrays(path)
    return traj.y, traj.meta


def save_trajectory(path, t, y=None, meta: dict | None = None, *, module=None, dims=None) -> Path:
    """Save a trajectory: ``save_trajectory("run.h5", sol)`` after ``sol = mod.solve(...)``, or
    ``save_trajectory("run.h5", t, y, meta)``.  Returns the path written.

    Parameters
    ----------
    path : path-like
        ``.h5`` (format ``methodgen-trajectory`` 1; needs h5py) or ``.npz``.
    t : array_like (rows,) or Solution
        The times of the rows, or a :class:`Solution` of a generated module (its
        ``t``, ``y`` — a batch's axes are named ``trajectory``, ``state`` — and
        ``h``, ``nsteps``, ``success``, ``message``).
    y : array_like (rows, ...), optional
        The states (not with a Solution).
    meta : dict, optional
        More metadata (text, numbers, booleans, arrays, mappings).
    module : module, optional
        The generated module: records ``method``, ``order``, ``state_names``,
        ``hamiltonian``, ``signature`` and its ``claims`` (``TRAITS``).
    dims : sequence of str, optional
        Names of the state axes in an ``.h5``.

    The file is written as ``methodgen run --save`` writes one: to a temporary
    file renamed into place (an existing file is replaced only by a complete
    solution).
    """
    info: dict = {}
    if y is None and hasattr(t, "t") and hasattr(t, "y"):
        sol = t
        t, y = sol.t, sol.y
        success = bool(getattr(sol, "success", True))
        info.update(h=getattr(sol, "h", None), steps=getattr(sol, "nsteps", None),
                    steps_done=getattr(sol, "nsteps", None), complete=success,
                    reason="complete" if success else "failed", message=getattr(sol, "message", None))
        if dims is None and np.ndim(y) == 3:
            dims = ("trajectory", "state")
        info["save_every"] = _solution_stride(sol)
    elif y is None:
        raise InputError("save_trajectory(path, t, y): give the states y, or a Solution as t")
    y = np.asarray(y)
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if module is not None:
        info.update(_module_meta(module))
    info = {k: v for k, v in info.items() if v is not None}
    info.update(meta or {})
    if len(t):
        info.setdefault("t_final", float(t[-1]))
        info.setdefault("t0", float(t[0]))
    kind = check_suffix(path, "save_trajectory")
    final = {k: info.pop(k) for k in ("complete", "reason", "steps_done", "t_final") if k in info}
    if kind == "hdf5":
        writer = H5ChunkWriter(path, info, dims=dims)
    else:
        writer = ChunkWriter(path, meta=info)
    try:
        if kind == "hdf5":
            writer.append(y, t=t)
        else:
            writer.append(y)
            final["t"] = t
        final.setdefault("steps_done", max(len(y) - 1, 0))
    except BaseException:
        writer.abort()
        raise
    return writer.close(**final)


def _solution_stride(sol) -> int | None:
    """The ``save_every`` of a Solution's rows: k when row i is the state after min(i·k, nsteps)
    steps; 0 for rows at chosen times (``t_eval``: the file's ``t`` says which)."""
    t = np.asarray(sol.t, dtype=np.float64)
    h = getattr(sol, "h", None)
    n = getattr(sol, "nsteps", None)
    if len(t) < 2 or not h or n is None:
        return 1 if len(t) < 2 else 0
    k = (t - t[0]) / float(h)
    steps = np.rint(k)
    if not np.allclose(k, steps, rtol=0, atol=1e-6):
        return 0
    every = int(steps[1])
    want = np.minimum(np.arange(len(t)) * every, int(n))     # the last row is the run's end
    return every if every >= 1 and np.array_equal(steps.astype(np.int64), want) else 0


def _module_meta(module) -> dict:
    """Provenance of a generated module: method, order, names, Hamiltonian, signature, claims."""
    tt = getattr(module, "TIME_TRANSFORM", None) or {}
    out = {"method": getattr(module, "METHOD", None), "order": getattr(module, "ORDER", None),
           "composition": getattr(module, "COMPOSITION", None) or "",
           "state_names": list(getattr(module, "STATE_NAMES", ()) or ()) or None,
           "hamiltonian": getattr(module, "HAMILTONIAN", None), "signature": getattr(module, "SIGNATURE", None),
           "time_column": tt.get("time", "")}
    traits = getattr(module, "TRAITS", None)
    if traits:
        out["claims"] = json.dumps(traits, default=str)
    return out


save = save_trajectory
load = read_trajectory


# --- killed runs -----------------------------------------------------------------------------------

def recover_orphans(folder) -> list[str]:
    """Rebuild the temporary files of killed saves in ``folder``, ``.npz`` and ``.h5``: notes for the user.

    ``.npz``: :func:`methodgen.runtime.runio.recover_orphans`.  ``.h5``: the rows the last
    flush recorded (``saved_rows``; a chunk that fails its checksum and the rows after
    it are dropped) go to ``NAME.recovered.h5`` (never over a file), marked
    ``complete = 0``, ``reason = "killed"``, with what they cover; then the temporary
    file is removed.  The rows are copied into a new file (as much free space again is
    needed); the temporary file is removed only once the copy is in place, and kept
    as it is when it cannot be rebuilt: h5py cannot open it, h5py is missing, or the
    copy fails (the note says why).
    """
    return _recover_npz(folder) + _recover_h5(folder)


def _recover_h5(folder) -> list[str]:
    folder = Path(folder)
    notes = []
    for tmp, name, fd in find_orphans(folder):
        try:
            if name.lower().endswith(".h5"):
                notes.append(_recover_one(folder, Path(tmp), name, fd))
        finally:
            os.close(fd)
    return notes


def _good_rows(f) -> int:
    """Rows of ``y`` and ``t`` that read back (checksums) up to the recorded ``saved_rows``."""
    if "y" not in f:
        return 0
    y, t = f["y"], f["t"] if "t" in f else None
    n = min(int(f.attrs.get("saved_rows", y.shape[0])), y.shape[0], t.shape[0] if t is not None else y.shape[0])
    step = max(1, (y.chunks or (n,))[0])
    good = 0
    while good < n:
        end = min(n, good + step)
        try:
            y[good:end]
            if t is not None:
                t[good:end]
        except OSError:
            break
        good = end
    return good


def _recover_one(folder: Path, tmp: Path, name: str, fd: int) -> str:
    size = 0
    try:
        size = os.fstat(fd).st_size
        h5py = require_h5py()
    except (OSError, InputError) as exc:
        return (f"found the temporary file of a killed save, {tmp} ({_fmt_size(size)}), but cannot rebuild "
                f"it: {exc}; it is kept as it is")
    try:
        src = h5py.File(tmp, "r", locking=False)
    except Exception as exc:  # noqa: BLE001 - whatever h5py says, the file is kept
        return (f"found the temporary file of a killed save, {tmp} ({_fmt_size(size)}), but h5py cannot "
                f"open it ({' '.join(str(exc).split())}); it is kept as it is — delete it if no run is "
                "writing it")
    writer = None
    try:
        with src:
            rows = _good_rows(src)
            if rows == 0:
                os.unlink(tmp)
                return (f"removed {tmp} ({_fmt_size(size)}): the temporary file of a killed save with no "
                        "complete chunk")
            meta = _read_meta(src.attrs)
            start = {k: v for k, v in meta.items()
                     if k not in _FORMAT_KEYS and k not in ("complete", "reason", "steps_done", "t_final")}
            y = src["y"]
            dims = [Path(y.dims[a][0].name).name if len(y.dims[a]) else f"axis_{a}" for a in range(1, y.ndim)]
            writer = H5ChunkWriter(folder / name, start, dims=dims, _recover=False)
            writer._candidates = list(_free_name(folder / name, "recovered"))
            step = max(1, (y.chunks or (rows,))[0]) * 64
            for i in range(0, rows, step):
                end = min(rows, i + step)
                writer.append(y[i:end], t=src["t"][i:end] if "t" in src else None)
        target = writer.close(complete=False, reason="killed")
        writer = None
        os.unlink(tmp)
    except (OSError, InputError) as exc:
        if writer is not None:
            writer.abort()
        return (f"found the temporary file of a killed save, {tmp} ({_fmt_size(size)}), but could not "
                f"rebuild it: {getattr(exc, 'strerror', None) or exc}; it is kept as it is")
    return f"recovered {rows} states (the complete chunks) of a killed save to {name} into {target}; removed {tmp}"
