"""A disk cache of the machine code :mod:`methodgen.codegen.llvmkernels` compiles.

A compiled module's kernels and its fused loop are translated to LLVM IR and compiled in
every process (for a cached Kepler energy-momentum module about 0.2 s: the translation in
Python, LLVM's -O2 pipeline, code generation) -- most of a warm start.  This cache keeps the object code, so a later process adds it to its engine
without translating or optimising anything.

**What a cached object is for** (its key, SHA-256 of all of it): for a generated kernel, the
digest of its kernel IR (:mod:`methodgen.codegen.kir`: the tree its machine code is printed from,
which the module holds as data; its text is never read); for methodgen's own runtime (the
stepper, the Wisdom–Holman flows), the text of the file it was executed from (verified against
its code: :mod:`methodgen.codegen.kernelsource`); the kernel's name, line and signature,
the translation-time constants a fused loop binds (values, and for functions their IR's digest
or the text of their file), the C-entry flag and LLVM pipeline options; the SHA-256 of the
translator, the IR's printer, the types and the runtime's interface (``llvmkernels.py``, ``kir.py``,
``ktypes.py``, ``nbabi.py``);
llvmlite's and LLVM's versions; the target triple, the host CPU's name and features.  Anything
else a kernel could depend on makes it uncacheable (:func:`key` returns None: compiled as before).

**Trust.** Object code is executable, so it is read only from the per-user cache
(``$METHODGEN_CACHE`` or the XDG cache, ``llvm/`` in it) under the rules of the module
cache (:func:`methodgen.codegen.store.check_cache_folder`: folders of this user that others cannot
write to) and only with the HMAC-SHA256 tag of the user's cache key (the key that tags
cached modules).  A file without a valid tag, or any error reading or writing, means no
cache: the kernel is compiled as if there were none (never an error, never a stale load).
``METHODGEN_LLVM_CACHE=0`` turns the cache off.  The folder is kept bounded: a store
removes temporary files of killed writers and, past ``_MAX_OBJECTS`` objects, the least
recently used ones.
"""

from __future__ import annotations

import hashlib
import hmac
import os
import tempfile

from . import kernelsource as _ks

__all__ = ["key", "load", "store", "enabled"]

_MAGIC = b"methodgen-llvm-object-v2\n"
#: objects kept: past _MAX_OBJECTS a store removes the least recently used down to _KEEP_OBJECTS
#: (a load touches its file), so edited and regenerated modules do not grow the folder forever
_MAX_OBJECTS = 4096
_KEEP_OBJECTS = 2048
#: a temporary file older than this (seconds) is a killed writer's: removed by the next store
_ORPHAN_AGE = 600.0
_TAG_LEN = 64          # hex HMAC-SHA256
_STATIC: list = []


def enabled() -> bool:
    """The cache is used unless ``METHODGEN_LLVM_CACHE=0``."""
    return os.environ.get("METHODGEN_LLVM_CACHE", "1").strip() != "0"


def _static(state) -> str:
    """What every key shares: translator, runtime, llvmlite/LLVM versions, host target."""
    if not _STATIC:
        import llvmlite
        import llvmlite.binding as llvm

        package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        parts = [llvmlite.__version__, ".".join(map(str, llvm.llvm_version_info)), state["triple"],
                 state["cpu"], state["features"]]
        for name in ("codegen/llvmkernels.py", "codegen/kir.py", "codegen/ktypes.py", "runtime/nbabi.py",
                     "codegen/llvmcache.py"):
            with open(os.path.join(package, *name.split("/")), "rb") as f:
                parts.append(hashlib.sha256(f.read()).hexdigest())
        _STATIC.append("\0".join(parts))
    return _STATIC[0]


def _function_part(fn) -> str | None:
    # a generated kernel: the digest of its kernel IR (methodgen.codegen.kir; its text is never
    # read); methodgen's own runtime: the digest of the text the function was executed from
    # (never a re-read file or linecache's copy): see methodgen.codegen.kernelsource
    py = getattr(fn, "py_func", fn)
    tree_digest = getattr(py, "__kir_digest__", None)
    if tree_digest is not None:
        return f"kir:{tree_digest}"
    digest = _ks.cache_digest(fn)
    return None if digest is None else f"fn:{digest}"


