"""The frontier against the peers on every built-in scene a peer can run.

Not a test: run it and read the tables (it takes minutes per scene).

    python benchmarks/frontier.py [--scenes kepler,henon-heiles-2d] [--backend numba]
                                  [--orders 2,4,6,8,10] [--quick] [--json out.json]

For each scene: ``methodgen bench SCENE --peers`` (:func:`methodgen.app.bench.work_precision`
with ``peers=True``), then its frontier table (:func:`methodgen.app.bench.frontier`): per final
error level, the cheapest run of methodgen, of methodgen with the energy kept to round-off,
and of each peer (heyoka on every unconstrained scene; REBOUND on scenes that declare
``[nbody]``), and our CPU time over each peer's.  Constrained scenes are skipped (the peers
integrate ODEs, not DAEs).
"""

from __future__ import annotations

import argparse
import json

import methodgen as mg
from methodgen.app.bench import work_precision
from methodgen.app.cli.bench import _print_frontier
from methodgen.symbolic.scene import load_scene


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", help="comma-separated scene names (default: every unconstrained built-in scene)")
    ap.add_argument("--backend", default="numba")
    ap.add_argument("--orders", default="2,4,6,8,10")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", help="write every scene's frontier here")
    a = ap.parse_args()
    names = a.scenes.split(",") if a.scenes else mg.scenes()
    orders = tuple(int(x) for x in a.orders.split(","))
    out = {}
    for name in names:
        scene = load_scene(name)
        if scene.system.constraints:
            print(f"{name}: skipped (constrained: the peers integrate ODEs)")
            continue
        wp = work_precision(scene, peers=True, backend=a.backend, orders=orders, quick=a.quick)
        print(f"\n== {name}: T = {wp['T']:g}, reference {wp['reference']}")
        for note in wp["notes"]:
            print(f"  note: {note}")
        _print_frontier(wp["frontier"])
        out[name] = {"T": wp["T"], "reference": wp["reference"], "frontier": wp["frontier"]}
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(out, fh, indent=1)


if __name__ == "__main__":
    main()
