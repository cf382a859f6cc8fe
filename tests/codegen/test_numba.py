"""The compiled backend (backend="numba", compiled through llvmlite): same interface and, to
round-off, the same results as the numpy backend.

Each compiled module is generated once per session into a temporary folder and compiled on
first use (its machine code kept in methodgen's cache).
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen.build import default_path, scene_module_path
from methodgen.codegen.emit import emit_source, module_filename, signature, template_hash

pytest.importorskip("llvmlite")

#: (scene, method) pairs covering every kind of step: Newton (reduced energy-momentum),
#: linearly implicit, explicit, constrained.
CASES = [("kepler", "energy-momentum"), ("henon-heiles", "kahan"),
         ("simple-pendulum", "stormer-verlet"), ("pendulum", "rattle")]


def _close(a, b, rtol=1e-12):
    scale = max(1.0, float(np.max(np.abs(b))))
    np.testing.assert_allclose(a, b, rtol=0, atol=rtol * scale)


@pytest.mark.parametrize("scene_name,method", CASES)
def test_agrees_with_numpy_to_roundoff(pair, scene_name, method):
    np_mod, nb_mod = pair(scene_name, method)
    scene = mg.load_scene(scene_name)
    y0 = np.array(scene.y0)
    i_np, i_nb = {}, {}
    ref = np_mod.integrate(y0, scene.h, 2000, info=i_np)
    got = nb_mod.integrate(y0, scene.h, 2000, info=i_nb)
    assert got.shape == ref.shape == (2001, y0.size)
    _close(got, ref)
    # Same start value and stopping rule: the same number of iterations per step
    # (a rare difference of one where a plateau test sits at round-off is allowed).
    assert np.mean(i_nb["newton_iterations"] != i_np["newton_iterations"]) < 0.01
    assert i_nb["compensation"].shape == y0.shape
    np.testing.assert_allclose(i_nb["compensation"], i_np["compensation"], rtol=0, atol=1e-15)


@pytest.mark.parametrize("scene_name,method", CASES)
def test_batch_matches_numpy_and_single_runs(pair, scene_name, method):
    np_mod, nb_mod = pair(scene_name, method)
    scene = mg.load_scene(scene_name)
    y0 = np.array(scene.y0)
    if np_mod.CONSTRAINTS:
        Y0 = np.array([y0, np_mod.project(y0 * [1, 1, 0.5, 0.5])])
    else:
        Y0 = y0 * (1.0 + 0.01 * np.arange(3))[:, None]
    ref = np_mod.integrate(Y0, scene.h, 500)
    got = nb_mod.integrate(Y0, scene.h, 500)
    assert got.shape == (501,) + Y0.shape
    _close(got, ref)
    # Trajectories are independent: a batch row is exactly the single run.
    np.testing.assert_array_equal(got[:, 1], nb_mod.integrate(Y0[1], scene.h, 500))


def test_interface_and_metadata(pair):
    np_mod, nb_mod = pair("kepler", "energy-momentum")
    assert nb_mod.BACKEND == "numba" and np_mod.BACKEND == "numpy"
    assert set(np_mod.__all__) == set(nb_mod.__all__)
    for name in ("METHOD", "ORDER", "TRAITS", "HAMILTONIAN", "STATE_NAMES", "PARAM_NAMES", "DEFAULT_PARAMS",
                 "INVARIANT_NAMES", "UNKNOWN_NAMES", "MAX_RESOLUTION", "MAX_PREDICTOR_DISAGREEMENT", "SOLVERS"):
        assert getattr(nb_mod, name) == getattr(np_mod, name), name
    assert nb_mod.SIGNATURE != np_mod.SIGNATURE
    y0 = np.array(mg.load_scene("kepler").y0)
    Y = y0 * (1.0 + 0.1 * np.arange(6).reshape(2, 3, 1))
    np.testing.assert_allclose(nb_mod.hamiltonian(Y), np_mod.hamiltonian(Y), rtol=1e-15)
    inv_nb, inv_np = nb_mod.invariants(Y), np_mod.invariants(Y)
    assert inv_nb.keys() == inv_np.keys()
    # Compiled residual and Jacobian broadcast like the numpy ones.
    z = np.array([1e-3, 2e-2, 1.5e-2]) * np.ones((4, 1, 1, 1))
    for fn in ("residual", "jacobian"):
        a = getattr(nb_mod, fn)(z, Y, 0.01, {"k": 2.0})
        b = getattr(np_mod, fn)(z, Y, 0.01, {"k": 2.0})
        assert a.shape == b.shape
        _close(a, b)
    np.testing.assert_array_equal(nb_mod.step(y0, 0.01), nb_mod.integrate(y0, 0.01, 1)[1])
    parts = list(nb_mod.iterate(y0, 0.01, 25, chunk=10))
    # (like the numpy iterate, chunks restart the compensation: equal to round-off)
    _close(np.concatenate(parts), nb_mod.integrate(y0, 0.01, 25))
    with pytest.raises(ValueError, match="solver"):
        nb_mod.integrate(y0, 0.01, 3, solver="bogus")
    with pytest.raises(ValueError, match="shape"):
        nb_mod.integrate(y0[:5], 0.01, 3)


@pytest.mark.parametrize("options", [{"solver": "simplified"}, {"solver": "fixed-point"},
                                     {"tol": 1e-10}, {"compensated": False},
                                     {"params": {"k": 1.3, "m": 0.7}}])
def test_solver_options_agree(pair, options):
    np_mod, nb_mod = pair("kepler", "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0)
    _close(nb_mod.integrate(y0, 0.01, 800, **options), np_mod.integrate(y0, 0.01, 800, **options))


def test_out_and_compensation_continuation(pair, tmp_path):
    _, nb_mod = pair("kepler", "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0)
    whole = nb_mod.integrate(y0, 0.01, 300)
    mm = np.lib.format.open_memmap(tmp_path / "t.npy", mode="w+", shape=whole.shape)
    assert nb_mod.integrate(y0, 0.01, 300, out=mm) is mm
    np.testing.assert_array_equal(mm, whole)
    # A float32 ``out`` would silently round the trajectory: refused (one rule for numbers).
    f32 = np.empty(whole.shape, dtype=np.float32)
    with pytest.raises(TypeError, match="float64"):
        nb_mod.integrate(y0, 0.01, 300, out=f32)
    # Two halves with the compensation carried through ``info`` = one run, bit for bit.
    info = {}
    first = nb_mod.integrate(y0, 0.01, 150, info=info)
    second = nb_mod.integrate(first[-1], 0.01, 150, info=info)
    np.testing.assert_array_equal(second, whole[150:])


def _outcome(mod, *args, **kw):
    try:
        return None, mod.integrate(*args, **kw)
    except (mod.ConvergenceError, mod.ResolutionError, mod.NonFiniteError) as exc:
        return exc, None


def test_convergence_error_with_step_and_partial_trajectory(pair):
    np_mod, nb_mod = pair("kepler", "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0)
    info = {}
    traj = np_mod.integrate(y0, 0.01, 700, info=info)
    its = info["newton_iterations"]
    # Start where a step needs few iterations, allow just that many: the run
    # fails at the first later step that needs more.
    k = int(np.flatnonzero(its < its.max())[0])
    limit = int(its[k])
    want = int(np.flatnonzero(its[k:] > limit)[0])
    exc_np, _ = _outcome(np_mod, traj[k], 0.01, 700 - k, maxiter=limit)
    exc_nb, _ = _outcome(nb_mod, traj[k], 0.01, 700 - k, maxiter=limit)
    assert isinstance(exc_nb, nb_mod.ConvergenceError) and isinstance(exc_np, np_mod.ConvergenceError)
    assert exc_nb.step == exc_np.step == want > 0
    assert exc_nb.trajectory.shape == (want + 1, 6)
    _close(exc_nb.trajectory, exc_np.trajectory)
    assert exc_nb.iterations == limit and exc_nb.trajectories is None
    assert "did not converge at step" in str(exc_nb)
    # The messages are written once for both backends (templates/_stepping.py.j2).
    assert str(exc_nb) == str(exc_np)


def test_resolution_errors(pair):
    np_mod, nb_mod = pair("kepler", "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0)
    for args in [(y0, 0.5, 20), (np.array([1.0, 0, 0, 0, 0, 0]), 0.01, 300)]:
        exc_np, _ = _outcome(np_mod, *args)
        exc_nb, _ = _outcome(nb_mod, *args)
        assert isinstance(exc_nb, nb_mod.ResolutionError) and isinstance(exc_np, np_mod.ResolutionError)
        assert exc_nb.step == exc_np.step >= 0     # h = 0.5 from pericentre: refused at step 0
        assert exc_nb.resolution == pytest.approx(exc_np.resolution, rel=1e-9)
        assert exc_nb.check == exc_np.check
        if exc_nb.resolution == exc_np.resolution:
            assert str(exc_nb) == str(exc_np)
        _close(exc_nb.trajectory, exc_np.trajectory)
    # check_resolution=False accepts the unresolved run, like numpy.
    infall = np.array([1.0, 0, 0, 0, 0, 0])
    _close(nb_mod.integrate(infall, 0.01, 300, check_resolution=False),
           np_mod.integrate(infall, 0.01, 300, check_resolution=False))


def test_batch_failure_names_the_trajectories(pair):
    np_mod, nb_mod = pair("kepler", "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0)
    Y = np.array([y0, y0 * [1, 1, 1, 1, 0.5, 0.5], [1.0, 0, 0, 0, 0, 0], [1.0, 0, 0, 0, 1e-3, 0]])
    exc_np, _ = _outcome(np_mod, Y, 0.01, 300)
    exc_nb, _ = _outcome(nb_mod, Y, 0.01, 300)
    assert type(exc_nb).__name__ == type(exc_np).__name__ == "ResolutionError"
    assert exc_nb.step == exc_np.step
    assert exc_nb.trajectory.shape == (exc_np.step + 1, 4, 6)
    _close(exc_nb.trajectory, exc_np.trajectory)
    assert "trajectories [2, 3]" in str(exc_nb)


def test_non_finite_error(pair):
    np_mod, nb_mod = pair("simple-pendulum", "stormer-verlet")
    y0 = np.array([0.0, 1e307])  # q grows by ~1e307 a step until it overflows
    exc_np, _ = _outcome(np_mod, y0, 1.0, 50)
    exc_nb, _ = _outcome(nb_mod, y0, 1.0, 50)
    assert isinstance(exc_nb, nb_mod.NonFiniteError) and isinstance(exc_np, np_mod.NonFiniteError)
    assert exc_nb.step == exc_np.step > 0
    assert exc_nb.trajectory.shape == exc_np.trajectory.shape
    assert np.all(np.isfinite(exc_nb.trajectory))


def test_constrained_checks_and_projection(pair):
    np_mod, nb_mod = pair("pendulum", "rattle")
    y0 = np.array(mg.load_scene("pendulum").y0)
    with pytest.raises(ValueError, match="constraint manifold"):
        nb_mod.integrate(y0 * 1.1, 0.01, 5)
    np.testing.assert_array_equal(nb_mod.project(y0 * 1.1), np_mod.project(y0 * 1.1))
    traj = nb_mod.integrate(y0, 0.01, 500)
    g, v = nb_mod.constraint_residuals(traj)
    assert np.max(np.abs(g)) < 1e-12 and np.max(np.abs(v)) < 1e-12


def test_without_llvmlite_falls_back_to_numpy(monkeypatch, tmp_path, kepler):
    # A None entry in sys.modules makes ``import llvmlite`` raise ImportError.
    monkeypatch.setitem(sys.modules, "llvmlite", None)
    with pytest.warns(RuntimeWarning, match=r'llvmlite is not installed.*pip install "methodgen\[fast\]"'):
        mod = mg.build(kepler, "energy-momentum", tmp_path / "k.py", backend="numba")
    assert mod.BACKEND == "numpy" and mod.SIGNATURE == signature(kepler, "energy-momentum")
    scheme = mg.discretize(kepler, "energy-momentum")
    with pytest.warns(RuntimeWarning, match="llvmlite is not installed"):
        mod2 = mg.generate(scheme, tmp_path / "k2.py", backend="numba")
    assert "from templates/module.py.j2" in (tmp_path / "k2.py").read_text()
    assert mod2.integrate(np.array(mg.load_scene("kepler").y0), 0.01, 3).shape == (4, 6)


def test_the_compiled_backend_runs_without_numba(tmp_path):
    """numba is not used: with ``import numba`` failing, a compiled module of each step kind
    (Newton, explicit with a lock-step batch, Gauss's stage kernels, a projected step) is built,
    runs, and gives the bits of the same module built in this process."""
    cases = [("kepler", "energy-momentum", {}), ("henon-heiles-2d", "stormer-verlet", {"order": 4}),
             ("kepler", "gauss", {"stages": 2}), ("henon-heiles-2d", "stormer-verlet", {"project": "energy"})]
    code = textwrap.dedent(f"""
        import sys, json
        sys.modules["numba"] = None
        import numpy as np, methodgen as mg
        out = []
        for scene, method, kw in {cases!r}:
            sc = mg.load_scene(scene)
            mod = mg.build(sc.system, method, backend="numba", **kw)
            y0 = np.array(sc.y0)
            out.append([mod.BACKEND, mod.integrate(y0, sc.h, 50)[-1].tolist(),
                        mod.integrate(np.stack([y0] * 20), sc.h, 5)[-1, -1].tolist()])
        print(json.dumps(out))
    """)
    env = dict(os.environ, METHODGEN_CACHE=str(tmp_path / "cache"))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert len(out) == 4 and all(backend == "numba" for backend, _, _ in out)
    # the same bits in this process (control: another step size gives other bits)
    sc = mg.load_scene("kepler")
    mod = mg.build(sc.system, "energy-momentum", backend="numba")
    assert mod.integrate(np.array(sc.y0), sc.h, 50)[-1].tolist() == out[0][1]
    assert mod.integrate(np.array(sc.y0), sc.h * (1 + 2**-40), 50)[-1].tolist() != out[0][1]


def test_a_kernel_without_a_tree_is_refused_by_name(monkeypatch, tmp_path):
    """A kernel with an expression the kernel IR has no node for cannot be compiled (there is no
    other compiler): generating its compiled module raises GenerationError naming the kernel and
    the expression, and pointing to the numpy backend, which builds it.  Made here by taking
    ``math.cos`` out of the IR's functions (the pendulum's kernels call it).  Control: with
    ``math.cos`` known the same scheme compiles and runs."""
    from methodgen.codegen import kir, kir_build

    scene = mg.load_scene("simple-pendulum")
    scheme = mg.discretize(scene.system, "midpoint")
    monkeypatch.setattr(kir_build, "FUNCTIONS", kir.FUNCTIONS - {"math.cos"})
    with pytest.raises(mg.GenerationError, match=r"cannot print the kernel _nb_\w+: .*math\.cos.* has no "
                                                 r"kernel-IR node.*backend=\"numpy\""):
        emit_source(scheme, backend="numba")
    assert "numpy.cos(" in emit_source(scheme, backend="numpy")
    monkeypatch.undo()
    mod = mg.generate(scheme, tmp_path / "pendulum_midpoint_numba.py", backend="numba")
    assert mod.BACKEND == "numba" and mod.integrate(np.array(scene.y0), scene.h, 3).shape == (4, 2)


def test_unknown_backend(kepler):
    with pytest.raises(mg.InputError, match="backend"):
        mg.build(kepler, "energy-momentum", backend="cython")


def test_signature_file_names_and_locations(kepler, monkeypatch, tmp_path):
    sig_np = signature(kepler, "energy-momentum")
    assert sig_np == signature(kepler, "energy-momentum", "numpy")
    assert signature(kepler, "energy-momentum", "numba") != sig_np
    # numpy signatures do not depend on the numba templates.
    assert template_hash("numpy") != template_hash("numba")
    assert module_filename("kepler", "energy-momentum", "numba") == "kepler_energy_momentum_numba.py"
    monkeypatch.setenv("METHODGEN_CACHE", str(tmp_path))
    scene = mg.load_scene("kepler")
    # generated/ holds the committed numpy modules only.
    assert scene_module_path(scene, "energy-momentum", "numba").parent == tmp_path
    assert default_path(kepler, "energy-momentum", "numba").parent == tmp_path


def test_emitted_source_is_deterministic_and_self_contained(kepler):
    code = textwrap.dedent("""
        import sys, methodgen as mg
        from methodgen.codegen.emit import emit_source
        sc = mg.load_scene("kepler")
        sys.stdout.write(emit_source(mg.discretize(sc.system, "energy-momentum"), backend="numba"))
    """)
    outs = set()
    for seed in ("0", "777"):
        env = {**os.environ, "PYTHONHASHSEED": seed}
        outs.add(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                                check=True).stdout)
    assert len(outs) == 1
    src = outs.pop()
    assert src == emit_source(mg.discretize(kepler, "energy-momentum"), backend="numba")
    head = src.splitlines()[:7]
    assert head[0].startswith("# content-sha256: ")
    assert "from templates/numba_module.py.j2" in head[1]
    assert any(line == "# signature: " + signature(kepler, "energy-momentum", "numba") for line in head)
    imported = set()
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, ast.Import):
            imported |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported |= {f"{node.module}.{a.name}" for a in node.names}
    # numpy and, of methodgen, only its compiled runtime's interface nbabi and the LLVM kernel
    # compiler (never numba, SymPy or the generator)
    assert imported <= {"math", "operator", "sys", "numpy", "methodgen.runtime.nbabi",
                        "methodgen.codegen.llvmkernels"}


def test_more_than_three_unknowns_uses_gaussian_elimination(tmp_path):
    # Non-separable H: the midpoint rule keeps all 4 unknowns (no 1x1..3x3 formula).
    system = mg.Hamiltonian("(px**2 + py**2)*(1 + x**2)/2 + (x**2 + y**2)/2 + x*y*px",
                            ["x", "y"], ["px", "py"], name="nonsep")
    scheme = mg.discretize(system, "midpoint")
    nb_mod = mg.generate(scheme, tmp_path / "nonsep_numba.py", backend="numba")
    np_mod = mg.generate(scheme, tmp_path / "nonsep.py")
    assert nb_mod._N == 4
    Y0 = np.array([0.3, -0.2, 0.1, 0.4]) * (1.0 + 0.1 * np.arange(3))[:, None]
    _close(nb_mod.integrate(Y0, 0.05, 300), np_mod.integrate(Y0, 0.05, 300))
