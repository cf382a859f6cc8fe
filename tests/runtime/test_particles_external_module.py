"""Energy-momentum particle modules with an external potential and above order 2: H kept to
round-off with a central trap (and L) and with an anisotropic one (L not claimed, and not kept),
Störmer–Verlet the control; the order shown numerically by halving h; the numpy module and the
compiled pair loops agreeing to round-off (the compiled loops bit for bit the plain-Python run of
the same stepper); a stage that does not converge says which."""

from __future__ import annotations

import numpy as np
import pytest

from methodgen.codegen.particle_emit import build_particles
from methodgen.problem.particles import Particles
from methodgen.symbolic.particle_scheme import certificates, discretize_particles, proved_invariants

KIN = "Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N)"
COUL = " + Sum(Sum(k/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)"
TRAP = " + Sum(m[i]*w**2*(x[i]**2 + y[i]**2)/2, i, 1, N)"
ANIS = " + Sum(m[i]*(w**2*x[i]**2 + 4*y[i]**2)/2 + x[i]**2*y[i]**2/8, i, 1, N)"
EPS = 2.220446049250313e-16


def family(W, name):
    return Particles(KIN + COUL + W, q=["x", "y"], p=["px", "py"], arrays=["m"], params={"k": 1.0, "w": 1.0},
                     name=name)


@pytest.fixture(scope="module")
def modules(tmp_path_factory):
    d = tmp_path_factory.mktemp("particles_ext")
    out = {}
    for name, W in (("trap", TRAP), ("anis", ANIS)):
        f = family(W, name)
        out[name] = f
        for method, order, backend in (("energy-momentum", 2, "numpy"), ("energy-momentum", 4, "numpy"),
                                       ("energy-momentum", 6, "numpy"), ("stormer-verlet", 2, "numpy"),
                                       ("energy-momentum", 4, "compiled")):
            if backend == "compiled":
                pytest.importorskip("llvmlite")
            out[name, method, order, backend] = build_particles(f, method, d / f"{name}{method}{order}{backend}.py",
                                                                order=order, backend=backend)
    return out


def crystal(n, seed=0):
    """Charges on a sunflower spiral of the trap's size, spinning, masses 0.5 … 1.5, jittered."""
    rng = np.random.default_rng(seed)
    r = np.sqrt((np.arange(n) + 0.5) / n) * n ** (1 / 3)
    a = 2.399963 * np.arange(n)
    q = np.stack([r * np.cos(a), r * np.sin(a)], axis=1) + 0.05 * rng.standard_normal((n, 2))
    m = 0.5 + rng.random(n)
    p = m[:, None] * 0.3 * np.stack([-q[:, 1], q[:, 0]], axis=1)
    return np.concatenate([q.ravel(), p.ravel()]), m


def drift(mod, T, m):
    inv = [mod.invariants(r, arrays={"m": m}) for r in T]
    return {k: max(abs(v[k] - inv[0][k]) for v in inv) for k in inv[0]}, inv[0]


def test_central_trap_keeps_h_and_l_and_stormer_verlet_does_not_keep_h(modules):
    y0, m = crystal(6)
    em, sv = modules["trap", "energy-momentum", 2, "numpy"], modules["trap", "stormer-verlet", 2, "numpy"]
    e, start = drift(em, em.integrate(y0, 0.01, 1000, arrays={"m": m}, save_every=10), m)
    c, _ = drift(sv, sv.integrate(y0, 0.01, 1000, arrays={"m": m}, save_every=10), m)
    H = abs(start["H"])
    assert e["H"] <= 1e-13 * H and e["L"] <= 1e-13 * max(1.0, abs(start["L"]))
    assert c["H"] > 1e-7 * H                                  # the control: a visible (bounded) energy error
    assert e["Px"] > 1e-2                                     # P is not kept, and not claimed
    scheme = discretize_particles(modules["trap"], "energy-momentum")
    assert set(proved_invariants(scheme, certificates(scheme))) == {"H", "L"}


