"""Trajectories on disk: chunked ``.npz`` files written atomically, and what a crash leaves.

A long run need not fit in memory: :class:`ChunkWriter` appends arrays as
separate entries (``chunk_00000``, ``chunk_00001``, …) of one ``.npz`` (a zip
of ``.npy`` files), written to a temporary file and renamed into place when
closed, so a crash never leaves a truncated file under the final name.
:func:`load_trajectory` concatenates the chunks again.

Faults lose nothing that was already written:

* **Disk full (or any write error) during a run**: :meth:`ChunkWriter.rescue`
  cuts the file after the last complete chunk (freeing the space of the
  partial one), writes the metadata and the zip directory, and moves it into
  place — every complete chunk stays readable.
* **A killed run** (SIGKILL, power cut of the process) leaves its temporary
  file ``.NAME.HOST-PID.XXXXXXXX.tmp`` (:func:`methodgen.codegen.store.make_temp`,
  shared with the module cache).  Each temporary file is locked
  (``flock``) by its writer while it exists, so a later run can tell an
  orphan (lock free: the writer is gone) from a file another run is still
  writing.  :func:`recover_orphans` rebuilds the complete chunks of an
  orphaned save into ``NAME.recovered.npz`` (entries are checked against
  their CRC and ``.npy`` header; a cut-off last chunk is dropped) and removes
  the temporary file.  The CLI does this at the start of every ``--save``.
* **A run that fails or is interrupted** never replaces an existing file: an
  incomplete save (closed with ``complete=False``, or finished by
  :meth:`ChunkWriter.rescue`) goes to ``NAME.partial.npz`` (``NAME.partial-2.npz``,
  …) when ``NAME.npz`` exists, with a :class:`RuntimeWarning` naming both.  Only
  a complete run replaces a file.

The metadata of every file says what its rows cover (:func:`extent`):
``steps_done = min((rows - 1) * save_every, steps)`` and ``t_final``, also in a
file rebuilt from a killed run.

The same run in an open, versioned HDF5 file (``--save FILE.h5``):
:mod:`methodgen.runtime.trajfile`, which uses the temporary files, locks and placement
rules of this module and reads and recovers both formats.
"""

from __future__ import annotations

import errno as _errno
import io
import os
import re
import struct
import time
import warnings
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..codegen.store import _temp_re, find_orphans, make_temp, storage_error
from ..errors import InputError, StorageError

__all__ = ["ChunkWriter", "load_trajectory", "recover_orphans", "extent"]

_ZIP_LOCAL = 0x04034B50


# --- npz files written chunk by chunk ---------------------------------------------------------

def _npy_bytes(array) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asanyarray(array), allow_pickle=False)
    return buf.getvalue()


def _finish_zip(fd: int, entries: list, end: int, meta: dict) -> None:
    """Cut the file at ``end`` (after the last complete entry) and write ``meta`` and the directory.

    ``entries`` are the :class:`zipfile.ZipInfo` of the complete entries (their
    data lies before ``end``); metadata keys already among them are not written again.
    """
    os.ftruncate(fd, end)
    fh = os.fdopen(os.dup(fd), "r+b")
    zf = None
    try:
        fh.seek(end)
        zf = zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_STORED, allowZip64=True)
        zf.filelist[:] = list(entries)
        zf.NameToInfo.update({e.filename: e for e in entries})
        have = {e.filename for e in entries}
        for key, value in meta.items():
            if key + ".npy" not in have:
                zf.writestr(key + ".npy", _npy_bytes(value))
        zf.close()
        fh.flush()
        os.fsync(fh.fileno())
    finally:
        if zf is not None:
            zf.fp = None  # after a failure: the ZipFile must not try again when collected
        try:
            fh.close()
        except OSError:
            pass


def _scalar(meta: dict, key: str, default=None):
    """``meta[key]`` as a Python scalar (values read back from a file are 0-d arrays)."""
    if key not in meta:
        return default
    value = np.asarray(meta[key])
    return value.item() if value.ndim == 0 else value.tolist()


