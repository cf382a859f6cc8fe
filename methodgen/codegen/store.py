"""Where generated modules live on disk, and whose they are: the per-user cache and its trust.

Generated modules are written atomically (:func:`write_atomic`); in the per-user cache
(:func:`cache_dir`) a module's first line is an HMAC of its text under the user's secret key
(:func:`write_module`), and a folder others could write to is refused
(:func:`check_cache_folder`), so that no one else can plant code methodgen will import.
:mod:`methodgen.codegen.emit` checks those tags when it loads a module; :mod:`methodgen.codegen.llvmcache`
keys its machine code the same way.  Every file methodgen writes goes through a temporary
file that says who wrote it (:func:`make_temp`: locked while its writer lives, so a later run
tells an orphan from a live file, :func:`find_orphans`); the trajectory files of
:mod:`methodgen.runtime.runio` use the same.  This module imports the standard library only.
"""

from __future__ import annotations

import errno
import hashlib
import hmac
import os
import re
import secrets
import socket
import stat
import tempfile
import time
from pathlib import Path

from ..errors import StorageError, UntrustedCacheError

try:  # POSIX; elsewhere temporary files are not locked and orphans are only reported
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

__all__ = ["cache_dir", "write_atomic", "cache_root_of", "check_cache_folder", "untagged", "write_module",
           "HEADER_KEYED", "KEY_FILE", "storage_error", "make_temp", "find_orphans", "umask"]

#: First line of a module in the per-user cache only (never in generated/): HMAC-SHA256 of
#: the rest of the file and its name under the user's secret key (see
#: :func:`methodgen.codegen.emit.file_status`).
HEADER_KEYED = "# methodgen-hmac-sha256: "
#: The per-user secret, in the cache root (mode 0600).
KEY_FILE = ".methodgen-key"


def cache_dir() -> Path:
    """Per-user cache for generated modules (``$METHODGEN_CACHE`` or the XDG cache)."""
    env = os.environ.get("METHODGEN_CACHE")
    if env:
        # "~/x" is the home folder's x (as a shell would expand it), never a folder named "~".
        try:
            return Path(env).expanduser()
        except RuntimeError as exc:   # "~nosuchuser/x": pathlib cannot find that home folder
            raise StorageError(f"METHODGEN_CACHE={env}: cannot expand ~ ({exc}: no such user, or no "
                               "home folder); give the cache folder without ~", path=env, errno=errno.ENOENT) from None
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "methodgen"


# --- temporary files that say who wrote them ----------------------------------------------

#: A temporary file younger than this and still empty may be between its creation
#: and its lock (``mkstemp`` then ``flock``): never judged an orphan.
_FRESH_SECONDS = 60.0

def storage_error(exc: OSError, action: str, path) -> StorageError:
    """``exc`` as a one-line :class:`StorageError`: ``cannot ACTION PATH: cause``."""
    if isinstance(exc, StorageError):
        return exc
    cause = exc.strerror or str(exc) or type(exc).__name__
    if exc.errno in (errno.ENOTDIR, errno.EEXIST):
        blocker = None
        for parent in Path(path).parents:
            try:
                if parent.exists():
                    blocker = None if parent.is_dir() else parent
                    break
            except OSError:
                break
        if blocker is not None:
            cause = f"{blocker} is a file, not a folder"
        elif exc.errno == errno.ENOTDIR:
            cause += " (a part of the path is a file, not a folder)"
    elif exc.errno in (errno.EACCES, errno.EPERM):
        cause += " (no permission)"
    return StorageError(f"cannot {action} {path}: {cause}", path, exc.errno)


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", socket.gethostname() or "host")[:40] or "host"


def _temp_re(name: str | None = None) -> re.Pattern:
    target = re.escape(name) if name is not None else r"(?P<name>.+)"
    return re.compile(r"^\." + target + r"\.(?P<host>[A-Za-z0-9_]+)-(?P<pid>\d+)\.[A-Za-z0-9_]+\.tmp$")


