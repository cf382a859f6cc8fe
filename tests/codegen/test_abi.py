"""methodgen.codegen.abi: the one owner of the interface between generated kernels and the runtime.

The post kernel's output layout is computed once (abi.PostLayout, from the module's IR); the
templates and the compiled runtime's configuration read it from there.  These tests check
that the layout says where the kernel really writes each value, by running a step of a
generated numpy module and reading the post kernel's output at the layout's offsets
(numerical checks at round-off tolerance), with a negative control: a layout shifted by one
entry is caught.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import methodgen as mg
from methodgen.codegen import abi
from methodgen.runtime import nbabi
from methodgen.codegen.emit import module_filename
from methodgen.codegen.lower import lower

# (scene, method): each kind of post output -- a carried estimate (energy-momentum), Kahan's
# linearly implicit step with the energy-jump values, a trapezoidal "direct" estimate, a
# first-same-as-last force (Störmer–Verlet), and a time transformation's domain conditions and
# guard (the log-form Kepler scene)
CASES = [("kepler", "energy-momentum"), ("henon-heiles", "kahan"), ("henon-heiles", "trapezoidal"),
         ("kepler", "stormer-verlet"), ("kepler-logh", "stormer-verlet")]


@pytest.fixture(scope="module", params=CASES, ids=["-".join(c) for c in CASES])
def case(request, tmp_path_factory):
    scene_name, method = request.param
    scene = mg.load_scene(scene_name)
    scheme = mg.discretize(scene.run_system, method, **scene.options(method))
    ir = lower(scheme, "0" * 64, "m")
    path = tmp_path_factory.mktemp("abi") / module_filename(scene_name.replace("-", "_"), method, "numpy")
    mod = mg.generate(scheme, path, backend="numpy")
    y0 = np.array(scene.y0, dtype=float)
    if hasattr(mod, "initial_state") and len(y0) != mod._DIM:    # a time transformation's K = 0
        y0 = mod.initial_state(y0, scene.t0)
    # the post kernel's output of the first step, as the module's own loop computed it
    seen = []
    post_kernel = mod._s_post

    def recording(*args):
        out = post_kernel(*args)
        seen.append(np.array(out, dtype=float))
        return out

    mod._s_post = recording
    try:
        traj = mod.integrate(y0, scene.h, 1)
    finally:
        mod._s_post = post_kernel
    return ir, mod, traj, seen[0]


def disagreements(layout: abi.PostLayout, ir, mod, traj, post) -> list[str]:
    """Where the post output, read at ``layout``'s offsets, is not what the offset names
    (numerically, to round-off)."""
    bad = []
    y0, y1 = traj[0], traj[1]
    dy = y1 - y0

    def close(a, b):
        return np.allclose(a, b, rtol=1e-9, atol=1e-12 * max(1.0, float(np.max(np.abs(b)))))

    if len(post) != layout.length:
        bad.append(f"length {len(post)} != {layout.length}")
        return bad
    if not close(post[:layout.n_state], dy):
        bad.append("Δy")
    p = mod._params(None)
    chk = np.asarray(mod._v_check(y1[None, :], p), dtype=float).reshape(-1)
    if layout.n_force:
        # the field at y1 is (∂H/∂p, -∇U): the carried force is ∇U(q1)
        d = layout.n_force
        if not close(post[layout.force:layout.force + d], -chk[1 + len(y1) - d:1 + len(y1)]):
            bad.append("end force")
    if layout.local_error is not None:
        norm2 = float(np.sum(dy[list(ir.lerr_norm)] ** 2))
        if not close(post[layout.lerr_norm], norm2):
            bad.append("|Δy|²")
        if layout.local_error == "direct" and not post[layout.lerr] >= 0.0:
            bad.append("|E|²")
    if layout.n_domain:
        u = post[layout.domain:layout.domain + layout.n_domain]
        if not np.all(u > 0.0):
            bad.append("domain conditions (expected > 0 on the orbit)")
    if layout.tt_guard:
        g, defect, scale = post[layout.tt:layout.tt + 3]
        if not (g > 0.0 and scale > 0.0 and abs(defect) <= 1e-6 * scale):
            bad.append("time-transformation guard")
    if layout.energy_jump:
        H1 = float(np.asarray(mod._v_hamiltonian(y1[None, :], p)).reshape(-1)[0])
        if not close(post[layout.ej], H1) or not post[layout.ej + 1] >= abs(H1) * (1 - 1e-12):
            bad.append("H and its size at y1")
    return bad


def test_the_layout_says_where_the_post_kernel_writes(case):
    ir, mod, traj, post = case
    assert disagreements(ir.post, ir, mod, traj, post) == []


@pytest.mark.parametrize("field", ["n_force", "n_domain", "n_lerr", "energy_jump"])
def test_negative_control_a_wrong_layout_is_caught(case, field):
    """A layout that miscounts one block is caught (or, where the module has no such block to
    miscount, changes nothing the runtime reads)."""
    ir, mod, traj, post = case
    layout = ir.post
    value = getattr(layout, field)
    wrong = dataclasses.replace(layout, **{field: (not value) if isinstance(value, bool) else value + 1})
    moved = (wrong.length, wrong.domain, wrong.tt, wrong.ej, wrong.lerr) != \
        (layout.length, layout.domain, layout.tt, layout.ej, layout.lerr)
    if moved:
        assert disagreements(wrong, ir, mod, traj, post) != []


def test_the_runtime_configuration_is_the_layout():
    """The compiled runtime's configuration names every offset of the layout (no second copy
    of the arithmetic), every name once and in the runtime's order."""
    scene = mg.load_scene("kepler-logh")
    ir = lower(mg.discretize(scene.run_system, "stormer-verlet"), "0" * 64, "m", backend="numba")
    cfg = ir.int_config
    assert list(cfg) == list(abi.CFG)
    post = ir.post
    assert (cfg["POST_EXTRA"], cfg["POST_DOMAIN"], cfg["POST_TT"], cfg["POST_EJ"], cfg["POST_LEN"]) == \
        (post.lerr, post.domain, post.tt, post.ej, post.length)
    assert list(ir.float_config) == list(abi.FCFG)
    arr = nbabi.int_config(**cfg)
    assert arr[nbabi.CFG["POST_DOMAIN"]] == post.domain
    with pytest.raises(ValueError, match="missing"):
        nbabi.int_config(**{k: v for k, v in cfg.items() if k != "KL"})


def test_an_unknown_local_error_kind_is_refused():
    with pytest.raises(ValueError, match="local_error"):
        abi.PostLayout(n_state=2, local_error="exact")