def extent(rows: int, meta: dict, last_row=None) -> dict:
    """``steps_done`` and ``t_final`` that ``rows`` saved states cover.

    Row i of a saved trajectory is the state after ``min(i * save_every, steps)``
    steps, so ``steps_done = min((rows - 1) * save_every, steps)``.

    Parameters
    ----------
    rows : int
        Saved states (the initial one included).
    meta : dict
        The file's metadata as written when it was opened: ``save_every`` (1 when
        absent), ``steps`` (the planned number; no cap when absent), ``h``,
        ``t0`` (0 when absent) and ``time_column`` (the state's physical-time
        coordinate of a time transformation or a time-dependent H; ``""``: none).
    last_row : array_like, optional
        The last saved state, to read ``time_column`` from.

    Returns
    -------
    dict
        ``steps_done``, and ``t_final`` when it follows from the metadata: the
        ``time_column`` of ``last_row``, else ``t0 + h * steps_done`` (a fictive
        step ``h`` of a time transformation gives no physical time: then the
        column is needed).
    """
    every = int(_scalar(meta, "save_every", 1) or 1)
    steps_done = max(int(rows) - 1, 0) * every
    planned = _scalar(meta, "steps")
    if planned is not None:
        steps_done = min(steps_done, int(planned))
    out = {"steps_done": steps_done}
    column = str(_scalar(meta, "time_column", "") or "")
    names = [str(n) for n in (_scalar(meta, "state_names", []) or [])]
    if column:
        if last_row is not None and column in names:
            out["t_final"] = float(np.asarray(last_row).reshape(-1)[names.index(column)])
    elif "h" in meta and not str(_scalar(meta, "time_transform", "") or ""):
        out["t_final"] = float(_scalar(meta, "t0", 0.0)) + float(_scalar(meta, "h")) * steps_done
    return out


def _free_name(path: Path, tag: str):
    """``NAME.TAG.npz``, ``NAME.TAG-2.npz``, … for ``path`` = ``NAME.npz`` (candidates, in order);
    the same with the suffix of ``path`` for another format (``NAME.TAG.h5`` …)."""
    path = Path(path)
    suffix = path.suffix if path.suffix else ".npz"
    stem = path.name[:-len(path.suffix)] if path.suffix else path.name
    for i in range(1, 1000):
        yield path.with_name(f"{stem}.{tag}{suffix}" if i == 1 else f"{stem}.{tag}-{i}{suffix}")


def _place_new(tmp: str, candidates) -> Path:
    """Move ``tmp`` to the first of the paths ``candidates`` where no file is.

    Never over an existing file: ``os.link`` fails instead of replacing (atomic,
    also against another run finishing at the same moment).  Where hard links
    cannot be made (``link()`` fails with anything but EEXIST: vfat, exFAT, SMB,
    FUSE mounts with ENOSYS …) the name is reserved with ``O_CREAT | O_EXCL`` and
    the bytes copied into it (:func:`_copy_new`) — never a rename onto the name, which
    could replace a complete run that took the name in the meantime.  Returns
    where the file went.
    """
    for target in candidates:
        try:
            os.link(tmp, target)
        except FileExistsError:
            continue
        except OSError:  # no hard links here (EPERM, EOPNOTSUPP, ENOSYS, EXDEV …): reserve and copy
            placed = _copy_new(tmp, target)
            if placed is None:
                continue
            os.unlink(tmp)
            return target
        os.unlink(tmp)
        return target
    raise FileExistsError(_errno.EEXIST, "no free name for the file", str(tmp))  # pragma: no cover


