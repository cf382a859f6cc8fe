"""The disk cache of LLVM machine code (methodgen.codegen.llvmcache).

A later process adds a module's kernels and fused loop from the cache without translating
anything, and runs bitwise what a fresh compilation runs.  Object code is executable: an
object whose tag does not verify, a cache folder others can write to, or an edited module
never leads to loading anything stale or planted -- the kernel is compiled afresh.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen.emit import module_filename

pytest.importorskip("llvmlite")

PROBE = textwrap.dedent("""
    import json, sys
    import numpy as np
    from methodgen.codegen import llvmkernels as lk
    calls = []
    real = lk._translate_and_compile

    def counting(py_func, *args):
        calls.append(py_func.__name__)
        return real(py_func, *args)

    lk._translate_and_compile = counting
    from methodgen.codegen.emit import load_module
    m = load_module(sys.argv[1])
    np.save(sys.argv[3], m.integrate(np.array(json.loads(sys.argv[2])), 0.05, 60))
    print(json.dumps(sorted(calls)))
""")


def _run(path, y0, out, cache, **env):
    e = dict(os.environ, METHODGEN_CACHE=str(cache), **env)
    proc = subprocess.run([sys.executable, "-c", PROBE, str(path), json.dumps(list(y0)), str(out)],
                          capture_output=True, text=True, env=e)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1]), np.load(out)


@pytest.fixture(scope="module")
def hh_module(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("llvmcache")
    scene = mg.load_scene("henon-heiles-2d")
    path = tmp / module_filename("hh", "energy_momentum", "numba")
    mg.generate(mg.discretize(scene.system, "energy-momentum"), path, backend="numba")
    return path, np.array(scene.y0, float)


def test_a_later_process_loads_the_machine_code_and_runs_the_same_bits(hh_module, tmp_path):
    path, y0 = hh_module
    cache = tmp_path / "cache"
    first, Y1 = _run(path, y0, tmp_path / "a.npy", cache)
    assert "stepper" in first                                        # compiled, then stored
    # a module's kernels are compiled only where their own machine code is called: the loop
    # inlines their kernel IR (llvmkernels.compile_kernel(lazy=True))
    assert "_nb_post" not in first
    assert len(list((cache / "llvm").glob("*.o"))) == len(first)
    second, Y2 = _run(path, y0, tmp_path / "b.npy", cache)
    assert second == []                                              # nothing translated
    assert np.array_equal(Y1, Y2)
    # control: with the cache off everything is translated again, to the same bits
    off, Y3 = _run(path, y0, tmp_path / "c.npy", cache, METHODGEN_LLVM_CACHE="0")
    assert off == first and np.array_equal(Y1, Y3)


def test_a_tampered_object_is_compiled_afresh_never_loaded(hh_module, tmp_path):
    path, y0 = hh_module
    cache = tmp_path / "cache"
    first, Y1 = _run(path, y0, tmp_path / "a.npy", cache)
    objs = sorted((cache / "llvm").glob("*.o"))
    for o in objs:                       # a changed instruction byte, the tag left as it was
        data = bytearray(o.read_bytes())
        data[-200] ^= 0xFF
        o.write_bytes(bytes(data))
    again, Y2 = _run(path, y0, tmp_path / "b.npy", cache)
    assert again == first and np.array_equal(Y1, Y2)                # every one recompiled
    assert _run(path, y0, tmp_path / "c.npy", cache)[0] == []        # and stored anew
    # a tag made with another key is refused too
    (cache / ".methodgen-key").write_text("ab" * 32 + "\n")
    os.chmod(cache / ".methodgen-key", 0o600)
    assert _run(path, y0, tmp_path / "d.npy", cache)[0] == first


def test_an_edited_module_is_not_served_its_old_code(tmp_path):
    """Two modules whose kernels have the same names, lines and signatures but whose text
    differs in one coefficient (a module edited and regenerated): the second is compiled
    afresh, and its trajectory is its own.  Control: the first, run again, loads its code."""
    runs = []
    for i, c in enumerate(("3", "4")):
        system = mg.Hamiltonian(f"(p1**2 + p2**2)/2 + (q1**2 + q2**2)/2 + q1**2*q2 - q2**3/{c}",
                                ["q1", "q2"], ["p1", "p2"])
        folder = tmp_path / f"m{i}"
        folder.mkdir()
        path = folder / module_filename("cubic", "energy_momentum", "numba")
        mg.generate(mg.discretize(system, "energy-momentum"), path, backend="numba")
        runs.append(path)
    cache = tmp_path / "cache"
    y0 = np.array([0.1, -0.2, 0.3, 0.1])
    first, Y1 = _run(runs[0], y0, tmp_path / "a.npy", cache)
    other, Y2 = _run(runs[1], y0, tmp_path / "b.npy", cache)
    assert other == first                  # every kernel translated again
    assert not np.array_equal(Y1, Y2)      # its own coefficients
    assert _run(runs[0], y0, tmp_path / "c.npy", cache)[0] == []


def test_a_cache_others_can_write_to_is_not_used(hh_module, tmp_path):
    path, y0 = hh_module
    cache = tmp_path / "cache"
    first, _ = _run(path, y0, tmp_path / "a.npy", cache)
    os.chmod(cache / "llvm", 0o775)
    assert _run(path, y0, tmp_path / "b.npy", cache)[0] == first     # not read
    os.chmod(cache / "llvm", 0o755)
    assert _run(path, y0, tmp_path / "c.npy", cache)[0] == []        # control: read again


def test_the_cache_stays_bounded_and_drops_killed_writers_files(tmp_path, monkeypatch):
    """A store removes a killed writer's old temporary file (not a fresh one: a writer may be
    at work) and, past the limit, the least recently used objects; a load marks its object as
    used.  Control: below the limit nothing is removed."""
    import time

    from methodgen.codegen import llvmcache

    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(llvmcache, "_MAX_OBJECTS", 4)
    monkeypatch.setattr(llvmcache, "_KEEP_OBJECTS", 2)
    for i in range(4):
        llvmcache.store(f"{i:064x}", f"f{i}", b"object %d" % i)
    folder = tmp_path / "cache" / "llvm"
    old = time.time() - 3600
    for i in range(4):
        os.utime(folder / f"{i:064x}.o", (old + i, old + i))
    assert llvmcache.load(f"{0:064x}", "f0") == b"object 0"        # used now: the newest
    stale, fresh = folder / ".tmp-killed.o", folder / ".tmp-writing.o"
    stale.write_bytes(b"x")
    os.utime(stale, (old, old))
    fresh.write_bytes(b"x")
    def objects():
        return sorted(p.name for p in folder.glob("*.o") if not p.name.startswith("."))

    assert len(objects()) == 4                                         # control: at the limit
    llvmcache.store(f"{9:064x}", "f9", b"object 9")                   # 5 > 4: down to 2
    assert objects() == sorted([f"{0:064x}.o", f"{9:064x}.o"])        # the two most recently used
    assert not stale.exists() and fresh.exists()
    assert llvmcache.load(f"{9:064x}", "f9") == b"object 9"
    assert llvmcache.load(f"{9:064x}", "f8") is None                  # the tag binds the symbol


def test_an_object_moved_to_another_key_is_never_loaded(tmp_path):
    """Two modules of the same kernels (names, lines, signatures) but another coefficient:
    their objects swapped file for file (each under the other's key) are refused and
    compiled afresh, and the run is the module's own.  Control: unswapped, all are loaded."""
    import re

    paths = []
    for i, c in enumerate(("3", "4")):
        system = mg.Hamiltonian(f"(p1**2 + p2**2)/2 + (q1**2 + q2**2)/2 + q1**2*q2 - q2**3/{c}",
                                ["q1", "q2"], ["p1", "p2"])
        folder = tmp_path / f"m{i}"
        folder.mkdir()
        paths.append(folder / module_filename("cubic", "energy_momentum", "numba"))
        mg.generate(mg.discretize(system, "energy-momentum"), paths[-1], backend="numba")
    cache = tmp_path / "cache"
    y0 = np.array([0.1, -0.2, 0.3, 0.1])
    first, Y1 = _run(paths[0], y0, tmp_path / "a.npy", cache)
    before = set((cache / "llvm").glob("*.o"))
    second, Y2 = _run(paths[1], y0, tmp_path / "b.npy", cache)
    assert _run(paths[1], y0, tmp_path / "c.npy", cache)[0] == []         # control: all loaded
    by_kernel = {}
    for o in sorted((cache / "llvm").glob("*.o")):
        m = re.search(rb"mg_[0-9a-f]{24}_(\w+?)(?:_c)?\x00", o.read_bytes())
        assert m, o
        by_kernel.setdefault(m.group(1), {})[o in before] = o
    pairs = [(d[True], d[False]) for d in by_kernel.values() if len(d) == 2]
    assert len(pairs) == len(second)
    for a, b in pairs:                                  # each object under the other's key
        da, db = a.read_bytes(), b.read_bytes()
        a.write_bytes(db)
        b.write_bytes(da)
    again, Y3 = _run(paths[1], y0, tmp_path / "d.npy", cache)
    assert again == second                              # every one refused, translated afresh
    assert np.array_equal(Y2, Y3) and not np.array_equal(Y1, Y3)
