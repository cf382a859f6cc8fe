"""N-body families over a symbolic N: cold build and per-step cost against hand-written pair loops.

Not a test: run it and read the table.  The hand-written baseline is numba code: install numba
to run it (methodgen itself does not use numba).

    python benchmarks/nbody_family.py [--sizes 3 11 21 51] [--steps 5000]

For each N and each method (Störmer–Verlet order 8, Kahan–Li s17; energy-momentum, the
LaBudde–Greenspan radial discrete gradient) of the planar ring (``nbody-ring``: a star and N - 1
planets): the wall time of a *cold build and first step* in a new process with a fresh
METHODGEN_CACHE (import methodgen, parse, derive, render, write, import, compile the pair-loop
stepper through LLVM, two steps), and the CPU time per step of the compiled module against a
hand-written numba pair loop of the same scheme at the same N (the same composition
coefficients, the same fixed-point rule), least of 5 repeats, after compilation.  The
hand-written loops use plain summation; the module carries compensated summation.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap
import time

import numba as nb
import numpy as np

COLD = textwrap.dedent("""
    import time, sys
    t0 = time.perf_counter()
    from methodgen.app.particles_scene import load_particles_scene
    from methodgen.codegen.particle_emit import build_particles
    s = load_particles_scene("nbody-ring")
    method, order, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    mod = build_particles(s.family, method, order=order, backend="compiled")
    y0, arrays = s.state(n)
    mod.integrate(y0, 0.01, 2, arrays=arrays)
    print(time.perf_counter() - t0)
""")


@nb.njit(cache=True)
def forces(Q, m, G, F):
    n = Q.shape[0]
    F[:, :] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            dx = Q[a, 0] - Q[b, 0]
            dy = Q[a, 1] - Q[b, 1]
            s = dx * dx + dy * dy
            f = G * m[a] * m[b] / (s * np.sqrt(s))
            F[a, 0] -= f * dx
            F[a, 1] -= f * dy
            F[b, 0] += f * dx
            F[b, 1] += f * dy


@nb.njit(cache=True)
def hand_sv(Q, P, m, G, h, steps, kicks, drifts):
    n = Q.shape[0]
    F = np.empty_like(Q)
    forces(Q, m, G, F)
    for s in range(steps):
        for k in range(drifts.size):
            P += (kicks[k] * h) * F
            for a in range(n):
                Q[a, 0] += (drifts[k] * h) * P[a, 0] / m[a]
                Q[a, 1] += (drifts[k] * h) * P[a, 1] / m[a]
            forces(Q, m, G, F)
        P += (kicks[-1] * h) * F


@nb.njit(cache=True)
def dg(Q, D, m, G, A):
    n = Q.shape[0]
    A[:, :] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            r0x = Q[a, 0] - Q[b, 0]
            r0y = Q[a, 1] - Q[b, 1]
            r1x = r0x + D[a, 0] - D[b, 0]
            r1y = r0y + D[a, 1] - D[b, 1]
            x = np.sqrt(r0x * r0x + r0y * r0y)
            y = np.sqrt(r1x * r1x + r1y * r1y)
            g = G * m[a] * m[b] / (x * y * (x + y))
            A[a, 0] += g * (r0x + r1x)
            A[a, 1] += g * (r0y + r1y)
            A[b, 0] -= g * (r0x + r1x)
            A[b, 1] -= g * (r0y + r1y)


@nb.njit(cache=True)
def hand_em(Q, P, m, G, h, steps):
    n = Q.shape[0]
    A = np.empty_like(Q)
    D = np.zeros_like(Q)
    its = 0
    for s in range(steps):
        D[:, :] = 0.0
        dg(Q, D, m, G, A)
        for a in range(n):
            for k in range(2):
                D[a, k] = h * (P[a, k] - 0.5 * h * A[a, k]) / m[a]
        last = np.inf
        for it in range(100):
            dg(Q, D, m, G, A)
            size = 0.0
            scale = 0.0
            for a in range(n):
                for k in range(2):
                    dn = h * (P[a, k] - 0.5 * h * A[a, k]) / m[a]
                    size = max(size, abs(dn - D[a, k]))
                    D[a, k] = dn
                    scale = max(scale, abs(Q[a, k]))
            its += 1
            if size <= 4 * 2.2e-16 * scale or (size <= 1e3 * 2.2e-16 * scale and size > 0.5 * last):
                break
            last = size
        Q += D
        P -= h * A
    return its


def _best(f, repeats=5):
    best = float("inf")
    for _ in range(repeats):
        t = time.process_time()
        f()
        best = min(best, time.process_time() - t)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[3, 11, 21, 51])
    # (enough steps that a call's fixed cost does not count: at N = 3 and 200 steps it was 3× a step)
    ap.add_argument("--steps", type=int, default=5000)
    args = ap.parse_args(argv)
    from methodgen.app.particles_scene import load_particles_scene
    from methodgen.codegen.particle_emit import build_particles

    print(f"load: {os.getloadavg()}")
    scene = load_particles_scene("nbody-ring")
    cases = (("stormer-verlet", 8), ("energy-momentum", 2))
    print(f"{'N':>4} {'method':>16} {'cold build+step s':>18} {'module us/step':>15} {'hand us/step':>13} {'ratio':>6}")
    for n in args.sizes:
        y0, arrays = scene.state(n)
        m = arrays["m"]
        for method, order in cases:
            with tempfile.TemporaryDirectory() as cache:
                env = {**os.environ, "METHODGEN_CACHE": cache}
                out = subprocess.run([sys.executable, "-c", COLD, method, str(order), str(n)], env=env,
                                     capture_output=True, text=True, check=True)
                cold = float(out.stdout.strip().splitlines()[-1])
            mod = build_particles(scene.family, method, order=order, backend="compiled")
            mod.integrate(y0, 0.01, 2, arrays=arrays)
            mine = _best(lambda: mod.integrate(y0, 0.01, args.steps, arrays=arrays, save_every=args.steps))
            Q, P = y0[:2 * n].reshape(n, 2).copy(), y0[2 * n:].reshape(n, 2).copy()
            if method == "stormer-verlet":
                k, d = np.array(mod.KICKS), np.array(mod.DRIFTS)
                hand_sv(Q.copy(), P.copy(), m, 1.0, 0.01, 2, k, d)
                hand = _best(lambda: hand_sv(Q.copy(), P.copy(), m, 1.0, 0.01, args.steps, k, d))
            else:
                hand_em(Q.copy(), P.copy(), m, 1.0, 0.01, 2)
                hand = _best(lambda: hand_em(Q.copy(), P.copy(), m, 1.0, 0.01, args.steps))
            print(f"{n:>4} {method:>16} {cold:>18.2f} {mine / args.steps * 1e6:>15.1f} "
                  f"{hand / args.steps * 1e6:>13.1f} {mine / hand:>6.2f}")


if __name__ == "__main__":
    main()
