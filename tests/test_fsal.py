"""First-same-as-last Störmer–Verlet (issue 26, item 2; methodgen/fsal.py): the force at a
stage's end starts the next stage, step and chunk.

(a) Against the step without first-same-as-last: a plain numpy reference written here
    (kick-drift-kick per stage, ∇U twice per stage).  Agreement is to round-off, not to
    the bit, and that is by design: the carried force is evaluated at the stage end's exact
    numerical state through the step's own sums, ``q0 + (Δq + c)``, where the step without
    first-same-as-last evaluated it afresh at the stored ``q1`` plus its compensation --
    the same point in exact arithmetic, rounded differently (and the generated kernels
    associate ``(h/2)·∇U`` differently from the reference).  Control: the reference with
    one wrong composition coefficient is far outside that tolerance.
(b) A run in three chunks passing ``info`` is bitwise the run in one piece; dropping
    ``info["force"]`` changes the bits (negative control); a malformed record is refused,
    one from another state or other parameters is not used.
(c) The composed orders 4 and 8 are still reached (error ratios under halving h).
The force count per stage is measured in tests/test_force_count.py.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from conftest import HH_T, HH_Y0

#: Agreement with the reference over STEPS steps: round-off of ~STEPS·stages operations.
TOL = 1e-12
STEPS = 200
H = 0.1


@pytest.fixture(scope="module")
def hh():
    return mg.load_scene("henon-heiles-2d").run_system


@pytest.fixture(scope="module")
def sv4(hh):
    return mg.build(hh, "stormer-verlet", order=4)


@pytest.fixture(scope="module")
def sv4_numba(hh):
    pytest.importorskip("numba")
    return mg.build(hh, "stormer-verlet", order=4, backend="numba")


def _grad_u(q):
    q1, q2 = q
    return np.array([q1 + 2 * q1 * q2, q2 + q1 * q1 - q2 * q2])


def _reference(y0, h, steps, gammas):
    """Composed Störmer–Verlet for Hénon–Heiles, two force evaluations per stage."""
    q, p = np.array(y0[:2]), np.array(y0[2:])
    for _ in range(steps):
        for g in gammas:
            hs = g * h
            p = p - hs / 2 * _grad_u(q)
            q = q + hs * p
            p = p - hs / 2 * _grad_u(q)
    return np.concatenate([q, p])


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_equals_two_force_reference_to_roundoff(sv4, sv4_numba, backend):
    mod = sv4 if backend == "numpy" else sv4_numba
    gam = [float(g) for g in mod.GAMMAS]
    ref = _reference(HH_Y0, H, STEPS, gam)
    for compensated in (True, False):
        got = mod.integrate(HH_Y0, H, STEPS, compensated=compensated)[-1]
        assert np.abs(got - ref).max() < TOL
    # control: one wrong coefficient (the set no longer sums to 1) is seen
    bad = list(gam)
    bad[0] *= 1 + 1e-6
    assert np.abs(_reference(HH_Y0, H, STEPS, bad) - ref).max() > 1e3 * TOL


def _chunked(mod, y0, h, splits, drop=False, params=None):
    info = {}
    y, parts = np.asarray(y0, dtype=float), []
    for n in splits:
        part = mod.integrate(y, h, n, params, info=info)
        parts.append(part if not parts else part[1:])
        y = part[-1]
        if drop:
            info.pop("force")
    return np.concatenate(parts)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("batch", [False, True], ids=["one", "batch"])
def test_chunks_are_bitwise_one_piece(sv4, sv4_numba, backend, batch):
    mod = sv4 if backend == "numpy" else sv4_numba
    y0 = np.stack([HH_Y0, 0.8 * HH_Y0]) if batch else HH_Y0
    whole = mod.integrate(y0, H, 300)
    assert np.array_equal(_chunked(mod, y0, H, [100, 77, 123]), whole)
    # negative control: without the carried force each chunk starts from a fresh
    # evaluation at y + c, which rounds differently from the carried one at some chunk
    # boundaries only (measured: 138 of 300 one-step chunks for one trajectory, none of
    # the two boundaries above), so the control chunks step by step, and the bits change
    dropped = _chunked(mod, y0, H, [1] * 300, drop=True)
    assert not np.array_equal(dropped, whole)
    assert np.abs(dropped - whole).max() < TOL


def test_t_eval_and_iterate_carry_the_force(sv4):
    whole = sv4.integrate(HH_Y0, H, 300)
    at = sv4.integrate(HH_Y0, H, t_eval=[0.0, 10 * H, 150 * H, 300 * H])
    assert np.array_equal(at, whole[[0, 10, 150, 300]])
    assert np.array_equal(np.concatenate(list(sv4.iterate(HH_Y0, H, 300, chunk=70))), whole)


def test_a_malformed_record_is_refused(sv4):
    info = {}
    part = sv4.integrate(HH_Y0, H, 10, info=info)
    y, comp, p, g = info["force"]
    with pytest.raises(ValueError, match=r"info\['force'\] holds a force of shape \(3,\)"):
        sv4.integrate(part[-1], H, 10, info={"compensation": comp, "force": (y, comp, p, np.zeros(3))})
    with pytest.raises(ValueError, match=r"info\['force'\] must be the record"):
        sv4.integrate(part[-1], H, 10, info={"compensation": comp, "force": g})


def test_a_record_of_another_state_is_not_used(sv4):
    info = {}
    sv4.integrate(HH_Y0, H, 10, info=info)
    y, comp, p, g = info["force"]
    other = 0.9 * HH_Y0
    fresh = sv4.integrate(other, H, 50)
    # the record belongs to another state: it must not be used (a used one would start
    # the run with the force at y, wrong by O(|y - other|))
    reused = sv4.integrate(other, H, 50, info={"force": (y, comp, p, g)})
    assert np.array_equal(reused, fresh)
    # control: the same force presented as this state's record is used, and it is wrong
    forged = sv4.integrate(other, H, 50, info={"force": (other.copy(), np.zeros(4), p, g)})
    assert np.abs(forged - fresh).max() > 1e-6


def test_a_record_for_other_parameters_is_not_used():
    sc = mg.load_scene("simple-pendulum")
    mod = mg.build(sc.run_system, "stormer-verlet", order=4)
    y0 = np.array(sc.y0)
    info = {}
    part = mod.integrate(y0, 0.05, 20, info=info)
    g2 = {"g": 2 * mod.DEFAULT_PARAMS["g"]}
    info2 = {"compensation": info["compensation"]}
    fresh = mod.integrate(part[-1], 0.05, 30, g2, info=info2)
    carried = mod.integrate(part[-1], 0.05, 30, g2, info=dict(info))
    assert np.array_equal(carried, fresh)
    # control: with the parameters it was made for, the record is used (other bits)
    assert not np.array_equal(mod.integrate(part[-1], 0.05, 30, info=dict(info)),
                              mod.integrate(part[-1], 0.05, 30, info=info2))


@pytest.mark.parametrize("K, N", [(4, 32), (8, 8)])
def test_composed_order(hh, hh_reference, K, N):
    mod = mg.build(hh, "stormer-verlet", order=K)
    errs = [float(np.abs(mod.integrate(HH_Y0, HH_T / n, n, check_resolution=False)[-1] - hh_reference).max())
            for n in (N, 2 * N)]
    assert errs[1] > 3e-13, f"error {errs[1]:.1e} at 2N is at round-off: the case measures nothing"
    assert errs[0] / errs[1] >= 2 ** (K - 0.7), f"order {np.log2(errs[0] / errs[1]):.2f} < {K} - 0.7 ({errs})"


def test_extended_refinement_with_the_carried_force(sv4):
    """extended=True moves the state off the double-precision step, so there the force is
    evaluated afresh at each stage's end: the same method to round-off, chunks bitwise."""
    ref = sv4.integrate(HH_Y0, H, 60)
    whole = sv4.integrate(HH_Y0, H, 60, extended=True)
    assert np.abs(whole - ref).max() < TOL
    parts = np.concatenate(list(sv4.iterate(HH_Y0, H, 60, chunk=25, extended=True)))
    assert np.array_equal(parts, whole)


def test_the_plan_is_checked_against_the_scheme(hh):
    """The first-same-as-last step with G0 = ∇U(q0) is the scheme's increment, expression for
    expression (exact, no floating point); a scheme whose increment differs gets no plan."""
    import dataclasses

    from methodgen.fsal import fsal_plan
    scheme = mg.discretize(hh, "stormer-verlet")
    plan = fsal_plan(scheme)
    assert plan is not None and len(plan.symbols) == 2
    # negative control: the same method name with another increment (second kick doubled)
    d = len(plan.symbols)
    inc = list(scheme.increment)
    changed = dataclasses.replace(scheme, increment=type(scheme.increment)(inc[:d] + [2 * e for e in inc[d:]]))
    assert fsal_plan(changed) is None
    assert fsal_plan(mg.discretize(hh, "midpoint")) is None
