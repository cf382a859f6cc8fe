"""Round-off of long runs: the extended-precision refinement (``integrate(..., extended=True)``).

With h = 0.01 the default stepper (round-off stopping + compensated summation)
leaves a tiny systematic energy drift, ~1e-21 per step for the harmonic
oscillator: the rounding of the stage sums q + Δq/2, p + Δp/2 is correlated
with the state.  It is invisible for 10⁴ steps in one trajectory but turns the
√t law into t after ~10⁵ steps (``methodgen bench harmonic --brouwer``).  Here
the drift is measured directly as the ensemble mean of the energy error of the
exact numerical states y + compensation (in extended precision).
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.scene import scene_names
from methodgen.build import scene_module_path
from methodgen.emit import load_module
from conftest import marked

pytestmark = pytest.mark.skipif(np.finfo(np.longdouble).nmant <= 52,
                                reason="numpy.longdouble is plain double on this platform")

BUILTIN = marked([(name, method) for name in scene_names() for method in mg.load_scene(name).methods])


def _module(scene_name, method):
    scene = mg.load_scene(scene_name)
    # A time-transformed scene's modules integrate K (its run system).
    return scene, load_module(scene_module_path(scene, method, system=scene.run_system))


def _energy_error(module, Y, comp, H0):
    LD = np.longdouble
    return module._v_hamiltonian(Y.astype(LD) + comp, tuple(LD(v) for v in module._params(None))) - H0


def test_extended_refinement_removes_the_systematic_round_off_drift():
    _, m = _module("harmonic", "midpoint")
    B, steps, h = 2000, 15_000, 0.01
    phase = np.random.default_rng(1).uniform(0, 2 * np.pi, B)
    Y0 = np.stack([np.cos(phase), np.sin(phase)], axis=1)
    H0 = _energy_error(m, Y0, np.zeros_like(Y0), 0)
    stats = {}
    finals = {}
    for extended in (False, True):
        info = {}
        Y = m.integrate(Y0, h, steps, info=info, extended=extended)[-1]
        d = _energy_error(m, Y, info["compensation"], H0).astype(float)
        stats[extended] = (d.mean(), d.std() / np.sqrt(B))
        finals[extended] = Y
    mean, sigma = stats[False]
    # Negative control: the default stepper's drift is there and this measurement sees it.
    assert mean > 6 * sigma, stats
    mean, sigma = stats[True]
    assert abs(mean) < 3 * sigma, stats
    # The refinement changes round-off only: the same method, the same trajectories.
    np.testing.assert_allclose(finals[True], finals[False], rtol=0, atol=1e-13)


@pytest.mark.parametrize("scene_name,method", BUILTIN)
def test_extended_refinement_is_the_same_method_for_every_builtin(scene_name, method):
    """Every kind of step (Newton, reduced, linearly implicit, explicit, constrained,
    guarded special functions) refines in long double and keeps its trajectory."""
    scene, m = _module(scene_name, method)
    y0 = np.array(scene.y0)
    if getattr(m, "TIME_TRANSFORM", None):
        y0 = m.initial_state(y0)  # the scene's y0 is in the original variables
    y1 = m.integrate(y0, scene.h, 3)[-1]
    if hasattr(m, "project"):
        y1 = m.project(y1)  # SHAKE leaves the hidden constraint at O(h²)
    for y in (y0, np.stack([y0, y1])):
        ref = m.integrate(y, scene.h, 20)
        info = {}
        got = m.integrate(y, scene.h, 20, extended=True, info=info)
        assert got.dtype == np.float64 and info["compensation"].dtype == np.float64
        scale = max(1.0, float(np.max(np.abs(ref))))
        # SHAKE's momenta are position differences over h: they pass round-off on amplified by 1/h.
        tol = 1e-11 if method == "shake" else 1e-13
        np.testing.assert_allclose(got, ref, rtol=0, atol=tol * scale)


def test_extended_refinement_needs_compensation_and_is_continued_in_chunks():
    _, m = _module("kepler", "energy-momentum")
    y0 = np.array(mg.load_scene("kepler").y0)
    with pytest.raises(ValueError, match="compensated=True"):
        m.integrate(y0, 0.01, 3, extended=True, compensated=False)
    whole = m.integrate(y0, 0.01, 40, extended=True)
    parts = np.concatenate(list(m.iterate(y0, 0.01, 40, chunk=15, extended=True)))
    np.testing.assert_array_equal(parts, whole)
    assert m.EXTENDED_BITS > 53


def test_cli_extended(capsys):
    from methodgen.cli import main
    assert main(["run", "harmonic", "--steps", "200", "--extended"]) == 0
    assert main(["run", "harmonic", "--steps", "200", "--extended", "--backend", "numba"]) == 2
    assert "numpy backend" in capsys.readouterr().err
