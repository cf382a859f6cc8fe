"""``methodgen bench SCENE``: speed against accuracy (work-precision against scipy and
optionally peers, solver variants, long runs, Brouwer's law)."""

from __future__ import annotations

import argparse
import dataclasses
import math

from ...codegen.emit import BACKENDS
from ...errors import InputError
from ..limits import check_memory, check_steps
from ...symbolic.scene import load_scene
from ...symbolic.schemes import METHODS
from ..stats import max_value
from .common import check_output_file, cli_advice, print_note, dump_json, fmt, parse_params, parse_y0, positive_int, step_size


def _print_bench(rep: dict) -> None:
    wp = rep.get("work_precision")
    if wp:
        print(f"work-precision on {wp['scene']}, t = 0 .. {wp['T']:g}; reference: {wp['reference']}")
        for note in wp.get("notes", []):  # bench --peers: a peer missing or not applicable
            print(f"  note: {note}")
        w = max([28] + [len(str(r["method"])) for r in wp["rows"]])  # composed rows: "em o10 (family)"
        print(f"{'method':<{w}} {'h / tol':>9} {'steps':>7} {'CPU s':>9} {'error':>10} {'energy err':>10} "
              f"{'rel. dE':>9} {'inv/constr':>10} {'Newton':>6}")
        for r in wp["rows"]:
            if "failed" in r:
                print(f"{r['method']:<{w}} {r.get('h', r.get('tol', 0)):9.3g}  failed: {cli_advice(r['failed'])[:60]}")
                continue
            par = r.get("h", r.get("tol"))
            others = [v for k, v in r["invariant_errors"].items() if k != "H"]
            if "constraint_error" in r:
                others.append(r["constraint_error"])
            print(f"{r['method']:<{w}} {par:9.3g} {r['steps']:7d} {r['seconds']:9.4f} {fmt(r['error']):>10} "
                  f"{fmt(r['energy_error']):>10} {fmt(r.get('energy_rel_error'), '.1e'):>9} "
                  f"{fmt(max_value(*others) if others else None):>10} {fmt(r.get('newton_mean'), '.2f'):>6}")
        tg = wp.get("targets")
        if tg:  # bench --peers: the cheapest run of each method at the issue-14 targets
            print(f"\ncheapest run with final error <= {tg['error']:g} and rel. dE <= {tg['energy_rel_error']:g}:")
            for r in tg["best"] or []:
                par = r.get("h", r.get("tol"))
                print(f"  {r['method']:<{w}} {par:9.3g} {r['seconds']:9.4f} s  error {fmt(r['error'])}  "
                      f"rel. dE {fmt(r.get('energy_rel_error'), '.1e')}")
            if not tg["best"]:
                print("  (none)")
            for name, r in (("heyoka tol 1e-15", tg.get("heyoka")), ("IAS15 eps 1e-9", tg.get("ias15"))):
                if r:
                    print(f"  for comparison, {name}: {r['seconds']:.4f} s, error {fmt(r['error'])}, "
                          f"rel. dE {fmt(r.get('energy_rel_error'), '.1e')}")
        fr = wp.get("frontier")
        if fr:
            _print_frontier(fr)
    sv = rep.get("solvers")
    if sv:
        print(f"\nnonlinear solvers on {sv['scene']} (h = {sv['h']:g}, {sv['steps']} steps)")
        print(f"{'method':<18} {'solver':<12} {'iterations':>10} {'µs/step':>9} {'energy err':>10}")
        for r in sv["rows"]:
            if "failed" in r:
                print(f"{r['method']:<18} {r['solver']:<12} failed: {cli_advice(r['failed'])[:200]}")
            else:
                print(f"{r['method']:<18} {r['solver']:<12} {r['mean_iterations']:10.2f} {r['us_per_step']:9.1f} "
                      f"{fmt(r['max_energy_error']):>10}")
    lr = rep.get("long")
    if lr:
        print(f"\nlong run on {lr['scene']}: {lr['steps']} steps of h = {lr['h']:g} (t = 0 .. {lr['T']:g})")
        print(f"{'method':<28} {'CPU s':>9} {'max energy err':>14} {'growth exponent':>16}")
        for r in lr["rows"]:
            print(f"{r['method']:<28} {r['seconds']:9.2f} {fmt(r['max_energy_error']):>14} "
                  f"{fmt(r['growth_exponent'], '.2f'):>16}")
    br = rep.get("brouwer")
    if br:
        print(f"\nBrouwer's law: harmonic oscillator, midpoint, h = {br['h']:g}, {br['ensemble']} random "
              f"phases, {br['steps']} steps")
        if br.get("note"):
            print(f"  note: {br['note']}")
        for r in br["rows"]:
            print(f"  {r['stepper']:<62} RMS energy error slope {r['slope']:.2f} "
                  f"(final {r['rms_energy_error'][-1]:.2e}, {r['seconds']:.1f} s)")


