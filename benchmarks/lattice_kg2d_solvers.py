"""The 2-D lattice modules' three step solvers on ``klein-gordon-2d`` (AVF, periodic N × N): time per
step and iterations per step, numpy and compiled backends.  A benchmark, not a test.

    python benchmarks/lattice_kg2d_solvers.py [--sizes 32,64,128] [--amps 1,6,10] [--hs 0.05,0.1]
                                              [--repeats 3] [--json out.json]

The solvers (``integrate(..., solver=...)``): ``simplified`` (simplified Newton with the linear
part's matrix by the FFT, the default), ``newton`` (the exact Jacobian, scipy.sparse, SuperLU once
per step at the predictor) and ``krylov`` (GMRES on exact Jacobian-vector products, FFT
preconditioner, Eisenstat–Walker forcing).  "Amplitude A" is the scene's Gaussian bump scaled to
the peak A (the scene's own is 2).  Each setting runs ``steps`` steps from the bump
(check_resolution=False: the large amplitudes at h = 0.1 are what is measured, resolved or not;
maxiter=400, so that slow convergence shows as a count instead of a failure); the time per step
is the min over ``--repeats`` runs, the solvers alternated within each repeat (the machine is
shared: the load, ``os.getloadavg()``, is printed before and after; BLAS runs one thread, see
below).  ``newton-full`` (SuperLU at
every iteration, ``NEWTON_REFACTOR = True``) is timed at amplitude 10 to choose between the two
Newton variants.  Also printed: the relative energy error |H - H0|/|H0| at the end of the run.
"""

from __future__ import annotations

import os
import sys

# One BLAS thread (set before numpy loads): scipy's GMRES orthogonalises with BLAS level-1 calls,
# which OpenBLAS threads at these lengths; on this shared 2-core machine the threads' spinning made
# the Krylov timings erratic (the same 128² step: 37 ms to 640 ms between runs).  Pass --blas-threads
# to override.
if "--blas-threads" not in sys.argv:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

STEPS = {32: 20, 64: 10, 128: 5}


def run(mod, y0, h, steps, solver):
    info = {}
    t = time.perf_counter()
    rows = mod.integrate(y0, h, steps, save_every=steps, info=info, solver=solver, maxiter=400,
                         check_resolution=False)
    dt = (time.perf_counter() - t) / steps
    H0 = mod.hamiltonian(rows[0])
    return dt, float(np.mean(info["newton_iterations"])), abs(mod.hamiltonian(rows[-1]) - H0) / abs(H0), \
        info.get("linear_iterations", 0) / steps


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="32,64,128")
    ap.add_argument("--amps", default="1,6,10")
    ap.add_argument("--hs", default="0.05,0.1")
    ap.add_argument("--backends", default="numpy,compiled")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None)
    ap.add_argument("--blas-threads", action="store_true", help="leave BLAS's thread count as the environment has it")
    args = ap.parse_args(argv)
    from methodgen.app.lattice_scene import load_lattice_scene
    from methodgen.codegen.lattice_emit import build_lattice

    sc = load_lattice_scene("klein-gordon-2d")
    mods = {b: build_lattice(sc.lattice, "avf", backend=b) for b in args.backends.split(",")}
    print(f"load average before: {os.getloadavg()}; OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}")
    out = []
    for n in map(int, args.sizes.split(",")):
        base = sc.y0((n, n))
        base = base / np.max(np.abs(base[0]))
        steps = STEPS.get(n, 5)
        for amp in map(float, args.amps.split(",")):
            for h in map(float, args.hs.split(",")):
                for backend, mod in mods.items():
                    y0 = amp * base
                    solvers = ["simplified", "newton", "krylov"] + (["newton-full"] if amp >= 10 else [])
                    best = {s: None for s in solvers}
                    for r in range(args.repeats):
                        # alternate the order between repeats (the load drifts)
                        for s in (solvers if r % 2 == 0 else solvers[::-1]):
                            mod.NEWTON_REFACTOR = s == "newton-full"
                            try:
                                got = run(mod, y0, h, steps, "newton" if s == "newton-full" else s)
                            except mod.ConvergenceError as exc:
                                got = (float("inf"), float("nan"), float("nan"), 0.0)
                                print("  failed:", s, str(exc)[:100])
                            finally:
                                mod.NEWTON_REFACTOR = False
                            if best[s] is None or got[0] < best[s][0]:
                                best[s] = got
                    for s in solvers:
                        t, its, dH, lin = best[s]
                        rec = dict(N=n, amp=amp, h=h, backend=backend, solver=s, ms=1e3 * t, iterations=its,
                                   energy_rel=dH, gmres_per_step=lin, steps=steps)
                        out.append(rec)
                        print(f"N={n:4d} A={amp:4g} h={h:5g} {backend:8s} {s:11s} {1e3 * t:9.2f} ms/step "
                              f"{its:6.2f} it/step" + (f" ({lin:.1f} GMRES/step)" if lin else "")
                              + f"  |dH|/H={dH:.1e}", flush=True)
    print(f"load average after: {os.getloadavg()}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
