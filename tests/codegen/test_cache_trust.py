"""Trust in the module cache (issue 13, item 5): a cached module is imported only if this
user's methodgen wrote it; folders others can write to are refused; negative controls show
that an intact file is used as it is."""

from __future__ import annotations

import hashlib
import importlib.util
import os
import stat
import sys
import warnings
from pathlib import Path

import pytest

import methodgen as mg
from methodgen.codegen.emit import (HEADER_CONTENT, HEADER_KEYED, KEY_FILE, emit_source, file_status, load_module,
                            signature, untagged, write_module)
from methodgen.errors import GenerationError, UntrustedCacheError

QUARTIC = mg.Hamiltonian("p**2/2 + q**4/4", q=["q"], p=["p"], name="quartic")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    root = tmp_path / "cache"
    monkeypatch.setenv("METHODGEN_CACHE", str(root))
    return root


@pytest.fixture
def marker(tmp_path):
    return tmp_path / "PAYLOAD_RAN"


def built(cache) -> Path:
    mod = mg.build(QUARTIC, "midpoint")
    path = Path(mod.__file__)
    assert path.parent == cache.resolve()
    return path


def plant(path: Path, marker: Path, keep_tag: bool = False) -> None:
    """What an attacker does: add a payload and recompute the plain content hash."""
    text = path.read_text()
    tag, plain = text.split("\n", 1)
    assert tag.startswith(HEADER_KEYED)
    body = plain.split("\n", 1)[1] + f"\nopen({str(marker)!r}, 'w').write('pwned')\n"
    planted = HEADER_CONTENT + hashlib.sha256(body.encode()).hexdigest() + "\n" + body
    path.write_text((tag + "\n" if keep_tag else "") + planted)
    assert file_status(path) == "untrusted"


def no_runtime_warnings(fn, *a):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = fn(*a)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
    return out


# --- the planted module ---------------------------------------------------------------------------

@pytest.mark.parametrize("keep_tag", [False, True], ids=["tag-removed", "old-tag-kept"])
def test_planted_module_with_recomputed_plain_hash_never_runs(cache, marker, keep_tag):
    """Was: mg.build imported it and ran the payload with no warning."""
    path = built(cache)
    plant(path, marker, keep_tag)
    with pytest.warns(RuntimeWarning, match="not written by this user's methodgen"):
        mod = mg.build(QUARTIC, "midpoint")
    assert not marker.exists()
    assert Path(mod.__file__) == path and file_status(path, mod.SIGNATURE) == "ok"
    assert "PAYLOAD" not in path.read_text()
    # Loading the planted file directly is refused as well.
    plant(path, marker, keep_tag)
    with pytest.raises(GenerationError, match="not written by this user's methodgen"):
        load_module(path)
    assert not marker.exists()


def test_intact_cache_file_is_imported_without_regeneration(cache, monkeypatch):
    """Negative control: the check does not fire on a file this user's methodgen wrote."""
    path = built(cache)
    mtime = path.stat().st_mtime_ns

    def boom(*a, **k):
        raise AssertionError("re-derived although the cached file is intact")

    monkeypatch.setattr(sys.modules["methodgen.symbolic.schemes"], "discretize", boom)  # build imports it on the cold path
    mod = no_runtime_warnings(mg.build, QUARTIC, "midpoint")
    assert Path(mod.__file__) == path and path.stat().st_mtime_ns == mtime


def test_a_file_tagged_under_another_key_is_regenerated(cache, marker):
    """Another user's (or a stolen old) key: the tag does not verify."""
    path = built(cache)
    key = cache / KEY_FILE
    key.write_text("ab" * 32 + "\n")
    os.chmod(key, 0o600)
    assert file_status(path) == "untrusted"
    with pytest.warns(RuntimeWarning, match="not written by this user's methodgen"):
        mg.build(QUARTIC, "midpoint")
    assert file_status(path) == "ok"


def test_tag_is_bound_to_the_file_name(cache):
    path = built(cache)
    other = path.with_name("other_" + path.name)
    other.write_bytes(path.read_bytes())
    assert file_status(path) == "ok" and file_status(other) == "untrusted"


