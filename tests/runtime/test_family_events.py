"""Events of the family modules' ``solve`` (lattice 1-D, 2-D, particles) and their Poincaré
sections: one implementation (:func:`methodgen.runtime.events.solve_family`) for all of them.

A crossing is located on the method's own map, the sub-step τ with g(Φ_τ(y_n)) = 0, so the
located state is bitwise ``step(y_n, τ)`` and energy-momentum's located states keep H to
round-off, where a linear interpolation between the steps does not (the control); g there is
zero to round-off, where τ moved by 1e-9 h is not (the control); a direction finds its
crossings and the other direction the others; a terminal count stops at its crossing; the
numpy and compiled lattice modules locate the same times; a crossing that cannot be located
(a failing step, no bracket) is reported, never guessed; bad input says what is valid.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.app.particles_scene import load_particles_scene
from methodgen.codegen.particle_emit import build_particles
from methodgen.errors import InputError, ParseError
from methodgen.runtime.events import solve_family

H_RING = 0.02           # nbody-ring: radius 1 .. 2.5 at N = 3, period 2π at r = 1: ~300 steps an orbit
EPS = np.finfo(float).eps


@pytest.fixture(scope="module")
def ring():
    """The nbody-ring scene at N = 3 (a star and two light planets): energy-momentum's module,
    the start and the masses."""
    sc = load_particles_scene("nbody-ring")
    y0, arrays = sc.state(3)
    return sc, y0, arrays


@pytest.fixture(scope="module")
def em(ring, tmp_path_factory):
    return build_particles(ring[0].family, "energy-momentum", tmp_path_factory.mktemp("fev") / "ring_em.py")


def _y2(t, y):
    """The second body's y (state (x1, y1, x2, y2, x3, y3, px1, …), particle-major)."""
    return y[..., 3]


def _with(fn, **attrs):
    def g(t, y):
        return fn(t, y)
    for k, v in attrs.items():
        setattr(g, k, v)
    return g


@pytest.fixture(scope="module")
def ring_run(ring, em):
    """Every upward crossing of y2 = 0 over 1.3 orbits of the inner planet (at t ≈ 0 and 2π),
    rows every step."""
    _, y0, arrays = ring
    return em.solve(y0, (0.0, 8.0), H_RING, arrays=arrays, events=_with(_y2, direction=1.0))


def test_located_states_are_steps_of_the_method_and_keep_h(ring, em, ring_run):
    """Each located state is bitwise ``step(y_n, τ)`` (y_n the run's row, τ the reported
    sub-step) and keeps H to 1e-13 relative; control: the linear interpolant between y_n and
    y_(n+1) at its own zero is another state, off in H by far more."""
    _, y0, arrays = ring
    sol = ring_run
    ye, n, tau = sol.y_events[0], sol.n_events[0], sol.tau_events[0]
    assert sol.status == 0 and len(ye) >= 2
    assert np.array_equal(sol.t_events[0], sol.t[n] + tau)
    H0 = em.hamiltonian(y0, arrays=arrays)
    for k in range(len(ye)):
        assert 0.0 < tau[k] <= sol.h
        assert np.array_equal(em.step(sol.y[n[k]], tau[k], arrays=arrays), ye[k])
        assert abs(em.hamiltonian(ye[k], arrays=arrays) - H0) <= 1e-13 * abs(H0)
        # control: linear interpolation across the same step
        a, b = sol.y[n[k]], sol.y[n[k] + 1]
        lin = a + (-a[3] / (b[3] - a[3])) * (b - a)
        assert not np.array_equal(lin, ye[k])
        assert abs(em.hamiltonian(lin, arrays=arrays) - H0) > 1e3 * max(
            abs(em.hamiltonian(ye[k], arrays=arrays) - H0), 1e-13 * abs(H0))


