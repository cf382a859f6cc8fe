"""First use of a numba module: fresh process → first step, on a cold machine and with the
shared runtime (methodgen.runtime.nbruntime) already compiled.  Not a test: run it and read the lines.

    python benchmarks/numba_first_use.py [--steps N]

For each configuration, in fresh processes with a fresh METHODGEN_CACHE:
  cold machine     -- a fresh NUMBA_CACHE_DIR too: the runtime is compiled as well;
  runtime cached   -- NUMBA_CACHE_DIR holds the runtime: the kernels of the new system compile;
  warm             -- the same caches again: everything loads;
then µs per step (CPU time, best of 5) and the module's size.  Wall-clock times; on a shared
machine compare within one run.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap

CONFIGS = [("kepler", "stormer-verlet", 10), ("kepler", "energy-momentum", 2), ("kepler", "energy-momentum", 8),
           ("henon-heiles-2d", "energy-momentum", 8), ("outer-solar-system", "stormer-verlet", 8),
           ("outer-solar-system", "energy-momentum", 2)]

PROBE = textwrap.dedent("""
    import sys, time
    t0 = time.perf_counter()
    import numpy as np
    import methodgen as mg
    scene, method, order, steps = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    sc = mg.load_scene(scene)
    m = mg.build(sc.system, method, backend="numba", order=order)
    y0 = np.array(sc.y0, dtype=float)
    m.integrate(y0, sc.h, 1)
    first = time.perf_counter() - t0
    best = float("inf")
    if steps:
        for _ in range(5):
            a = time.process_time(); m.integrate(y0, sc.h, steps); best = min(best, time.process_time() - a)
    import os
    print(f"{first:.2f} {best / max(steps, 1) * 1e6:.3f} {os.path.getsize(m.__file__)}")
""")


def _probe(env, scene, method, order, steps=0):
    out = subprocess.run([sys.executable, "-c", PROBE, scene, method, str(order), str(steps)], env=env,
                         capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), float(out[1]), int(out[2])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=5000, help="steps of the per-step timing")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as root:
        runtime = os.path.join(root, "runtime")
        base = {**os.environ, "NUMBA_CACHE_DIR": runtime}
        subprocess.run([sys.executable, "-c", "import methodgen.runtime.nbruntime"], env=base, check=True)
        for i, (scene, method, order) in enumerate(CONFIGS):
            cold = {**os.environ, "METHODGEN_CACHE": os.path.join(root, f"c{i}"),
                    "NUMBA_CACHE_DIR": os.path.join(root, f"n{i}")}
            new = {**base, "METHODGEN_CACHE": os.path.join(root, f"m{i}")}
            t_cold = _probe(cold, scene, method, order)[0]
            t_new = _probe(new, scene, method, order)[0]
            t_warm, us, size = _probe(new, scene, method, order, args.steps)
            print(f"{scene} {method} o{order}: cold machine {t_cold:.2f} s, runtime cached {t_new:.2f} s, "
                  f"warm {t_warm:.2f} s; {us:.3f} µs/step; module {size} bytes", flush=True)


if __name__ == "__main__":
    main()
