"""Processed compositions against the unprocessed ones and heyoka, at equal final error.

Not a test: run it and read the table (issue 26, item 2; methodgen/symbolic/processing.py).

    python benchmarks/processed.py [--problems kepler,hh,oss] [--backend numba] [--json FILE]

For each problem every (family, order, h) row reports the CPU seconds of the integration call
(``time.process_time``, minimum of 3, compiled before timing) over T keeping the end state
only (``save_every=steps``), and the CPU of one run keeping about 1000 rows (a processed run
post-processes the rows it returns, so it pays its processor per kept row), the final-state error against heyoka in long double (tol 1e-18) and the
largest relative energy error over the kept rows.  Families: Störmer–Verlet and
energy–momentum composed by the default families (Kahan–Li order 8, Sofroniou–Spaletta order 10)
and processed (Blanes–Casas–Murua orders 6 and 8).  heyoka's ``taylor_adaptive`` (double,
tol 1e-15, 1e-12) runs in the same process.  Then, at error levels every family reaches, the
CPU of each family's cheapest row (log-log interpolation, ``projection_vs_em.cpu_at``) and the
ratio to the unprocessed order-8 composition of the same base method.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

import methodgen as mg
from methodgen.app import peers
from methodgen.codegen.build import build_processed

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from projection_vs_em import cpu_at  # noqa: E402

#: name: (scene, T, {(method, order, processed): h ladder})
PROBLEMS = {
    "kepler": ("kepler", 2000.0, {
        ("stormer-verlet", 8, False): (0.08, 0.04, 0.02), ("stormer-verlet", 10, False): (0.16, 0.08, 0.04),
        ("stormer-verlet", 6, True): (0.04, 0.02, 0.01), ("stormer-verlet", 8, True): (0.06, 0.03, 0.015),
        ("energy-momentum", 8, False): (0.08, 0.04, 0.02), ("energy-momentum", 10, False): (0.16, 0.08, 0.04),
        ("energy-momentum", 8, True): (0.06, 0.03, 0.015),
        ("energy-momentum", 6, True): (0.04, 0.02, 0.01)}),
    "hh": ("henon-heiles-2d", 1.0e4, {
        ("stormer-verlet", 8, False): (0.5, 0.25, 0.125), ("stormer-verlet", 10, False): (0.8, 0.4, 0.2),
        ("stormer-verlet", 6, True): (0.3, 0.15, 0.075), ("stormer-verlet", 8, True): (0.4, 0.2, 0.1),
        ("energy-momentum", 8, False): (0.5, 0.25, 0.125), ("energy-momentum", 10, False): (0.8, 0.4, 0.2),
        ("energy-momentum", 8, True): (0.4, 0.2, 0.1),
        ("energy-momentum", 6, True): (0.3, 0.15, 0.075)}),
    "oss": ("outer-solar-system", 2.0e5, {
        ("stormer-verlet", 8, False): (200.0, 100.0, 50.0), ("stormer-verlet", 10, False): (250.0, 125.0, 62.5),
        ("stormer-verlet", 6, True): (100.0, 50.0, 25.0), ("stormer-verlet", 8, True): (150.0, 75.0, 37.5),
        ("energy-momentum", 8, False): (200.0, 100.0, 50.0), ("energy-momentum", 10, False): (250.0, 125.0, 62.5),
        ("energy-momentum", 8, True): (150.0, 75.0, 37.5)}),
}


def label(method, order, processed):
    short = {"stormer-verlet": "SV", "energy-momentum": "EM"}[method]
    return f"{short} o{order} {'processed' if processed else 'composed'}"


def run_problem(name, backend):
    scene_name, T, ladder = PROBLEMS[name]
    sc = mg.load_scene(scene_name)
    system = sc.run_system
    y0 = np.array(sc.y0, dtype=float)
    ref = peers.heyoka_reference(system, y0, T)
    rows = []
    for (method, order, processed), hs in ladder.items():
        if processed:
            mod = build_processed(system, method, order, backend=backend)
            errs = (mod.kernel.ResolutionError, mod.kernel.ConvergenceError, mod.kernel.NonFiniteError)
        else:
            mod = mg.build(system, method, backend=backend, order=order)
            errs = (mod.ResolutionError, mod.ConvergenceError, mod.NonFiniteError)
        lab = label(method, order, processed)
        for h in hs:
            steps = int(round(T / h))
            h = T / steps
            every = max(1, steps // 1000)
            mod.integrate(y0, h, min(steps, 10), check_resolution=False)  # compile / warm up
            try:
                # timed for the end state (one row: what a run for the final state costs, as
                # heyoka's propagate_until), the energy error from an untimed run keeping ~1000 rows
                cpu, end = peers.min_cpu(lambda: mod.integrate(y0, h, steps, save_every=steps,
                                                               check_resolution=False))
                cpu_rows, traj = peers.min_cpu(lambda: mod.integrate(y0, h, steps, save_every=every,
                                                                     check_resolution=False), repeats=1)
            except errs as exc:
                print(f"{name:6s} {lab:24s} h={h:<8g} {type(exc).__name__}", flush=True)
                continue
            H = mod.hamiltonian(traj)
            assert np.array_equal(end[-1], traj[-1])
            row = {"family": lab, "method": method, "order": order, "processed": processed, "h": h,
                   "steps": steps, "cpu": cpu, "cpu_1000_rows": cpu_rows,
                   "error": float(np.max(np.abs(end[-1] - ref))),
                   "energy_rel": float(np.max(np.abs(H - H[0])) / abs(H[0]))}
            rows.append(row)
            print(f"{name:6s} {lab:24s} h={h:<8g} cpu={cpu:8.4f} s (1000 rows {cpu_rows:.4f} s)  "
                  f"err={row['error']:.3e}  |dH|/|H|={row['energy_rel']:.2e}", flush=True)
    hy = []
    for tol in (1e-15, 1e-12):
        ta = peers._heyoka_integrator(system, y0, tol)

        def run():
            ta.time = 0.0
            ta.state[:] = y0
            return ta.propagate_until(float(T))

        cpu, _ = peers.min_cpu(run)
        err = float(np.max(np.abs(np.array(ta.state) - ref)))
        hy.append({"tol": tol, "cpu": cpu, "error": err})
        print(f"{name:6s} heyoka tol {tol:g}: cpu={cpu:8.4f} s  err={err:.3e}", flush=True)
    return {"problem": name, "T": T, "rows": rows, "heyoka": hy}


#: The final-error levels of the comparison.
LEVELS = (1e-6, 1e-8, 1e-10, 1e-12)


def compare(result):
    """At each of :data:`LEVELS`, each family's cheapest CPU reaching it (None: no row of that
    family reaches it, or it is below the family's cheapest row and not interpolated)."""
    rows = result["rows"]
    fams = sorted({r["family"] for r in rows})
    by = {f: [r for r in rows if r["family"] == f] for f in fams}
    return [{"error": err, "cpu": {f: cpu_at(rs, err) for f, rs in by.items()}} for err in LEVELS]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", default="kepler,hh,oss")
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    results = []
    for name in a.problems.split(","):
        res = run_problem(name, a.backend)
        res["comparison"] = compare(res)
        results.append(res)
        print(f"\n{name}: CPU (s) of each family's cheapest run at equal final error; in parentheses "
              "the ratio to the composed order 8 of the same base method")
        for c in res["comparison"]:
            cells = []
            for f, v in sorted(c["cpu"].items()):
                base = c["cpu"].get(f[:2] + " o8 composed")
                cells.append((f"{f} {v:.4f}" + (f" ({v / base:.2f}x)" if base else "")) if v else f"{f} -")
            print(f"  error {c['error']:.0e}: " + "; ".join(cells))
        if a.json:
            with open(a.json, "w") as fh:
                json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
