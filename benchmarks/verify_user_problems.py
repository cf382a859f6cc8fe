"""Time ``methodgen verify`` on every user problem × applicable method (a benchmark, not a test).

Each (scene, method) runs in its own subprocess with a wall-clock cap, so a
derivation that hangs cannot stall the table.  Prints a Markdown table of
seconds and status counts, and optionally writes JSON.

    python benchmarks/verify_user_problems.py [--problems DIR] [--cap 120] [--json out.json]
        [--only SCENE[,SCENE]] [--methods M[,M]]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

ALL_METHODS = ["midpoint", "trapezoidal", "kahan", "energy-momentum", "avf", "gonzalez", "itoh-abe",
               "stormer-verlet", "rattle", "shake", "gauss", "energy-collocation"]


def applicable(scene_path: Path) -> list[str]:
    import methodgen as mg
    from methodgen.errors import MethodgenError

    scene = mg.load_scene(str(scene_path))
    out = []
    for m in ALL_METHODS:
        try:
            mg.discretize(scene.system, m)
        except MethodgenError:
            continue
        except Exception:  # noqa: BLE001 - a crash here is a finding too
            out.append(m)
            continue
        out.append(m)
    return out


def run_one(scene_path: Path, method: str, cap: float, extra: list[str]) -> dict:
    cmd = [sys.executable, "-m", "methodgen", "verify", str(scene_path), "--method", method, "--json",
           *extra]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=cap)
    except subprocess.TimeoutExpired:
        return {"seconds": cap, "outcome": f"killed after {cap:.0f} s", "statuses": {}}
    dt = time.perf_counter() - t0
    try:
        data = json.loads(proc.stdout)
    except json.JSONDecodeError:
        last = (proc.stderr.strip().splitlines() or ["?"])[-1]
        return {"seconds": dt, "outcome": f"exit {proc.returncode}: {last[:100]}", "statuses": {}}
    counts = Counter(c["status"] for c in data["certificates"])
    return {"seconds": dt, "outcome": "ok" if data["ok"] else "REFUTED", "statuses": dict(counts)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    here = Path(__file__).resolve().parent.parent
    ap.add_argument("--problems", default=str(here / "tests" / "user_problems"))
    ap.add_argument("--cap", type=float, default=120.0)
    ap.add_argument("--json")
    ap.add_argument("--only")
    ap.add_argument("--methods")
    ap.add_argument("--extra", default="", help="extra verify arguments, space separated")
    args = ap.parse_args(argv)
    scenes = sorted(Path(args.problems).glob("*.toml"))
    if args.only:
        keep = set(args.only.split(","))
        scenes = [s for s in scenes if s.stem in keep]
    rows = []
    print("| problem | method | seconds | outcome | statuses |")
    print("|---|---|---|---|---|")
    for sp in scenes:
        methods = applicable(sp)
        if args.methods:
            methods = [m for m in methods if m in args.methods.split(",")]
        for m in methods:
            r = run_one(sp, m, args.cap, args.extra.split())
            r.update(problem=sp.stem, method=m)
            rows.append(r)
            st = ", ".join(f"{k} {v}" for k, v in sorted(r["statuses"].items()))
            print(f"| {sp.stem} | {m} | {r['seconds']:.1f} | {r['outcome']} | {st} |", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
