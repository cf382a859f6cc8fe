"""Wisdom–Holman splittings on the outer solar system against heyoka, IAS15, WHFast and our
composed Störmer–Verlet, in one run.

Not a test: run it and read the table (about a minute; the numba runtime compiles once, ~10 s).

    python benchmarks/wisdom_holman.py [--json benchmarks/wisdom_holman.json]

Problem: the built-in ``outer-solar-system`` scene, T = 2·10⁵ days (issue 26's definition).
Every row: CPU (``time.process_time``) of the integration call for the end state only, min of
5; error at T in the max norm against heyoka in long double (tol 1e-18); the relative energy
error is the maximum over every step of an untimed rerun (WHFast: a heartbeat per step).
methodgen's Wisdom–Holman families run with the corrector of Laskar & Robutel (2001) except
the classic ``wisdom-holman``; REBOUND's WHFast uses Jacobi coordinates and its order-11 and
order-17 symplectic correctors.  The frontier table gives, per error level, each tool's
cheapest run and our time over each peer's (below 1: we are faster).
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

import methodgen as mg
from methodgen.app import peers
from methodgen.runtime.nbody import MAX_STEP_FRACTION, wisdom_holman

T = 2.0e5
LEVELS = (1e-6, 1e-8, 1e-9, 1e-10, 1e-11, 4e-12)
FAMILIES = (("wisdom-holman", False), ("saba3", True), ("saba4", True), ("sbab3", True), ("sbab4", True),
            ("sbab5", True))


def rel_energy(H):
    return float(np.max(np.abs(H - H[0])) / abs(H[0]))


def ours(scene, y0, ref):
    rows = []
    for family, corr in FAMILIES:
        wh = wisdom_holman(scene, family, corrector=corr)
        top = MAX_STEP_FRACTION * float(np.min(wh.periods(y0)))
        wh.integrate(y0, top, 1)
        for k in range(12 if family == "wisdom-holman" else 24):
            steps = int(math.ceil(T / (top / 2 ** (k / 4 if corr else k / 2))))
            h = T / steps
            cpu, Y = peers.min_cpu(lambda: wh.integrate(y0, h, steps, save_every=steps), repeats=5)
            traj = wh.integrate(y0, h, steps)
            assert np.array_equal(traj[-1], Y[-1])
            row = {"tool": "methodgen", "method": wh.METHOD, "h": h, "steps": steps, "cpu": cpu,
                   "error": float(np.max(np.abs(Y[-1] - ref))), "energy_rel": rel_energy(wh.hamiltonian(traj))}
            rows.append(row)
            print(f"{row['method']:24s} h={h:8.2f} cpu={cpu:.4f} err={row['error']:.2e} dE={row['energy_rel']:.1e}",
                  flush=True)
            if row["error"] < 2e-12:
                break
    return rows


def composed(scene, y0, ref):
    """Our best composed explicit method before this work (Störmer–Verlet, orders 8 and 10)."""
    rows = []
    for order in (8, 10):
        mod = mg.build(scene.system, "stormer-verlet", backend="numba", order=order)
        mod.integrate(y0, 100.0, 2, check_resolution=False)
        for h in (200.0, 160.0, 125.0, 100.0, 80.0):
            steps = int(round(T / h))
            cpu, Y = peers.min_cpu(lambda: mod.integrate(y0, T / steps, steps, save_every=steps,
                                                         check_resolution=False), repeats=5)
            traj = mod.integrate(y0, T / steps, steps, save_every=max(1, steps // 2000), check_resolution=False)
            row = {"tool": "methodgen", "method": f"stormer-verlet o{order}", "h": T / steps, "steps": steps,
                   "cpu": cpu, "error": float(np.max(np.abs(Y[-1] - ref))),
                   "energy_rel": rel_energy(mod.hamiltonian(traj))}
            rows.append(row)
            print(f"{row['method']:24s} h={row['h']:8.2f} cpu={cpu:.4f} err={row['error']:.2e} "
                  f"dE={row['energy_rel']:.1e}", flush=True)
    return rows


def heyoka(scene, y0, ref):
    rows = []
    for tol in (1e-9, 1e-12, 1e-15):
        ta = peers._heyoka_integrator(scene.system, y0, tol)

        def run():
            ta.time = 0.0
            ta.state[:] = y0
            return ta.propagate_until(T)

        cpu, _ = peers.min_cpu(run, repeats=5)
        err = float(np.max(np.abs(np.array(ta.state) - ref)))
        rows.append({"tool": "heyoka", "method": f"heyoka tol {tol:g}", "tol": tol, "cpu": cpu, "error": err})
        print(f"heyoka tol {tol:g}: cpu={cpu:.4f} err={err:.2e}", flush=True)
    return rows


def rebound(scene, y0, ref):
    import rebound as rb

    rows = []
    runs = [("ias15", eps, None) for eps in (1e-5, 1e-7, 1e-9)]
    runs += [("whfast", h, c) for c in (11, 17) for h in (40.0, 20.0, 10.0, 5.0)]
    for integrator, param, corr in runs:
        def run():
            sim = peers._rebound_sim(rb, scene, y0, integrator, param)
            if corr is not None:
                peers._configure(sim, "whfast", corrector=corr)
            t0 = time.process_time()
            sim.integrate(T, exact_finish_time=0 if integrator == "whfast" else 1)
            return time.process_time() - t0, sim

        best, sim = math.inf, None
        for _ in range(5):
            sec, sim = run()
            best = min(best, sec)
        state = peers._rebound_state(scene, sim)
        name = "REBOUND IAS15" if integrator == "ias15" else f"REBOUND WHFast c{corr}"
        row = {"tool": name, "method": name, "cpu": best, "error": float(np.max(np.abs(state - ref))),
               ("tol" if integrator == "ias15" else "h"): param, "t_end": sim.t}
        rows.append(row)
        print(f"{name:24s} {param:g}: cpu={best:.4f} err={row['error']:.2e} (t = {sim.t:g})", flush=True)
    return rows


def frontier(rows):
    tools = sorted({r["tool"] for r in rows}, key=lambda t: (t != "methodgen", t))
    out = []
    for level in LEVELS:
        best = {}
        for r in rows:
            if r["error"] <= level and (r["tool"] not in best or r["cpu"] < best[r["tool"]]["cpu"]):
                best[r["tool"]] = r
        out.append({"level": level, "best": best})
        ours_ = best.get("methodgen")
        cells = []
        for t in tools:
            b = best.get(t)
            cells.append(f"{t}: " + ("—" if b is None else f"{b['cpu']:.4f} s ({b['method']}"
                                     + (f", h = {b['h']:.3g}" if 'h' in b else "") + ")"))
            if t != "methodgen" and b is not None and ours_ is not None:
                cells[-1] += f" ratio {ours_['cpu'] / b['cpu']:.2f}"
        print(f"error ≤ {level:g}:  " + ";  ".join(cells))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json")
    a = ap.parse_args()
    scene = mg.load_scene("outer-solar-system")
    y0 = np.array(scene.y0)
    ref = peers.heyoka_reference(scene.system, y0, T)
    t = time.perf_counter()
    wisdom_holman(scene, "sbab4").integrate(y0, 100.0, 1)
    print(f"first use of the Wisdom–Holman runtime in this process: {time.perf_counter() - t:.2f} s")
    rows = ours(scene, y0, ref) + composed(scene, y0, ref) + heyoka(scene, y0, ref) + rebound(scene, y0, ref)
    table = frontier(rows)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump({"T": T, "versions": peers.versions(), "rows": rows,
                       "frontier": [{"level": e["level"], "best": e["best"]} for e in table]}, fh, indent=1)


if __name__ == "__main__":
    main()