def _value_part(value) -> str | None:
    import types

    import numpy

    if value is None or type(value) in (bool, int, float, str):
        return f"{type(value).__name__}:{value!r}"
    if isinstance(value, numpy.ndarray):
        return f"array:{value.dtype.str}:{value.shape}:{hashlib.sha256(value.tobytes()).hexdigest()}"
    if isinstance(value, types.ModuleType):
        return f"module:{value.__name__}"
    return _function_part(value)


def key(py_func, sig, globals_, c_entry, state, options: str = "") -> str | None:
    """The cache key of this compilation (hex SHA-256), or None when it cannot be cached.
    ``options``: the compilation's other options as text (LLVM's pipeline settings), if any."""
    if not enabled():
        return None
    try:
        fn = _function_part(py_func)
        if fn is None:
            return None
        parts = [_static(state), fn, str(sig), f"c_entry:{bool(c_entry)}"]
        if options:
            parts.append(f"options:{options}")
        if globals_ is not None:
            for name in sorted(globals_):
                v = _value_part(globals_[name])
                if v is None:
                    return None
                parts.append(f"{name}={v}")
    except (OSError, TypeError, ValueError):
        return None
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()


def _folder_and_key(create: bool):
    """(the cache's llvm/ folder, the user's cache key), or None where the cache cannot be
    trusted or used."""
    from . import store
    from ..errors import StorageError, UntrustedCacheError

    try:
        root = store.cache_dir()
        folder = root / "llvm"
        if create:
            root.mkdir(mode=0o700, parents=True, exist_ok=True)
            folder.mkdir(mode=0o755, exist_ok=True)
        if not folder.is_dir():
            return None
        root = root.resolve()
        store._check_folder(root)
        store._check_folder(folder)
        secret = store._cache_key(root, create=create)
    except (OSError, RuntimeError, StorageError, UntrustedCacheError):
        return None
    if secret is None:
        return None
    return folder, secret


def _tag(secret: bytes, key_: str, name: str, obj: bytes) -> bytes:
    # the whole key is tagged with the object: an object stored under one key and moved to
    # another's file name (a swapped or planted file) does not verify
    return hmac.new(secret, _MAGIC + key_.encode() + b"\0" + name.encode() + b"\0" + obj,
                    hashlib.sha256).hexdigest().encode()


def load(key_: str, name: str) -> bytes | None:
    """The object code stored under ``key_`` for the symbol ``name``, if present and tagged
    with the user's key; else None."""
    where = _folder_and_key(create=False)
    if where is None:
        return None
    folder, secret = where
    try:
        with open(folder / f"{key_}.o", "rb") as f:
            data = f.read()
    except OSError:
        return None
    if not data.startswith(_MAGIC) or len(data) < len(_MAGIC) + _TAG_LEN + 1:
        return None
    tag = data[len(_MAGIC):len(_MAGIC) + _TAG_LEN]
    obj = data[len(_MAGIC) + _TAG_LEN + 1:]
    if not hmac.compare_digest(tag, _tag(secret, key_, name, obj)):
        return None
    try:
        os.utime(folder / f"{key_}.o")          # recently used: kept by the pruning in store()
    except OSError:
        pass
    return obj


def _tidy(folder) -> None:
    """Remove killed writers' temporary files, and the least recently used objects past
    _MAX_OBJECTS (down to _KEEP_OBJECTS)."""
    import time

    now = time.time()
    objects = []
    try:
        with os.scandir(folder) as it:
            for e in it:
                try:
                    if e.name.startswith(".tmp-"):
                        if now - e.stat().st_mtime > _ORPHAN_AGE:
                            os.unlink(e.path)
                    elif e.name.endswith(".o"):
                        objects.append((e.stat().st_mtime, e.path))
                except OSError:
                    pass
    except OSError:
        return
    if len(objects) > _MAX_OBJECTS:
        objects.sort()
        for _, path in objects[:len(objects) - _KEEP_OBJECTS]:
            try:
                os.unlink(path)
            except OSError:
                pass


def store(key_: str, name: str, obj: bytes) -> None:
    """Keep ``obj`` under ``key_`` (atomically; nothing on any error)."""
    where = _folder_and_key(create=True)
    if where is None:
        return
    folder, secret = where
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".tmp-", suffix=".o")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(_MAGIC + _tag(secret, key_, name, obj) + b"\n" + obj)
            os.replace(tmp, folder / f"{key_}.o")
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
    except OSError:
        return
    _tidy(folder)