def _copy_new(tmp: str, target) -> Path | None:
    """Copy ``tmp`` into ``target`` created for it (``O_EXCL``); None when ``target`` is taken.

    Also None when the reserved file lost its name while being written (a
    complete run renamed itself onto it: that file wins, and this one goes to the
    next free name).  ``tmp`` is left in place (the caller removes it once the
    copy is in place): a process killed during the copy leaves a short file under
    the reserved name — never over another file — and its temporary file, which
    the next ``--save`` into the folder rebuilds (:func:`recover_orphans`).
    """
    try:
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
    except FileExistsError:
        return None
    try:
        with open(tmp, "rb") as src, os.fdopen(os.dup(fd), "wb") as dst:
            while True:
                block = src.read(1 << 20)
                if not block:
                    break
                dst.write(block)
            dst.flush()
            os.fsync(dst.fileno())
        mine = os.fstat(fd)
        try:
            now = os.stat(target)
        except FileNotFoundError:
            return None
        if (now.st_dev, now.st_ino) != (mine.st_dev, mine.st_ino):
            return None
    except BaseException:
        try:   # a half copy must not stay under the name (the temporary file still has it all)
            if (os.stat(target).st_ino, os.stat(target).st_dev) == (os.fstat(fd).st_ino, os.fstat(fd).st_dev):
                os.unlink(target)
        except OSError:
            pass
        raise
    finally:
        os.close(fd)
    return Path(target)


class _LockedTemp:
    """What both chunk writers (this module's ``.npz``, :mod:`methodgen.runtime.trajfile`'s ``.h5``) do
    with their locked temporary file: release the lock after giving up the open file
    (``_abandon_file``, the writer's own), and discard the file altogether."""

    _lock = None
    _tmp = None

    def _abandon_file(self) -> None:   # pragma: no cover - every writer defines it
        raise NotImplementedError

    def _release(self) -> None:
        self._abandon_file()
        if self._lock is not None:
            try:
                os.close(self._lock)
            except OSError:  # pragma: no cover
                pass
            self._lock = None

    def _discard(self) -> None:
        tmp, self._tmp = self._tmp, None
        self._release()
        if tmp:
            try:
                os.unlink(tmp)
            except OSError:
                pass