def _print_frontier(fr: dict) -> None:
    """The frontier table of ``bench --peers``: per final-error level, the cheapest run of each
    tool (CPU s, and what it was) and our time over each peer's (> 1: the peer is faster)."""
    peers = [t for t in fr["tools"] if not t.startswith("methodgen")]
    print(f"\nfrontier: the cheapest run of each tool at each final error (CPU s; "
          f"'energy kept': rel. dE <= {fr['energy_rel_error']:g} at every step; ratio = ours / peer's)")
    head = f"{'error <=':>9} " + " ".join(f"{t:>22}" for t in fr["tools"]) + "".join(
        f" {'ratio ' + t.split()[-1]:>13}" for t in peers)
    print(head)
    for e in fr["table"]:
        cells = []
        for t in fr["tools"]:
            r = e["best"][t]
            cells.append(f"{'—':>22}" if r is None else f"{r['seconds']:>9.3g} {_short(r):>12}")
        ratios = "".join(f" {'—' if e['ratio'][t] is None else format(e['ratio'][t], '.2f'):>13}" for t in peers)
        print(f"{e['level']:>9.0e} " + " ".join(cells) + ratios)
    if fr["table"] and any(e["best"]["methodgen"] for e in fr["table"]):
        print("  (methodgen's cheapest runs: " + "; ".join(
            f"{e['level']:.0e}: {e['best']['methodgen']['method']} h = {e['best']['methodgen'].get('h', 0):.3g}"
            for e in fr["table"] if e["best"]["methodgen"]) + ")")


def _short(row: dict) -> str:
    """A short name of the run behind a frontier cell (its step size or tolerance)."""
    if "tol" in row:
        return f"tol {row['tol']:.0e}"
    if "h" in row:
        return f"h {row['h']:.3g}"
    return ""


def _bench_orders(text: str) -> tuple[int, ...]:
    """``bench --orders``: comma-separated orders among 2, 4, 6, 8, 10 (an argparse error otherwise)."""
    from ...symbolic.compositions import ORDERS

    out = []
    for part in text.split(","):
        part = part.strip()
        try:
            k = int(part)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected comma-separated orders among {','.join(map(str, ORDERS))}, got {part!r}") from None
        if k not in ORDERS:
            raise argparse.ArgumentTypeError(
                f"order {k} is not available: orders are {','.join(map(str, ORDERS))} "
                "(2: the base method; above: symmetric compositions)")
        out.append(k)
    return tuple(sorted(set(out)))


def _with_param_values(system, values: dict):
    """A copy of ``system`` whose parameter defaults are ``values`` (the other parameters kept).

    Its fingerprint differs, so its modules are generated into the cache under their own
    signature (``generated/`` is never touched by an override).
    """
    new = object.__new__(type(system))
    for slot in type(system).__slots__:
        if hasattr(system, slot):
            object.__setattr__(new, slot, getattr(system, slot))
    object.__setattr__(new, "param_values", {**system.param_values, **values})
    return new


def _bench_overrides(scene, args):
    """``bench --y0/--param/--h`` applied to the scene (validated like ``run``'s, one-line errors).

    Unlike ``run`` (which passes parameters at run time), bench also derives reference
    solutions and peers' models from the system, so the parameters become the system's
    defaults here.
    """
    import dataclasses
    y0_text, items, h = getattr(args, "y0", None), getattr(args, "param", None), getattr(args, "h", None)
    if y0_text is not None:
        scene = dataclasses.replace(scene, y0=tuple(parse_y0(y0_text, len(scene.y0))))
    if items:
        values = parse_params(items, list(scene.system.param_values))
        scene = dataclasses.replace(scene, system=_with_param_values(scene.system, values))
    if h is not None:
        if not h > 0:   # every bench run goes forward from t = 0 (a negative h: a negative final time)
            raise InputError(f"--h must be positive for bench (its runs go forward in time from t = 0), got {h:g}")
        scene = dataclasses.replace(scene, h=float(h))
    return scene