def test_anisotropic_trap_keeps_h_and_l_is_not_claimed(modules):
    y0, m = crystal(5, seed=1)
    em, sv = modules["anis", "energy-momentum", 2, "numpy"], modules["anis", "stormer-verlet", 2, "numpy"]
    e, start = drift(em, em.integrate(y0, 0.01, 1000, arrays={"m": m}, save_every=10), m)
    c, _ = drift(sv, sv.integrate(y0, 0.01, 1000, arrays={"m": m}, save_every=10), m)
    assert e["H"] <= 1e-13 * abs(start["H"]) and c["H"] > 1e-7 * abs(start["H"])
    assert e["L"] > 1e-3                                      # the torque of the anisotropic trap: L changes
    scheme = discretize_particles(modules["anis"], "energy-momentum")
    assert scheme.external_kind == "itoh-abe"
    assert set(proved_invariants(scheme, certificates(scheme))) == {"H"}
    assert "not L" in em.__doc__


@pytest.mark.parametrize("order", [4, 6])
def test_composed_energy_momentum_shows_its_order_and_keeps_h(modules, order):
    """Numerical, not a proof: the error at t = 1 against an order-8 composition at h = 1/32 falls by
    about 2^order per halving of h (accepted: above 0.75 · 2^order); H to round-off at every h."""
    f = modules["trap"]
    ref = build_particles(f, "energy-momentum", order=8)
    y0, m = crystal(4, seed=2)
    yref = ref.integrate(y0, 1 / 32, 32, arrays={"m": m}, save_every=32)[-1]
    mod = modules["trap", "energy-momentum", order, "numpy"]
    assert mod.ORDER == order and len(mod.GAMMAS) > 1 and min(mod.GAMMAS) < 0     # negative stages included
    errs = []
    for k in (4, 8, 16):
        T = mod.integrate(y0, 1 / k, k, arrays={"m": m})
        errs.append(np.max(np.abs(T[-1] - yref)))
        e, start = drift(mod, T, m)
        assert e["H"] <= 1e-13 * abs(start["H"])
    ratios = [errs[i] / errs[i + 1] for i in range(2)]
    assert all(r > 0.75 * 2 ** order for r in ratios), ratios
    # the control: order 2 at the same h falls by about 4 only
    base = modules["trap", "energy-momentum", 2, "numpy"]
    e2 = [np.max(np.abs(base.integrate(y0, 1 / k, k, arrays={"m": m})[-1] - yref)) for k in (4, 8)]
    assert e2[0] / e2[1] < 5


@pytest.mark.parametrize("name", ["trap", "anis"])
def test_numpy_and_compiled_agree_and_the_compiled_loop_is_the_python_run(modules, name):
    """The compiled pair loops (order 4: five stages, with W) against the same stepper run as Python:
    bit for bit; against the numpy module's vectorised step: to round-off (1e-13 after 100 steps; the
    pair sums are associated differently)."""
    from methodgen.runtime import particle_driver as drv

    mod = modules[name, "energy-momentum", 4, "compiled"]
    assert mod.HAS_EXTERNAL == 1
    y0, m = crystal(5, seed=3)
    n = 5
    Q, P = y0[:2 * n].reshape(n, 2), y0[2 * n:].reshape(n, 2)
    runs = []
    for python in (False, True):
        T, _, status = drv.run_em(mod._vel, mod._gpair, mod._gext, Q.copy(), P.copy(), m[None, :].copy(), (1.0, 1.0),
                                  0.01, 20, 1, 100, 4 * EPS, mod.GAMMAS, mod.HAS_EXTERNAL, python=python)
        assert status[0] == 0
        runs.append(T)
    assert np.array_equal(runs[0], runs[1])
    a = modules[name, "energy-momentum", 4, "numpy"].integrate(y0, 0.01, 100, arrays={"m": m})
    b = mod.integrate(y0, 0.01, 100, arrays={"m": m})
    assert np.max(np.abs(a - b)) < 1e-13
    # the control: without the external potential's discrete gradient the run is another one
    T, _, _ = drv.run_em(mod._vel, mod._gpair, mod._gext, Q.copy(), P.copy(), m[None, :].copy(), (1.0, 1.0),
                         0.01, 20, 1, 100, 4 * EPS, mod.GAMMAS, 0, python=False)
    assert np.max(np.abs(T - runs[0])) > 1e-6


