"""The module signature covers the generator's own sources (a stale derivation is never current)."""
import shutil
from pathlib import Path

import methodgen
from methodgen.codegen import emit


def _copy_package(tmp_path):
    src = Path(methodgen.__file__).resolve().parent
    dst = tmp_path / "methodgen"
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("__pycache__"))
    return dst


def test_generator_edit_changes_hash(tmp_path):
    root = _copy_package(tmp_path)
    before = emit._generator_tree_hash(root)
    assert before == emit.generator_hash()  # the copy hashes like the package itself
    lower = root / "codegen" / "lower.py"
    lower.write_text(lower.read_text() + "\n# a derivation change\n")
    assert emit._generator_tree_hash(root) != before
    scheme = root / "symbolic" / "schemes" / "midpoint.py"
    lower.write_text(lower.read_text().replace("\n# a derivation change\n", ""))
    assert emit._generator_tree_hash(root) == before
    scheme.write_text(scheme.read_text() + "\n# x\n")
    assert emit._generator_tree_hash(root) != before


def test_front_end_edit_keeps_hash(tmp_path):
    # Negative control of the exclusions: the CLI and verify never shape a module.
    root = _copy_package(tmp_path)
    before = emit._generator_tree_hash(root)
    for rel in ("app/cli/run.py", "app/cli/common.py", "symbolic/verify/report.py", "app/bench.py",
                "runtime/trajfile.py", "symbolic/scenes/kepler.toml"):
        f = root / rel
        f.write_text(f.read_text() + "\n# front end\n")
    assert emit._generator_tree_hash(root) == before


def test_signature_follows_generator_hash(monkeypatch):
    system = methodgen.Hamiltonian("p**2/2 + q**2/2", q=["q"], p=["p"])
    sig = emit.signature(system, "midpoint")
    monkeypatch.setattr(emit, "generator_hash", lambda: "0" * 64)
    assert emit.signature(system, "midpoint") != sig
