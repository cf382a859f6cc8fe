"""First-same-as-last Störmer–Verlet (issue 26, item 2; methodgen/symbolic/fsal.py): the force at a
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
(d) A record of another module (its key: backend, signature, method, order, H) or of another
    state shape is not used; the record keeps the compensation the last stage used.
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
def sv4(hh):
    return mg.build(hh, "stormer-verlet", order=4)


@pytest.fixture(scope="module")
def sv4_numba(hh):
    pytest.importorskip("llvmlite")
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
    # One-step chunks: a fresh evaluation at y + c rounds differently from the carried
    # force at some boundaries only (measured: 25 of 300 steps for one trajectory, and a
    # differing force need not change the state's bits), so only chunks at every step make
    # a record that is ignored visible.
    assert np.array_equal(_chunked(mod, y0, H, [1] * 300), whole)
    # negative control: without the carried force the bits change
    dropped = _chunked(mod, y0, H, [1] * 300, drop=True)
    assert not np.array_equal(dropped, whole)
    assert np.abs(dropped - whole).max() < TOL


def _perturbed_record(info):
    """``info`` with its force record's force changed by a relative 1e-9: a record the
    module accepts (its key, state, compensation and parameters; within the carried force's
    tolerance of ∇U at the state) whose use is visible in the bits."""
    key, y, comp, p, g = info["force"]
    return {"compensation": info["compensation"], "force": (key, y, comp, p, g * (1 + 1e-9))}


def test_t_eval_and_iterate_carry_the_force(sv4):
    whole = sv4.integrate(HH_Y0, H, 300)
    every = np.arange(301) * H
    assert np.array_equal(sv4.integrate(HH_Y0, H, t_eval=every), whole)
    assert np.array_equal(np.concatenate(list(sv4.iterate(HH_Y0, H, 300, chunk=1))), whole)
    # negative control: the same one-step segments without the carried force
    assert not np.array_equal(_chunked(sv4, HH_Y0, H, [1] * 300, drop=True), whole)


def test_t_eval_starts_from_an_incoming_record(sv4):
    whole = sv4.integrate(HH_Y0, H, 300)
    info = {}
    part = sv4.integrate(HH_Y0, H, 37, info=info)
    at = sv4.integrate(part[-1], H, t_eval=np.arange(264) * H, info=dict(info))
    assert np.array_equal(at, whole[37:])
    # The incoming record reaches the first segment: a (valid, perturbed) record changes the
    # t_eval run exactly as it changes the plain run; without it passed on, the t_eval run
    # would be the fresh one.
    fresh = sv4.integrate(part[-1], H, 263, info={"compensation": info["compensation"]})
    plain = sv4.integrate(part[-1], H, 263, info=_perturbed_record(info))
    at = sv4.integrate(part[-1], H, t_eval=np.arange(264) * H, info=_perturbed_record(info))
    assert not np.array_equal(plain, fresh)  # control: the perturbed record is visible
    assert np.array_equal(at, plain)


def test_a_malformed_record_is_refused(sv4):
    info = {}
    part = sv4.integrate(HH_Y0, H, 10, info=info)
    key, y, comp, p, g = info["force"]
    with pytest.raises(ValueError, match=r"info\['force'\] is inconsistent: state \(4,\), compensation \(4,\), "
                                         r"force \(3,\)"):
        sv4.integrate(part[-1], H, 10, info={"compensation": comp, "force": (key, y, comp, p, np.zeros(3))})
    with pytest.raises(ValueError, match=r"info\['force'\] must be the record"):
        sv4.integrate(part[-1], H, 10, info={"compensation": comp, "force": g})
    with pytest.raises(ValueError, match=r"info\['force'\] must be the record"):
        sv4.integrate(part[-1], H, 10, info={"compensation": comp, "force": (y, comp, p, g)})


def test_a_record_of_another_state_is_not_used(sv4):
    info = {}
    sv4.integrate(HH_Y0, H, 10, info=info)
    key, y, comp, p, g = info["force"]
    other = 0.9 * HH_Y0
    fresh = sv4.integrate(other, H, 50)
    # the record belongs to another state: it must not be used (a used one would start
    # the run with the force at y, wrong by O(|y - other|))
    reused = sv4.integrate(other, H, 50, info={"force": (key, y, comp, p, g)})
    assert np.array_equal(reused, fresh)
    # control: the same force presented as this state's record is not ∇U there: refused
    with pytest.raises(ValueError, match=r"is not the force ∇U at its state \(relative difference"):
        sv4.integrate(other, H, 50, info={"force": (key, other.copy(), np.zeros(4), p, g)})


def test_a_record_of_another_state_shape_is_ignored(sv4):
    """A well-formed single-trajectory record given to a batch run (no compensation) is
    "not this state": the batch starts afresh instead of raising."""
    info = {}
    sv4.integrate(HH_Y0, H, 5, info=info)
    Y0 = np.stack([HH_Y0, HH_Y0])
    assert np.array_equal(sv4.integrate(Y0, H, 5, info={"force": info["force"]}), sv4.integrate(Y0, H, 5))


def _other_potential(y0_like):
    """A module of another H with the state shape of ``y0_like`` and no parameters."""
    import sympy as sp
    d = len(y0_like) // 2
    q = sp.symbols(f"q1:{d + 1}", real=True)
    p = sp.symbols(f"p1:{d + 1}", real=True)
    H = sum(pi ** 2 for pi in p) / 2 + sum(qi ** 4 for qi in q) / 4 + q[0] * q[-1]
    return mg.build(mg.Hamiltonian(H, list(q), list(p), name=f"fsal_other_{d}"), "stormer-verlet", order=4)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_record_of_another_module_is_not_used(sv4, sv4_numba, backend):
    """Two modules of the same state shape and parameters: continuing the second from the
    first's end state with the first's info must not use the first's force."""
    mod = sv4 if backend == "numpy" else sv4_numba
    other = _other_potential(HH_Y0)  # numpy: the record's module, cheap
    info = {}
    end = other.integrate(HH_Y0, H, 10, info=info)[-1]
    fresh = mod.integrate(end, H, 50, info={"compensation": info["compensation"]})
    shared = mod.integrate(end, H, 50, info=dict(info))
    assert np.array_equal(shared, fresh)
    # negative control: the same record under this module's key passes the check on the key,
    # and its force is the other H's: the check of the force against ∇U at the state refuses it
    key, y, comp, p, g = info["force"]
    with pytest.raises(ValueError, match=r"info\['force'\] is not the force ∇U at its state"):
        mod.integrate(end, H, 50, info={"compensation": comp, "force": (mod._FSAL_KEY, y, comp, p, g)})


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_the_record_keeps_the_compensation_used(sv4, sv4_numba, backend):
    """compensated=False steps with the incoming compensation unchanged: the record holds it
    (not zeros), so it describes the state the force was evaluated at."""
    sv4 = sv4 if backend == "numpy" else sv4_numba
    info = {}
    sv4.integrate(HH_Y0, H, 37, info=info)
    comp_in = info["compensation"].copy()
    assert np.any(comp_in != 0)  # control: zeros would not tell the two apart
    end = sv4.integrate(sv4.integrate(HH_Y0, H, 37)[-1], H, 20, info=info, compensated=False)[-1]
    _, y, comp, _, _ = info["force"]
    assert np.array_equal(y, end) and np.array_equal(comp, comp_in)
    assert not np.any(info["compensation"])  # what integrate reports for compensated=False


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
    """extended=True: the refined increment is evaluated afresh in long double (two forces) and
    does not use the carried force, which feeds only the checks of the next post kernel.  So
    this shows the same method to round-off and extended chunks bitwise the run in one piece
    -- not that the force is carried (the trajectory does not depend on it); that is
    test_chunks_are_bitwise_one_piece's job."""
    ref = sv4.integrate(HH_Y0, H, 60)
    whole = sv4.integrate(HH_Y0, H, 60, extended=True)
    assert np.abs(whole - ref).max() < TOL
    parts = np.concatenate(list(sv4.iterate(HH_Y0, H, 60, chunk=25, extended=True)))
    assert np.array_equal(parts, whole)


