"""Issue 25's first-use targets: a new Hamiltonian to its first compiled step, beside heyoka.

Not a test: run it and read the table (wall seconds; compare only rows of one run).

    python benchmarks/build_targets.py [--only kepler,henon-heiles-2d,...] [--json FILE]

Each configuration runs in a fresh process with a fresh ``METHODGEN_CACHE``.  Measured: process
start → ``mg.build(system, method, backend="numba", ...)`` → the first step, the build alone
(``build→step``), how many kernels the module has (all compiled through LLVM IR) and the peak
resident memory of the process.  heyoka's ``taylor_adaptive`` construction (tol 1e-15; for the
outer solar system also ``compact_mode=True``) is timed in its own fresh process in the same run,
cold (an empty disk cache of heyoka's compiled code) and warm (its cache filled by the run
before).  The machine's cores and load average are printed (and kept in the JSON): quote them
with every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

HERE = str(Path(__file__).resolve().parent)

SMALL = ["stormer-verlet:2", "stormer-verlet:10", "energy-momentum:2", "energy-momentum:8", "midpoint:2",
         "avf:2", "gauss:3", "gauss:6", "energy-collocation:3", "energy-collocation:4"]
CONFIGS = ([f"kepler:{m}" for m in SMALL] + [f"henon-heiles-2d:{m}" for m in SMALL if not m.startswith("avf")]
           + [f"outer-solar-system:{m}" for m in ("stormer-verlet:2", "stormer-verlet:4", "stormer-verlet:8",
                                                    "stormer-verlet:10", "energy-momentum:2", "energy-momentum:4",
                                                    "energy-momentum:8", "energy-momentum:10", "gauss:3")]
           + ["fpu64:energy-momentum:2", "toda200:energy-momentum:2"])
TARGET = {"kepler": 2.0, "henon-heiles-2d": 2.0, "outer-solar-system": 3.0, "fpu64": 5.0, "toda200": None,
          ("outer-solar-system", "gauss"): 10.0}

PROBE = textwrap.dedent(r"""
    import sys, time, json, resource
    t0 = time.perf_counter()
    import numpy as np
    import methodgen as mg
    from methodgen.codegen import llvmkernels
    name, method, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
    sys.path.insert(0, sys.argv[4])      # benchmarks/: the problems by name
    from _problems import problem
    system, y0, h = problem(name)
    opts = {"stages": k} if method in ("gauss", "energy-collocation") else {"order": k}
    if method in ("midpoint", "avf"):
        opts = {}
    t1 = time.perf_counter()
    m = mg.build(system, method, backend="numba", **opts)
    m.integrate(y0, h, 1)
    t2 = time.perf_counter()
    kinds = [type(getattr(m, a)).__name__ for a in dir(m) if a.startswith("_nb_") and not a.endswith("_rows")
             and callable(getattr(m, a))]
    print(json.dumps({"first": t2 - t0, "build": t2 - t1, "llvm": kinds.count("LLVMKernel"),
                      "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
""")

HEYOKA = textwrap.dedent(r"""
    import sys, time, json
    import numpy as np
    import methodgen as mg
    from methodgen.app.peers import heyoka_system, import_peer
    hy = import_peer("heyoka")
    sc = mg.load_scene(sys.argv[1])
    _, sys_ = heyoka_system(sc.system)
    if sys.argv[3] == "cold":       # heyoka's disk cache of compiled code: a fresh, empty one
        import tempfile
        hy.llvm_state.set_diskcache_path(tempfile.mkdtemp())
    t = time.perf_counter()
    ta = hy.taylor_adaptive(sys_, [float(v) for v in sc.y0], tol=1e-15, compact_mode=sys.argv[2] == "1")
    print(json.dumps({"build": time.perf_counter() - t}))
""")


def run(code, args, env):
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env)
    if out.returncode:
        return {"error": out.stderr.strip().splitlines()[-1][:120]}
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated system names")
    ap.add_argument("--json")
    a = ap.parse_args()
    only = set(a.only.split(",")) if a.only else None
    rows = []
    print(f"{'system':<20} {'method':<22} {'first use':>9} {'build→step':>10} {'target':>6} {'kernels':>7} "
          f"{'RSS MB':>7}")
    for cfg in CONFIGS:
        name, method, k = cfg.split(":")
        if only and name not in only:
            continue
        env = dict(os.environ, METHODGEN_CACHE=tempfile.mkdtemp())
        r = run(PROBE, [name, method, k, HERE], env)
        r.update(system=name, method=f"{method} {k}")
        rows.append(r)
        t = TARGET.get((name, method), TARGET.get(name))
        if "error" in r:
            print(f"{name:<20} {method + ' ' + k:<22} error: {r['error']}")
        else:
            ok = "" if t is None else ("  met" if r["build"] <= t else "  MISSED")
            print(f"{name:<20} {method + ' ' + k:<22} {r['first']:9.2f} {r['build']:10.2f} {t or '-':>6}"
                  f" {r['llvm']:>7} {r['rss_mb']:7.0f}{ok}", flush=True)
    for name, compact in (("kepler", "0"), ("henon-heiles-2d", "0"), ("outer-solar-system", "0"),
                          ("outer-solar-system", "1")):
        if only and name not in only:
            continue
        # cold: an empty disk cache of heyoka's; warm: its own cache, filled by the run before
        for state in ("cold", "warm-up", "warm"):
            r = run(HEYOKA, [name, compact, state], dict(os.environ))
            if state == "warm-up":
                continue
            r.update(system=name, method="heyoka taylor_adaptive" + (" compact" if compact == "1" else ""),
                     cache=state)
            rows.append(r)
            print(f"{name:<20} {r['method'] + ' (' + state + ')':<37} "
                  + (f"build {r['build']:.2f} s" if "build" in r else r["error"]), flush=True)
    load = os.getloadavg()
    print(f"machine: {os.cpu_count()} cores; load average at the end {load[0]:.2f} (1 min), "
          f"{load[1]:.2f} (5 min)")
    rows.append({"machine": {"cores": os.cpu_count(), "loadavg": list(load)}})
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