def test_g_is_zero_at_the_located_state(ring, em, ring_run):
    """|g| at each located state is within a few ulps of the coordinates' scale; control: τ
    moved by 1e-9 h gives |g| far above that bound (so the bound resolves τ)."""
    _, _, arrays = ring
    sol = ring_run
    scale = np.abs(sol.y[:, :6]).max()
    bound = 4 * np.spacing(scale)
    for y_at, n, tau in zip(sol.y_events[0], sol.n_events[0], sol.tau_events[0]):
        assert abs(_y2(0.0, y_at)) <= bound
        for off in (-1e-9 * sol.h, 1e-9 * sol.h):
            assert abs(_y2(0.0, em.step(sol.y[n], tau + off, arrays=arrays))) > 10 * bound


def test_direction_filters_and_the_other_direction_finds_the_others(ring, em, ring_run):
    """Upward crossings of y2 = 0 are at x2 > 0 (counter-clockwise orbits), downward at x2 < 0;
    both directions together are the union; control: the two sets are disjoint."""
    _, y0, arrays = ring
    up = ring_run
    down = em.solve(y0, (0.0, 8.0), H_RING, arrays=arrays, events=_with(_y2, direction=-1.0))
    both = em.solve(y0, (0.0, 8.0), H_RING, arrays=arrays, events=_y2)
    assert (up.y_events[0][:, 2] > 0).all() and (down.y_events[0][:, 2] < 0).all()
    assert len(down.t_events[0]) >= 1
    assert np.array_equal(np.sort(np.r_[up.t_events[0], down.t_events[0]]), both.t_events[0])
    assert not set(up.t_events[0].tolist()) & set(down.t_events[0].tolist())


def test_terminal_stops_at_the_first_and_at_the_nth_crossing(ring, em, ring_run):
    """terminal=True ends the run at the first crossing, terminal=2 at the second: status 1,
    the message names the event, the last row is the located state and the rows before it are
    the run's (the same chunks as the run without terminal: bitwise); control: the two stops
    differ."""
    _, y0, arrays = ring
    full = ring_run
    one = em.solve(y0, (0.0, 8.0), H_RING, arrays=arrays, events=[_y2, _with(_y2, direction=1.0, terminal=True)])
    two = em.solve(y0, (0.0, 8.0), H_RING, arrays=arrays, events=_with(_y2, direction=1.0, terminal=2))
    for sol, k in ((one, 1), (two, 2)):
        ev = sol.t_events[-1]
        assert sol.status == 1 and sol.success and f"event {len(sol.t_events) - 1}" in sol.message
        assert len(ev) == k and ev[-1] == full.t_events[0][k - 1] and sol.t[-1] == ev[-1]
        assert np.array_equal(sol.y[-1], sol.y_events[-1][-1])
        assert np.array_equal(sol.y[:-1], full.y[:len(sol.y) - 1])
    # the non-terminal event of the same list records the crossings before the stop (y2 starts just below 0)
    assert len(one.t_events[0]) >= 1 and one.t_events[0].max() <= one.t[-1]
    assert one.t[-1] != two.t[-1]


def test_text_events_and_a_poincare_section(ring, em, ring_run):
    """``mg.poincare`` takes text over the family's indexed fields: ``"y[2] = 0, py[2] > 0"`` gives
    the hand-written upward crossings bitwise; ``x[N]`` resolves at each size and ``m[i]`` from
    the arrays; control: another size's x[N] is another body."""
    sc, y0, arrays = ring
    t, pts, sol = mg.poincare(em, y0, H_RING, "y[2] = 0, py[2] > 0", crossings=2, arrays=arrays)
    assert sol.status == 1 and pts.shape == (2, 12)
    assert np.array_equal(pts, ring_run.y_events[0][:2]) and np.array_equal(t, ring_run.t_events[0][:2])
    far = mg.event(em, "x[N]**2 + y[N]**2 = 4")
    assert far(0.0, y0) == pytest.approx(y0[4] ** 2 + y0[5] ** 2 - 4, abs=1e-15)
    y4, _ = sc.state(4)
    assert far(0.0, y4) == pytest.approx(y4[6] ** 2 + y4[7] ** 2 - 4, abs=1e-15)
    assert far(0.0, y4) != pytest.approx(y4[4] ** 2 + y4[5] ** 2 - 4, abs=1e-6)       # control
    momentum = mg.event(em, "Sum(px[i], i, 1, N)", arrays=arrays)
    assert momentum(0.0, y0) == pytest.approx(y0[6] + y0[8] + y0[10], abs=1e-18)
    weighted = mg.event(em, "m[2]*x[2]", arrays=arrays)
    assert weighted(0.0, y0) == pytest.approx(arrays["m"][1] * y0[2], rel=1e-15)


