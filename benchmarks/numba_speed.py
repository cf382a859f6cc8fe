"""Speed of the numba backend on the Kepler energy-momentum scheme (the ``kepler`` scene).

Not a test: run it and read the table.  The hand-written baseline is numba code: install numba
to run it (methodgen itself does not use numba).

    python benchmarks/numba_speed.py [--steps N] [--batch B] [--batch-steps N]

Rows, all from one run on this machine (h = 0.01, e = 0.6, y0 of the scene):
  1. generated numba module, one trajectory (µs per step, after compilation);
  2. a hand-written numba kernel of the same scheme (below: reduced form in Δq,
     analytic 3x3 Jacobian, same start value, stopping rule and compensated
     summation) -- the target the generated module should be within 2x of;
  3. generated numpy module, one trajectory;
  4. numpy and numba modules on a batch of B initial conditions (µs per
     trajectory-step);
  5. compilation: the numba module is generated into a fresh folder and loaded
     in two fresh processes in turn -- the first compiles (first call), the
     second loads the machine code cached on disk (``cache=True``).
Each row reports its largest deviation from the generated numba trajectory.
Times are CPU times (least over repeats), compile times wall-clock.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

import methodgen as mg

EPS = 2.220446049250313e-16
TOL_ROUNDOFF = 4.0 * EPS
TOL_PLATEAU = 1.4901161193847656e-08


@numba.njit(cache=True)
def hand_kepler_em(y0, h, steps, m, k, traj):
    """Energy-momentum method for Kepler written by hand (reduced to the unknown Δq).

    R(Δq) = Δq - (h/m)(p0 - (h/2) κ∇U),  κ∇U = k (q0 + q1) / (r0 r1 (r0 + r1)),
    p1 = p0 - h κ∇U; Newton with the analytic Jacobian, start value the
    explicit predictor (h/m)(p0 - (h/2) k q0 / r0³), increments added with
    compensated summation.
    """
    y = y0.copy()
    c = np.zeros(6)
    traj[0] = y
    dq = np.empty(3)
    s = np.empty(3)
    dkap = np.empty(3)
    a = np.empty((3, 3))
    hm = h / m
    for n in range(steps):
        q0x, q0y, q0z = y[0], y[1], y[2]
        r0 = math.sqrt(q0x * q0x + q0y * q0y + q0z * q0z)
        g = 0.5 * h * k / (r0 * r0 * r0)
        dq[0] = hm * (y[3] - g * q0x)
        dq[1] = hm * (y[4] - g * q0y)
        dq[2] = hm * (y[5] - g * q0z)
        prev = math.inf
        kap = 0.0
        for it in range(50):
            q1x, q1y, q1z = q0x + dq[0], q0y + dq[1], q0z + dq[2]
            r1 = math.sqrt(q1x * q1x + q1y * q1y + q1z * q1z)
            kap = k / (r0 * r1 * (r0 + r1))
            s[0], s[1], s[2] = dq[0] + 2.0 * q0x, dq[1] + 2.0 * q0y, dq[2] + 2.0 * q0z
            # dκ/dΔq = -κ (r0 + 2 r1) / (r1² (r0 + r1)) q1
            f = -kap * (r0 + 2.0 * r1) / (r1 * r1 * (r0 + r1))
            dkap[0], dkap[1], dkap[2] = f * q1x, f * q1y, f * q1z
            cj = 0.5 * h * hm
            r = np.empty(3)
            for i in range(3):
                r[i] = dq[i] - hm * (y[3 + i] - 0.5 * h * kap * s[i])
                for j in range(3):
                    a[i, j] = cj * s[i] * dkap[j] + ((1.0 + cj * kap) if i == j else 0.0)
            # 3x3 solve by cofactors
            c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
            c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
            c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
            det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
            x0 = (r[0] * c00 + r[1] * (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2])
                  + r[2] * (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1])) / det
            x1 = (r[0] * c01 + r[1] * (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0])
                  + r[2] * (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2])) / det
            x2 = (r[0] * c02 + r[1] * (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1])
                  + r[2] * (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0])) / det
            dq[0] -= x0
            dq[1] -= x1
            dq[2] -= x2
            nd = max(abs(x0), abs(x1), abs(x2))
            nz = max(abs(dq[0]), abs(dq[1]), abs(dq[2]))
            if nd <= TOL_ROUNDOFF * nz or (nd >= prev and prev <= TOL_PLATEAU * nz):
                break
            prev = nd
        # increment at the converged Δq (κ evaluated there)
        q1x, q1y, q1z = q0x + dq[0], q0y + dq[1], q0z + dq[2]
        r1 = math.sqrt(q1x * q1x + q1y * q1y + q1z * q1z)
        kap = h * k / (r0 * r1 * (r0 + r1))
        inc0, inc1, inc2 = dq[0], dq[1], dq[2]
        inc3 = -kap * (dq[0] + 2.0 * q0x)
        inc4 = -kap * (dq[1] + 2.0 * q0y)
        inc5 = -kap * (dq[2] + 2.0 * q0z)
        for i, d in enumerate((inc0, inc1, inc2, inc3, inc4, inc5)):
            t = d + c[i]
            u = y[i] + t
            c[i] = t - (u - y[i])
            y[i] = u
        traj[n + 1] = y


def best_time(fn, repeat=3):
    """Least CPU time of this process over ``repeat`` calls (other load on a shared
    machine does not count; every row here runs on one thread)."""
    best = math.inf
    out = None
    for _ in range(repeat):
        t = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t)
    return best, out


COLD = """
import json, sys, time
t0 = time.perf_counter()
import numpy as np
from methodgen.codegen.emit import load_module
t1 = time.perf_counter()
mod = load_module(sys.argv[1])
t2 = time.perf_counter()
mod.integrate(np.array(json.loads(sys.argv[2])), 0.01, 10)
t3 = time.perf_counter()
mod.integrate(np.array(json.loads(sys.argv[2])), 0.01, 10)
t4 = time.perf_counter()
print(json.dumps({"load": t2 - t1, "first_call": t3 - t2, "second_call": t4 - t3}))
"""


def compile_times(system, y0):
    """Generate into a fresh folder; load and call in two fresh processes in turn."""
    folder = Path(tempfile.mkdtemp(prefix="methodgen-numba-"))
    path = folder / "kepler_energy_momentum_numba.py"
    t = time.perf_counter()
    mg.build(system, "energy-momentum", path, backend="numba")  # writes (and imports) the file only
    gen = time.perf_counter() - t
    runs = []
    for _ in range(2):
        res = subprocess.run([sys.executable, "-c", COLD, str(path), json.dumps(list(y0))],
                             capture_output=True, text=True, check=True)
        runs.append(json.loads(res.stdout))
    return gen, runs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=200_000, help="steps of the single-trajectory rows")
    ap.add_argument("--batch", type=int, default=10_000, help="batch size B")
    ap.add_argument("--batch-steps", type=int, default=200, help="steps of the batch rows")
    args = ap.parse_args()

    scene = mg.load_scene("kepler")
    y0 = np.array(scene.y0)
    h = scene.h
    m, k = scene.system.param_values["m"], scene.system.param_values["k"]

    gen, cold = compile_times(scene.system, y0)
    nb = mg.build(scene.system, "energy-momentum", backend="numba")
    npm = mg.build(scene.system, "energy-momentum")
    nb.integrate(y0, h, 10)
    hand_traj = np.empty((args.steps + 1, 6))
    hand_kepler_em(y0, h, 10, m, k, hand_traj)  # compile (or load from cache)

    rows = []
    t, ref = best_time(lambda: nb.integrate(y0, h, args.steps), repeat=5)
    rows.append(("numba module, 1 trajectory", t / args.steps * 1e6, 0.0))
    t, _ = best_time(lambda: hand_kepler_em(y0, h, args.steps, m, k, hand_traj), repeat=5)
    rows.append(("hand-written numba kernel", t / args.steps * 1e6, float(np.max(np.abs(hand_traj - ref)))))
    n_np = max(1, args.steps // 20)
    t, traj = best_time(lambda: npm.integrate(y0, h, n_np), repeat=1)
    rows.append((f"numpy module, 1 trajectory ({n_np} steps)", t / n_np * 1e6,
                 float(np.max(np.abs(traj - ref[:n_np + 1])))))

    rng = np.random.default_rng(0)
    Y0 = y0 * (1.0 + 0.02 * rng.standard_normal((args.batch, 6)))
    work = args.batch * args.batch_steps
    t, tb = best_time(lambda: nb.integrate(Y0, h, args.batch_steps), repeat=2)
    rows.append((f"numba module, batch {args.batch}", t / work * 1e6, 0.0))
    t, tn = best_time(lambda: npm.integrate(Y0, h, args.batch_steps), repeat=1)
    rows.append((f"numpy module, batch {args.batch}", t / work * 1e6, float(np.max(np.abs(tn - tb)))))

    print(f"Kepler energy-momentum, h = {h}, e = 0.6; numba {numba.__version__}, numpy {np.__version__}")
    print(f"{'row':<42} {'us/step':>10} {'max |dy| vs numba':>18}")
    for name, us, dev in rows:
        print(f"{name:<42} {us:>10.3f} {dev:>18.2e}")
    ratio = rows[0][1] / rows[1][1]
    print(f"generated / hand-written: {ratio:.2f}x")
    print(f"generation (derive + lower + emit): {gen:.2f} s")
    for label, r in zip(("fresh process, no cache (compiles)", "fresh process, cached"), cold):
        print(f"{label:<36} load {r['load']:.2f} s, first call {r['first_call']:.3f} s, "
              f"second call {r['second_call'] * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