def test_extended_record_holds_the_force_at_its_state(sv4):
    """The refined state is off the double-precision step's end, so the record an extended run
    leaves is evaluated at the state it names (y + compensation), bitwise."""
    info = {}
    sv4.integrate(HH_Y0, H, 60, extended=True, info=info)
    _, y, comp, p, g = info["force"]
    assert np.array_equal(g, sv4._v_force(y, comp, p))
    # control: the comparison sees the compensation (the force at y alone differs)
    assert not np.array_equal(g, sv4._v_force(y, np.zeros_like(comp), p))


def test_the_plan_is_checked_against_the_scheme(hh):
    """The first-same-as-last step with G0 = ∇U(q0) is the scheme's increment, expression for
    expression (exact, no floating point); a scheme whose increment differs gets no plan."""
    import dataclasses

    from methodgen.symbolic.fsal import fsal_plan
    scheme = mg.discretize(hh, "stormer-verlet")
    plan = fsal_plan(scheme)
    assert plan is not None and len(plan.symbols) == 2
    # negative control: the same method name with another increment (second kick doubled)
    d = len(plan.symbols)
    inc = list(scheme.increment)
    changed = dataclasses.replace(scheme, increment=type(scheme.increment)(inc[:d] + [2 * e for e in inc[d:]]))
    assert fsal_plan(changed) is None
    assert fsal_plan(mg.discretize(hh, "midpoint")) is None


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_an_edited_carried_force_is_refused(sv4, sv4_numba, backend):
    """A carried force edited in place (×1.5: used silently before, a 1.3e-3 final error) is
    refused; a copy of the record (pickled, as a worker process would get it) is checked and
    accepted, bitwise the run in one piece; the record as left is used without a check."""
    import pickle

    mod = sv4 if backend == "numpy" else sv4_numba
    whole = mod.integrate(HH_Y0, H, 60)
    info = {}
    part = mod.integrate(HH_Y0, H, 30, info=info)
    copied = pickle.loads(pickle.dumps(info))
    assert np.array_equal(np.concatenate([part, mod.integrate(part[-1], H, 30, info=copied)[1:]]), whole)
    kept = info["force"][4].copy()
    info["force"][4][...] *= 1.5
    with pytest.raises(ValueError, match=r"relative difference 0.5 in a component, tolerance 1e-08"):
        mod.integrate(part[-1], H, 30, info=info)
    info["force"][4][...] = kept                    # control: the record as it was left
    assert np.array_equal(np.concatenate([part, mod.integrate(part[-1], H, 30, info=info)[1:]]), whole)


def test_an_edited_small_component_is_refused(tmp_path):
    """The tolerance is per component: a light body's small force component ×1000 is refused
    although it is far below the largest component; control: the record as left is used."""
    mod = mg.generate(mg.discretize(mg.Hamiltonian("(p1**2 + p2**2)/2 + q1**2/2 + 1e-12*q2**2/2",
                                                   ["q1", "q2"], ["p1", "p2"]), "stormer-verlet"),
                      tmp_path / "light.py")
    y0 = np.array([0.6, 1.0, 0.1, 0.2])
    info = {}
    part = mod.integrate(y0, 0.1, 10, info=info)
    kept = info["force"][4].copy()
    info["force"][4][..., 1] *= 1000
    with pytest.raises(ValueError, match="is not the force ∇U at its state"):
        mod.integrate(part[-1], 0.1, 10, info=info)
    info["force"][4][...] = kept                    # control: the record as it was left
    whole = mod.integrate(y0, 0.1, 20)
    assert np.array_equal(np.concatenate([part, mod.integrate(part[-1], 0.1, 10, info=info)[1:]]), whole)
