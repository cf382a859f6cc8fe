"""1-D lattice modules of order 4, 6, 8: symmetric compositions of the order-2 AVF / midpoint step.

The order is shown numerically (error ratios on halving h against a fine reference; control: order
2's ratio), what each stage keeps is kept (AVF's H, midpoint's NLS mass; controls: the invariant
the method does not keep drifts), the numpy and compiled backends agree (the compiled loop is its
own Python source bitwise), order 2 is the module it was (same signature, file and bits), and bad
input and failures say what and where."""

from __future__ import annotations

import numpy as np
import pytest

from methodgen.app.lattice_scene import load_lattice_scene
from methodgen.codegen.lattice_emit import build_lattice, lattice_signature
from methodgen.errors import InputError
from methodgen.symbolic.lattice_scheme import certificates, discretize_lattice, proved_invariants

N = 16


@pytest.fixture(scope="module")
def sg():
    return load_lattice_scene("sine-gordon")


@pytest.fixture(scope="module")
def nls():
    return load_lattice_scene("nls")


@pytest.fixture(scope="module")
def mods(sg, tmp_path_factory):
    d = tmp_path_factory.mktemp("comp")
    return {o: build_lattice(sg.lattice, "avf", d / f"sg{o}.py", order=o) for o in (2, 4, 6, 8)}


def _error_ratios(mod, y0, ref, t=1.0, ms=(5, 10, 20)):
    errs = [np.max(np.abs(mod.integrate(y0, t / m, m)[-1] - ref)) for m in ms]
    return errs, [errs[k] / errs[k + 1] for k in range(len(errs) - 1)]


def test_the_order_is_shown_numerically(sg, mods):
    """Numerical evidence of the order (not a proof: the composition's order conditions are
    exact, the lattice method's order is not certified): halving h divides the error at t = 1 by
    ≈ 2^order against an order-8 run at h = 1/40.  Control: order 2 divides it by ≈ 4 (< 5)."""
    y0 = sg.y0(N)
    ref = mods[8].integrate(y0, 1.0 / 40, 40)[-1]
    for order in (4, 6):
        errs, ratios = _error_ratios(mods[order], y0, ref)
        assert min(ratios) > 0.75 * 2**order, (order, errs, ratios)
        assert errs[-1] > 1e-13                   # (above the reference's error and round-off)
    errs, ratios = _error_ratios(mods[2], y0, ref)
    assert max(ratios) < 5, (errs, ratios)       # control: order 2 is not order 4
    assert min(ratios) > 0.75 * 4


def test_module_constants_say_the_composition(mods):
    from methodgen.symbolic.compositions import composition

    m4 = mods[4]
    assert (m4.ORDER, m4.TRAITS["order"], m4.TRAITS["stages"], m4.TRAITS["composition"]) == (4, 4, 5, "suzuki")
    assert m4.GAMMAS == composition(4, "suzuki").floats() and min(m4.GAMMAS) < 0
    assert abs(sum(m4.GAMMAS) - 1) < 1e-15 and m4.GAMMAS == m4.GAMMAS[::-1]
    assert "order 4 (suzuki composition, 5 stages)" in m4.__doc__
    assert (mods[2].ORDER, mods[2].GAMMAS, mods[2].TRAITS["stages"]) == (2, (1.0,), 1)
    assert "Composed symmetrically" not in mods[2].__doc__


def test_a_step_is_the_composition_of_order_2_steps(sg, mods):
    """One order-4 step is the order-2 module's steps of sizes γ_k h, one after the other (two Newton
    solves from different predictors: to round-off); control: one order-2 step of size h is not."""
    y = sg.y0(N)
    h = 0.1
    one = mods[4].step(y, h)
    z = y
    for g in mods[4].GAMMAS:
        z = mods[2].step(z, g * h)
    assert np.max(np.abs(one - z)) < 1e-13
    assert np.max(np.abs(one - mods[2].step(y, h))) > 1e-6


def test_avf_order_4_keeps_energy(sg, mods):
    """AVF composed to order 4 keeps H to round-off over 1000 steps (each stage does, for any
    γ_k h, negative ones included); control: midpoint composed to order 4 does not keep the
    sine-Gordon energy (not quadratic), its error many times larger."""
    pytest.importorskip("llvmlite")         # (1000 steps of 5 stages: the compiled loop, ~0.1 s)
    y0 = sg.y0(N)
    h, steps = 0.05, 1000
    avf = build_lattice(sg.lattice, "avf", order=4, backend="compiled")
    T = avf.integrate(y0, h, steps, save_every=10)
    H = np.array([avf.hamiltonian(r) for r in T])
    err = np.max(np.abs(H - H[0])) / abs(H[0])
    assert err <= 1e-13
    mid = build_lattice(sg.lattice, "midpoint", order=4, backend="compiled")
    Tm = mid.integrate(y0, h, steps, save_every=10)
    Hm = np.array([mid.hamiltonian(r) for r in Tm])
    assert np.max(np.abs(Hm - Hm[0])) / abs(Hm[0]) > 1e-9         # control: really not kept
    assert np.max(np.abs(T[-1] - Tm[-1])) < 1e-3                   # (the same motion, to O(h⁴))


