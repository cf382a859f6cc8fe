"""Splitting families against heyoka and IAS15 on Hénon–Heiles and the outer solar system.

Not a test: run it and read the table (issue 26, item 2).

    python benchmarks/splitting_speed.py [--scene henon-heiles-2d|outer-solar-system] [--quick]

Every row comes from one run on this machine: methodgen's numba modules (Störmer–Verlet,
its compositions and the splitting families, ``composition=``), heyoka's
``taylor_adaptive`` in double precision, and for the N-body scene REBOUND's IAS15.  Times
are the CPU time of the integration call alone (``time.process_time``), the minimum of 3
calls, after compilation / set-up.  Errors: the largest component of the final state's
difference from heyoka in long double (``high_accuracy=True``, tol 1e-18); the relative
energy error is ``max_n |H(y_n) - H(y_0)| / |H(y_0)|`` over every step of methodgen's rows
and over heyoka's own steps (its dense trajectory is not formed).  Targets: final error
≤ 1e-10 and relative energy error ≤ 1e-14.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

import methodgen as mg
from methodgen.app import peers

#: (order, family, step sizes) per scene: the rows of methodgen.
ROWS = {
    "henon-heiles-2d": [(10, None, (0.2,)), (8, None, (0.2,)),
                        (6, "blanes-moan-rkn", (0.1, 0.125, 0.2, 0.4)), (6, "blanes-moan", (0.1, 0.2)),
                        (4, "blanes-moan-rkn", (0.05,)), (4, "blanes-moan", (0.05,)), (4, "mclachlan", (0.05,))],
    "outer-solar-system": [(8, None, (40.0,)), (6, "blanes-moan-rkn", (20.0, 25.0, 40.0, 80.0)),
                           (6, "blanes-moan", (20.0, 40.0)), (4, "blanes-moan-rkn", (20.0,))],
}
T_OF = {"henon-heiles-2d": 1e4, "outer-solar-system": 2e5}


def cpu_min(run, repeats=3):
    best, out = math.inf, None
    for _ in range(repeats):
        t0 = time.process_time()
        out = run()
        best = min(best, time.process_time() - t0)
    return best, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="henon-heiles-2d", choices=sorted(ROWS))
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    scene = mg.load_scene(args.scene)
    system, y0, T = scene.run_system, np.array(scene.y0, dtype=float), T_OF[args.scene]
    ref = peers.heyoka_reference(system, y0, T)
    rows = []
    H0 = None
    for order, family, hs in ROWS[args.scene]:
        mod = mg.build(system, "stormer-verlet", backend="numba", order=order, composition=family)
        H0 = float(mod.hamiltonian(y0))
        for h in hs:
            n = round(T / h)
            h = T / n
            mod.integrate(y0, h, 10)  # compiled already; warm the caches
            sec, traj = cpu_min(lambda: mod.integrate(y0, h, n))
            E = np.abs(mod.hamiltonian(traj) - H0) / abs(H0)
            rows.append({"method": f"SV o{order} {family or 'default'}", "stages": len(mod.DRIFT), "h": h,
                         "cpu_s": sec, "us_per_step": 1e6 * sec / n, "error": float(np.abs(traj[-1] - ref).max()),
                         "energy_rel_max": float(E.max())})
    # heyoka, double precision, tol 1e-15 (and 1e-12 for scale)
    for tol in (1e-15, 1e-12):
        ta = peers._heyoka_integrator(system, y0, tol)
        states = []

        def run():
            ta.time = 0.0
            ta.state[:] = y0
            return ta.propagate_until(float(T))

        sec, _ = cpu_min(run)
        final = np.array(ta.state)
        ta.time = 0.0
        ta.state[:] = y0
        ta.propagate_until(float(T), callback=lambda i: states.append(np.array(i.state)) or True)
        E = np.abs(mod.hamiltonian(np.array(states)) - H0) / abs(H0)
        rows.append({"method": f"heyoka tol {tol:g}", "cpu_s": sec, "error": float(np.abs(final - ref).max()),
                     "energy_rel_max": float(E.max())})
    if scene.nbody is not None:
        rebound = peers.import_peer("rebound")
        for eps in (1e-9,):
            best, sim = math.inf, None
            for _ in range(3):
                sim = peers._rebound_sim(rebound, scene, y0, "ias15", eps)
                t0 = time.process_time()
                sim.integrate(T)
                best = min(best, time.process_time() - t0)
            final = peers._rebound_state(scene, sim)
            rows.append({"method": f"REBOUND IAS15 eps {eps:g}", "cpu_s": best,
                         "error": float(np.abs(final - ref).max()),
                         "energy_rel_final": float(abs(mod.hamiltonian(final) - H0) / abs(H0))})
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    print(f"{args.scene}: T = {T:g}, reference heyoka long double tol 1e-18; CPU min of 3")
    for r in rows:
        extra = f"  h = {r['h']:<8.4g} {r['us_per_step']:7.2f} µs/step" if "h" in r else " " * 30
        e = r.get("energy_rel_max", r.get("energy_rel_final"))
        print(f"  {r['method']:<32}{extra}  CPU {r['cpu_s']:8.4f} s  error {r['error']:.2e}  "
              f"rel. energy error {e:.2e}")


if __name__ == "__main__":
    main()