def test_no_bytecode_is_trusted_instead_of_the_checked_source(cache, marker):
    """A .pyc matching the source's mtime and size would be run by a plain import; not by load_module."""
    path = built(cache)
    payload = compile(f"open({str(marker)!r}, 'w').write('pwned')\n", str(path), "exec")
    st = path.stat()
    from importlib._bootstrap_external import _code_to_timestamp_pyc
    pyc = Path(importlib.util.cache_from_source(str(path)))
    pyc.parent.mkdir(exist_ok=True)
    pyc.write_bytes(bytes(_code_to_timestamp_pyc(payload, int(st.st_mtime), st.st_size)))
    mod = load_module(path)
    assert not marker.exists() and mod.METHOD == "midpoint"


# --- folders and key ------------------------------------------------------------------------------

@pytest.mark.parametrize("mode, who", [(0o775, "group"), (0o757, "others"), (0o777, "group and others")])
def test_cache_folder_writable_by_others_is_refused(cache, mode, who):
    path = built(cache)
    os.chmod(cache, mode)
    with pytest.raises(UntrustedCacheError, match=f"writable by {who} .*chmod go-w"):
        mg.build(QUARTIC, "midpoint")
    with pytest.raises(UntrustedCacheError):
        load_module(path)
    os.chmod(cache, 0o755)  # control: the same folder, private again, is used
    no_runtime_warnings(mg.build, QUARTIC, "midpoint")


def test_cache_folder_of_another_user_is_refused(cache, monkeypatch):
    built(cache)
    uid = os.geteuid()
    monkeypatch.setattr(os, "geteuid", lambda: uid + 4242)
    with pytest.raises(UntrustedCacheError, match="not to you"):
        mg.build(QUARTIC, "midpoint")


def test_cache_folder_refused_on_the_command_line(cache, tmp_path):
    import subprocess
    cache.mkdir(mode=0o775)
    os.chmod(cache, 0o775)
    f = tmp_path / "quartic.toml"
    f.write_text('name = "quartic"\n[system]\nH = "p**2/2 + q**4/4"\nq = ["q"]\np = ["p"]\n'
                 '[run]\nmethod = "midpoint"\nh = 0.1\nsteps = 10\ny0 = [0.5, 0.1]\n')
    res = subprocess.run([sys.executable, "-m", "methodgen", "run", str(f)], capture_output=True, text=True,
                         env={**os.environ, "METHODGEN_CACHE": str(cache)})
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert res.stderr.count("\n") == 1 and "writable by group" in res.stderr


def test_key_readable_by_others_is_refused(cache):
    path = built(cache)
    key = cache / KEY_FILE
    assert stat.S_IMODE(key.stat().st_mode) == 0o600
    os.chmod(key, 0o644)
    with pytest.raises(UntrustedCacheError, match="not a private file"):
        file_status(path)
    os.chmod(key, 0o600)
    assert file_status(path) == "ok"


def test_ordinary_permissions_and_private_root(cache):
    path = built(cache)
    umask = os.umask(0o022)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644 & ~umask  # not mkstemp's 0600
    assert stat.S_IMODE(cache.stat().st_mode) == 0o700
    assert not [p for p in cache.iterdir() if p.name.endswith(".tmp")]


# --- what stays as it was -------------------------------------------------------------------------

def test_files_outside_the_cache_keep_their_deterministic_bytes(cache, tmp_path):
    scheme = mg.discretize(QUARTIC, "midpoint")
    src = emit_source(scheme, signature(QUARTIC, "midpoint"))
    out = tmp_path / "mine" / "quartic_midpoint.py"
    write_module(out, src)
    assert out.read_text() == src and not src.startswith(HEADER_KEYED)
    assert file_status(out) == "ok"  # the plain content hash is all a file outside the cache needs
    # In the cache: the same text after one key line; untagged() gives it back (the sweep ships that).
    path = built(cache)
    assert path.read_text().startswith(HEADER_KEYED) and untagged(path.read_text()) == src


def test_generated_folder_modules_load_with_their_plain_hash():
    root = Path(__file__).resolve().parents[2] / "generated"
    path = root / "harmonic_midpoint.py"
    if not path.is_file():
        pytest.skip("no checkout generated/")
    assert not path.read_text().startswith(HEADER_KEYED)
    assert load_module(path).METHOD == "midpoint"


def test_orphaned_temporary_module_of_a_killed_generation_is_removed(cache):
    path = built(cache)
    from methodgen.runtime.runio import make_temp
    fd, tmp = make_temp(cache, path.name)
    os.write(fd, b"# half a module")
    os.close(fd)  # the writer is gone: its lock with it
    path.unlink()
    built(cache)
    assert not os.path.exists(tmp)
