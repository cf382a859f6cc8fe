"""One particle module for every N: the same steps as methodgen's module of H written out at
N = 3 and 5, energy to round-off by energy-momentum (Störmer–Verlet, the control, drifts),
momenta kept, the compiled pair loops bit for bit the plain-Python run of the same stepper,
failures that say what failed."""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen.particle_emit import build_particles
from methodgen.problem.particles import Particles

GRAV = ("Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N)"
        " - Sum(Sum(G*m[i]*m[j]/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)")


@pytest.fixture(scope="module")
def family():
    return Particles(GRAV, q=["x", "y"], p=["px", "py"], arrays=["m"], params={"G": 1.0}, name="grav")


@pytest.fixture(scope="module")
def modules(family, tmp_path_factory):
    d = tmp_path_factory.mktemp("particles")
    out = {}
    for method, order in (("stormer-verlet", 2), ("stormer-verlet", 4), ("energy-momentum", 2)):
        for backend in ("numpy", "compiled"):
            if backend == "compiled":
                pytest.importorskip("llvmlite")
            out[method, order, backend] = build_particles(family, method, d / f"{method}{order}{backend}.py",
                                                          order=order, backend=backend)
    return out


def ring(n, seed=0):
    """Bodies near a circle, tangential velocities, zero total momentum; masses 0.5 … 1.5."""
    rng = np.random.default_rng(seed)
    ang = 2 * np.pi * np.arange(n) / n + 0.1 * rng.random(n)
    r = 1 + 0.1 * rng.random(n)
    m = 0.5 + rng.random(n)
    q = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
    v = 0.5 * np.stack([-np.sin(ang), np.cos(ang)], axis=1)
    p = m[:, None] * v
    p -= m[:, None] * p.sum(axis=0) / m.sum()
    return np.concatenate([q.ravel(), p.ravel()]), m


def star(n):
    """A star (mass 1) and n - 1 planets (mass 1e-3) on near-circular orbits of radii 1 … 2."""
    r = np.concatenate([[0.0], 1 + np.arange(n - 1) / max(1, n - 2)])
    ang = 2.4 * np.arange(n)
    m = np.concatenate([[1.0], np.full(n - 1, 1e-3)])
    v = np.where(r > 0, 1 / np.sqrt(np.where(r > 0, r, 1)), 0.0) * 1.02
    q = np.stack([r * np.cos(ang), r * np.sin(ang)], axis=1)
    p = m[:, None] * v[:, None] * np.stack([-np.sin(ang), np.cos(ang)], axis=1)
    p -= m[:, None] * p.sum(axis=0) / m.sum()
    return np.concatenate([q.ravel(), p.ravel()]), m


@pytest.mark.parametrize("method,order", [("stormer-verlet", 4), ("energy-momentum", 2)])
def test_one_module_at_two_sizes_is_the_written_out_module(family, modules, method, order, tmp_path):
    """The family's module (built once) at N = 3 and N = 5 against methodgen's module of H written out
    at each N (the masses as parameters m1 … mN): the same trajectory to round-off, 1e-12 after
    50 steps (not bitwise: the pair sums are associated differently, and the written-out
    energy-momentum module solves its step by another iteration)."""
    mod = modules[method, order, "numpy"]
    for n in (3, 5):
        H, q, p, arrays = family.expand(n)
        y0, m = ring(n, seed=n)
        params = {"G": 1.0, **{f"m{k + 1}": float(m[k]) for k in range(n)}}
        ref = mg.build(mg.Hamiltonian(H, [s.name for s in q], [s.name for s in p], params=params,
                                      name=f"wo{n}"), method, path=tmp_path / f"wo{n}.py", order=order)
        a = mod.integrate(y0, 0.01, 50, arrays={"m": m})
        b = ref.integrate(y0, 0.01, 50)
        assert np.max(np.abs(a - b)) < 1e-12
        assert abs(mod.hamiltonian(y0, arrays={"m": m}) - ref.hamiltonian(y0)) < 1e-14
        # negative control: the other method's module is not the reference's step
        other = modules[("energy-momentum", 2, "numpy") if method == "stormer-verlet" else
                        ("stormer-verlet", 2, "numpy")]
        c = other.integrate(y0, 0.01, 50, arrays={"m": m})
        assert np.max(np.abs(c - b)) > 1e-9


