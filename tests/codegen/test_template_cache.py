"""Compiled Jinja templates kept in the per-user cache (``emit._tagged_bytecode_cache``): a fresh
process renders without compiling the templates again, under the machine-code cache's trust rules
(the user's HMAC tag): a tampered entry is compiled afresh, never loaded."""

from __future__ import annotations

import jinja2
import pytest

from methodgen.codegen import emit


@pytest.fixture
def counting(monkeypatch, tmp_path):
    """A fresh cache, and the number of templates Jinja compiles from source."""
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("METHODGEN_LLVM_CACHE", raising=False)
    calls = []
    real = jinja2.Environment.compile

    def compile_(self, source, name=None, filename=None, *a, **k):
        calls.append(name)
        return real(self, source, name, filename, *a, **k)
    monkeypatch.setattr(jinja2.Environment, "compile", compile_)
    return calls


def _render():
    """A template rendered through a new environment (as a new process makes it)."""
    env = emit._environment_for.__wrapped__(str(emit.template_dir()))
    return env.get_template("lattice_errors.py.j2").render()


def _objects(tmp_path):
    return sorted((tmp_path / "cache" / "llvm").glob("*.o"))


def test_a_new_environment_loads_the_compiled_template(counting, tmp_path):
    first = _render()
    assert counting == ["lattice_errors.py.j2"] and _objects(tmp_path)
    counting.clear()
    assert _render() == first
    assert counting == []          # loaded, not compiled


def test_a_tampered_entry_is_compiled_afresh(counting, tmp_path):
    first = _render()
    for path in _objects(tmp_path):
        data = bytearray(path.read_bytes())
        data[-1] ^= 1               # the code changed, the tag not: the tag no longer verifies
        path.write_bytes(bytes(data))
    counting.clear()
    assert _render() == first
    assert counting == ["lattice_errors.py.j2"]


def test_off_with_the_machine_code_cache(counting, tmp_path, monkeypatch):
    monkeypatch.setenv("METHODGEN_LLVM_CACHE", "0")
    _render()
    _render()
    assert counting == ["lattice_errors.py.j2", "lattice_errors.py.j2"] and not _objects(tmp_path)
