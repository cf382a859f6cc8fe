"""Events of ``mod.solve`` and Poincaré sections (methodgen.runtime.events), on both backends.

A crossing is located on the method's own map (the sub-step τ with g(Φ_τ(y_n)) = 0), so the
located state keeps what the method keeps: energy-momentum's located states keep H to
round-off, where a linear interpolation between the steps does not (the control).  Located
crossings agree with a reference root (the same map, bisected independently to adjacent
floats); a wrong direction is caught; text is parsed by the whitelist parser.
"""

from __future__ import annotations

import numpy as np
import pytest

import methodgen as mg
from methodgen.errors import InputError, ParseError

BACKENDS = ["numpy", pytest.param("numba", marks=pytest.mark.skipif(
    __import__("importlib").util.find_spec("llvmlite") is None, reason="llvmlite not installed"))]
Y0 = np.array([0.0, 0.1, 0.35, 0.2])      # Hénon–Heiles (q1, q2, p1, p2), H ≈ 0.086
H = 0.05


@pytest.fixture(scope="module")
def hh2d():
    return mg.load_scene("henon-heiles-2d").system


@pytest.fixture(scope="module", params=BACKENDS)
def em(request, hh2d):
    return mg.build(hh2d, "energy-momentum", backend=request.param)


def _q1(t, y):
    return y[..., 0]


def _up(fn, **attrs):
    def g(t, y):
        return fn(t, y)
    g.direction = 1.0
    for k, v in attrs.items():
        setattr(g, k, v)
    return g


def test_located_states_keep_h_and_control_linear_interpolation(em):
    sol = em.solve(Y0, (0.0, 60.0), H, events=_up(_q1))
    ye = sol.y_events[0]
    assert sol.status == 0 and len(ye) >= 5
    H0 = float(em.hamiltonian(Y0))
    assert np.abs(ye[:, 0]).max() <= 1e-14 * np.abs(Y0).max()          # |g| at the located states
    assert np.abs(em.hamiltonian(ye) - H0).max() <= 4 * np.finfo(float).eps * abs(H0)
    # control: linear interpolation between the steps around each crossing
    Y = em.integrate(Y0, sol.h, sol.nsteps)
    i = np.flatnonzero((Y[:-1, 0] < 0) & (Y[1:, 0] >= 0))
    w = -Y[i, 0] / (Y[i + 1, 0] - Y[i, 0])
    lin = Y[i] + w[:, None] * (Y[i + 1] - Y[i])
    assert len(i) == len(ye)
    assert np.abs(em.hamiltonian(lin) - H0).max() > 1e3 * np.abs(em.hamiltonian(ye) - H0).max() + 1e-12


def _bisect(mod, y, h, fn):
    """Reference root of g(Φ_τ(y)) on (0, h): plain bisection on the same map."""
    a, b = 0.0, h
    ga = fn(0.0, y)
    for _ in range(200):
        m = 0.5 * (a + b)
        if m in (a, b):
            break
        gm = fn(0.0, mod.integrate(y, m, 1)[1])
        if (gm > 0) == (ga > 0):
            a, ga = m, gm
        else:
            b = m
    return a, b