def cmd_bench(args) -> int:
    from .. import bench

    own = load_scene(args.scene)
    scene = _bench_overrides(own, args)
    # A y0 at a singularity of H, or parameters making the field undefined (m = 0) or overflow:
    # one line now (naming --param when they are the cause), not a failure minutes later.
    extended = bench.extended_scene(scene)
    try:   # the same y0 with the scene's own parameters: tells whether --param is the cause
        own = bench.extended_scene(dataclasses.replace(scene, system=own.system))
    except InputError:
        own = None
    bench.check_initial_state(extended, own=own)
    for flag, least in (("long_steps", 1), ("brouwer_steps", 1), ("ensemble", 2)):
        value = getattr(args, flag, None)
        if value is None:
            continue
        if value < least:   # 0 is not "the default": a run of no steps, or a slope of one point
            why = "a slope over random phases needs two" if flag == "ensemble" else "0 steps measure nothing"
            raise InputError(f"--{flag.replace('_', '-')} must be at least {least}, got {value} ({why})")
        if flag != "ensemble":
            check_steps(value, f"--{flag.replace('_', '-')} {value}")
    long_steps = args.long_steps if args.long_steps is not None else (20_000 if args.quick else 1_000_000)
    brouwer_steps = args.brouwer_steps if args.brouwer_steps is not None else (10_000 if args.quick else 1_000_000)
    if args.long:
        # The long run keeps the time and energy error of every step (and their concatenation).
        check_memory(32 * long_steps, f"--long-steps {long_steps} keeps the energy error of every "
                     "step", "take fewer --long-steps")
    if args.plot is not None:
        # Checked before the runs (minutes), like run's --save: folder exists, a file name, writable.
        if args.only_extras:
            raise InputError("--plot draws the work-precision diagram; drop --only-extras")
        args.plot = str(check_output_file(args.plot, "--plot"))
    orders = getattr(args, "orders", None)
    if orders is not None and not args.peers and orders != (2,):
        raise InputError("--orders above 2 (compositions) are benchmarked with --peers; "
                         "without --peers the base methods are compared with scipy")
    solver = getattr(args, "solver", None)
    if solver is not None and not args.peers:
        raise InputError("--solver applies to the --peers rows; without --peers the solver table compares them")
    methods = args.methods or list(scene.methods)
    from ...symbolic.nbody import FAMILIES as WH_FAMILIES
    splittings = [m for m in methods if m in WH_FAMILIES]
    if splittings:
        # no generated module to time against scipy; --peers adds the splittings' own rows
        methods = [m for m in methods if m not in WH_FAMILIES]
        if not methods:
            raise InputError(f"{', '.join(splittings)}: Wisdom–Holman splittings are benchmarked by --peers on a "
                             "scene of several free [nbody] bodies (it adds their rows); pass --methods with "
                             "generated methods for the rest of the bench")
        print_note(f"{', '.join(splittings)} left out: Wisdom–Holman splittings have their rows with --peers")
    for m in methods:
        if m not in METHODS:
            raise InputError(f"unknown method {m!r}; known methods: {', '.join(METHODS)}")
    progress = not args.json
    rep: dict = {"scene": scene.name, "quick": bool(args.quick)}
    if not args.only_extras:
        if args.t_final is not None and not (math.isfinite(args.t_final) and args.t_final > 0):
            raise InputError(f"--t-final must be a positive number, got {args.t_final}")
        rep["work_precision"] = bench.work_precision(scene, methods, quick=args.quick, progress=progress,
                                                     peers=args.peers, backend=args.backend, T=args.t_final,
                                                     orders=orders, solver=solver,
                                                     composition=getattr(args, "composition", None))
        rep["solvers"] = bench.solver_variants(scene, methods, steps=300 if args.quick else 2000,
                                               check_resolution=args.check_resolution)
    if args.long:
        rep["long"] = bench.long_run(scene, methods, steps=long_steps, progress=progress,
                                     check_resolution=args.check_resolution)
    if args.brouwer:
        rep["brouwer"] = bench.brouwer(ensemble=args.ensemble, steps=brouwer_steps, progress=progress,
                                       dyadic=not args.quick, check_resolution=args.check_resolution)
    if args.plot:
        if "work_precision" not in rep:
            raise InputError("--plot draws the work-precision diagram; drop --only-extras")
        from ..plots import plot_work_precision
        wp = rep["work_precision"]
        title = f"{scene.name}: work-precision"
        if args.peers:
            title += f", t = 0 .. {wp['T']:g}, methodgen backend {wp.get('backend', args.backend)}"
        rep["plot"] = str(plot_work_precision(wp["rows"], args.plot, title=title, targets=wp.get("targets")))
    if args.json:
        print(dump_json(rep))
    else:
        _print_bench(rep)
        if "plot" in rep:
            print(f"work-precision diagram written to {rep['plot']}")
    return 0