def test_a_stage_that_does_not_converge_says_which(modules):
    y0, m = crystal(4, seed=4)
    for key in (("trap", "energy-momentum", 4, "numpy"), ("trap", "energy-momentum", 4, "compiled")):
        mod = modules[key]
        with pytest.raises(mod.ConvergenceError, match=r"step 0 \(stage 1 of 5\).*did not converge") as exc:
            mod.integrate(y0, 2.0, 3, arrays={"m": m}, maxiter=3)
        assert exc.value.step == 0 and exc.value.residual > 0


@pytest.mark.parametrize("W,kind", [(" - Sum(m[i]/sqrt(x[i]**2 + y[i]**2 + 1/4), i, 1, N)", "central"),
                                    (" - Sum(m[i]/sqrt((x[i] - 1)**2 + y[i]**2 + 1/4), i, 1, N)", "itoh-abe")])
def test_the_discrete_gradient_of_w_has_no_cancellation_as_q1_tends_to_q0(W, kind, tmp_path):
    """G(q0, q0 + δ) for δ = 1e-9 … 0 as printed in the module: within 1e-14 of ∇W at the midpoint (the
    two differ by O(δ²)); the naive quotient (W(q1) - W(q0))/δ of the same W, the control, is off by
    about ε/δ."""
    f = family(W, f"cf_{kind.replace('-', '_')}")
    assert discretize_particles(f, "energy-momentum").external_kind == kind
    mod = build_particles(f, "energy-momentum", tmp_path / "m.py")
    rng = np.random.default_rng(5)
    Q0 = rng.uniform(-2, 2, (6, 2))
    M = np.ones((1, 6))
    p = (1.0, 1.0)

    def W_at(Q):
        return -1 / np.sqrt((Q[:, 0] - (kind == "itoh-abe")) ** 2 + Q[:, 1] ** 2 + 0.25)

    def grad(Q):
        r3 = ((Q[:, 0] - (kind == "itoh-abe")) ** 2 + Q[:, 1] ** 2 + 0.25) ** 1.5
        return np.stack([(Q[:, 0] - (kind == "itoh-abe")) / r3, Q[:, 1] / r3], axis=1)

    naive_err = 0.0
    for delta in (1e-9, 1e-12, 0.0):
        Q1 = Q0 + delta
        G = np.stack(mod._external_g(Q0, Q1, M, p), axis=1)
        assert np.all(np.isfinite(G))
        err = np.max(np.abs(G - grad((Q0 + Q1) / 2)))
        assert err < 1e-14 * np.max(np.abs(grad(Q0))) + 1e-15
        if delta:
            D = np.zeros_like(Q0)
            D[:, 0] = delta
            naive_err = max(naive_err, np.max(np.abs((W_at(Q0 + D) - W_at(Q0)) / delta - grad(Q0 + D / 2)[:, 0])))
    assert naive_err > 1e-6                              # the control: the cancellation this form avoids


@pytest.mark.parametrize("order", [3, 10, "4"])
def test_build_refuses_an_order_not_offered_naming_the_valid_ones(modules, order, tmp_path):
    from methodgen.errors import InputError

    with pytest.raises(InputError, match="the orders are 2, 4, 6, 8"):
        build_particles(modules["trap"], "energy-momentum", tmp_path / "bad.py", order=order)
    assert not (tmp_path / "bad.py").exists()
