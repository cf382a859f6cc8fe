"""Explicit adaptivity: the log-Hamiltonian leapfrog composed to high order against heyoka and IAS15.

Not a test: run it and read the table (never assert wall time).

    python benchmarks/kepler_logh.py [--backend numba] [--ecc 0.6 0.9 0.99] [--T 2000] [--project]

For each eccentricity, in one run on this machine: the generated Störmer–Verlet module of the
logarithmic Hamiltonian (``methodgen.time_transform(system, form="log")``, drift–kick–drift
leapfrog of Λ = log(T + e) − log(−U), composed to order 2…10) run to the physical time T with
:func:`methodgen.runtime.physical_time.run_to_time` (whole fictive steps, then one step solved to land
on t = T); heyoka ``taylor_adaptive`` (tol 1e-15, double); REBOUND IAS15 (default ε = 1e-9).
Rows: least CPU seconds of the integration call over 3 repeats (module build / compile and
integrator set-up excluded), the max-norm error of (q, p) at T against the exact Kepler
solution (Kepler's equation solved with mpmath at 40 digits), and the relative energy error at T.
``--project`` adds each configuration with the standard projection onto the log form's Λ
(``project="energy-standard"``), and a column with the largest relative error of the physical H
over every fictive step of an untimed run of the same steps (the frontier's "energy kept" test).
"""

from __future__ import annotations

import argparse
import math
import time

import mpmath
import numpy as np

import methodgen as mg
from methodgen.runtime.physical_time import run_to_time

H_TEXT = "(px**2 + py**2 + pz**2)/(2*m) - k/sqrt(x**2 + y**2 + z**2)"


def kepler_y0(ecc):
    """Pericentre of the orbit a = 1 (period 2π) in the direction of the kepler scene's y0."""
    r0 = 1 - ecc
    v0 = math.sqrt((1 + ecc) / (1 - ecc))
    return np.array([r0, 0.0, 0.0, 0.0, 0.8 * v0, 0.6 * v0])


def kepler_exact(ecc, T):
    """The state at T of the orbit of :func:`kepler_y0` (a = 1, k = m = 1), at 40 digits."""
    mpmath.mp.dps = 40
    e = mpmath.mpf(ecc)
    M = mpmath.mpf(T) % (2 * mpmath.pi)
    E = mpmath.findroot(lambda E: E - e * mpmath.sin(E) - M, M + e * mpmath.sin(M))
    b = mpmath.sqrt(1 - e * e)
    den = 1 - e * mpmath.cos(E)
    u = np.array([1.0, 0.0, 0.0])
    w = np.array([0.0, 0.8, 0.6])
    xq, yq = mpmath.cos(E) - e, b * mpmath.sin(E)
    vx, vy = -mpmath.sin(E) / den, b * mpmath.cos(E) / den
    return np.concatenate([float(xq) * u + float(yq) * w, float(vx) * u + float(vy) * w])


def energy(y):
    return 0.5 * float(y[3:] @ y[3:]) - 1.0 / math.sqrt(float(y[:3] @ y[:3]))


def min_cpu(fn, repeats=3):
    best, out = math.inf, None
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def ours(system, ecc, T, order, h, backend, project=None):
    L = mg.time_transform(system, form="log")
    mod = mg.build(L, "stormer-verlet", backend=backend, order=order,
                   **({"project": project} if project else {}))
    y0 = kepler_y0(ecc)
    Y0 = mod.initial_state(y0)
    run_to_time(mod, Y0, min(T, 1.0), h)     # compile / warm up outside the timed region
    info = {}
    sec, Y = min_cpu(lambda: run_to_time(mod, Y0, T, h, info=info))
    y, t = mod.physical_state(Y)
    # the physical H over every fictive step (untimed)
    ys, _ = mod.physical_state(mod.integrate(Y0, h, info["steps"]))
    E = 0.5 * np.sum(ys[:, 3:] ** 2, axis=1) - 1 / np.sqrt(np.sum(ys[:, :3] ** 2, axis=1))
    info["max_dE"] = float(np.max(np.abs(E - E[0])) / abs(E[0]))
    return sec, y, info


