"""The 2-D Klein–Gordon lattice (the built-in ``klein-gordon-2d`` scene, AVF, periodic N × M):
cold build, per-step cost at n, 2n and 4n sites, Newton iterations, and the energy error.  A
benchmark, not a test.

    python benchmarks/lattice_kg2d.py [--sizes 128x128,256x128,256x256] [--steps 200] [--energy-steps 10000]

Measured:

* **cold build**: a fresh interpreter and a fresh ``METHODGEN_CACHE`` (a subprocess): import
  methodgen, load the scene, derive, print, write and import the module (numpy, and compiled:
  its site kernel compiled through LLVM at the first step), and take the first step at 128 × 128;
* **per step** (warm, min of 3 repeats, the scene's h = 0.01 and Gaussian bump): the numpy module
  and the compiled one (the site kernel compiled, the FFT solve numpy's), with the mean
  simplified-Newton iterations, and the slope of log(time) against log(sites) between successive
  sizes (1 is linear; the FFT adds a log factor);
* **the solve, chosen by measurement**: the same steps with the linear part's FFT solve replaced
  by the identity (plain fixed-point iteration on ``z = y0 + h J ∇̄H``): iterations and time
  per step at each size, and at the first size with a 4 times longer step (``--stiff-h``), where
  the linear part's stiffness h·ω_max exceeds 2 and the fixed point cannot converge;
* **energy**: relative max |H - H0| over ``--energy-steps`` steps at 128 × 128 for AVF, and for
  the midpoint rule (the control, which does not keep H).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

COLD = """
import time
t0 = time.perf_counter()
from methodgen.app.lattice_scene import load_lattice_scene
from methodgen.codegen.lattice_emit import build_lattice
sc = load_lattice_scene("klein-gordon-2d")
m = build_lattice(sc.lattice, "avf", backend={backend!r})
m.integrate(sc.y0((128, 128)), 0.01, 1)
print(time.perf_counter() - t0)
"""


def cold(backend: str) -> float:
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "METHODGEN_CACHE": cache}
        out = subprocess.run([sys.executable, "-c", COLD.format(backend=backend)], env=env, check=True,
                             capture_output=True, text=True).stdout
    return float(out.split()[-1])


def per_step(mod, y0, h, steps):
    mod.integrate(y0, h, 5)
    best, info = [], {}
    for _ in range(3):
        t = time.perf_counter()
        mod.integrate(y0, h, steps, save_every=steps, info=info)
        best.append((time.perf_counter() - t) / steps)
    return min(best), float(np.mean(info["newton_iterations"]))


def fixed_point(mod, y0, h, steps, maxiter=500):
    """The steps with the identity in place of the linear part's solve: z ← z - R(z); (time per
    step, mean iterations), or the failure's message."""
    y, n, m = mod._size(y0)
    p = mod._params(None)
    Y, dy, dy2, its = y.copy(), None, None, []
    apply = mod._apply
    mod._apply = lambda inv, R, n, m: R        # the identity: no FFT round trip either
    t = time.perf_counter()
    try:
        with np.errstate(over="ignore", invalid="ignore"):   # (a diverging iteration overflows: reported below)
            for s in range(steps):
                Y1, it = mod._step(Y, h, n, m, p, mod._Simplified(None, h, n, m, p), maxiter, 4 * mod._EPS, s, False, dy,
                                   dy2)
                dy2, dy, Y = dy, Y1 - Y, Y1
                its.append(it)
    except (mod.ConvergenceError, mod.NonFiniteError) as exc:
        return {"failed": str(exc)[:160]}
    finally:
        mod._apply = apply
    return {"per_step_ms": (time.perf_counter() - t) / steps * 1e3, "iterations": float(np.mean(its))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="128x128,256x128,256x256")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--energy-steps", type=int, default=10_000)
    ap.add_argument("--stiff-h", type=float, default=0.08)
    args = ap.parse_args()
    from methodgen.app.lattice_scene import load_lattice_scene
    from methodgen.codegen.lattice_emit import build_lattice

    out = {"load_before": os.getloadavg()[0],
           "cold_build_to_first_step_s": {b: cold(b) for b in ("numpy", "compiled")}}
    sc = load_lattice_scene("klein-gordon-2d")
    mod = build_lattice(sc.lattice, "avf")
    comp = build_lattice(sc.lattice, "avf", backend="compiled")
    h = sc.h
    sizes = [tuple(map(int, s.split("x"))) for s in args.sizes.split(",")]
    prev = prev_c = None
    for n, m in sizes:
        t, its = per_step(mod, sc.y0((n, m)), h, args.steps)
        row = {"sites": n * m, "per_step_ms": t * 1e3, "newton_iterations": its,
               "per_site_and_iteration_ns": t / (n * m * its) * 1e9}
        if prev is not None:
            row["slope_vs_previous"] = math.log(t / prev[1]) / math.log(n * m / prev[0])
        prev = (n * m, t)
        tc, itc = per_step(comp, sc.y0((n, m)), h, args.steps)
        row["compiled"] = {"per_step_ms": tc * 1e3, "newton_iterations": itc}
        if prev_c is not None:
            row["compiled"]["slope_vs_previous"] = math.log(tc / prev_c[1]) / math.log(n * m / prev_c[0])
        prev_c = (n * m, tc)
        row["fixed_point"] = fixed_point(mod, sc.y0((n, m)), h, 20)
        out[f"{n}x{m}"] = row
    n, m = sizes[0]
    t, its = per_step(mod, sc.y0((n, m)), args.stiff_h, max(20, args.steps // 4))
    out[f"{n}x{m}_h={args.stiff_h}"] = {"per_step_ms": t * 1e3, "newton_iterations": its,
                                        "fixed_point": fixed_point(mod, sc.y0((n, m)), args.stiff_h, 20)}
    y0 = sc.y0((128, 128))
    every = max(1, args.energy_steps // 100)
    for method in ("avf", "midpoint"):
        md = mod if method == "avf" else build_lattice(sc.lattice, "midpoint")
        info = {}
        t0 = time.perf_counter()
        tr = md.integrate(y0, h, args.energy_steps, save_every=every, info=info)
        secs = time.perf_counter() - t0
        H = np.array([mod.hamiltonian(r) for r in tr])
        out[f"{method}_energy_128x128_{args.energy_steps}_steps"] = {
            "relative_max_error": float(np.max(np.abs(H - H[0])) / abs(H[0])), "seconds": secs,
            "newton_iterations": float(np.mean(info["newton_iterations"]))}
    out["load_after"] = os.getloadavg()[0]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
