"""The cache stamp of methodgen's compiled runtimes: their machine code is current only if
their source's SHA-256 is.

numba decides whether a cached function is current from a stamp of its source file: a
content hash in recent numba, (mtime, size) in older ones, where an edit that keeps both
would load stale machine code.  :func:`install_stamp_guard` replaces the stamp of one file
by its content hash.  Kept apart from :mod:`methodgen.runtime.nbruntime` so that the guard can be
installed (and tested) without compiling or loading the runtime itself.

A generated module that may never use numba (a cached module on its fused loop) defers its
guard (:func:`defer_stamp_guard`); :func:`numba` -- the one door through which methodgen's
lazy paths import numba -- installs the deferred guards before numba is returned, so no
function of such a module is compiled or loaded from numba's cache without its guard.

This module imports the standard library only (numba when a guard is installed).
"""

from __future__ import annotations

import hashlib
import os
import sys
import threading

__all__ = ["source_digest", "install_stamp_guard", "defer_stamp_guard", "numba"]

_DEFERRED: list = []
_LOCK = threading.Lock()


def source_digest(path: str) -> str:
    """SHA-256 (hex) of the bytes of the file ``path``."""
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def install_stamp_guard(path: str, digest: str, *, owner: str = "methodgen.runtime.nbruntime",
                        tag: str | None = None) -> None:
    """Make numba stamp the cache of the functions of the file ``path`` with ``digest``.

    numba decides whether a cached function is current from a stamp of its
    source file: a content hash in recent numba, (mtime, size) in older ones,
    where an edit that keeps both would load stale machine code.  The locators
    registered here (in front of numba's own, for this file only) keep numba's
    choice of folder and replace the stamp by ``(owner, digest)``.

    Parameters
    ----------
    path : str
        Absolute path of the source file.
    digest : str
        Its content hash (taken from the bytes that were imported).
    owner : str
        First element of the stamp.
    tag : str, optional
        Appended to numba's disambiguator (the function's line number), so the
        cache files of this file's functions are this tag's own.  numba records the
        importing module's name in a cached function's environment and imports that
        module by name when it loads the function; a file imported under two names
        (methodgen's loader gives each generated module a private name, a user may
        import the same file by its plain name) needs one cache entry per name, or
        the second name's process loads an entry that refers to a module it cannot
        import.
    """
    from numba.core import caching

    bases = []
    for name in ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator"):
        base = getattr(caching, name, None) or getattr(caching, "_" + name, None)
        if base is not None:
            bases.append(base)
    guarded = []
    for base in bases:
        def from_function(cls, py_func, py_file, _base=base):
            if os.path.abspath(py_file) != path:
                return None
            return _base.from_function.__func__(cls, py_func, py_file)

        methods = {"get_source_stamp": lambda self: (owner, digest), "from_function": classmethod(from_function)}
        if tag:
            methods["get_disambiguator"] = lambda self, _base=base: f"{_base.get_disambiguator(self)}-{tag}"
        guarded.append(type("Guarded" + base.__name__.lstrip("_"), (base,), methods))
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl")
    impl._locator_classes = [c for c in guarded] + [
        c for c in impl._locator_classes if getattr(c, "_methodgen_path", None) != path]
    for c in guarded:
        c._methodgen_path = path


def defer_stamp_guard(path: str, digest: str, *, owner: str = "methodgen.runtime.nbruntime",
                      tag: str | None = None) -> None:
    """:func:`install_stamp_guard` now if numba is imported, else when :func:`numba` first
    imports it."""
    with _LOCK:
        if sys.modules.get("numba") is None:
            _DEFERRED.append((path, digest, owner, tag))
            return
    install_stamp_guard(path, digest, owner=owner, tag=tag)


def numba():
    """The numba module, imported on first call, with every deferred guard installed.

    Raises
    ------
    ImportError
        numba is not installed: the compiled backend needs it only for a kernel the LLVM
        translator refuses (or ``METHODGEN_KERNELS=numba``), and says so.
    """
    try:
        import numba as nb
    except ImportError:
        raise ImportError("numba is needed here: a kernel uses a construct methodgen's LLVM translator does not "
                          "know (or METHODGEN_KERNELS=numba asks for numba); install it with pip install numba "
                          "(or \"methodgen[numba]\"), or use backend=\"numpy\"") from None

    flush_deferred()
    return nb


def flush_deferred() -> None:
    """Install the guards :func:`defer_stamp_guard` kept (numba is imported by the caller)."""
    with _LOCK:
        pending = list(_DEFERRED)
        _DEFERRED.clear()
    for path, digest, owner, tag in pending:
        install_stamp_guard(path, digest, owner=owner, tag=tag)
