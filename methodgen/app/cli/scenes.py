"""``methodgen scenes`` and ``methodgen methods``: the built-in scenes and the methods."""

from __future__ import annotations

import json

from ...symbolic.scene import load_scene, scene_names
from ...symbolic.schemes import METHODS, SYMMETRIC_METHODS


def cmd_scenes(args) -> int:
    rows = []
    for name in scene_names():
        s = load_scene(name)
        rows.append({"name": s.name, "description": s.description, "methods": list(s.methods),
                     "dim": getattr(s.system, "dim", None),   # None: a Poisson system (see "state")
                     "state": len(s.system.y), "constraints": len(s.system.constraints),
                     "order": s.order, "composition": s.composition, "stages": s.stages,
                     "time_transform": s.time_transform})
    from ..lattice_scene import lattice_scene_names, load_lattice_scene

    lattices = []
    for name in lattice_scene_names():
        s = load_lattice_scene(name)
        lattices.append({"name": s.name, "description": s.description, "methods": list(s.methods),
                         "size": " × ".join(x.name for x in getattr(s.lattice, "sizes", (s.lattice.size,))),
                         "default_size": list(s.size) if isinstance(s.size, tuple) else s.size,
                         "min_size": s.lattice.nmin,
                         "invariants": ["H", *s.lattice.invariants]})
    from ..particles_scene import load_particles_scene, particles_scene_names

    particles = []
    for name in particles_scene_names():
        s = load_particles_scene(name)
        particles.append({"name": s.name, "description": s.description, "methods": list(s.methods),
                          "size": s.family.size.name, "default_size": s.size, "min_size": s.family.nmin,
                          "order": s.order, "orders": dict(s.orders)})
    if args.json:
        print(json.dumps({"scenes": rows, "lattices": lattices, "particles": particles}))
    else:
        for r in rows:
            print(f"{r['name']:<20} {', '.join(r['methods']):<32} {r['description']}")
        print("\nlattices of any size (methodgen run NAME --param N=…; one module for every N):")
        for r in lattices:
            print(f"{r['name']:<20} {', '.join(r['methods']):<32} {r['description']}")
        print("\nparticles of any number N (methodgen run NAME --param N=…; one module for every N):")
        for r in particles:
            print(f"{r['name']:<20} {', '.join(r['methods']):<32} {r['description']}")
    return 0


def cmd_methods(args) -> int:
    from ...symbolic.compositions import DEFAULT_FAMILY, ALL_FAMILIES, ORDERS

    # "composable": symmetric of order 2 on every system it applies to, so --order K works;
    # the others only where the scheme is symmetric of order 2 for the system.
    rows = [{"name": name, "summary": mod.SUMMARY, "composable": name in SYMMETRIC_METHODS}
            for name, mod in METHODS.items()]
    high = [o for o in ORDERS if o > 2]
    comp = {"orders": list(ORDERS), "families": {f: list(o) for f, o in ALL_FAMILIES.items()},
            "default_family": {str(o): DEFAULT_FAMILY[o] for o in high},
            "composable": [r["name"] for r in rows if r["composable"]]}
    from ...symbolic.nbody import FAMILIES as WH_FAMILIES
    nbody = {"splittings": list(WH_FAMILIES), "applies_to": "scenes with an [nbody] table",
             "commands": ["run", "verify", "bench --peers"]}
    if args.json:
        print(json.dumps({"methods": rows, "compositions": comp, "nbody": nbody}))
    else:
        for r in rows:
            print(f"{r['name']:<18} {r['summary']}")
        print("\ngauss and energy-collocation solve a dense Newton system of s·2d unknowns every "
              "iteration (LU: O((s·2d)³) a step): on many bodies prefer stormer-verlet --order 8/10, "
              "or a Wisdom–Holman splitting ([nbody] scenes)")
        others = [r["name"] for r in rows if not r["composable"]]
        print(f"\nhigher order: --order {'/'.join(map(str, high))} (scene: [run] order) composes a "
              f"symmetric order-2 method symmetrically; the method's exact invariants and symplecticity "
              f"are kept")
        print(f"  composable: {', '.join(comp['composable'])}"
              + (f"; {', '.join(others)} only where symmetric of order 2 for the system" if others else ""))
        print("  families (--composition, [run] composition): "
              + ", ".join(f"{f} ({', '.join(map(str, o))})" for f, o in ALL_FAMILIES.items()))
        print("  default: " + ", ".join(f"order {o} {DEFAULT_FAMILY[o]}" for o in high))
        from ...symbolic.splittings import RKN_FAMILIES, SPLITTING_FAMILIES
        print(f"  splittings of T + U (stormer-verlet only): {', '.join(SPLITTING_FAMILIES)}; "
              f"{', '.join(RKN_FAMILIES)}: order 6 for T quadratic with a constant mass only (RKN)")
        from ...symbolic.compositions import PROCESSED_FAMILIES
        print(f"  processed (a kernel between two processors, any composable method; not symmetric, "
              f"invariants and symplecticity kept; pays off when few rows are kept): "
              f"{', '.join(PROCESSED_FAMILIES)}")
        from ...symbolic.lattice_scheme import LATTICE_METHODS
        print("\nlattices of symbolic size (lattice scenes, methodgen.lattice): "
              + "; ".join(f"{k}: {v}" for k, v in LATTICE_METHODS.items()))
        print(f"\n[nbody] scenes (run, verify, bench --peers): Wisdom–Holman splittings in Jacobi coordinates, "
              f"Kepler flows solved exactly, with the Laskar–Robutel corrector: {', '.join(WH_FAMILIES)}")
    return 0


def add_parser(sub) -> None:
    """Register ``scenes`` and ``methods`` on ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser("methods", help="list the methods")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_methods)