def test_midpoint_order_4_keeps_nls_mass(nls, tmp_path):
    """Midpoint composed to order 4 keeps the quadratic NLS mass to round-off; control: AVF composed
    to order 4 (energy-preserving, not mass-preserving) drifts in the mass."""
    pytest.importorskip("llvmlite")
    n, h, steps = 32, 0.05, 1000
    y0 = nls.y0(n)
    out = {}
    for method in ("midpoint", "avf"):
        mod = build_lattice(nls.lattice, method, tmp_path / f"nls_{method}.py", order=4, backend="compiled")
        T = mod.integrate(y0, h, steps, save_every=20)
        mass = np.array([mod.invariants(r)["mass"] for r in T])
        out[method] = np.max(np.abs(mass - mass[0])) / mass[0]
    assert out["midpoint"] <= 1e-13
    assert out["avf"] > 1e-9, out                                   # control


def test_proved_invariants_are_unchanged_by_composition(sg, nls):
    """The certificates are of the stage map (the same pieces at every order); what is proved kept
    is the same; the order is not among the certified claims."""
    for scene, method in ((sg, "avf"), (nls, "midpoint"), (nls, "avf")):
        s2 = discretize_lattice(scene.lattice, method)
        s4 = discretize_lattice(scene.lattice, method, order=4)
        c2, c4 = certificates(s2), certificates(s4)
        assert [c.claim for c in c2] == [c.claim for c in c4]
        assert proved_invariants(s2, c2) == proved_invariants(s4, c4)
        assert (s4.traits["order"], s4.traits["stages"]) == (4, 5)
    assert "mass" in proved_invariants(*(lambda s: (s, certificates(s)))(discretize_lattice(nls.lattice, "midpoint",
                                                                                            order=6)))


def test_order_2_is_the_module_it_was(sg, mods, tmp_path):
    """order=2 is the default: the same signature (so the same file, and no order in its name), the
    same bits; an order-4 module never shares its file (signatures differ by order and family)."""
    lat = sg.lattice
    assert lattice_signature(lat, "avf") == lattice_signature(lat, "avf", order=2)
    sigs = {lattice_signature(lat, "avf", order=o, composition=f)
            for o, f in ((2, None), (4, None), (4, "triple-jump"), (6, None), (6, "suzuki"), (8, None))}
    assert len(sigs) == 6
    assert lattice_signature(lat, "avf", order=4) == lattice_signature(lat, "avf", order=4, composition="suzuki")
    default = build_lattice(lat, "avf")
    two = build_lattice(lat, "avf", order=2)
    four = build_lattice(lat, "avf", order=4)
    assert default.__file__ == two.__file__ != four.__file__ and "order4" in four.__file__
    y0 = sg.y0(N)
    assert np.array_equal(default.integrate(y0, 0.05, 30), mods[2].integrate(y0, 0.05, 30))


def test_compiled_agrees_with_numpy_and_with_its_python_source(sg, mods, tmp_path):
    """The compiled order-4 module against the numpy one (two arithmetics: to round-off, as at order
    2), and the compiled loop against the same source run as Python: the same bits."""
    pytest.importorskip("llvmlite")
    from methodgen.runtime.lattice_driver import run_steps

    c = build_lattice(sg.lattice, "avf", tmp_path / "c4.py", backend="compiled", order=4)
    assert (c.ORDER, c.GAMMAS) == (4, mods[4].GAMMAS)
    y0 = sg.y0(N)
    ia, ic = {}, {}
    ra = mods[4].integrate(y0, 0.05, 25, save_every=4, info=ia)
    rc = c.integrate(y0, 0.05, 25, save_every=4, info=ic)
    assert np.max(np.abs(ra - rc)) < 1e-13
    # (summed over 5 stages, each of which may stop one iteration apart at the round-off plateau)
    assert np.max(np.abs(ia["newton_iterations"] - ic["newton_iterations"])) <= 5
    out = []
    p = np.array(c._params(None))
    for python in (False, True):
        Y = y0.reshape(2, N).copy()
        out.append(run_steps(c._grad_sites, Y, 0.05, 4, 1, p, 50, 4 * 2.2e-16, True, True, 1.0, python=python,
                             gammas=c.GAMMAS))
    assert out[0][2] == (0, 0, 0, 0.0, 0)
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


