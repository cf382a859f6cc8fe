"""Per-step cost of numba modules on the stepper against the template route.

Not a test: run it and read the table (CPU time, least of the repeats; on a shared
machine compare only rows of one run).

    python benchmarks/nbruntime_step_cost.py [--steps N] [--repeat R] [--route shared|template|both]

For each configuration a module is generated into a fresh folder on each route: the
stepper (methodgen.runtime.stepper compiled per module, the default route) and, where it still exists, the
template route (one compiled loop per module, ``templates/numba_runtime.py.j2``) by
forcing ``methodgen.codegen.emit.shared_runtime_supports`` to False *in this script only*.  Each
row gives µs per step, Newton iterations per step, and whether the two routes' trajectories
agree bitwise.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import methodgen as mg
from methodgen.codegen import emit
from methodgen.codegen.emit import module_filename

CONFIGS = [("kepler", "stormer-verlet", dict(order=10)), ("henon-heiles-2d", "energy-momentum", dict(order=8)),
           ("outer-solar-system", "energy-momentum", dict(order=2)), ("kepler", "energy-momentum", dict(order=2)),
           ("kepler", "gauss", dict(stages=3))]


def _generate(folder: Path, scene, method, options, template: bool):
    scheme = mg.discretize(scene.system, method, **options)
    tag = "_".join(f"{k}{v}" for k, v in options.items()) + ("_tpl" if template else "")
    path = folder / module_filename(scene.name, f"{method}_{tag}", "numba")
    saved = emit.shared_runtime_supports
    if template:
        emit.shared_runtime_supports = lambda ir: False
    try:
        return mg.generate(scheme, path, backend="numba")
    finally:
        emit.shared_runtime_supports = saved


def _time(mod, y0, h, steps, repeat):
    best = math.inf
    out = None
    for _ in range(repeat):
        t = time.process_time()
        out = mod.integrate(y0, h, steps)
        best = min(best, time.process_time() - t)
    return best / steps * 1e6, out


def _template_route_exists() -> bool:
    # The template route is the fallback for step structures the shared runtime does not know;
    # once every structure runs on the runtime it may be gone.
    root = Path(emit.__file__).resolve().parents[2]
    return hasattr(emit, "shared_runtime_supports") and (root / "templates" / "numba_runtime.py.j2").exists()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--route", choices=("shared", "template", "both"), default="both")
    ap.add_argument("--only", default="", help="substring of 'scene method' to select configurations")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()}")
    folder = Path(tempfile.mkdtemp(prefix="mg-stepcost-"))
    routes = ("shared", "template") if args.route == "both" else (args.route,)
    if "template" in routes and not _template_route_exists():
        print("the template route is not in this methodgen: timing the shared runtime only")
        routes = ("shared",)
    for scene_name, method, options in CONFIGS:
        if args.only and args.only not in f"{scene_name} {method} {options}":
            continue
        scene = mg.load_scene(scene_name)
        y0 = np.array(scene.y0, dtype=float)
        mods = {r: _generate(folder, scene, method, options, r == "template") for r in routes}
        for m in mods.values():
            m.integrate(y0, scene.h, 10)  # compile / load
        res = {}
        # interleave the routes so that both see the same load
        for _ in range(args.repeat):
            for r, m in mods.items():
                us, out = _time(m, y0, scene.h, args.steps, 1)
                best, _ = res.get(r, (math.inf, None))
                res[r] = (min(best, us), out)
        line = f"{scene_name} {method} {options}:"
        for r, m in mods.items():
            info = {}
            m.integrate(y0, scene.h, 200, info=info)
            its = info.get("newton_iterations")
            it = float(np.mean(its)) if its is not None and np.size(its) else 0.0
            line += f"  {r} {res[r][0]:.3f} µs/step ({it:.2f} it/step)"
        if len(mods) == 2:
            line += (f"  ratio {res['shared'][0] / res['template'][0]:.2f}x"
                     f"  bitwise {np.array_equal(res['shared'][1], res['template'][1])}")
        print(line, flush=True)
    print(f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
