"""Ensembles of Kepler orbits: methodgen's batched numba path against heyoka's batch mode.

Not a test: run it and read the table (issue 26, item 4).

    python benchmarks/ensemble.py [--batch 1000 10000] [--t-final T] [--json FILE] [--quick]

The ensemble: B planar Kepler orbits (μ = 1, a = 1, period 2π), eccentricities uniform in
[0.1, 0.6], mean anomaly and argument of pericentre uniform in [0, 2π) (seed 0).  The exact
state at T comes from Kepler's equation (Newton's method in float64 to round-off, about 1e-15).
The error of a run is the largest component of ``|y(T) - exact|`` over the ensemble.

Rows, all from one run (CPU time of the integration call, ``time.process_time``, the least of
``--repeats``; compilation, heyoka's JIT and set-up excluded):

* **cost per trajectory at equal error**: for each target (1e-6, 1e-10) and each
  configuration the cheapest run that meets it -- methodgen (numba, default checks on): the
  largest step of the halving grid ``T / (N_0 2^k)`` whose error is within the target
  (Störmer–Verlet compositions and a splitting family), and the log-Hamiltonian form
  (``methodgen.time_transform(..., form="log")``, orders 6, 8, 10) at the fewest fictive
  steps per orbit of a grid.  Its fictive time is 2π per orbit for every e (a = 1), so after
  N = T k / 2π steps of 2π/k every lane ends at its own physical time t_b near T -- at T
  itself up to the phase error when T is a whole number of periods (the default); the
  error is taken against the exact state at t_b and the table shows max |t_b - T|.  (Landing
  each lane exactly on T needs a last step of its own size: ``run_to_time`` does it for one
  trajectory, the batch path has one h for all lanes.)
  heyoka (``taylor_adaptive_batch``, batches of ``recommended_simd_size()`` lanes, the
  ensemble integrated chunk by chunk): the largest tolerance of 1e-6 ... 1e-16 that meets it.
  CPU µs per trajectory.
* **per trajectory-step**: CPU µs per trajectory per step (heyoka: per step of a lane, its
  own adaptive steps counted from ``propagate_res``), methodgen's one-trajectory path and its
  lock-step path (``methodgen.nbbatch``) side by side.

heyoka is optional: without it its rows are skipped with a message.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time

import numpy as np

import methodgen as mg
from methodgen.runtime import nbabi

H_TEXT = "(px**2 + py**2)/2 - 1/sqrt(x**2 + y**2)"
#: (label, order, composition) of methodgen's rows
METHODS = [("SV o6 blanes-moan-rkn", 6, "blanes-moan-rkn"), ("SV o8", 8, None), ("SV o10", 10, None)]
TARGETS = (1e-6, 1e-10)
#: the log-Hamiltonian rows: orders, fictive steps per orbit (fewest first)
LOGH_ORDERS = (6, 8, 10)
LOGH_STEPS_PER_ORBIT = (8, 10, 12, 14, 17, 20, 24, 28, 40, 56, 80)
HEYOKA_TOLS = tuple(10.0 ** -k for k in range(6, 17))


# --- the ensemble and its exact solution -------------------------------------------------

def ensemble(B: int, seed: int = 0):
    """Eccentricity, mean anomaly at t = 0 and argument of pericentre of B orbits."""
    rng = np.random.default_rng(seed)
    return rng.uniform(0.1, 0.6, B), rng.uniform(0.0, 2 * np.pi, B), rng.uniform(0.0, 2 * np.pi, B)


def kepler_state(e, M, w):
    """States (B, 4) = (x, y, px, py) of orbits with a = μ = 1 at mean anomaly M."""
    E = M + e * np.sin(M)
    for _ in range(60):  # Newton on E - e sin E - M: quadratic, converged long before 60
        dE = (E - e * np.sin(E) - M) / (1.0 - e * np.cos(E))
        E = E - dE
        if np.max(np.abs(dE)) < 1e-16:
            break
    c, s, b = np.cos(E), np.sin(E), np.sqrt(1.0 - e * e)
    xo, yo = c - e, b * s
    k = 1.0 / (1.0 - e * c)
    vxo, vyo = -s * k, b * c * k
    cw, sw = np.cos(w), np.sin(w)
    return np.stack([cw * xo - sw * yo, sw * xo + cw * yo, cw * vxo - sw * vyo, sw * vxo + cw * vyo], axis=1)


def cpu_min(fn, repeats):
    best, out = math.inf, None
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


# --- methodgen -------------------------------------------------------------------------------

def ours(mod, Y0, T, N, repeats, block=True):
    """(CPU s, final states) of N steps of T/N; ``block`` False forces the one-trajectory path."""
    # the threshold lives in methodgen.runtime.nbabi (read by use_block at every call)
    saved = nbabi.MIN_BATCH
    nbabi.MIN_BATCH = saved if block else 1 << 62
    try:
        h = T / N
        mod.integrate(Y0[:64], h, 2)  # compiled (and the block kernel) before the timed region
        sec, traj = cpu_min(lambda: mod.integrate(Y0, h, N, save_every=N), repeats)
    finally:
        nbabi.MIN_BATCH = saved
    return sec, traj[-1]


def ours_at_targets(mod, Y0, exact, T, repeats, n0, max_work):
    """Per target: (N, error, CPU s) of the fewest steps of the grid n0 * 2^k that meet it
    (None where the work limit B * N > max_work stops the search first)."""
    found, N = {}, n0
    B = Y0.shape[0]
    while len(found) < len(TARGETS) and B * N <= max_work:
        try:
            sec, yT = ours(mod, Y0, T, N, repeats)
            err = float(np.max(np.abs(yT - exact)))
        except Exception as exc:  # a step refused by the checks: a finer grid
            sec, err = math.nan, math.inf
            print(f"    N = {N}: {type(exc).__name__}: {str(exc)[:100]}")
        for tgt in TARGETS:
            if tgt not in found and err <= tgt:
                found[tgt] = (N, err, sec)
        N *= 2
    return found


def logh_module(order):
    """The log-Hamiltonian form of planar Kepler (fictive time dτ = dt / r, 2π per orbit for
    a = 1): Störmer–Verlet of order ``order`` on it stays explicit (lock-step path)."""
    system = mg.Hamiltonian(H_TEXT, ["x", "y"], ["px", "py"], name="kepler_planar")
    return mg.build(mg.time_transform(system, form="log"), "stormer-verlet", backend="numba", order=order)


def ours_logh(mod, e, M, w, T, k, repeats):
    """(CPU s, steps, error, largest |t - T|): N = T k / (2π) fictive steps of 2π/k, every
    lane ending at its own physical time t_b near T (the fictive time of an orbit is 2π
    whatever e, the physical times differ by up to 2e); the error is against the exact
    state at t_b.  Landing every lane on T exactly would take a last step of its own size
    (``methodgen.runtime.physical_time.run_to_time`` does it for one trajectory; not for batches)."""
    N = round(T * k / (2 * np.pi))
    h = 2 * np.pi / k
    Y0 = mod.initial_state(kepler_state(e, M, w))
    mod.integrate(Y0[:64], h, 2)
    sec, traj = cpu_min(lambda: mod.integrate(Y0, h, N, save_every=N), repeats)
    yT, t = mod.physical_state(traj[-1])
    err = float(np.max(np.abs(yT - kepler_state(e, M + t, w))))
    return sec, N, err, float(np.max(np.abs(t - T)))


# --- heyoka ----------------------------------------------------------------------------------

def heyoka_module():
    try:
        import heyoka
    except ImportError:
        return None
    return heyoka


def heyoka_batch(hy, tol, lanes):
    x, y, px, py = hy.make_vars("x", "y", "px", "py")
    r3 = (x * x + y * y) ** -1.5
    sys_ = [(x, px), (y, py), (px, -x * r3), (py, -y * r3)]
    return hy.taylor_adaptive_batch(sys_, np.zeros((4, lanes)), tol=tol)


def heyoka_run(ta, Y0, T, repeats):
    """(CPU s, final states, lane-steps) of the ensemble, ``lanes`` orbits per propagation."""
    lanes = ta.state.shape[1]
    B = Y0.shape[0]
    pad = (-B) % lanes
    Yp = np.concatenate([Y0, np.repeat(Y0[-1:], pad, axis=0)]) if pad else Y0
    out = np.empty_like(Yp)
    zero = np.zeros(lanes)
    steps = [0]

    def run():
        steps[0] = 0
        for b0 in range(0, Yp.shape[0], lanes):
            ta.set_time(zero)
            ta.state[:] = Yp[b0:b0 + lanes].T
            ta.propagate_until(T)
            out[b0:b0 + lanes] = ta.state.T
            steps[0] += sum(r[3] for r in ta.propagate_res[:min(lanes, B - b0)])
        return out[:B]

    sec, yT = cpu_min(run, repeats)
    for r in ta.propagate_res:
        if "time_limit" not in str(r[0]):
            raise RuntimeError(f"heyoka stopped with {r[0]}")
    return sec, yT.copy(), steps[0]


# --- main ------------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, nargs="+", default=[1000, 10000])
    ap.add_argument("--t-final", type=float, default=20 * np.pi, help="T (default 10 periods)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--n0", type=int, default=250, help="coarsest number of steps of the grid")
    ap.add_argument("--max-work", type=float, default=1e9, help="largest B * N tried")
    ap.add_argument("--quick", action="store_true", help="fixed-step SV o8 and logH o10 only, one repeat")
    ap.add_argument("--json", metavar="FILE", help="also write the rows as JSON")
    args = ap.parse_args()
    T = float(args.t_final)
    methods = [m for m in METHODS if m[1] == 8] if args.quick else METHODS
    repeats = 1 if args.quick else args.repeats
    hy = heyoka_module()
    if hy is None:
        print("heyoka is not installed: its rows are skipped (pip install heyoka)")
    mods = {label: mg.build_text(H_TEXT, ["x", "y"], ["px", "py"], "stormer-verlet", name="kepler_planar",
                                 backend="numba", order=order, composition=comp)
            for label, order, comp in methods}
    logh = {order: logh_module(order) for order in LOGH_ORDERS}
    sv2 = mg.build_text(H_TEXT, ["x", "y"], ["px", "py"], "stormer-verlet", name="kepler_planar", backend="numba")
    rows = []
    for B in args.batch:
        e, M, w = ensemble(B)
        Y0 = kepler_state(e, M, w)
        exact = kepler_state(e, M + T, w)
        print(f"B = {B}, T = {T:.6g}, load average {os.getloadavg()[0]:.2f}")
        for label, _, _ in methods:
            found = ours_at_targets(mods[label], Y0, exact, T, repeats, args.n0, args.max_work)
            for tgt in TARGETS:
                if tgt in found:
                    N, err, sec = found[tgt]
                    rows.append(dict(kind="equal-error", batch=B, target=tgt, who="methodgen", config=f"{label}, h = T/{N}",
                                     steps=N, error=err, us_per_traj=1e6 * sec / B, us_per_traj_step=1e6 * sec / (B * N)))
                else:
                    rows.append(dict(kind="equal-error", batch=B, target=tgt, who="methodgen", config=label,
                                     steps=None, error=None, us_per_traj=None, us_per_traj_step=None))
        for order in (LOGH_ORDERS[-1:] if args.quick else LOGH_ORDERS):
            mod = logh[order]
            for k in LOGH_STEPS_PER_ORBIT:
                try:
                    sec, N, err, dt = ours_logh(mod, e, M, w, T, k, repeats)
                except Exception as exc:
                    print(f"    logH o{order}, 2π/{k}: {type(exc).__name__}: {str(exc)[:100]}")
                    continue
                for tgt in TARGETS:
                    if err <= tgt and not any(r["who"] == "methodgen" and r["batch"] == B and r["target"] == tgt
                                              and r["config"].startswith(f"logH o{order}") for r in rows
                                              if r["kind"] == "equal-error"):
                        rows.append(dict(kind="equal-error", batch=B, target=tgt, who="methodgen",
                                         config=f"logH o{order}, h = 2π/{k} (t ends within {dt:.2f} of T)",
                                         steps=N, error=err, us_per_traj=1e6 * sec / B,
                                         us_per_traj_step=1e6 * sec / (B * N)))
        if hy is not None:
            lanes = hy.recommended_simd_size()
            best = {}
            for tol in HEYOKA_TOLS:
                ta = heyoka_batch(hy, tol, lanes)
                sec, yT, nsteps = heyoka_run(ta, Y0, T, repeats)
                err = float(np.max(np.abs(yT - exact)))
                for tgt in TARGETS:
                    if tgt not in best and err <= tgt:
                        best[tgt] = (tol, err, sec, nsteps)
                if len(best) == len(TARGETS):
                    break
            for tgt in TARGETS:
                if tgt in best:
                    tol, err, sec, nsteps = best[tgt]
                    rows.append(dict(kind="equal-error", batch=B, target=tgt, who="heyoka",
                                     config=f"batch {lanes} lanes, tol {tol:.0e}", steps=nsteps / B, error=err,
                                     us_per_traj=1e6 * sec / B, us_per_traj_step=1e6 * sec / nsteps))
        # per trajectory-step, both paths of methodgen side by side
        N = 4 * args.n0
        for label, mod, yb, h in [("SV o2", sv2, Y0, T / N),
                                  ("logH o10", logh[10], logh[10].initial_state(Y0), 2 * np.pi / 14)]:
            for block in (False, True):
                sec, _ = ours(mod, yb, h * N, N, repeats, block=block)
                rows.append(dict(kind="per-step", batch=B, who="methodgen",
                                 config=f"{label}, {'lock-step' if block else 'one-trajectory'} path",
                                 steps=N, us_per_traj_step=1e6 * sec / (B * N), us_per_traj=1e6 * sec / B))
        rows[-1]["load_average"] = os.getloadavg()[0]
    print_table(rows)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(dict(t_final=T, load_average=os.getloadavg(), rows=rows), f, indent=1)


def print_table(rows):
    print(f"\n{'B':>6} {'target':>7} {'who':<10} {'configuration':<44} {'steps/traj':>10} {'error':>9} "
          f"{'µs/traj':>9} {'µs/traj-step':>12}")
    for r in rows:
        fmt = lambda v, f: "-" if v is None else format(v, f)  # noqa: E731
        print(f"{r['batch']:>6} {fmt(r.get('target'), '.0e'):>7} {r['who']:<10} {r['config']:<44} "
              f"{fmt(r['steps'], '.0f'):>10} {fmt(r.get('error'), '.1e'):>9} {fmt(r['us_per_traj'], '.2f'):>9} "
              f"{fmt(r['us_per_traj_step'], '.4f'):>12}")


if __name__ == "__main__":
    main()