def umask() -> int:
    """The process umask (read from /proc where possible: setting it to read it is not thread-safe)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    old = os.umask(0o022)
    os.umask(old)
    return old


def make_temp(folder: Path, name: str) -> tuple[int, str]:
    """Create and lock a temporary file for ``folder/name``: ``(fd, path)``.

    The name ``.NAME.HOST-PID.XXXXXXXX.tmp`` says which file it becomes and who
    writes it; the ``flock`` held on ``fd`` until it is closed tells a later run
    that the writer is alive (the kernel drops the lock when a process dies,
    also on SIGKILL).  The file gets ordinary permissions (0644 less the umask;
    ``mkstemp`` alone would leave it 0600).
    """
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.{_host()}-{os.getpid()}.", suffix=".tmp", dir=str(folder))
    try:
        os.fchmod(fd, 0o644 & ~umask())
    except (OSError, AttributeError):  # pragma: no cover - file systems or platforms without modes
        pass
    if fcntl is not None:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # pragma: no cover - a file system without locks: still usable
            pass
    return fd, tmp


def find_orphans(folder: Path, name: str | None = None):
    """Temporary files in ``folder`` whose writer is gone: yields ``(path, target name, fd)``.

    ``fd`` is an open descriptor holding the file's lock (so no other run
    claims the same orphan); the caller removes or rebuilds the file and
    closes ``fd``.  Files of other hosts (a shared file system), files still
    locked by their writer, and fresh empty files are left alone.
    """
    if fcntl is None:  # pragma: no cover - cannot tell orphans from live files
        return
    pattern = _temp_re(name)
    try:
        entries = sorted(Path(folder).iterdir())
    except OSError:
        return
    host = _host()
    for p in entries:
        m = pattern.match(p.name)
        if not m or m.group("host") != host:
            continue
        try:
            fd = os.open(p, os.O_RDWR | getattr(os, "O_NOFOLLOW", 0))
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            st = os.fstat(fd)
            if st.st_size == 0 and time.time() - st.st_mtime < _FRESH_SECONDS:
                raise BlockingIOError  # maybe between mkstemp and flock
            if not os.path.exists(p) or os.stat(p).st_ino != st.st_ino:
                raise BlockingIOError  # renamed into place or replaced meanwhile
        except OSError:
            os.close(fd)
            continue
        yield p, (name if name is not None else m.group("name")), fd


# --- files --------------------------------------------------------------------

def write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file + ``os.replace``).

    The file gets ordinary permissions (0644 less the umask).  The temporary
    file ``.NAME.HOST-PID.XXXXXXXX.tmp`` is locked while it exists, so the
    leftover of a killed process can be recognised (:func:`find_orphans`).

    Raises
    ------
    StorageError
        One line naming ``path`` and the cause (disk full, no permission, a
        missing folder or a file in the way); also an ``OSError``.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = make_temp(path.parent, path.name)
    except OSError as exc:
        raise storage_error(exc, "write", path) from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
            os.replace(tmp, path)  # still locked: never taken for an orphan
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise storage_error(exc, "write", path) from None
        raise


# --- the per-user cache: who wrote a file ---------------------------------------

def cache_root_of(path) -> Path | None:
    """The cache root (resolved) when ``path`` lies in the per-user cache, else None."""
    try:
        root = cache_dir().resolve()
        Path(path).resolve().relative_to(root)
    except (ValueError, OSError, RuntimeError):
        return None
    return root


def _check_folder(folder: Path) -> None:
    try:
        st = os.stat(folder)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise storage_error(exc, "use cache folder", folder) from None
    if not stat.S_ISDIR(st.st_mode):
        raise StorageError(f"cannot use cache folder {folder}: it is not a folder", folder, errno.ENOTDIR)
    if os.name == "nt":  # pragma: no cover - no POSIX owners and modes to check
        return
    uid = os.geteuid() if hasattr(os, "geteuid") else None
    if uid is not None and st.st_uid != uid:
        raise UntrustedCacheError(
            f"cache folder {folder} belongs to uid {st.st_uid}, not to you (uid {uid}); methodgen does "
            "not import code from a folder someone else controls — set METHODGEN_CACHE to a folder of "
            "your own")
    if st.st_mode & 0o022:
        who = " and ".join(w for w, bit in (("group", 0o020), ("others", 0o002)) if st.st_mode & bit)
        raise UntrustedCacheError(
            f"cache folder {folder} is writable by {who} (mode {stat.S_IMODE(st.st_mode):04o}); methodgen "
            f"does not import code from a folder others can write to — run: chmod go-w {folder} "
            "(or set METHODGEN_CACHE to a private folder)")


def check_cache_folder(path) -> Path | None:
    """Refuse a cache others could plant code in; no-op outside the cache.

    For a ``path`` in the per-user cache, the cache root, the file's folder and
    its ``__pycache__`` (compiled code could be planted there) must belong to the
    user and not be writable by group or others — the rule of ssh's
    ``StrictModes`` and pip's cache.  Below a root that others cannot even
    enter (mode ``0700``), nothing else needs checking.

    Returns
    -------
    Path or None
        The cache root, or None when ``path`` is not in the cache.

    Raises
    ------
    UntrustedCacheError
        A folder that is not the user's or is group/other-writable.
    """
    root = cache_root_of(path)
    if root is None:
        return None
    _check_folder(root)
    try:
        closed = not (os.stat(root).st_mode & 0o011)
    except OSError:
        closed = False
    if not closed:
        folder = Path(path).resolve().parent
        for d in ([folder] if folder != root else []) + [folder / "__pycache__"]:
            _check_folder(d)
    return root


def _read_key(keyfile: Path) -> bytes | None:
    try:
        fd = os.open(keyfile, os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0))
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise UntrustedCacheError(f"cannot read the cache key {keyfile}: {exc.strerror or exc} (a "
                                  "symbolic link or no permission); remove it to get a new one") from None
    try:
        st = os.fstat(fd)
        data = os.read(fd, 256)
    finally:
        os.close(fd)
    uid = os.geteuid() if hasattr(os, "geteuid") else st.st_uid
    private = os.name == "nt" or (st.st_uid == uid and not st.st_mode & 0o077)
    if not stat.S_ISREG(st.st_mode) or not private:
        raise UntrustedCacheError(
            f"cache key {keyfile} is not a private file of yours (mode {stat.S_IMODE(st.st_mode):04o}, uid "
            f"{st.st_uid}); anyone who can read it can forge cached modules — remove it (a new key is "
            "made and the cache regenerated)")
    try:
        key = bytes.fromhex(data.decode("ascii").strip())
    except (UnicodeDecodeError, ValueError):
        key = b""
    if len(key) < 32:
        raise UntrustedCacheError(f"cache key {keyfile} is damaged; remove it (a new key is made and the "
                                  "cache regenerated)")
    return key


def _cache_key(root: Path, create: bool) -> bytes | None:
    """The user's secret key of the cache ``root``; made (0600, atomically) on first use if ``create``."""
    keyfile = root / KEY_FILE
    key = _read_key(keyfile)
    if key is not None or not create:
        return key
    try:
        fd, tmp = make_temp(root, KEY_FILE)
    except OSError as exc:
        raise storage_error(exc, "create the cache key in", root) from None
    try:
        if hasattr(os, "fchmod"):
            os.fchmod(fd, 0o600)
        os.write(fd, (secrets.token_hex(32) + "\n").encode("ascii"))
        os.fsync(fd)
        try:
            os.link(tmp, keyfile)  # atomic and never over a key another process made first
        except FileExistsError:
            pass
        except OSError:  # pragma: no cover - no hard links here: rename (last writer wins)
            if not keyfile.exists():
                os.replace(tmp, keyfile)
    except OSError as exc:
        raise storage_error(exc, "create the cache key", keyfile) from None
    finally:
        os.close(fd)
        try:
            os.unlink(tmp)
        except OSError:
            pass
    return _read_key(keyfile)