class ChunkWriter(_LockedTemp):
    """Write a trajectory chunk by chunk into ``path`` (an ``.npz``).

    Parameters
    ----------
    path : path-like
        Final file name (``.npz`` is appended if missing).
    meta : dict, optional
        Metadata arrays written at once (a file rebuilt after a crash has them).
        More can be given to :meth:`close`.  ``save_every``, ``steps``, ``h``,
        ``t0`` and ``time_column`` here let :meth:`close`, :meth:`rescue` and a
        rebuild after a kill record what the rows cover (:func:`extent`).

    Attributes
    ----------
    path : Path
        The requested file; :meth:`close` returns where the file went (another
        name for an incomplete run when ``path`` exists).

    Raises
    ------
    StorageError
        The folder cannot be created or written (``.bad_path``), or the disk is full.
    """

    def __init__(self, path, meta: dict | None = None):
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz")
        self.path = path
        self.chunks = 0
        self.rows = 0
        self._start_meta = dict(meta or {})
        self._last_row = None
        self.failed: StorageError | None = None
        self._good: list = []
        self._good_end = 0
        self._good_rows = 0
        self._meta_keys: set[str] = set()
        self._zip = self._fh = None
        self._lock = None
        self._tmp = None
        self.recovered: list[str] = []
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            # Messages about orphaned saves of killed runs found (and rebuilt) in the folder.
            self.recovered = recover_orphans(path.parent)
            self._lock, self._tmp = make_temp(path.parent, path.name)
            # The zip gets its own descriptor: the lock stays on ``_lock`` whatever
            # happens to the zip's buffered file after a failed write.
            self._fh = open(self._tmp, "r+b")
            self._zip = zipfile.ZipFile(self._fh, "w", compression=zipfile.ZIP_STORED, allowZip64=True)
        except OSError as exc:
            self._discard()
            raise storage_error(exc, "write", path) from None
        try:
            for key, value in (meta or {}).items():
                self._write(key, value, rows=0)
                self._meta_keys.add(key)
        except BaseException:
            self._discard()
            raise

    def _write(self, name: str, array, rows: int) -> None:
        if self.failed is not None:
            raise self.failed
        try:
            with self._zip.open(name + ".npy", "w", force_zip64=True) as fh:
                np.lib.format.write_array(fh, np.asanyarray(array), allow_pickle=False)
            self._fh.flush()  # the entry is in the kernel: a killed process keeps it
        except OSError as exc:
            self.failed = storage_error(exc, "write", self.path)
            raise self.failed from None
        except BaseException:
            # Ctrl-C in the middle of an entry: the zip is unusable, the chunks before are not.
            self.failed = StorageError(f"writing {self.path} was interrupted", self.path, _errno.EINTR)
            raise
        self._good = list(self._zip.filelist)
        self._good_end = self._zip.start_dir
        self._good_rows += rows

    def append(self, states: np.ndarray) -> None:
        """Append consecutive states, shape (n, ...).

        Raises
        ------
        StorageError
            The write failed (e.g. disk full); :meth:`rescue` keeps the chunks before it.
        """
        self._write(f"chunk_{self.chunks:05d}", states, rows=len(states))
        self.chunks += 1
        self.rows += len(states)
        if len(states):
            self._last_row = np.array(states[-1], copy=True)

    @property
    def saved_rows(self) -> int:
        """Rows of the chunks written completely."""
        return self._good_rows

    def _extent(self, meta: dict) -> dict:
        """``meta`` with ``steps_done``/``t_final`` of the complete chunks filled in where not given."""
        return {**extent(self._good_rows, self._start_meta, self._last_row), **meta}

    def close(self, **meta) -> Path:
        """Write metadata arrays, close, and move the file into place; returns where it went.

        ``steps_done`` and ``t_final`` default to what the rows cover (:func:`extent`).
        A run closed with ``complete=False`` (failed, interrupted) replaces no
        file: when :attr:`path` exists it is kept and this file goes to
        ``NAME.partial.npz`` (or ``NAME.partial-2.npz``, …), with a RuntimeWarning.
        After a failed write (disk full) this is :meth:`rescue`.
        """
        if self.failed is not None:
            return self.rescue(**meta)
        meta = self._extent(meta)
        try:
            for key, value in meta.items():
                if key not in self._meta_keys:
                    self._write(key, value, rows=0)
            self._zip.close()
            self._fh.flush()
            os.fsync(self._fh.fileno())
            self._fh.close()
            if bool(meta.get("complete", True)):
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

    def _place_incomplete(self) -> Path:
        """Move the finished temporary file of an incomplete run into place, never over a file."""
        where = _place_new(self._tmp, [self.path, *_free_name(self.path, "partial")])
        if where != self.path:
            warnings.warn(f"{self.path} exists and this run did not complete, so it is kept as it was; "
                          f"the {self._good_rows} states of this run are saved to {where}",
                          RuntimeWarning, stacklevel=4)
        return where

    def rescue(self, **meta) -> Path:
        """Keep every complete chunk after a failed write: cut, finish, move into place.

        The partial chunk is cut off (which frees its space), then the metadata
        (``meta``; dropped if even that does not fit) and the zip directory are
        written and the file is renamed to :attr:`path`.

        The file is marked ``complete = False``, ``reason = "write-error"``, with the
        ``steps_done``/``t_final`` its rows cover; like any incomplete save it
        replaces no existing file (see :meth:`close`).

        Returns
        -------
        Path
            Where the readable ``.npz`` with :attr:`saved_rows` states went.

        Raises
        ------
        StorageError
            Not even the directory could be written; the message says where the
            temporary file with the complete chunks is (the next ``--save`` into
            the same folder rebuilds it).
        """
        self._abandon_zip()
        # What is kept is incomplete (a chunk or the metadata did not fit): say so, count its rows.
        meta = {**meta, **extent(self._good_rows, self._start_meta, self._last_row),
                "complete": False, "reason": "write-error"}
        last = None
        for extra in (meta, {}):
            try:
                _finish_zip(self._lock, self._good, self._good_end, extra)
                where = self._place_incomplete()
            except OSError as exc:
                last = exc
                continue
            self._release()
            return where
        tmp = self._tmp
        self._release()  # unlocked: a later run sees an orphan and rebuilds it
        raise StorageError(f"cannot finish {self.path}: {last.strerror or last}; the {len(self._good)} "
                           f"complete entries are in {tmp} (the next --save into {self.path.parent} "
                           "rebuilds them)", self.path, last.errno)

    def abort(self) -> None:
        """Drop the file (nothing is kept)."""
        self._discard()

    def _abandon_zip(self) -> None:
        if self._zip is not None:
            self._zip.fp = None  # the ZipFile must never write its directory now
            self._zip = None
        if self._fh is not None:
            try:
                self._fh.close()  # may try (and fail) to flush a partial entry: cut off later
            except OSError:
                pass
            self._fh = None

    _abandon_file = _abandon_zip