def test_crossing_agrees_with_a_reference_root(em):
    sol = em.solve(Y0, (0.0, 20.0), H, events=_up(_q1))
    te = sol.t_events[0][0]
    n = int(te // sol.h)
    y_n = em.integrate(Y0, sol.h, n)[-1]
    a, b = _bisect(em, y_n, sol.h, _q1)
    tau = te - n * sol.h
    assert a - 4e-16 * sol.h <= tau <= b + 4e-16 * sol.h + 1e-15


def test_direction_is_honoured_and_a_wrong_sign_is_caught(em):
    up = em.solve(Y0, (0.0, 40.0), H, events=_up(_q1)).y_events[0]
    both = em.solve(Y0, (0.0, 40.0), H, events=_q1).y_events[0]
    down = em.solve(Y0, (0.0, 40.0), H, events=_up(_q1, direction=-1.0)).y_events[0]
    assert (up[:, 2] > 0).all() and (down[:, 2] < 0).all()       # ẋ = p1 at q1 = 0
    assert len(both) == len(up) + len(down)
    # control: the other sign gives the other crossings
    assert not np.array_equal(up, down)


def test_terminal_stops_at_the_nth_crossing(em):
    sol = em.solve(Y0, (0.0, 200.0), H, events=_up(_q1, terminal=3), save_every=10)
    assert sol.status == 1 and "terminal event" in sol.message
    assert len(sol.t_events[0]) == 3 and sol.t[-1] == sol.t_events[0][-1]
    assert np.array_equal(sol.y[-1], sol.y_events[0][-1])
    # the rows before the crossing are the run's rows
    full = em.integrate(Y0, sol.h, sol.nsteps, save_every=10)
    assert np.array_equal(sol.y[:len(full) - 1], full[:-1])


def test_text_events_poincare_section(em):
    t, pts, sol = mg.poincare(em, Y0, H, "q1 = 0, p1 > 0", crossings=12)
    assert sol.status == 1 and pts.shape == (12, 4) and (pts[:, 2] > 0).all()
    assert np.abs(pts[:, 0]).max() <= 1e-14
    # the same run with a hand-written event (poincare's span: 1e6 h) gives the same states
    ref = em.solve(Y0, (0.0, 1e6 * H), H, events=_up(_q1, terminal=12))
    assert ref.h == sol.h and np.array_equal(pts, ref.y_events[0])
    ring = mg.event(em, "q1**2 + q2**2 = 0.04", direction=-1)
    s2 = em.solve(Y0, (0.0, 30.0), H, events=[ring, mg.event(em, "q2")])
    r2 = (s2.y_events[0][:, :2] ** 2).sum(axis=1)
    assert len(r2) and np.abs(r2 - 0.04).max() <= 1e-15


def test_sympy_events_are_the_text_events(em):
    """A SymPy expression (or equation) in symbols named as the state gives the text's event;
    control: another expression gives other crossings; a foreign symbol is refused."""
    import sympy as sp
    q1, q2 = sp.symbols("q1 q2")            # without real=True: matched by name
    text = em.solve(Y0, (0.0, 30.0), H, events=mg.event(em, "q1**2 + q2**2 = 0.04", direction=-1))
    expr = em.solve(Y0, (0.0, 30.0), H, events=mg.event(em, sp.Eq(q1**2 + q2**2, sp.Rational(1, 25)),
                                                         direction=-1))
    assert len(text.t_events[0]) and np.array_equal(text.t_events[0], expr.t_events[0])
    other = em.solve(Y0, (0.0, 30.0), H, events=mg.event(em, q1**2 + q2**2 - sp.Rational(1, 16), direction=-1))
    assert not np.array_equal(other.t_events[0], text.t_events[0])
    with pytest.raises(InputError, match="not state components"):
        mg.event(em, sp.Symbol("zz") + q1)


def test_event_text_is_data(em):
    with pytest.raises(ParseError, match="only direct calls of|unknown function"):
        mg.event(em, "__import__('os').system('true')")
    with pytest.raises(ParseError, match="unknown symbol 'zz'"):
        mg.event(em, "zz + 1")
    with pytest.raises(InputError, match="lhs = rhs"):
        mg.section_event(em, "q1 > 0")
    with pytest.raises(InputError, match="one comparison"):
        mg.event(em, "q1", condition="p1")


def test_events_in_a_batch_are_each_trajectorys(em):
    """A batch's crossings, with the trajectory of each, are those of each trajectory run alone
    (times to 1e-13) and keep H; control: the trajectory indices are not all one lane's."""
    Y = np.array([Y0, [0.0, -0.1, 0.3, 0.1], [0.0, 0.2, 0.2, 0.3]])
    ev = _up(_q1)
    sol = em.solve(Y, (0.0, 40.0), H, events=ev)
    lanes = sol.trajectory_events[0]
    assert sol.y.shape == (801, 3, 4) and set(lanes.tolist()) == {0, 1, 2}
    for b in range(3):
        alone = em.solve(Y[b], (0.0, 40.0), H, events=ev)
        assert np.array_equal(alone.trajectory_events[0], np.zeros(len(alone.t_events[0]), dtype=np.int64))
        mine = np.sort(sol.t_events[0][lanes == b])
        assert len(mine) == len(alone.t_events[0]) and np.abs(mine - alone.t_events[0]).max() <= 1e-13
        Hb = em.hamiltonian(sol.y_events[0][lanes == b])
        assert np.abs(Hb - em.hamiltonian(Y[b])).max() <= 4 * np.finfo(float).eps * abs(float(em.hamiltonian(Y[b])))


def test_events_refuse_what_they_cannot_do(em):
    with pytest.raises(ValueError, match="terminal events need one trajectory"):
        em.solve(np.stack([Y0, Y0]), (0.0, 1.0), H, events=_up(_q1, terminal=True))
    with pytest.raises(ValueError, match="t_eval and events"):
        em.solve(Y0, (0.0, 1.0), H, events=_q1, t_eval=[0.0, 1.0])


def test_cli_section(tmp_path, capsys):
    """``methodgen run SCENE --section TEXT [--plot F] [--json]``: the crossings in --steps steps;
    a malformed section is a one-line error with exit 2 (no traceback)."""
    import json

    from methodgen.app.cli import main

    argv = ["run", "henon-heiles-2d", "--y0", "0,0.1,0.35,0.2", "--h", "0.05", "--steps", "2000",
            "--section", "q1 = 0, p1 > 0"]
    assert main(argv + ["--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["crossings"] == len(rep["y_events"]) >= 5 and rep["max_abs_g"] <= 1e-14
    assert rep["invariant_errors_at_crossings"]["H"] <= 1e-15
    assert all(p[2] > 0 for p in rep["y_events"])
    plot = tmp_path / "section.png"
    assert main(argv + ["--plot", str(plot)]) == 0
    assert plot.stat().st_size > 1000 and "crossings of 'q1 = 0, p1 > 0'" in capsys.readouterr().out
    assert main(argv[:-1] + ["q1 > 0"]) == 2
    err = capsys.readouterr().err
    assert "lhs = rhs" in err and "Traceback" not in err


def test_section_figure_is_returned():
    pytest.importorskip("matplotlib")
    from methodgen.app.plots import section_figure

    pts = np.array([[0.0, 0.1, 0.3, 0.2], [0.0, -0.1, 0.2, 0.1]])
    fig = section_figure(pts, ["q1", "q2", "p1", "p2"], "q1 = 0, p1 > 0")
    ax = fig.axes[0]
    # the plane of the coordinate the surface does not name: (q2, p2)
    assert ax.get_xlabel() == "q2" and ax.get_ylabel() == "p2"
    assert np.array_equal(ax.lines[0].get_xdata(), pts[:, 1])
