"""Warm start: seconds from ``import`` to the first step of a cached module, in fresh processes.

Not a test: run it and read the lines.

    python benchmarks/warm_start.py [--backend numpy numba] [--runs 5] [--system kepler]

For each backend: a private cache (a temporary folder), one cold process that
derives and writes the module (``methodgen.build_text``), then ``--runs`` fresh
processes that find it through the warm-start index.  Each process measures from
just before ``import numpy, methodgen`` to the end of the first ``step`` (the
first numba call loads the compiled code from numba's disk cache), and says
whether SymPy was imported.  The process's own start-up (the interpreter) is
printed apart as the wall time of the whole process.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

SYSTEMS = {
    "osc": ("p**2/(2*m) + k*q**2/2", ["q"], ["p"], {"m": 1.0, "k": 1.0}, [1.0, 0.0], "midpoint"),
    "kepler": ("(px**2 + py**2 + pz**2)/(2*m) - k/sqrt(x**2 + y**2 + z**2)", ["x", "y", "z"],
               ["px", "py", "pz"], {"m": 1.0, "k": 1.0}, [0.4, 0.0, 0.0, 0.0, 1.6, 1.2], "energy-momentum"),
}

PROBE = r"""
import time
t0 = time.perf_counter()
import json, sys
import numpy as np
import methodgen as mg
H, q, p, params, y0, method, backend = json.loads(sys.argv[1])
mod = mg.build_text(H, q, p, method, params=params, name="bench", backend=backend)
mod.step(np.array(y0), 0.01)
t1 = time.perf_counter()
print(json.dumps({"seconds": t1 - t0, "sympy": "sympy" in sys.modules}))
"""


def one(args: list, cache: str) -> tuple[dict, float]:
    env = {**os.environ, "METHODGEN_CACHE": cache, "PYTHONPATH": str(ROOT)}
    t = time.perf_counter()
    out = subprocess.run([sys.executable, "-c", PROBE, json.dumps(args)], capture_output=True, text=True,
                         env=env, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1]), time.perf_counter() - t


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", nargs="+", default=["numpy", "numba"])
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--system", choices=sorted(SYSTEMS), default="kepler")
    a = ap.parse_args(argv)
    H, q, p, params, y0, method = SYSTEMS[a.system]
    for backend in a.backend:
        with tempfile.TemporaryDirectory() as tmp:
            cache = os.path.join(tmp, "cache")
            args = [H, q, p, params, y0, method, backend]
            cold, cold_wall = one(args, cache)
            warm = [one(args, cache) for _ in range(a.runs)]
            secs = [w["seconds"] for w, _ in warm]
            walls = [wall for _, wall in warm]
            print(f"{a.system} {method} {backend}: cold {cold['seconds']:.2f} s (sympy {cold['sympy']}); "
                  f"warm import->first step median {statistics.median(secs):.3f} s "
                  f"(min {min(secs):.3f}, max {max(secs):.3f}; sympy "
                  f"{any(w['sympy'] for w, _ in warm)}); whole process median {statistics.median(walls):.3f} s")


if __name__ == "__main__":
    main()
