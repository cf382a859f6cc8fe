"""Energy-momentum with an external potential W against without: the per-step and per-sweep cost.

Not a test: run it and read the table.

    python benchmarks/nbody_external.py [--sizes 21 51] [--steps 2000] [--orders 2 4]

The scene ``trap`` (N unit charges, Coulomb pairs) three ways, compiled backend, the same initial
state: without W (the pairs alone), with the central trap ``W = m w² |q|²/2`` (the chord form
``G = W_σ[σ0, σ1] (q0 + q1)``) and with an anisotropic trap plus a quartic term (the symmetrised
Itoh–Abe discrete gradient, 2 components × 2 quotients per particle).  A step's cost is its sweeps
(iterations) times one sweep's, and W changes the iteration count (it changes the dynamics), so
both are given: µs a step and µs a sweep (a step's time over the fixed-point iterations it took
plus the predictor's sweep), the least CPU time of ``--repeats`` runs, after compilation.  Last, the cold
build of the scene (import, parse, derive, render, write, import, compile the stepper through
LLVM, two steps) in a new process with a fresh METHODGEN_CACHE.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap
import time

import numpy as np

COLD = textwrap.dedent("""
    import time, sys
    t0 = time.perf_counter()
    from methodgen.app.particles_scene import load_particles_scene
    from methodgen.codegen.particle_emit import build_particles
    s = load_particles_scene("trap")
    mod = build_particles(s.family, "energy-momentum", order=int(sys.argv[1]), backend="compiled")
    y0, arrays = s.state(int(sys.argv[2]))
    mod.integrate(y0, 0.01, 2, arrays=arrays)
    print(time.perf_counter() - t0)
""")

KIN = "Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N)"
PAIR = " + Sum(Sum(k*c[i]*c[j]/sqrt((x[i] - x[j])**2 + (y[i] - y[j])**2), j, i + 1, N), i, 1, N)"
VARIANTS = {
    "no W": "",
    "central W": " + Sum(m[i]*w**2*(x[i]**2 + y[i]**2)/2, i, 1, N)",
    "Itoh-Abe W": " + Sum(m[i]*(w**2*x[i]**2 + 2*w**2*y[i]**2)/2 + x[i]**4/40, i, 1, N)",
}


def _best(f, repeats=5):
    best = float("inf")
    for _ in range(repeats):
        t = time.process_time()
        f()
        best = min(best, time.process_time() - t)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[21, 51])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--orders", type=int, nargs="+", default=[2])
    ap.add_argument("--repeats", type=int, default=5, help="the least CPU time of this many runs")
    args = ap.parse_args(argv)
    from methodgen.app.particles_scene import load_particles_scene
    from methodgen.codegen.particle_emit import build_particles
    from methodgen.problem.particles import Particles

    print(f"load: {os.getloadavg()}")
    scene = load_particles_scene("trap")
    print(f"{'N':>4} {'order':>5} {'variant':>11} {'us/step':>9} {'sweeps/step':>11} {'us/sweep':>9} "
          f"{'step ratio':>10} {'sweep ratio':>11}")
    for n in args.sizes:
        y0, arrays = scene.state(n)
        for order in args.orders:
            base = None
            for name, W in VARIANTS.items():
                fam = Particles(KIN + W + PAIR, q=["x", "y"], p=["px", "py"], arrays=["m", "c"],
                                params={"k": 1.0, "w": 1.0}, name=f"bench_{len(W)}")
                mod = build_particles(fam, "energy-momentum", order=order, backend="compiled")
                mod.integrate(y0, 0.01, 2, arrays=arrays)
                info = {}
                mod.integrate(y0, 0.01, args.steps, arrays=arrays, save_every=args.steps, info=info)
                sweeps = float(np.mean(info["iterations"])) + len(mod.GAMMAS)     # + each stage's predictor
                cpu = _best(lambda: mod.integrate(y0, 0.01, args.steps, arrays=arrays, save_every=args.steps),
                            args.repeats)
                step, sweep = cpu / args.steps * 1e6, cpu / args.steps / sweeps * 1e6
                if base is None:
                    base = (step, sweep)
                print(f"{n:>4} {order:>5} {name:>11} {step:>9.1f} {sweeps:>11.2f} {sweep:>9.2f} "
                      f"{step / base[0]:>10.3f} {sweep / base[1]:>11.3f}")
    for order in args.orders:
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "METHODGEN_CACHE": cache}
            out = subprocess.run([sys.executable, "-c", COLD, str(order), str(args.sizes[0])], env=env,
                                 capture_output=True, text=True, check=True)
        print(f"cold build + 2 steps of the scene trap, energy-momentum order {order}, N = {args.sizes[0]}: "
              f"{float(out.stdout.strip().splitlines()[-1]):.2f} s")


if __name__ == "__main__":
    main()
