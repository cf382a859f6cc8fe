"""An explicit module's loop with its post kernel inlined (methodgen.fused).

The fused loop is an accelerator of the shared runtime: on every step that passes every
check it gives the runtime's numbers bitwise; on a step where any check would fail it hands
the whole call back, so failures are reported by the runtime exactly as before.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg

pytest.importorskip("numba")

from methodgen import nbruntime  # noqa: E402

E = 0.99
APO = np.array([1 + E, 0.0, 0.0, 0.0, math.sqrt((1 - E) / (1 + E)), 0.0])


def _counting(monkeypatch):
    """Count the calls of the shared runtime's compiled loop."""
    calls = []
    real = nbruntime.loop_for

    def loop_for(n):
        calls.append(n)
        return real(n)

    monkeypatch.setattr(nbruntime, "loop_for", loop_for)
    return calls


@pytest.mark.parametrize("case", ["kepler-sv10", "hh-sv8-rkn", "logh-sv6"])
def test_fused_loop_is_bitwise_the_runtime(monkeypatch, case):
    if case == "logh-sv6":
        L = mg.time_transform(mg.load_scene("kepler").system, form="log")
        mod = mg.build(L, "stormer-verlet", backend="numba", order=6)
        y0 = mod.initial_state(np.array([0.4, 0.0, 0.0, 0.0, 0.8 * 2.0, 0.6 * 2.0]))
        h = 2 * math.pi / 40
    else:
        name, order, comp = {"kepler-sv10": ("kepler", 10, None),
                             "hh-sv8-rkn": ("henon-heiles-2d", 6, "blanes-moan-rkn")}[case]
        scene = mg.load_scene(name)
        mod = mg.build(scene.system, "stormer-verlet", backend="numba", order=order, composition=comp)
        y0, h = np.array(scene.y0, float), scene.h
    Y0 = np.stack([y0, y0 * (1 + 1e-3)])
    runs = {}
    for fused in ("1", "0"):
        monkeypatch.setenv("METHODGEN_FUSED", fused)
        calls = _counting(monkeypatch)
        one = mod.integrate(y0, h, 400)
        batch = mod.integrate(Y0, h, 300, save_every=7)
        # two chunks carry compensation and force as one call does
        info = {}
        first = mod.integrate(y0, h, 150, info=info)
        second = mod.integrate(first[-1], h, 250, info=info)
        runs[fused] = (one, batch, np.concatenate([first, second[1:]]))
        assert (calls == []) == (fused == "1"), (fused, calls)   # the fused path was taken (or not)
    for a, b in zip(runs["1"], runs["0"]):
        assert np.array_equal(a, b)
    assert np.array_equal(runs["1"][0], runs["1"][2])


def test_a_failing_step_is_reported_by_the_runtime_as_before(monkeypatch):
    """Kepler at e = 0.99 with a step that jumps over the pericentre: the fused loop stops and
    hands the call back; the error, its step, its check and the rows before it are those of
    the runtime alone."""
    mod = mg.build(mg.load_scene("kepler").system, "stormer-verlet", backend="numba", order=4)
    got = {}
    for fused in ("1", "0"):
        monkeypatch.setenv("METHODGEN_FUSED", fused)
        calls = _counting(monkeypatch)
        with pytest.raises(mod.ResolutionError) as info:
            mod.integrate(APO, 0.2, 200)
        e = info.value
        got[fused] = (e.step, e.check, str(e), e.trajectory.tobytes())
        assert len(calls) == 1                     # fused: stopped, then the runtime ran the call
    assert got["1"] == got["0"]
    # control: resolved, the same run completes on the fused path alone
    monkeypatch.setenv("METHODGEN_FUSED", "1")
    calls = _counting(monkeypatch)
    assert np.all(np.isfinite(mod.integrate(APO, 0.2, 200, check_resolution=False)))
    assert calls == []
