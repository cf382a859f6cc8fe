"""Exception hierarchy of methodgen.

Every error a user can provoke with bad input is a :class:`MethodgenError`; the
CLI turns these into a one-line message and a non-zero exit status, never a
traceback.  Errors raised *inside generated modules* are defined in the module
itself (generated code must not import methodgen), but they carry the same
names so that ``except module.ConvergenceError`` reads naturally.
"""

from __future__ import annotations


class MethodgenError(Exception):
    """Base class of every error methodgen raises on purpose."""


class InputError(MethodgenError, ValueError):
    """Bad user input: a Hamiltonian, a scene file, an initial value, a step size."""


class ParseError(InputError):
    """Expression text that is not in the accepted grammar."""


class SceneError(InputError):
    """A scene file that cannot be read or does not follow the scene format."""


class MethodNotApplicable(InputError):
    """A method was asked for a system it does not apply to."""


class NumericalError(MethodgenError, RuntimeError):
    """A computation methodgen runs itself failed on valid input (a reference solution that did
    not reach its end): exit status 3 on the command line, like a Newton failure."""


class GenerationError(MethodgenError):
    """Code generation failed or a generated file cannot be trusted."""


import errno as _errno  # noqa: E402 - used by the classes below only

#: errno values meaning "this path cannot be used" (a bad path: exit status 2 on the command
#: line), as opposed to faults of the running system such as a full disk (exit status 3).
BAD_PATH_ERRNOS = frozenset(getattr(_errno, name) for name in (
    "EACCES", "EPERM", "ENOENT", "ENOTDIR", "EISDIR", "EEXIST", "ENAMETOOLONG", "ELOOP", "EROFS")
    if hasattr(_errno, name))


class StorageError(MethodgenError, OSError):
    """A file or folder could not be read or written.

    Also an :class:`OSError` (``.errno`` is the cause), so ``except OSError`` keeps
    working.  ``.path`` names the file; :attr:`bad_path` is True when the path itself
    cannot be used (missing folder, no permission, a file where a folder should be,
    read-only file system) and False for a fault of the running system (disk full,
    quota exceeded, I/O error).
    """

    def __init__(self, message: str, path=None, errno: int | None = None):
        OSError.__init__(self, errno, message)
        self.message, self.path = message, None if path is None else str(path)

    def __str__(self) -> str:
        return self.message

    def __reduce__(self):  # picklable (Dask ships exceptions between processes)
        return type(self), (self.message, self.path, self.errno)

    @property
    def bad_path(self) -> bool:
        return self.errno in BAD_PATH_ERRNOS


class UntrustedCacheError(GenerationError):
    """The module cache cannot be trusted: a folder others can write to or that is not
    the user's own, or a key file others can read.  Nothing is imported from it."""
