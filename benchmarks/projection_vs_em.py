"""Symmetric projection against the explicit route and composed energy-momentum, one run.

Not a test: run it and read the table (wall time is never asserted anywhere).

    python benchmarks/projection_vs_em.py [--problems kepler,hh,oss] [--backend numba]
                                          [--orders 4,6,10] [--json FILE]

For each problem, every (method, order, h) row reports the CPU seconds of the integration
call (``time.process_time``, minimum of 3; compiled before timing), the final-state error
against a reference (heyoka in long double where installed, else DOP853 at rtol 1e-13:
:func:`methodgen.app.bench.reference`), and the largest |H - H0| over ~1000 saved states.
Methods: ``stormer-verlet`` (explicit), ``stormer-verlet-projected`` (symmetric projection
onto H = H0, methodgen.symbolic.projection), ``standard-projected`` (the standard projection onto
H = H0: Φ_h once per step, not symmetric) and ``energy-momentum`` (implicit, H exact), each
composed to the orders given.  Then, at error levels every family reaches, the CPU of each
family's cheapest row reaching that error (interpolated log-log between its rows), and the
ratio projected / explicit and energy-momentum / explicit.

Problems (the issue's): Kepler e = 0.6 (T = 2000), Hénon–Heiles at H = 1/8 (T = 1e4), the
outer solar system (T = 2e5 days, scene ``outer-solar-system``).
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

import methodgen as mg
from methodgen.app.bench import reference
from methodgen.app.peers import min_cpu

PROBLEMS = {
    # name: (scene, y0 override, T, {order: h ladder})
    "kepler": ("kepler", None, 2000.0,
               {4: (0.02, 0.01, 0.005), 6: (0.05, 0.025, 0.0125), 8: (0.08, 0.04, 0.02),
                10: (0.16, 0.08, 0.04)}),
    "hh": ("henon-heiles-2d", None, 1.0e4,
           {4: (0.2, 0.1, 0.05), 6: (0.4, 0.2, 0.1), 8: (0.5, 0.25, 0.125), 10: (0.8, 0.4, 0.2)}),
    "oss": ("outer-solar-system", None, 2.0e5,
            {4: (50.0, 25.0, 12.5), 6: (100.0, 50.0, 25.0), 8: (200.0, 100.0, 50.0),
             10: (250.0, 125.0, 62.5)}),
}
#: label: (method, options).  "projected+I": onto H and every exact first integral the
#: module monitors (N-body: total momentum and angular momentum, which an energy-only
#: projection does not keep).
FAMILIES = {"stormer-verlet": ("stormer-verlet", {}),
            "stormer-verlet-projected": ("stormer-verlet-projected", {}),
            "projected+I": ("stormer-verlet", {"project": "invariants"}),
            "standard-projected": ("stormer-verlet", {"project": "energy-standard"}),
            "energy-momentum": ("energy-momentum", {})}
METHODS = tuple(FAMILIES)


def run_problem(name, orders, backend, methods=METHODS, em_orders=None):
    scene_name, y0o, T, ladder = PROBLEMS[name]
    sc = mg.load_scene(scene_name)
    system = sc.run_system
    y0 = np.array(sc.y0 if y0o is None else y0o, dtype=float)
    ref = reference(system, y0, T, heyoka=True)
    rows = []
    for method in methods:
        for order in orders:
            if method == "energy-momentum" and em_orders is not None and order not in em_orders:
                continue
            base, opts = FAMILIES[method]
            mod = mg.build(system, base, backend=backend, order=order, **opts)
            for h in ladder[order]:
                steps = int(round(T / h))
                every = max(1, steps // 1000)
                mod.integrate(y0, h, min(steps, 10))  # compile / warm up
                info = {}
                try:
                    cpu, traj = min_cpu(lambda: mod.integrate(y0, h, steps, save_every=every, info=info))
                except (mod.ResolutionError, mod.ConvergenceError, mod.NonFiniteError) as exc:
                    rows.append({"method": method, "order": order, "h": h, "failed": type(exc).__name__})
                    print(f"{name:6s} {method:26s} o{order:<2d} h={h:<8g} {type(exc).__name__}", flush=True)
                    continue
                H = mod.hamiltonian(traj)
                row = {"method": method, "order": order, "h": h, "steps": steps, "cpu": cpu,
                       "error": float(np.max(np.abs(traj[-1] - ref.y))),
                       "energy_error": float(np.max(np.abs(H - H[0]))),
                       "energy_rel": float(np.max(np.abs(H - H[0])) / abs(H[0])),
                       # iterations per step: the projection's (projected), Newton's max over the
                       # stages (energy-momentum), 0 (explicit)
                       "iterations": float(np.mean(info["newton_iterations"])) if steps else 0.0}
                rows.append(row)
                print(f"{name:6s} {method:26s} o{order:<2d} h={h:<8g} cpu={cpu:8.4f} s  "
                      f"err={row['error']:.3e}  |dH|/|H|={row['energy_rel']:.2e}  it={row['iterations']:.2f}",
                      flush=True)
    return {"problem": name, "scene": scene_name, "T": T, "reference": ref.kind, "rows": rows}


def cpu_at(rows, err):
    """The cheapest CPU of ``rows`` (one family) reaching final error ``err``: log-log
    interpolation between consecutive rows of one order; None if no order reaches it."""
    best = None
    by_order = {}
    for r in rows:
        if "cpu" in r and math.isfinite(r["error"]):
            by_order.setdefault(r["order"], []).append(r)
    for rs in by_order.values():
        rs = sorted(rs, key=lambda r: r["cpu"])
        for a, b in zip(rs, rs[1:]):
            lo, hi = sorted((a["error"], b["error"]))
            if lo <= err <= hi and a["error"] != b["error"]:
                t = (math.log(err) - math.log(a["error"])) / (math.log(b["error"]) - math.log(a["error"]))
                c = math.exp(math.log(a["cpu"]) + t * (math.log(b["cpu"]) - math.log(a["cpu"])))
                best = c if best is None else min(best, c)
        for r in rs:   # a row at or below err counts as it is
            if r["error"] <= err:
                best = r["cpu"] if best is None else min(best, r["cpu"])
    return best


def compare(result):
    rows = result["rows"]
    fam = {m: [r for r in rows if r["method"] == m] for m in METHODS}
    fam = {m: rs for m, rs in fam.items() if rs}
    errs = sorted({r["error"] for r in rows if "cpu" in r})
    lo = max(min((r["error"] for r in rs if "cpu" in r), default=math.inf) for rs in fam.values())
    hi = min(max((r["error"] for r in rs if "cpu" in r), default=0.0) for rs in fam.values())
    out = []
    if not errs or lo > hi:
        return out
    for err in np.geomspace(max(lo, 1e-14), hi, 5):
        c = {m: cpu_at(rs, err) for m, rs in fam.items()}
        sv = c.get("stormer-verlet")
        out.append({"error": float(err), **{m: c[m] for m in c},
                    **{f"{m}/explicit": (c[m] / sv if sv and c.get(m) else None)
                       for m in c if m != "stormer-verlet"}})
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", default="kepler,hh,oss")
    ap.add_argument("--orders", default="4,6,8,10")
    ap.add_argument("--em-orders", default=None, help="orders of energy-momentum (default: --orders)")
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--methods", default=",".join(METHODS), help=f"of {', '.join(METHODS)}")
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    orders = [int(k) for k in a.orders.split(",")]
    em = None if a.em_orders is None else [int(k) for k in a.em_orders.split(",")]
    results = []
    for name in a.problems.split(","):
        res = run_problem(name, orders, a.backend, methods=a.methods.split(","), em_orders=em)
        res["comparison"] = compare(res)
        results.append(res)
        print(f"\n{name}: CPU (s) of each family's cheapest run at equal final error "
              f"(reference: {res['reference']})")
        for c in res["comparison"]:
            def f(x):
                return f"{x:.4f}" if x else "   -  "
            print(f"  error {c['error']:.2e}: " + "  ".join(
                f"{m} {f(c.get(m))}" + ("" if m == "stormer-verlet" else f" ({f(c.get(m + '/explicit'))}x)")
                for m in METHODS if m in c))
        if a.json:
            with open(a.json, "w") as fh:
                json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()