def test_a_lattice_locates_the_same_times_on_both_backends(tmp_path):
    """sine-Gordon at N = 16, q[1] crossing 0: the numpy and compiled modules (the same rows
    bitwise) locate the same times to round-off (4 ulps; bitwise here) and the same states to
    round-off (the one fresh step from a row is not bitwise across the backends), g is zero to
    round-off, AVF's energy is kept at the located states, and text and callable events agree
    bitwise; control: the linear interpolant's zero of q[1] is off by far more."""
    pytest.importorskip("llvmlite")
    sc = mg.load_lattice_scene("sine-gordon")
    y0 = sc.y0(16)
    got = {}
    for backend in ("numpy", "compiled"):
        mod = mg.build_lattice(sc.lattice, "avf", tmp_path / f"sg_{backend}.py", backend=backend)
        sol = mod.solve(y0, (0.0, 5.0), 0.02, events=mg.event(mod, "q[1] = 0"))
        assert len(sol.t_events[0]) >= 2
        assert np.abs(sol.y_events[0][:, 0]).max() <= 4 * np.spacing(np.abs(sol.y[:, :16]).max())
        H0 = mod.hamiltonian(y0)
        assert max(abs(mod.hamiltonian(y) - H0) for y in sol.y_events[0]) <= 1e-13 * abs(H0)
        n, tau = sol.n_events[0], sol.tau_events[0]
        assert np.array_equal(mod.step(sol.y[n[0]], tau[0]), sol.y_events[0][0])
        if backend == "numpy":
            call = mod.solve(y0, (0.0, 5.0), 0.02, events=lambda t, y: y[0])
            assert np.array_equal(sol.t_events[0], call.t_events[0])
        got[backend] = sol
    a, b = got["numpy"], got["compiled"]
    assert np.array_equal(a.y, b.y)
    assert np.abs(a.t_events[0] - b.t_events[0]).max() <= 4 * np.spacing(a.t_events[0]).max()
    assert np.abs(a.y_events[0] - b.y_events[0]).max() <= 4 * np.spacing(np.abs(a.y).max())
    # control: the zero of q[1] interpolated linearly between the rows
    n = a.n_events[0]
    q0, q1 = a.y[n, 0], a.y[n + 1, 0]
    lin = a.t[n] + a.h * q0 / (q0 - q1)
    assert np.abs(lin - a.t_events[0]).min() > 1e6 * np.spacing(a.t_events[0]).max()


def test_a_2d_lattice_takes_callables_and_refuses_text(tmp_path):
    """Klein–Gordon 2-D at 6 × 6: a terminal callable on the site (1, 1) stops at its second
    crossing, the located state (2, N, M) bitwise ``step(y_n, τ)``; with save_every=5 the same
    crossing and the rows every 5 steps of the run (bitwise those of save_every=1); text is
    refused with what to give instead."""
    sc = mg.load_lattice_scene("klein-gordon-2d")
    mod = mg.build_lattice(sc.lattice, "avf", tmp_path / "kg.py")
    y0 = sc.y0((6, 6))
    g = _with(lambda t, y: y[..., 0, 0, 0], terminal=2)
    sol = mod.solve(y0, (0.0, 12.0), 0.04, events=g)
    assert sol.status == 1 and sol.y_events[0].shape == (2, 2, 6, 6)
    assert np.array_equal(sol.y[-1], sol.y_events[0][-1]) and sol.t[-1] == sol.t_events[0][-1]
    n, tau = sol.n_events[0][-1], sol.tau_events[0][-1]
    assert np.array_equal(mod.step(sol.y[n], tau), sol.y_events[0][-1])
    assert abs(sol.y_events[0][-1][0, 0, 0]) <= 4 * np.spacing(np.abs(sol.y[:, 0]).max())
    thin = mod.solve(y0, (0.0, 12.0), 0.04, events=g, save_every=5)
    assert np.array_equal(thin.y_events[0], sol.y_events[0])
    assert np.array_equal(thin.y[:-2], sol.y[:-2][::5]) and np.array_equal(thin.y[-2], sol.y[-2])
    with pytest.raises(InputError, match="callable g"):
        mg.event(mod, "q[1] = 0")