def _keyed_tag(key: bytes, name: str, text: str) -> str:
    return hmac.new(key, b"methodgen-module-v1\0" + name.encode() + b"\0" + text.encode(),
                    hashlib.sha256).hexdigest()


def untagged(text: str) -> str:
    """A module's text without the cache-only key line (what :func:`render` emitted)."""
    return text.partition("\n")[2] if text.startswith(HEADER_KEYED) else text


def write_module(path, text: str) -> None:
    """Write a generated module; in the per-user cache, with the user's key tag.

    Outside the cache (``generated/``, a path of the user's choosing) the bytes
    are exactly ``text`` (deterministic, committable).  In the cache the
    folder is checked (:func:`check_cache_folder`), the key made on first use,
    temporary files of killed writers removed, and the first line becomes
    ``# methodgen-hmac-sha256: …``.

    Raises
    ------
    StorageError, UntrustedCacheError
    """
    path = Path(path)
    text = untagged(text)
    root = cache_root_of(path)
    if root is not None:
        if not root.exists():
            try:
                root.mkdir(mode=0o700, parents=True, exist_ok=True)
            except OSError as exc:
                raise storage_error(exc, "create cache folder", root) from None
        check_cache_folder(path)
        key = _cache_key(root, create=True)
        try:
            path.parent.mkdir(mode=0o755, parents=True, exist_ok=True)
        except OSError as exc:
            raise storage_error(exc, "create cache folder", path.parent) from None
        for orphan, _, fd in find_orphans(path.parent, path.name):
            try:
                os.unlink(orphan)  # the temporary file of a killed generation: nothing to keep
            except OSError:
                pass
            finally:
                os.close(fd)
        text = HEADER_KEYED + _keyed_tag(key, path.name, text) + "\n" + text
    write_atomic(path, text)
