"""Shared fixtures: the built-in systems and their generated modules (in a temp folder)."""

from __future__ import annotations

import numpy as np
import pytest

from pathlib import Path

import methodgen as mg
from methodgen.codegen.emit import file_status, load_module, module_filename, signature

ROOT = Path(__file__).resolve().parent.parent

#: Every (built-in scene, method) pair.
SCENE_METHODS = [(name, m) for name in mg.scenes() for m in mg.load_scene(name).methods]

#: Built-in scenes too heavy for the default run: the 6-body outer solar system costs
#: ~20 s of derivation per method and > 60 s of verification (issue 16 is about that).
#: Suite-wide parametrisations run them only with ``-m slow``.
HEAVY_SCENES = frozenset({"outer-solar-system"})


def marked(pairs):
    """``pairs`` of (scene, ...) as pytest params, the heavy scenes marked slow."""
    return [pytest.param(*p, marks=pytest.mark.slow) if p[0] in HEAVY_SCENES else p for p in pairs]

KEPLER_Y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])
#: The henon-heiles-2d scene's regular orbit at H = 1/8, and the time of the order tests.
HH_Y0 = np.array([0.0, 0.0, 0.4330127018922193, 0.25])
HH_T = 10.0


@pytest.fixture(scope="session")
def hh_reference():
    """Hénon–Heiles 2-DOF from HH_Y0 at HH_T by DOP853 at rtol 2.3e-14 (the order tests' reference)."""
    from scipy.integrate import solve_ivp

    def f(t, y):
        q1, q2, p1, p2 = y
        return [p1, p2, -q1 - 2 * q1 * q2, -q2 - q1**2 + q2**2]

    return solve_ivp(f, (0, HH_T), HH_Y0, method="DOP853", rtol=2.3e-14, atol=1e-16).y[:, -1]


def hh_error_ratio(mod, hs, reference):
    """(errors at HH_T against ``reference`` for the step sizes ``hs``, their ratio): halving h
    divides the error of an order-K method by 2^K."""
    errs = [float(np.max(np.abs(mod.integrate(HH_Y0, h, int(round(HH_T / h)))[-1] - reference))) for h in hs]
    return errs, errs[0] / errs[1]


def scene_system(name):
    """The system a built-in scene's modules integrate: its time transformation K when the
    scene declares one (``[run] time_transform``), else its Hamiltonian."""
    return mg.load_scene(name).run_system


def scene_y0(scene, module):
    """The scene's ``y0`` as ``module``'s state: mapped onto K = 0 (``initial_state``) when the
    module integrates a time transformation (the scene's y0 is in the original variables)."""
    y0 = np.array(scene.y0, dtype=float)
    return module.initial_state(y0) if getattr(module, "TIME_TRANSFORM", None) else y0


@pytest.fixture(scope="session")
def kepler():
    return mg.load_scene("kepler").system


@pytest.fixture(scope="session")
def harmonic():
    return mg.load_scene("harmonic").system


@pytest.fixture(scope="session")
def hh():
    """The henon-heiles-2d scene's system (the order tests' Hénon–Heiles, from HH_Y0 to HH_T)."""
    return mg.load_scene("henon-heiles-2d").run_system


@pytest.fixture(scope="session")
def modules(tmp_path_factory):
    """Generate (once per session) a module per (scene, method) into a temp folder."""
    cache = {}
    root = tmp_path_factory.mktemp("generated")

    def get(system, method):
        key = (system.fingerprint(), method)
        if key not in cache:
            scheme = mg.discretize(system, method)
            fname = module_filename(system.name or "system", method)
            committed = ROOT / "generated" / fname
            # Use the committed module when it is exactly what the generator would
            # write (its sync is tested separately); otherwise generate to a temp dir
            # without touching generated/.
            if file_status(committed, signature(system, method)) == "ok":
                cache[key] = (scheme, load_module(committed))
            else:
                cache[key] = (scheme, mg.generate(scheme, root / fname))
        return cache[key]

    return get


@pytest.fixture(scope="session")
def pair(modules, tmp_path_factory):
    """``pair(scene, method)`` -> (numpy module, numba module), generated once per session
    (shared by the numba tests, so each module compiles once; callers importorskip numba)."""
    root = tmp_path_factory.mktemp("numba")
    cache = {}

    def get(scene_name, method):
        if (scene_name, method) not in cache:
            scene = mg.load_scene(scene_name)
            scheme, np_mod = modules(scene.system, method)
            path = root / module_filename(scene.name, method, "numba")
            cache[scene_name, method] = (np_mod, mg.generate(scheme, path, backend="numba"))
        return cache[scene_name, method]

    return get


# Progress lines on stderr depend on how long a phase takes (methodgen.codegen.progress: over 2 s), so
# on a loaded machine they would come and go; the suite runs without them (subprocesses too)
# unless a test sets the threshold itself (tests/test_progress.py).
import os as _os  # noqa: E402

_os.environ.setdefault("METHODGEN_PROGRESS_SECONDS", "1e9")
