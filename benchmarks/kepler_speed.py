"""Speed of the generated Kepler energy-momentum solver against scipy.optimize.fsolve.

Not a test: run it and read the table.

    python benchmarks/kepler_speed.py [--steps N] [--batch B]

Rows, all from one run on this machine:
  * generated module, one trajectory (µs per step);
  * generated module, a batch of B initial conditions (µs per trajectory-step);
  * the same scheme written by hand from the lecture notes as a numpy residual in the 6
    unknowns (q1, p1), solved per step with scipy.optimize.fsolve (what a user would write
    without methodgen), with fsolve's default tolerance.
Each row also reports the maximum relative energy error, to show the accuracy bought.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import fsolve

import methodgen as mg
from methodgen.codegen.build import scene_module_path

Y0 = np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2])
H_STEP = 0.01


def energy(y):
    return 0.5 * np.sum(y[..., 3:] ** 2, axis=-1) - 1 / np.linalg.norm(y[..., :3], axis=-1)


def fsolve_em(y0, h, steps):
    """Exercise 1.1 written by hand: naive κ quotient, 6 unknowns, fsolve."""
    def U(q):
        return -1.0 / np.sqrt(q @ q)

    def gradU(q):
        return q / (q @ q) ** 1.5

    def residual(y1, y0):
        q0, p0, q1, p1 = y0[:3], y0[3:], y1[:3], y1[3:]
        qm = 0.5 * (q0 + q1)
        g = gradU(qm)
        denom = (q1 - q0) @ g
        kappa = (U(q1) - U(q0)) / denom if denom != 0 else 1.0
        return np.concatenate([(q1 - q0) / h - 0.5 * (p0 + p1), (p1 - p0) / h + kappa * g])

    traj = np.empty((steps + 1, 6))
    traj[0] = y = y0
    for n in range(steps):
        y = fsolve(residual, y + h * np.concatenate([y[3:], -gradU(y[:3])]), args=(y,))
        traj[n + 1] = y
    return traj


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=10_000)
    ap.add_argument("--batch", type=int, default=10_000)
    ap.add_argument("--batch-steps", type=int, default=100)
    ap.add_argument("--fsolve-steps", type=int, default=2_000)
    ap.add_argument("--repeats", type=int, default=3, help="report the least CPU time of this many runs")
    args = ap.parse_args()

    scene = mg.load_scene("kepler")
    mod = mg.build(scene.system, "energy-momentum", scene_module_path(scene, "energy-momentum"))
    mod.integrate(Y0, H_STEP, 10)  # warm-up

    def best(fn, repeats):
        """Least CPU time over repeats: this VM's wall clock and CPU share are noisy."""
        times, out = [], None
        for _ in range(repeats):
            t = time.process_time()
            out = fn()
            times.append(time.process_time() - t)
        return min(times), out

    rows = []
    dt, tr = best(lambda: mod.integrate(Y0, H_STEP, args.steps), args.repeats)
    rows.append(("generated, 1 trajectory", dt / args.steps * 1e6, np.max(np.abs(energy(tr) + 0.5)) / 0.5))

    rng = np.random.default_rng(0)
    Yb = Y0 * (1 + 0.01 * rng.standard_normal((args.batch, 6)))
    dt, trb = best(lambda: mod.integrate(Yb, H_STEP, args.batch_steps), args.repeats)
    e = energy(trb)
    rows.append((f"generated, batch of {args.batch}", dt / (args.batch * args.batch_steps) * 1e6,
                 np.max(np.abs(e - e[0]) / np.abs(e[0]))))

    dt, trf = best(lambda: fsolve_em(Y0, H_STEP, args.fsolve_steps), args.repeats)
    rows.append(("hand-written residual + fsolve", dt / args.fsolve_steps * 1e6,
                 np.max(np.abs(energy(trf) + 0.5)) / 0.5))

    print(f"Kepler 3D, e = 0.6, energy-momentum, h = {H_STEP}")
    print(f"{'path (least CPU time of ' + str(args.repeats) + ' runs)':<34} {'µs/step':>12} {'max rel energy error':>22}")
    for name, us, err in rows:
        print(f"{name:<34} {us:12.2f} {err:22.2e}")
    print(f"speed-up of the generated single trajectory over fsolve: {rows[2][1] / rows[0][1]:.1f}x")


if __name__ == "__main__":
    main()
