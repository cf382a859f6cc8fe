"""Where the first use of a numba module goes: per phase and per compiled kernel.

    python benchmarks/first_use_phases.py [CONFIG ...] [--steps N] [--loops auto|on|off]

CONFIG is ``scene:method:order`` (built-in scenes), ``fpu64:energy-momentum:2`` (an
FPU-beta chain of 64 particles, written with indexed sums) or ``toda200:energy-momentum:2``
(a periodic Toda ring of 200).  Each runs in a fresh process with a fresh METHODGEN_CACHE and
the default NUMBA_CACHE_DIR (the shared runtime already compiled on this machine: run once
to warm it).  Printed: the phases build reports (derive, lower, render, write, load), the
numba compile time of each kernel (inside load), first use (process start → first step), µs
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

DEFAULT = ["outer-solar-system:stormer-verlet:2", "outer-solar-system:stormer-verlet:8",
           "outer-solar-system:energy-momentum:2", "outer-solar-system:energy-momentum:8",
           "fpu64:energy-momentum:2", "toda200:energy-momentum:2"]

PROBE = textwrap.dedent(r"""
    import sys, time, os, json
    t0 = time.perf_counter()
    import numpy as np
    import numba.core.dispatcher as _d
    import methodgen as mg
    from methodgen.lower import uses_loops
    name, method, order, steps, loops = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
    compiles = []
    _orig = _d.Dispatcher.compile
    def _timed(self, sig):
        a = time.perf_counter()
        try:
            return _orig(self, sig)
        finally:
            compiles.append((self.py_func.__name__, time.perf_counter() - a))
    _d.Dispatcher.compile = _timed
    phases = {}
    def progress(ph, el, done):
        if done:
            phases[ph] = phases.get(ph, 0.0) + el
    if name.startswith("fpu"):
        n = int(name[3:])
        H = (f"Sum(p[i]**2/2, i, 1, {n}) + q[1]**2/2 + beta*q[1]**4/4 + Sum((q[i+1] - q[i])**2/2 "
             f"+ beta*(q[i+1] - q[i])**4/4, i, 1, {n - 1}) + q[{n}]**2/2 + beta*q[{n}]**4/4")
        system = mg.Hamiltonian(H, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                                params={"beta": 1.0}, name=name)
        y0 = np.array([np.sin(np.pi * i / (n + 1)) for i in range(1, n + 1)] + [0.0] * n)
        h = 0.05
    elif name.startswith("toda"):
        n = int(name[4:])
        H = f"Sum(p[i]**2/2, i, 1, {n}) + Sum(exp(q[i] - q[i % {n} + 1]), i, 1, {n})"
        system = mg.Hamiltonian(H, q=[f"q{i}" for i in range(1, n + 1)], p=[f"p{i}" for i in range(1, n + 1)],
                                name=name)
        y0 = np.array([0.1 * np.sin(2 * np.pi * i / n) for i in range(n)] + [0.2 * np.cos(2 * np.pi * i / n) for i in range(n)])
        h = 0.05
    else:
        sc = mg.load_scene(name)
        system, y0, h = sc.system, np.array(sc.y0, dtype=float), sc.h
    opts = {} if loops == "auto" else {"loops": loops == "on"}
    t1 = time.perf_counter()
    m = mg.build(system, method, backend="numba", order=order, progress=progress, **opts)
    m.integrate(y0, h, 1)
    first = time.perf_counter() - t0
    build = time.perf_counter() - t1
    best = float("inf")
    if steps:
        for _ in range(5):
            a = time.process_time(); m.integrate(y0, h, steps); best = min(best, time.process_time() - a)
    print(json.dumps({"first": first, "build": build, "phases": phases, "compiles": compiles,
                      "us": best / max(steps, 1) * 1e6, "size": os.path.getsize(m.__file__),
                      "lines": sum(1 for _ in open(m.__file__))}))
""")


def probe(config: str, steps: int, loops: str, cache: str) -> dict:
    import json
    name, method, order = config.split(":")
    env = {**os.environ, "METHODGEN_CACHE": cache}
    out = subprocess.run([sys.executable, "-c", PROBE, name, method, order, str(steps), loops], env=env,
                         capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"{config}: {out.stderr.strip().splitlines()[-1]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("configs", nargs="*", default=DEFAULT)
    ap.add_argument("--steps", type=int, default=2000, help="steps of the per-step timing (0: none)")
    ap.add_argument("--loops", default="auto", choices=("auto", "on", "off"))
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f}", flush=True)
    with tempfile.TemporaryDirectory() as root:
        for i, config in enumerate(args.configs):
            r = probe(config, args.steps, args.loops, os.path.join(root, f"c{i}"))
            ph = " ".join(f"{k} {v:.2f}" for k, v in r["phases"].items())
            comp = " ".join(f"{k} {v:.2f}" for k, v in r["compiles"] if v >= 0.05)
            print(f"{config}: first use {r['first']:.2f} s (build→first step {r['build']:.2f} s); {ph}; "
                  f"compile [{comp}]; {r['us']:.2f} µs/step; module {r['size']} bytes, {r['lines']} lines; "
                  f"load {os.getloadavg()[0]:.2f}", flush=True)


if __name__ == "__main__":
    main()