def test_bad_input_says_what_is_valid(ring, em):
    _, y0, arrays = ring
    with pytest.raises(ValueError, match="events must be a callable"):
        em.solve(y0, (0.0, 1.0), H_RING, arrays=arrays, events=[_y2, "y[2]"])
    with pytest.raises(ValueError, match=r"takes the options \['arrays', 'maxiter', 'tol'\].*t_eval"):
        em.solve(y0, (0.0, 1.0), H_RING, arrays=arrays, events=_y2, t_eval=[0.0, 1.0])
    with pytest.raises(ValueError, match="terminal must be a bool or a count"):
        em.solve(y0, (0.0, 1.0), H_RING, arrays=arrays, events=_with(_y2, terminal=-1))
    with pytest.raises(InputError, match=r"write x\[k\]; valid: x\[k\], y\[k\], px\[k\], py\[k\]"):
        mg.event(em, "x = 0")
    with pytest.raises(InputError, match="text over its indexed fields"):
        import sympy as sp
        mg.event(em, sp.Symbol("x1"))
    with pytest.raises(InputError, match="pass arrays="):
        mg.event(em, "m[1]*x[1]")
    with pytest.raises(ParseError, match="only direct calls of"):
        mg.event(em, "__import__('os').system('true')")
    with pytest.raises(InputError, match="lhs = rhs"):
        mg.section_event(em, "x[1] > 0")


def _failing(integrate, when):
    """``integrate`` whose one-step calls of a sub-step (the location's) are changed by ``when``."""
    def run(y0, h, steps, params=None, **kw):
        out = integrate(y0, h, steps, params, **kw)
        return when(out, h) if steps == 1 else out
    run.__signature__ = __import__("inspect").signature(integrate)
    return run


@pytest.mark.parametrize("fault,match", [
    ("raise", "failed while locating"),
    ("shift", "cannot be located on the method's map"),
])
def test_a_crossing_that_cannot_be_located_is_reported(ring, em, fault, match):
    """A step failing while locating, or a fresh step that does not show the run's sign change
    (here: its end moved to the side the step started on), ends the run with status -1 and says why; no crossing is recorded and
    the run's rows end at the step's start; control: the same run unchanged locates it."""
    _, y0, arrays = ring

    def when(out, h):
        if fault == "raise":
            raise em.ConvergenceError("step 0: injected", step=0, residual=1.0)
        out = out.copy()
        out[-1, 3] = 1e-3 if out[-1, 3] < 0 else out[-1, 3]
        return out

    kw = dict(save_every=1, options={"arrays": arrays}, invariants=lambda y: em.invariants(y, None, arrays),
              solution=em.Solution, failures=(em.ConvergenceError, em.NonFiniteError))
    down = _with(_y2, direction=-1.0)          # (the first downward crossing is near t = π, step 157)
    sol = solve_family(_failing(em.integrate, when), y0, 0.0, H_RING, 400, None, down, **kw)
    assert sol.status == -1 and not sol.success and match in sol.message
    assert len(sol.t_events[0]) == 0
    n = int(round(sol.t[-1] / H_RING))
    assert n > 100 and sol.nsteps == n and sol.y[-1][3] > 0 and sol.t[-1] == n * H_RING
    control = solve_family(em.integrate, y0, 0.0, H_RING, 400, None, down, **kw)
    assert control.status == 0 and len(control.t_events[0]) == 1 and control.n_events[0][0] == n
