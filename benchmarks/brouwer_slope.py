"""Brouwer's law of the default stepper on a scene: RMS energy error over phases along the
orbit, log-log slope over the last two decades of t (issue 16's target: <= 0.55).

Not a test: run it and read the line.

    python benchmarks/brouwer_slope.py kepler --backend numba [--steps 1e6] [--phases 8] [--h 0.01]
    python benchmarks/brouwer_slope.py outer-solar-system --backend numpy
    python benchmarks/brouwer_slope.py henon-heiles-2d --method stormer-verlet --order 10 --h 0.1 \
        --backend numba --steps 1e7 --phases 16 [--compensated False]

Phases: the states of one run from the scene's y0 at evenly spaced steps (4000 steps).  The
energy is that of the exact numerical state y + c (the compensation the module carries),
evaluated in numpy.longdouble by H lambdified from the scene's SymPy expression: a float64
evaluation would put a floor of ~eps·|terms| under the measurement.  Default settings
otherwise (round-off stopping, compensated summation and stage sums), batched integrate in
chunks with the compensation carried through ``info``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import sympy as sp

import methodgen as mg
from methodgen.codegen.build import build


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene")
    ap.add_argument("--method", default="energy-momentum")
    ap.add_argument("--backend", default="numpy", choices=["numpy", "numba"])
    ap.add_argument("--steps", type=float, default=1e6)
    ap.add_argument("--phases", type=int, default=8)
    ap.add_argument("--h", type=float, default=None, help="default: the scene's step")
    ap.add_argument("--order", type=int, default=2, help="compose the method to this order (default 2: the "
                    "method itself)")
    ap.add_argument("--compensated", default="True", choices=["True", "False"],
                    help="integrate's compensated (default True)")
    ap.add_argument("--one-by-one", action="store_true",
                    help="integrate each phase as one trajectory (the numpy backend's scalar path, "
                         "faster than its batch path for looped modules and small batches)")
    args = ap.parse_args(argv)
    scene = mg.load_scene(args.scene)
    system = scene.system
    mod = build(system, args.method, backend=args.backend, order=args.order)
    comp_opt = args.compensated == "True"
    h = args.h or scene.h
    steps = int(args.steps)
    pre = mod.integrate(np.array(scene.y0, float), h, 4000)
    Y0 = pre[np.linspace(0, len(pre) - 1, args.phases).astype(int)]
    Hf = sp.lambdify(list(system.y) + list(system.params), system.H, "numpy")
    pv = [np.longdouble(repr(float(system.param_values[str(s)]))) for s in system.params]

    def energy(Y, C):
        Z = Y.astype(np.longdouble) + C.astype(np.longdouble)
        return Hf(*[Z[:, i] for i in range(Z.shape[1])], *pv)

    H0 = energy(Y0, np.zeros_like(Y0))
    record = np.unique(np.geomspace(10, steps, 40).astype(int))
    Y, info, done, rms = Y0.copy(), {"compensation": np.zeros_like(Y0)}, 0, []
    infos = [{"compensation": np.zeros(Y0.shape[1])} for _ in Y0]
    t0 = time.process_time()
    for target in record:
        if args.one_by_one:
            for b in range(len(Y)):
                Y[b] = mod.integrate(Y[b], h, int(target - done), info=infos[b], compensated=comp_opt)[-1]
            comp = np.array([i["compensation"] for i in infos])
        else:
            Y = mod.integrate(Y, h, int(target - done), info=info, compensated=comp_opt)[-1]
            comp = info["compensation"]
        done = target
        rms.append(float(np.sqrt(np.mean((energy(Y, comp) - H0) ** 2))))
    t, rms = record * h, np.array(rms)
    keep = (rms > 0) & (t >= t[-1] / 100)
    slope = np.polyfit(np.log(t[keep]), np.log(rms[keep]), 1)[0]
    print(f"{args.scene} {args.method} o{args.order} compensated={args.compensated} {args.backend} h={h} "
          f"steps={steps} phases={args.phases}: "
          f"slope {slope:.3f}, RMS at the end {rms[-1]:.2e}, {time.process_time() - t0:.0f} s CPU")


if __name__ == "__main__":
    main()