@pytest.mark.parametrize("order", [3, 10, True, 4.0, "4"])
def test_an_order_not_offered_is_refused_naming_them(sg, order):
    for call in (lambda: build_lattice(sg.lattice, "avf", order=order),
                 lambda: discretize_lattice(sg.lattice, "midpoint", order)):
        with pytest.raises(InputError, match="2, 4, 6, 8"):
            call()


def test_an_unknown_family_is_refused(sg):
    with pytest.raises(InputError, match="suzuki"):
        build_lattice(sg.lattice, "avf", order=4, composition="stormer-verlet")
    with pytest.raises(InputError, match="kahan-li"):
        build_lattice(sg.lattice, "avf", order=4, composition="kahan-li")    # (it has orders 6 and 8)


@pytest.mark.parametrize("backend", ["numpy", "compiled"])
def test_a_newton_failure_names_its_step_and_stage(sg, backend, tmp_path):
    """A stage whose Newton iteration does not converge raises ConvergenceError naming the step and
    the stage, with the residual; never a silently wrong state.  Kahan–Li's order 6 takes stages of
    0.39 h first and -0.71 h third: at a large h and a few iterations the first converges and a
    longer one does not."""
    if backend == "compiled":
        pytest.importorskip("llvmlite")
    mod = build_lattice(sg.lattice, "avf", tmp_path / f"f_{backend}.py", order=6, backend=backend)
    y0 = sg.y0(N)
    with pytest.raises(Exception) as got:
        mod.integrate(y0, 0.5, 3, maxiter=6, check_resolution=False)
    exc = got.value
    assert type(exc).__name__ == "ConvergenceError"
    assert exc.stage == 3                                          # (measured: -0.71 h, the first long one)
    assert f"step 0 (stage {exc.stage} of 9)" in str(exc) and "residual" in str(exc)
    assert np.isfinite(exc.residual) and exc.residual > 0
    assert exc.trajectory.shape == (1, 2 * N)                       # only the start: nothing after


# --- the CLI and scene files ------------------------------------------------------------------------

def _cli(capsys, *argv):
    import json

    from methodgen.app import cli

    code = cli.main([*argv, "--json"])
    out, err = capsys.readouterr()
    return code, (json.loads(out) if out.strip() else None), err


def test_cli_runs_a_lattice_at_order_4_and_refuses_other_orders(capsys):
    pytest.importorskip("llvmlite")
    code, rep, err = _cli(capsys, "run", "sine-gordon", "--order", "4", "--param", "N=16", "--steps", "40",
                          "--backend", "numba")
    assert code == 0, err
    assert (rep["order"], rep["traits"]["order"], rep["traits"]["stages"]) == (4, 4, 5)
    assert rep["invariants"]["H"]["max_abs_error"] <= 1e-13 * abs(rep["invariants"]["H"]["initial"])
    code, rep2, err = _cli(capsys, "run", "sine-gordon", "--param", "N=16", "--steps", "40", "--backend", "numba")
    assert code == 0 and rep2["order"] == 2 and rep2["y_final"] != rep["y_final"]      # control: the default
    for bad in ("3", "10", "four"):
        code, _, err = _cli(capsys, "run", "sine-gordon", "--order", bad)
        assert code == 2 and "2, 4, 6, 8" in err, err


def test_scene_order_one_number_or_per_method(tmp_path):
    from methodgen.errors import SceneError

    base = open(load_lattice_scene("sine-gordon").source).read()          # (methods avf and midpoint)
    good = tmp_path / "o.toml"
    good.write_text(base.replace("[run]\n", "[run]\norder = {avf = 4}\n", 1))
    scene = load_lattice_scene(good)
    assert (scene.order("avf"), scene.order("midpoint")) == (4, 2)
    good.write_text(base.replace("[run]\n", "[run]\norder = 6\n", 1))
    assert load_lattice_scene(good).orders == {"avf": 6, "midpoint": 6}
    for value, fragment in (("3", "2, 4, 6, 8"), ("10", "2, 4, 6, 8"), ("true", "order"), ("{kdv = 4}", "does not run")):
        good.write_text(base.replace("[run]\n", f"[run]\norder = {value}\n", 1))
        with pytest.raises(SceneError, match=fragment):
            load_lattice_scene(good)
