"""KdV on a periodic lattice as u' = S ∇H: the built-in ``kdv`` scene's AVF
module (or ``kdv4``'s: the fourth-order stencils, a Newton matrix of half-width 4), its cold
build, its step cost at several N and its energy error.  A benchmark, not a test.

    python benchmarks/lattice_kdv.py [--scene kdv4] [--sizes 512,1024,2048] [--steps 2000] [--numpy]

Measured:

* **cold build**: a fresh interpreter and a fresh ``METHODGEN_CACHE`` (a subprocess): import
  methodgen, load the scene, derive, print, write and import the module (numpy and compiled), and
  take the first step at N = 512;
* **per step** (warm, min of 3 repeats, h = 0.01, the scene's two solitons): the compiled module
  (and with ``--numpy`` the numpy one), with the mean Newton iterations (the dispersion's stiffness h/dx³ grows as N³, and simplified
  Newton takes a little more iterations at large N; the cost per iteration is linear in N);
* **energy and mass**: relative |H - H0| and |M - M0| over 10⁴ steps at N = 512 (compiled).
"""

from __future__ import annotations

import argparse
import json
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
sc = load_lattice_scene({scene!r})
m = build_lattice(sc.lattice, "avf", backend={backend!r})
m.integrate(sc.y0(512), 0.01, 1)
print(time.perf_counter() - t0)
"""


def cold(backend: str, scene: str) -> float:
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "METHODGEN_CACHE": cache}
        out = subprocess.run([sys.executable, "-c", COLD.format(backend=backend, scene=scene)], env=env, check=True,
                             capture_output=True, text=True).stdout
    return float(out.split()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="512,1024,2048")
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--scene", default="kdv", choices=("kdv", "kdv4"))
    ap.add_argument("--numpy", action="store_true", help="time the numpy module too")
    args = ap.parse_args()
    from methodgen.app.lattice_scene import load_lattice_scene
    from methodgen.codegen.lattice_emit import build_lattice

    out = {"scene": args.scene, "load_before": os.getloadavg()[0],
           "cold_build_to_first_step_s": {b: cold(b, args.scene) for b in ("numpy", "compiled")}}
    sc = load_lattice_scene(args.scene)
    mod = build_lattice(sc.lattice, "avf", backend="compiled")
    backends = [("compiled", mod)] + ([("numpy", build_lattice(sc.lattice, "avf"))] if args.numpy else [])
    for n in map(int, args.sizes.split(",")):
        u0 = sc.y0(n)
        for name, m in backends:
            steps = args.steps if name == "compiled" else max(args.steps // 10, 20)
            m.integrate(u0, 0.01, 20)
            best, info = [], {}
            for _ in range(3):
                t = time.perf_counter()
                m.integrate(u0, 0.01, steps, save_every=steps, info=info)
                best.append((time.perf_counter() - t) / steps)
            out[f"N={n} {name}"] = {"per_step_us": min(best) * 1e6,
                                    "newton_iterations": float(np.mean(info["newton_iterations"]))}
    tr = mod.integrate(sc.y0(512), 0.01, 10_000, save_every=10)
    values = [mod.invariants(r) for r in tr]
    for k in ("H", "mass"):
        v = np.array([x[k] for x in values])
        out[f"{k}_relative_error_1e4_steps"] = float(np.max(np.abs(v - v[0])) / abs(v[0]))
    out["load_after"] = os.getloadavg()[0]
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
