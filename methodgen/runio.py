"""Trajectories on disk: chunked ``.npz`` files written atomically.

A long run need not fit in memory: :class:`ChunkWriter` appends arrays as
separate entries (``chunk_00000``, ``chunk_00001``, …) of one ``.npz`` (a zip
of ``.npy`` files), written to a temporary file and renamed into place when
closed, so a crash never leaves a truncated file under the final name.
:func:`load_trajectory` concatenates the chunks again.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["ChunkWriter", "load_trajectory"]


class ChunkWriter:
    """Write a trajectory chunk by chunk into ``path`` (an ``.npz``).

    Parameters
    ----------
    path : path-like
        Final file name (``.npz`` is appended if missing).
    """

    def __init__(self, path):
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz")
        self.path = path
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, self._tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=str(path.parent))
        os.close(fd)
        self._zip = zipfile.ZipFile(self._tmp, "w", compression=zipfile.ZIP_STORED, allowZip64=True)
        self.chunks = 0
        self.rows = 0

    def _put(self, name: str, array) -> None:
        with self._zip.open(name + ".npy", "w", force_zip64=True) as fh:
            np.lib.format.write_array(fh, np.asanyarray(array), allow_pickle=False)

    def append(self, states: np.ndarray) -> None:
        """Append consecutive states, shape (n, ...)."""
        self._put(f"chunk_{self.chunks:05d}", states)
        self.chunks += 1
        self.rows += len(states)

    def close(self, **meta) -> Path:
        """Write metadata arrays, close, and move the file into place; returns its path."""
        for key, value in meta.items():
            self._put(key, np.asarray(value))
        self._zip.close()
        os.replace(self._tmp, self.path)
        return self.path

    def abort(self) -> None:
        try:
            self._zip.close()
        finally:
            if os.path.exists(self._tmp):
                os.unlink(self._tmp)


def load_trajectory(path) -> tuple[np.ndarray, dict]:
    """Read a file written by :class:`ChunkWriter`: ``(states, metadata)``."""
    with np.load(path, allow_pickle=False) as data:
        keys = sorted(k for k in data.files if k.startswith("chunk_"))
        states = np.concatenate([data[k] for k in keys]) if keys else np.zeros((0,))
        meta = {k: data[k] for k in data.files if not k.startswith("chunk_")}
    return states, meta