def add_parser(sub) -> None:
    """Register ``bench`` on ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser("bench", help="measure speed against accuracy: work-precision vs scipy, "
                                     "solver variants, long runs, Brouwer's law")
    p.add_argument("scene", help="built-in scene name or path to a scene TOML file")
    p.add_argument("--methods", nargs="+", metavar="M", help="methods (default: the scene's)")
    p.add_argument("--quick", action="store_true", help="a small configuration (seconds)")
    p.add_argument("--long", action="store_true", help="also the long run (energy-error envelope)")
    p.add_argument("--long-steps", type=positive_int, metavar="N",
                   help="steps of the long run, at least 1 (default 10^6; 2*10^4 with --quick)")
    p.add_argument("--brouwer", action="store_true",
                   help="also the Brouwer experiment (harmonic oscillator ensemble, midpoint)")
    p.add_argument("--brouwer-steps", type=positive_int, metavar="N",
                   help="steps of the Brouwer experiment, at least 1 (default 10^6, about 10 min; 10^4 with --quick)")
    p.add_argument("--ensemble", type=positive_int, default=100, help="ensemble size, at least 2 (default 100)")
    p.add_argument("--only-extras", action="store_true",
                   help="skip the work-precision and solver tables (run only --long/--brouwer)")
    p.add_argument("--plot", metavar="FILE", help="write the work-precision diagram")
    p.add_argument("--peers", action="store_true",
                   help="heyoka and REBOUND on the same problem, in the same table and plot "
                        "(methodgen[peers]; a missing one is a note); step sizes scaled from the scene's h")
    p.add_argument("--backend", choices=BACKENDS, default="numpy",
                   help="backend of methodgen's rows (numba: compiled loop, compiled before timing)")
    p.add_argument("--t-final", type=float, metavar="T",
                   help="final time of the work-precision runs (default 20, 2 with --quick; with --peers the "
                        "scene's h*steps)")
    p.add_argument("--orders", type=_bench_orders, metavar="K,K,...",
                   help="with --peers: orders of methodgen's rows, each method at each order (default 2,4,6,8,10; "
                        "above 2 the symmetric composition of the order's default family, step sizes per order "
                        "down to a final error of 1e-12); without --peers only 2")
    p.add_argument("--composition", metavar="FAMILY",
                   help="with --peers: the family of the rows above order 2 where it has the order (a splitting "
                        "family, e.g. blanes-moan-rkn, for stormer-verlet only); default the order's default family")
    p.add_argument("--solver", choices=("newton", "simplified", "fixed-point", "reuse", "auto"),
                   help="with --peers: nonlinear solver of methodgen's rows (default: the module's)")
    p.add_argument("--y0", metavar="V1,V2,...", help="initial state, q then p (default: the scene's)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="parameter value (repeatable; the system is derived with it: its modules go to the cache)")
    p.add_argument("--h", type=step_size, help="the scene's step size for this bench (with --peers the step-size ladder is scaled from it)")
    p.add_argument("--no-check-resolution", dest="check_resolution", action="store_false",
                   help="the solver table, --long and --brouwer runs do not refuse a step size h estimated to "
                        "under-resolve the motion (the work-precision rows never do: their step-size ladder is "
                        "the measurement)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_bench)