def heyoka_row(system, ecc, T, tol=1e-15):
    from methodgen.app.peers import _heyoka_integrator
    y0 = kepler_y0(ecc)
    ta = _heyoka_integrator(system, y0, tol)

    def run():
        ta.time = 0.0
        ta.state[:] = y0
        return ta.propagate_until(float(T))

    sec, out = min_cpu(run)
    return sec, np.array(ta.state), int(out[3])


def ias15_row(ecc, T, epsilon=1e-9):
    import rebound

    from methodgen.app.peers import _configure
    y0 = kepler_y0(ecc)
    sims = []

    def run():
        sim = rebound.Simulation()
        sim.G = 1.0
        sim.add(m=1.0)       # a fixed centre: the body is a test particle, as in H
        sim.add(m=0.0, x=y0[0], y=y0[1], z=y0[2], vx=y0[3], vy=y0[4], vz=y0[5])
        sim.integrator = "ias15"
        _configure(sim, "ias15", epsilon=epsilon)
        sims.append(sim)
        t0 = time.process_time()
        sim.integrate(T, exact_finish_time=1)
        return time.process_time() - t0

    best = min(run() for _ in range(3))
    sim = sims[-1]
    c, p = sim.particles[0], sim.particles[1]
    y = np.array([p.x - c.x, p.y - c.y, p.z - c.z, p.vx - c.vx, p.vy - c.vy, p.vz - c.vz])
    return best, y, int(sim.steps_done)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--ecc", type=float, nargs="+", default=[0.6, 0.9, 0.99])
    ap.add_argument("--T", type=float, default=2000.0)
    ap.add_argument("--orders", type=int, nargs="+", default=[2, 4, 6, 8, 10])
    ap.add_argument("--steps-per-orbit", type=int, nargs="+", default=[25, 50, 100, 200, 400])
    ap.add_argument("--project", action="store_true", help="add the standard projection's rows")
    args = ap.parse_args()
    system = mg.Hamiltonian(H_TEXT, q=["x", "y", "z"], p=["px", "py", "pz"], params={"m": 1.0, "k": 1.0},
                            name="kepler3")
    print(f"{'ecc':>5} {'method':<28} {'CPU s':>9} {'error at T':>11} {'rel dE at T':>11} {'max rel dE':>11}  notes")
    for ecc in args.ecc:
        ref = kepler_exact(ecc, args.T)
        E0 = energy(kepler_y0(ecc))
        for order in args.orders:
            for spo in args.steps_per_orbit:
                h = 2 * math.pi / spo      # fictive time per orbit: ∮ (k/r) dt = 2π for a = 1
                for project in (None, "energy-standard") if args.project else (None,):
                    name = f"logH SV o{order:<2}" + (" proj" if project else "     ")
                    try:
                        sec, y, info = ours(system, ecc, args.T, order, h, args.backend, project)
                    except Exception as exc:   # a refused run is a result too
                        print(f"{ecc:5.2f} {name} h=2π/{spo:<4}  refused: {str(exc)[:90]}")
                        continue
                    err = float(np.max(np.abs(y - ref)))
                    dE = abs(energy(y) - E0) / abs(E0)
                    print(f"{ecc:5.2f} {name} h=2π/{spo:<7} {sec:9.4f} {err:11.2e} {dE:11.2e} {info['max_dE']:11.2e}  "
                          f"steps {info['steps']}, calls {info['calls']}, |t-T| {abs(info['t_error']):.1e}")
        sec, y, n = heyoka_row(system, ecc, args.T)
        print(f"{ecc:5.2f} {'heyoka taylor tol 1e-15':<28} {sec:9.4f} {float(np.max(np.abs(y - ref))):11.2e} "
              f"{abs(energy(y) - E0) / abs(E0):11.2e}  steps {n}")
        try:
            sec, y, n = ias15_row(ecc, args.T)
            print(f"{ecc:5.2f} {'REBOUND IAS15 eps 1e-9':<28} {sec:9.4f} {float(np.max(np.abs(y - ref))):11.2e} "
                  f"{abs(energy(y) - E0) / abs(E0):11.2e}  steps {n}")
        except ImportError:
            print(f"{ecc:5.2f} REBOUND not installed")


if __name__ == "__main__":
    main()
