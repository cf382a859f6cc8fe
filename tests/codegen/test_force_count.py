"""How many times a generated Störmer–Verlet module evaluates ∇U and U per stage (issue 26,
item 2: first-same-as-last).  Counted, not assumed.

Instrument: the simple pendulum, ``U = -m g l cos(q)``, so every evaluation of ∇U in a
kernel is one call of ``sin`` and every evaluation of U one call of ``cos``.  The numpy
module's kernels call them through its module globals ``math`` (one trajectory) and
``numpy`` (a batch), which the test replaces by counting proxies.  The per-step count is
the difference between runs of 2N and N steps divided by N, so the one-off evaluations at
the initial state (the ``check`` and ``hs`` kernels) drop out.  The numba backend's
kernels are compiled, so there the count is read off the generated ``_nb_post`` source.

What the count is (first-same-as-last): per stage the ``post`` kernel evaluates ∇U once,
at the stage's end q1 -- the start force comes in as an input, the end force of the stage
before -- and U once (H at y1 for the energy-jump test, carried to the next stage as its
start value).  The local error estimate costs no force (Δp is already the trapezoidal rule
of the forces); a composition of s stages runs the whole per-stage sequence s times (s ∇U
per step), and makes the energy-jump test once per composed step: U once per step, from the
``hs`` kernel at its end (its post kernel gives no H).  (Before first-same-as-last it was 2 ∇U
per stage; before the per-step energy jump, s U per step.)

The shipped modules in generated/ are checked to have the first-same-as-last kernels, so a
rewrite of the scheme or its lowering cannot turn it off unseen.

Negative control: a module whose ``_s_post`` is called twice per stage doubles the
count, so the instrument sees an extra evaluation.
"""

from __future__ import annotations

import inspect
import re
import types

import numpy as np
import pytest

import methodgen as mg

#: ∇U and U evaluations per stage in the post kernel (see the module docstring).
GRAD_PER_STAGE = 1
U_PER_STAGE = 1


class _Counting(types.SimpleNamespace):
    """A stand-in for a module (``math`` or ``numpy``): counts the calls of ``sin`` and
    ``cos`` and forwards everything else to the real module."""

    def __init__(self, real):
        super().__init__()
        object.__setattr__(self, "_real", real)
        object.__setattr__(self, "calls", {"sin": 0, "cos": 0})

    def __getattr__(self, name):
        real = getattr(object.__getattribute__(self, "_real"), name)
        if name in ("sin", "cos"):
            calls = object.__getattribute__(self, "calls")

            def counted(*a, **k):
                calls[name] += 1
                return real(*a, **k)
            return counted
        return real


@pytest.fixture(scope="module")
def pendulum():
    return mg.load_scene("simple-pendulum")


@pytest.fixture(scope="module", params=[2, 4])
def sv_module(request, pendulum):
    return request.param, mg.build(pendulum.run_system, "stormer-verlet", order=request.param)


def _per_step(mod, y0, h, n, attr, real, monkeypatch):
    proxy = _Counting(real)
    monkeypatch.setattr(mod, attr, proxy)
    mod.integrate(y0, h, n)
    once = dict(proxy.calls)
    proxy.calls.update(sin=0, cos=0)
    mod.integrate(y0, h, 2 * n)
    twice = dict(proxy.calls)
    monkeypatch.setattr(mod, attr, real)
    return {k: (twice[k] - once[k]) / n for k in once}


def _stages(mod):
    return mod.COMPOSITION["stages"] if mod.COMPOSITION else 1


@pytest.mark.parametrize("batch", [False, True], ids=["one", "batch"])
def test_force_evaluations_per_step(sv_module, pendulum, batch, monkeypatch):
    import math
    order, mod = sv_module
    s = _stages(mod)
    assert s == len(mod.GAMMAS) and (s == 1) == (order == 2)
    y0 = np.array(pendulum.y0)
    if batch:
        per = _per_step(mod, np.stack([y0, 0.9 * y0]), 0.05, 8, "numpy", np, monkeypatch)
    else:
        per = _per_step(mod, y0, 0.05, 8, "math", math, monkeypatch)
    assert per == {"sin": GRAD_PER_STAGE * s, "cos": U_PER_STAGE * s if s == 1 else 1}


