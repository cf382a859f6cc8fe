"""Cold first use through the CLI, two source trees side by side: wall and CPU time per process.

    python benchmarks/cold_first_use.py --old /path/to/old/tree --new . [--rounds 5] [CONFIG ...]

CONFIG is a key of :data:`CONFIGS` (default: all).  Each run is a fresh process
(``python -m methodgen run SCENE ... --backend numba --steps 10``) with a fresh, empty
``METHODGEN_CACHE`` and ``PYTHONPATH`` set to the tree; the trees alternate (old, new;
then new, old) so that a change of the machine's load falls on both.  Printed per
configuration and tree: wall and CPU seconds of the whole process (CPU from the child's
rusage: on a shared machine under load it moves far less than wall), min/median, the
phases the CLI reports (``METHODGEN_PROGRESS_SECONDS=0``; wall), the ratios new/old, and
whether every run ended on the same ``y_final`` line.  Not a test.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time

CONFIGS = {
    "kepSV10": "kepler --method stormer-verlet --order 10",
    "kepEM": "kepler --method energy-momentum",
    "ossEM": "outer-solar-system --method energy-momentum",
    "ossSV8": "outer-solar-system --method stormer-verlet --order 8",
}


def one(tree: str, config: str) -> tuple[float, float, dict, tuple]:
    """(wall, cpu, phases, y_final lines) of one cold process."""
    with tempfile.TemporaryDirectory() as d:
        env = {**os.environ, "PYTHONPATH": tree, "METHODGEN_CACHE": os.path.join(d, "c"),
               "METHODGEN_PROGRESS_SECONDS": "0"}
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "methodgen", "run", *CONFIGS[config].split(),
                              "--backend", "numba", "--steps", "10"], env=env, capture_output=True, text=True, cwd=d)
        wall = time.perf_counter() - t
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if out.returncode:
            raise SystemExit(f"{tree} {config}: {out.stderr.strip()[-2000:]}")
        cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
        phases = {m.group(1): float(m.group(2))
                  for m in re.finditer(r"methodgen: (\w+) \S+ done in ([\d.]+) s", out.stderr)}
        return wall, cpu, phases, tuple(l for l in out.stdout.splitlines() if l.startswith("y_final"))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("configs", nargs="*", default=list(CONFIGS))
    ap.add_argument("--old", required=True, help="source tree of the reference")
    ap.add_argument("--new", required=True, help="source tree measured against it")
    ap.add_argument("--rounds", type=int, default=5)
    a = ap.parse_args(argv)
    trees = {"old": os.path.abspath(a.old), "new": os.path.abspath(a.new)}
    print(f"load average {os.getloadavg()}", flush=True)
    runs = {(c, t): [] for c in a.configs for t in trees}
    for r in range(a.rounds):
        for c in a.configs:
            for t in (("old", "new") if r % 2 == 0 else ("new", "old")):
                runs[c, t].append(one(trees[t], c))
    for c in a.configs:
        for t in trees:
            w = [x[0] for x in runs[c, t]]
            u = [x[1] for x in runs[c, t]]
            ph = {}
            for x in runs[c, t]:
                for k, v in x[2].items():
                    ph.setdefault(k, []).append(v)
            phs = " ".join(f"{k} {min(v):.2f}/{statistics.median(v):.2f}" for k, v in ph.items())
            print(f"{c:8s} {t}: wall min {min(w):.2f} med {statistics.median(w):.2f}; cpu min {min(u):.2f} "
                  f"med {statistics.median(u):.2f} | phases (wall, min/med) {phs}")
        (wo, uo), (wn, un) = [([x[0] for x in runs[c, t]], [x[1] for x in runs[c, t]]) for t in trees]
        same = len({x[3] for t in trees for x in runs[c, t]}) == 1
        print(f"{c:8s} new/old: wall min {min(wn) / min(wo):.2f} med {statistics.median(wn) / statistics.median(wo):.2f}; "
              f"cpu min {min(un) / min(uo):.2f} med {statistics.median(un) / statistics.median(uo):.2f}; "
              f"same y_final in every run: {same}")
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
