"""Generation as a product: deterministic, in sync, signed, atomic, reusable, installable."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import methodgen as mg
from methodgen.codegen.emit import emit_source, file_status, signature

ROOT = Path(__file__).resolve().parents[2]


def test_generated_folder_is_in_sync():
    """The only golden test: regenerating generated/ changes nothing."""
    res = subprocess.run([sys.executable, "-m", "methodgen", "generate", "--check"], cwd=ROOT,
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr


def test_check_detects_a_modified_file(tmp_path):
    out = tmp_path / "gen"
    res = subprocess.run([sys.executable, "-m", "methodgen", "generate", "harmonic", "--out", str(out)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    f = out / "harmonic_midpoint.py"
    ok = subprocess.run([sys.executable, "-m", "methodgen", "generate", "harmonic", "--check", "--out", str(out)],
                        capture_output=True, text=True)
    assert ok.returncode == 0
    f.write_text(f.read_text().replace("ORDER = 2", "ORDER = 3"))
    bad = subprocess.run([sys.executable, "-m", "methodgen", "generate", "harmonic", "--check", "--out", str(out)],
                         capture_output=True, text=True)
    assert bad.returncode == 1 and "harmonic_midpoint.py" in bad.stdout


def test_same_input_same_bytes_across_hash_seeds(tmp_path):
    code = textwrap.dedent("""
        import sys, methodgen as mg
        from methodgen.codegen.emit import emit_source
        sc = mg.load_scene("kepler")
        sys.stdout.write(emit_source(mg.discretize(sc.system, "energy-momentum")))
    """)
    outs = set()
    for seed in ("0", "1", "12345"):
        env = {**os.environ, "PYTHONHASHSEED": seed}
        outs.add(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                                check=True).stdout)
    assert len(outs) == 1


def test_provenance_header(kepler):
    src = emit_source(mg.discretize(kepler, "energy-momentum"))
    head = src.splitlines()[:7]
    assert head[0].startswith("# content-sha256: ")
    assert any("sympy" in line and "templates sha256" in line for line in head)
    assert any(line.startswith("# signature: " + signature(kepler, "energy-momentum")) for line in head)
    assert any("H = (px**2 + py**2 + pz**2)/(2*m)" in line for line in head)


def test_edited_file_is_detected_and_never_trusted(tmp_path, kepler):
    path = tmp_path / "k.py"
    mod = mg.build(kepler, "energy-momentum", path)
    sig = mod.SIGNATURE
    assert file_status(path, sig) == "ok"
    text = path.read_text()
    path.write_text(text.replace("_TOL_ROUNDOFF = 4.0 * _EPS", "_TOL_ROUNDOFF = 1e-3"))
    assert file_status(path, sig) == "corrupt"
    path.write_text(text[: len(text) // 2])  # truncated
    assert file_status(path, sig) == "corrupt"
    with pytest.warns(RuntimeWarning, match="content hash"):
        mod2 = mg.build(kepler, "energy-momentum", path)
    assert file_status(path, sig) == "ok" and path.read_text() == text
    assert mod2.SIGNATURE == sig
    with pytest.raises(mg.GenerationError):
        path.write_text(text + "\nprint('x')\n")
        from methodgen.codegen.emit import load_module
        load_module(path)


def test_build_reuses_an_up_to_date_file_without_deriving(tmp_path, kepler, monkeypatch):
    path = tmp_path / "k.py"
    mg.build(kepler, "energy-momentum", path)
    mtime = path.stat().st_mtime_ns

    def boom(*a, **k):
        raise AssertionError("re-derived although nothing changed")

    monkeypatch.setattr(sys.modules["methodgen.symbolic.schemes"], "discretize", boom)  # build imports it on the cold path
    mod = mg.build(kepler, "energy-momentum", path)
    assert mod.METHOD == "energy-momentum" and path.stat().st_mtime_ns == mtime
    # A different system has a different signature: it must derive (and here hits the trap).
    other = mg.Hamiltonian("(px**2+py**2+pz**2)/(2*m) - 2*k/sqrt(x**2+y**2+z**2)",
                           q=["x", "y", "z"], p=["px", "py", "pz"], params={"m": 1.0, "k": 1.0},
                           name="kepler")
    with pytest.raises(AssertionError, match="re-derived"):
        mg.build(other, "energy-momentum", path)


def test_generate_default_paths(tmp_path, monkeypatch, harmonic):
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path / "cache"))
    own = mg.Hamiltonian("p**2/2 + q**4/4", q=["q"], p=["p"], name="quartic")
    mod = mg.generate(mg.discretize(own, "midpoint"))
    assert Path(mod.__file__).parent == tmp_path / "cache"
    # A built-in scene's system goes to the checkout's generated/ (same bytes: in sync).
    mod = mg.generate(mg.discretize(harmonic, "midpoint"))
    assert Path(mod.__file__) == ROOT / "generated" / "harmonic_midpoint.py"
    # ... but the same name with a different H is not the built-in scene.
    fake = mg.Hamiltonian("p**2/2 + 2*q**2", q=["q"], p=["p"], name="harmonic")
    assert Path(mg.generate(mg.discretize(fake, "midpoint")).__file__).parent == tmp_path / "cache"


def test_two_processes_generating_at_once_leave_one_valid_file(tmp_path):
    path = tmp_path / "k.py"
    code = textwrap.dedent(f"""
        import methodgen as mg
        from methodgen.codegen.emit import emit_source, write_atomic
        sc = mg.load_scene("kepler")
        src = emit_source(mg.discretize(sc.system, "midpoint"))
        for _ in range(20):
            write_atomic({str(path)!r}, src)
    """)
    procs = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(2)]
    assert all(p.wait() == 0 for p in procs)
    assert file_status(path) == "ok"
    assert not [p for p in tmp_path.iterdir() if p.name != "k.py"]  # no temp files left


def test_non_editable_install_can_generate(tmp_path):
    """Build a wheel, install it into a bare folder, generate from there (templates are packaged)."""
    wheel_dir = tmp_path / "wheel"
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
                          "-q", "-w", str(wheel_dir), str(ROOT)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    target = tmp_path / "site"
    wheel = next(wheel_dir.glob("methodgen-*.whl"))
    res = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target",
                          str(target), str(wheel)], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    # every module, template and scene of every layer is in the wheel (the package list is explicit)
    def files(root, pattern):
        return {p.relative_to(root).as_posix() for p in root.rglob(pattern) if "__pycache__" not in p.parts}
    src = ROOT / "methodgen"
    assert files(target / "methodgen", "*.py") == files(src, "*.py")
    assert files(target / "methodgen", "*.toml") == files(src, "*.toml")
    assert {p.name for p in (target / "methodgen" / "codegen" / "templates").glob("*.j2")} == \
        {p.name for p in (ROOT / "templates").glob("*.j2")}
    # the console script names the command line where it is
    entry = next(target.glob("methodgen-*.dist-info")) / "entry_points.txt"
    assert "methodgen = methodgen.app.cli:main" in entry.read_text()
    code = textwrap.dedent("""
        import methodgen as mg, numpy as np, sys
        assert "site" in mg.__file__, mg.__file__
        import contextlib, io
        from methodgen.app.cli import main
        with contextlib.redirect_stdout(io.StringIO()) as listed:
            assert main(["scenes"]) == 0
        assert "kepler" in listed.getvalue()
        from methodgen.codegen.emit import template_dir
        assert str(template_dir()).startswith(sys.argv[1]), template_dir()
        sc = mg.load_scene("kepler")
        mod = mg.generate(mg.discretize(sc.system, "energy-momentum"), sys.argv[2])
        tr = mod.integrate(np.array(sc.y0), 0.01, 10)
        print(abs(mod.hamiltonian(tr) + 0.5).max())
    """)
    env = {**os.environ, "PYTHONPATH": str(target)}
    res = subprocess.run([sys.executable, "-c", code, str(target), str(tmp_path / "out.py")],
                         capture_output=True, text=True, env=env, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert float(res.stdout) < 1e-14