def test_energy_momentum_keeps_h_and_stormer_verlet_does_not(modules):
    y0, m = star(6)
    h, steps = 0.02, 2000
    err = {}
    for key in (("energy-momentum", 2, "numpy"), ("stormer-verlet", 2, "numpy")):
        mod = modules[key]
        T = mod.integrate(y0, h, steps, arrays={"m": m}, save_every=20)
        inv = [mod.invariants(r, arrays={"m": m}) for r in T]
        err[key[0]] = {k: max(abs(v[k] - inv[0][k]) for v in inv) for k in inv[0]}
        scale = abs(inv[0]["H"])
        assert err[key[0]]["Px"] < 1e-13 and err[key[0]]["Py"] < 1e-13 and err[key[0]]["L"] < 1e-13
    assert err["energy-momentum"]["H"] < 1e-13 * max(1.0, scale)
    assert err["stormer-verlet"]["H"] > 1e-7 * scale              # the control: a bounded, visible error


@pytest.mark.parametrize("method,order", [("stormer-verlet", 4), ("energy-momentum", 2)])
def test_compiled_pair_loops_are_the_python_run_bit_for_bit(family, modules, method, order):
    from methodgen.runtime import particle_driver as drv

    mod = modules[method, order, "compiled"]
    y0, m = ring(5, seed=2)
    n = 5
    M = m[None, :].copy()
    Q, P = y0[:2 * n].reshape(n, 2), y0[2 * n:].reshape(n, 2)
    runs = []
    for python in (False, True):
        if method == "stormer-verlet":
            T, _, status = drv.run_sv(mod._vel, mod._fpair, mod._fext, Q.copy(), P.copy(), M, (1.0,), 0.01, 30, 1,
                                      mod.KICKS, mod.DRIFTS, mod.HAS_EXTERNAL, python=python)
        else:
            T, _, status = drv.run_em(mod._vel, mod._gpair, mod._gext, Q.copy(), P.copy(), M, (1.0,), 0.01, 30, 1,
                                      100, 4 * 2.220446049250313e-16, mod.GAMMAS, mod.HAS_EXTERNAL, python=python)
        assert status[0] == 0
        runs.append(T)
    assert np.array_equal(runs[0], runs[1])
    # and the numpy module's vectorised step, to round-off
    ref = modules[method, order, "numpy"].integrate(y0, 0.01, 30, arrays={"m": m})
    assert np.max(np.abs(ref - runs[0])) < 1e-13


def test_failures_say_what_failed(modules):
    y0, m = ring(4, seed=3)
    mod = modules["energy-momentum", 2, "numpy"]
    with pytest.raises(mod.ConvergenceError, match="step 0.*did not converge") as exc:
        mod.integrate(y0, 3.0, 5, arrays={"m": m}, maxiter=3)
    assert exc.value.step == 0 and exc.value.residual > 0
    cmod = modules["energy-momentum", 2, "compiled"]
    with pytest.raises(cmod.ConvergenceError, match="step 0"):
        cmod.integrate(y0, 3.0, 5, arrays={"m": m}, maxiter=3)
    with pytest.raises(ValueError, match="array 'm'"):
        mod.integrate(y0, 0.01, 2)
    with pytest.raises(ValueError, match="4 finite numbers"):
        mod.integrate(y0, 0.01, 2, arrays={"m": m[:3]})
    with pytest.raises(ValueError, match="flat state"):
        mod.integrate(y0[:-1], 0.01, 2, arrays={"m": m})
    clash = y0.copy()
    clash[2:4] = clash[0:2]                                    # two bodies at one place
    sv = modules["stormer-verlet", 2, "numpy"]
    with pytest.raises(sv.NonFiniteError, match="step 0"), np.errstate(all="ignore"):
        sv.integrate(clash, 0.01, 2, arrays={"m": m})


def test_rendering_is_deterministic_and_imports_numpy_only(family):
    import ast

    from methodgen.codegen.particle_emit import render
    from methodgen.symbolic.particle_scheme import discretize_particles

    scheme = discretize_particles(family, "stormer-verlet", 8)
    a, b = render(scheme, "sig"), render(scheme, "sig")
    assert a == b and a.startswith("# content-sha256: ") and "# signature: sig" in a
    tree = ast.parse(a)
    # the module's own imports (top level and in its functions), but solve()'s events path, which
    # imports methodgen's one event location (methodgen.runtime.events) only when given events
    solve = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "solve")
    lazy = {id(n) for n in ast.walk(solve) if isinstance(n, ast.ImportFrom)}
    assert {n.module for n in ast.walk(solve) if isinstance(n, ast.ImportFrom)} == {"methodgen.runtime.events"}
    imported = {n.names[0].name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import)}
    imported |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and id(n) not in lazy}
    assert imported == {"math", "numpy"}
