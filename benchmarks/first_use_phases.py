"""Where the first use of a numba module goes: per phase, and which route compiled its kernels.

    python benchmarks/first_use_phases.py [CONFIG ...] [--steps N]

CONFIG is ``scene:method:order`` (built-in scenes), ``fpu64:energy-momentum:2`` (an
FPU-beta chain of 64 particles, written with indexed sums) or ``toda200:energy-momentum:2``
(a periodic Toda ring of 200).  Each runs in a fresh process with a fresh METHODGEN_CACHE and
the default NUMBA_CACHE_DIR (the shared runtime already compiled on this machine: run once
to warm it).  Printed: the phases build reports (derive, lower, render, write, load), how
many kernels took the LLVM route and how many numba (inside load), first use (process start → first step), µs
per step (CPU time, best of 5) and the module size.  Wall-clock times: on a shared machine
compare configurations within one run.  Not a test.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

HERE = str(Path(__file__).resolve().parent)

DEFAULT = ["outer-solar-system:stormer-verlet:2", "outer-solar-system:stormer-verlet:8",
           "outer-solar-system:energy-momentum:2", "outer-solar-system:energy-momentum:8",
           "fpu64:energy-momentum:2", "toda200:energy-momentum:2"]

PROBE = textwrap.dedent(r"""
    import sys, time, os, json
    t0 = time.perf_counter()
    import numpy as np
    import methodgen as mg
    name, method, order, steps = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    phases = {}
    def progress(ph, el, done):
        if done:
            phases[ph] = phases.get(ph, 0.0) + el
    sys.path.insert(0, sys.argv[5])      # benchmarks/: the problems by name
    from _problems import problem
    system, y0, h = problem(name)
    t1 = time.perf_counter()
    m = mg.build(system, method, backend="numba", order=order, progress=progress)
    m.integrate(y0, h, 1)
    first = time.perf_counter() - t0
    build = time.perf_counter() - t1
    best = float("inf")
    if steps:
        for _ in range(5):
            a = time.process_time(); m.integrate(y0, h, steps); best = min(best, time.process_time() - a)
    # which route compiled each kernel (numba, when imported at all, only for what the LLVM route
    # cannot translate; its compile time is then inside the "load" phase)
    kinds = [type(getattr(m, a)).__name__ for a in dir(m) if a.startswith("_nb_") and callable(getattr(m, a))]
    compiles = [("llvm", kinds.count("LLVMKernel")), ("numba", kinds.count("CPUDispatcher"))]
    print(json.dumps({"first": first, "build": build, "phases": phases, "compiles": compiles,
                      "us": best / max(steps, 1) * 1e6, "size": os.path.getsize(m.__file__),
                      "lines": sum(1 for _ in open(m.__file__))}))
""")


def probe(config: str, steps: int, cache: str) -> dict:
    import json
    name, method, order = config.split(":")
    env = {**os.environ, "METHODGEN_CACHE": cache}
    out = subprocess.run([sys.executable, "-c", PROBE, name, method, order, str(steps), HERE], env=env,
                         capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"{config}: {out.stderr.strip().splitlines()[-1]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("configs", nargs="*", default=DEFAULT)
    ap.add_argument("--steps", type=int, default=2000, help="steps of the per-step timing (0: none)")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}", flush=True)
    with tempfile.TemporaryDirectory() as root:
        for i, config in enumerate(args.configs):
            r = probe(config, args.steps, os.path.join(root, f"c{i}"))
            ph = " ".join(f"{k} {v:.2f}" for k, v in r["phases"].items())
            comp = " ".join(f"{k} {v}" for k, v in r["compiles"])
            print(f"{config}: first use {r['first']:.2f} s (build→first step {r['build']:.2f} s); {ph}; "
                  f"compile [{comp}]; {r['us']:.2f} µs/step; module {r['size']} bytes, {r['lines']} lines; "
                  f"load {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":
    main()