def load_trajectory(path) -> tuple[np.ndarray, dict]:
    """Read a file written by :class:`ChunkWriter`: ``(states, metadata)``.

    An ``.h5`` trajectory is read by :func:`methodgen.runtime.trajfile.load_trajectory` (both
    formats); given one, this says so.
    """
    try:
        with open(path, "rb") as fh:
            hdf5 = fh.read(8) == b"\x89HDF\r\n\x1a\n"
    except OSError:
        hdf5 = False
    if hdf5:
        raise InputError(f"{path} is an HDF5 trajectory file: read it with "
                         "methodgen.runtime.trajfile.load_trajectory(path), which reads .npz and .h5 files")
    with np.load(path, allow_pickle=False) as data:
        keys = sorted(k for k in data.files if k.startswith("chunk_"))
        states = np.concatenate([data[k] for k in keys]) if keys else np.zeros((0,))
        meta = {k: data[k] for k in data.files if not k.startswith("chunk_")}
    return states, meta


# --- what a killed run leaves ------------------------------------------------------------------

def _complete_entries(fd: int) -> tuple[list, int, int]:
    """The complete ``.npy`` entries at the start of a zip without directory.

    Reads local headers one after the other; an entry counts when its data is
    all there, matches its CRC and is a well-formed ``.npy`` of exactly that
    size.  Returns ``(entries, end offset, rows in chunk_* entries)``.
    """
    fh = os.fdopen(os.dup(fd), "rb")
    entries, pos, rows = [], 0, 0
    try:
        size = os.fstat(fd).st_size
        while pos + 30 <= size:
            fh.seek(pos)
            (sig, version, flags, method, mtime, mdate, crc, csize, usize, nlen, xlen) = \
                struct.unpack("<IHHHHHIIIHH", fh.read(30))
            if sig != _ZIP_LOCAL or method != zipfile.ZIP_STORED or flags & 0x8:
                break
            name = fh.read(nlen).decode("utf-8", "replace")
            extra = fh.read(xlen)
            if 0xFFFFFFFF in (csize, usize):  # zip64: sizes in the extra field (id 1)
                i = 0
                while i + 4 <= len(extra):
                    tag, ln = struct.unpack("<HH", extra[i:i + 4])
                    if tag == 1:
                        vals = list(struct.unpack("<" + "Q" * (ln // 8), extra[i + 4:i + 4 + ln]))
                        if usize == 0xFFFFFFFF and vals:
                            usize = vals.pop(0)
                        if csize == 0xFFFFFFFF and vals:
                            csize = vals.pop(0)
                    i += 4 + ln
            start = pos + 30 + nlen + xlen
            if csize != usize or start + csize > size or not name.endswith(".npy") or csize < 16:
                break
            fh.seek(start)
            head = io.BytesIO(fh.read(min(csize, 1 << 16)))
            try:
                ver = np.lib.format.read_magic(head)
                read = (np.lib.format.read_array_header_1_0 if ver == (1, 0)
                        else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read(head)
            except Exception:  # noqa: BLE001 - anything malformed ends the usable part
                break
            if dtype.hasobject or head.tell() + int(np.prod(shape)) * dtype.itemsize != csize:
                break
            fh.seek(start)
            c, left = 0, csize
            while left:
                block = fh.read(min(left, 1 << 20))
                if not block:
                    break
                c = zlib.crc32(block, c)
                left -= len(block)
            if left or c != crc:
                break
            dt = (((mdate >> 9) & 0x7F) + 1980, max(1, (mdate >> 5) & 0xF), max(1, mdate & 0x1F),
                  (mtime >> 11) & 0x1F, (mtime >> 5) & 0x3F, (mtime & 0x1F) * 2)
            info = zipfile.ZipInfo(name, date_time=dt)
            info.compress_type = zipfile.ZIP_STORED
            info.CRC, info.compress_size, info.file_size = crc, csize, usize
            info.header_offset, info.flag_bits = pos, flags
            info.extract_version = max(version, info.extract_version)
            info.external_attr = 0o600 << 16
            entries.append(info)
            if name.startswith("chunk_") and shape:
                rows += int(shape[0])
            pos = start + csize
    finally:
        fh.close()
    return entries, pos, rows


def _entry_array(fd: int, info: zipfile.ZipInfo) -> np.ndarray:
    """The ``.npy`` array of a complete stored entry (found by :func:`_complete_entries`)."""
    fh = os.fdopen(os.dup(fd), "rb")
    try:
        fh.seek(info.header_offset + 26)
        nlen, xlen = struct.unpack("<HH", fh.read(4))
        fh.seek(info.header_offset + 30 + nlen + xlen)
        return np.lib.format.read_array(io.BytesIO(fh.read(info.compress_size)), allow_pickle=False)
    finally:
        fh.close()


def _rebuilt_meta(fd: int, entries: list, chunks: list, rows: int) -> dict:
    """Metadata of a save rebuilt after a kill: what its complete chunks cover (:func:`extent`)."""
    keys = ("save_every", "steps", "h", "t0", "time_column", "state_names", "time_transform")
    start = {e.filename[:-4]: _entry_array(fd, e) for e in entries if e.filename[:-4] in keys}
    last = _entry_array(fd, chunks[-1])
    last_row = last[-1] if len(last) else None
    return {**extent(rows, start, last_row), "complete": False, "reason": "killed"}


def _fmt_size(n: int) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n} B"  # pragma: no cover


def recover_orphans(folder) -> list[str]:
    """Rebuild or remove the temporary ``.npz`` files of killed runs in ``folder``.

    The complete chunks of an orphan go to ``NAME.recovered.npz`` (or
    ``NAME.recovered-2.npz``, …, never over an existing file), marked
    ``complete = False`` and ``reason = "killed"``, with the ``steps_done`` and
    ``t_final`` its rows cover (:func:`extent`, from the metadata the run wrote
    first: ``save_every``, ``steps``, ``h``, ``time_column``); an orphan without a
    complete chunk is removed.  Temporary files of older methodgen versions
    (no owner in the name, no lock) are only reported; those of ``.h5`` files are
    left to :func:`methodgen.runtime.trajfile.recover_orphans` (which does both).

    Returns
    -------
    list of str
        One message per file found, for the user.
    """
    folder = Path(folder)
    notes = []
    for tmp, name, fd in find_orphans(folder):
        size = 0
        try:
            if not name.endswith(".npz"):
                continue
            size = os.fstat(fd).st_size
            entries, end, rows = _complete_entries(fd)
            chunks = [e for e in entries if e.filename.startswith("chunk_")]
            if not chunks:
                os.unlink(tmp)
                notes.append(f"removed {tmp} ({_fmt_size(size)}): the temporary file of a killed save "
                             "with no complete chunk")
                continue
            _finish_zip(fd, entries, end, _rebuilt_meta(fd, entries, chunks, rows))
            target = _place_new(str(tmp), _free_name(folder / name, "recovered"))
            notes.append(f"recovered {len(chunks)} complete chunks ({rows} states) of a killed save to "
                         f"{name} into {target}; removed {tmp}")
        except OSError as exc:
            notes.append(f"found the temporary file of a killed save, {tmp} ({_fmt_size(size)}), "
                         f"but could not rebuild it: {exc.strerror or exc}")
        finally:
            os.close(fd)
    legacy = re.compile(r"^\.(?P<name>.+\.npz)\.[a-z0-9_]{8}\.tmp$")
    try:
        others = sorted(folder.iterdir())
    except OSError:
        others = []
    for p in others:
        if legacy.match(p.name) and not _temp_re().match(p.name):
            try:
                size = p.stat().st_size
            except OSError:
                continue
            notes.append(f"{p} ({_fmt_size(size)}) looks like the temporary file of an unfinished save "
                         "by an older methodgen; it is not readable as it is — delete it if no run is "
                         "writing it")
    return notes