def test_negative_control_an_extra_evaluation_is_seen(sv_module, pendulum, monkeypatch):
    import math
    order, mod = sv_module
    real_post = mod._s_post

    def post_twice(*a):
        real_post(*a)
        return real_post(*a)
    monkeypatch.setattr(mod, "_s_post", post_twice)
    per = _per_step(mod, np.array(pendulum.y0), 0.05, 8, "math", math, monkeypatch)
    s = _stages(mod)
    assert per == {"sin": 2 * GRAD_PER_STAGE * s, "cos": 2 * U_PER_STAGE * s if s == 1 else 1}


def test_numba_post_kernel_source(pendulum):
    """The numba module's post kernel evaluates ∇U and U as often as the numpy one (read off
    the generated source: numba kernels cannot be instrumented)."""
    pytest.importorskip("llvmlite")
    mod = mg.build(pendulum.run_system, "stormer-verlet", order=2, backend="numba")
    src = inspect.getsource(mod)
    body = re.search(r"\ndef _nb_post\(.*?(?=\n(?:@|def |# ---))", src, re.S)
    assert body is not None, "no _nb_post kernel in the numba module"
    code = body.group(0)
    assert len(re.findall(r"\bmath\.sin\(", code)) == GRAD_PER_STAGE
    assert len(re.findall(r"\bmath\.cos\(", code)) == U_PER_STAGE


_ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def _has_fsal_kernels(text):
    """The first-same-as-last pieces of a generated module: the post kernel takes the start
    force ``_g``, the force kernels (one trajectory, batch), the record and its key."""
    return (re.search(r"\ndef _s_post\(_y, _c, _g, _ha, _hd, _hb, _p\)", text) is not None
            and all(f"\ndef {name}(" in text for name in ("_s_force", "_v_force", "_start_force", "_force_record"))
            and "\n_FSAL_KEY = " in text)


def test_shipped_stormer_verlet_modules_are_first_same_as_last():
    shipped = sorted((_ROOT / "generated").glob("*_stormer_verlet*.py"))
    assert len(shipped) >= 4, [p.name for p in shipped]  # double well, Hénon–Heiles, outer solar system, pendulum
    missing = [p.name for p in shipped if not _has_fsal_kernels(p.read_text())]
    assert not missing, f"generated Störmer–Verlet modules without first-same-as-last: {missing}"
    # negative control: the check tells a module without them (another method) apart
    assert not _has_fsal_kernels((_ROOT / "generated" / "henon_heiles_2d_midpoint.py").read_text())


def _per_step_extended(mod, y0, monkeypatch):
    """∇U (sin) per step with extended=True: (math, numpy) -- the post kernel's double-precision
    force (math) and the long-double refinement's (numpy) apart."""
    import math
    pm, pn = _Counting(math), _Counting(np)
    monkeypatch.setattr(mod, "math", pm)
    monkeypatch.setattr(mod, "numpy", pn)
    mod.integrate(y0, 0.05, 8, extended=True)
    once = pm.calls["sin"], pn.calls["sin"]
    mod.integrate(y0, 0.05, 16, extended=True)
    twice = pm.calls["sin"] - once[0], pn.calls["sin"] - once[1]
    monkeypatch.setattr(mod, "math", math)
    monkeypatch.setattr(mod, "numpy", np)
    return (twice[0] - once[0]) / 8, (twice[1] - once[1]) / 8


def test_extended_force_evaluations_per_step(sv_module, pendulum, monkeypatch):
    """extended=True: per stage ∇U once in double (the post kernel, whose end force starts the
    next stage's checks) and twice in long double (the refined increment, a two-force step)."""
    order, mod = sv_module
    s = _stages(mod)
    y0 = np.array(pendulum.y0)
    assert _per_step_extended(mod, y0, monkeypatch) == (GRAD_PER_STAGE * s, 2 * s)
    # negative control: a loop that evaluates the force afresh after each stage as well (as
    # extended mode did before) is seen
    real_post = mod._s_post

    def post_and_force(y, comp, *rest):
        mod._s_force(y, comp, rest[-1])
        return real_post(y, comp, *rest)
    monkeypatch.setattr(mod, "_s_post", post_and_force)
    assert _per_step_extended(mod, y0, monkeypatch) == (2 * GRAD_PER_STAGE * s, 2 * s)
