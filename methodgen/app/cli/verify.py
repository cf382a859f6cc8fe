"""``methodgen verify SCENE [--method M] [--order K] [--composition F] [--stages S] [--time-transform G] [--json] [--format …] [--timeout S]``.

Verifies every claim that applies to the scene's methods (or one method) and
prints the certificates.  ``--json`` prints exactly one JSON object
``{"ok": bool, "verdict": str, "certificates": [...], "reports": [...]}``.  The exit
status is 0 when every report is ok (something verified, every claim decided),
1 when some claim is refuted, 3 when nothing is refuted but some claim is
``undecided`` (exception or ``--timeout`` overrun) or a report has no certificate
at all — never "ok" then; bad input is a one-line error, exit 2.  Once a verification has run for 2 s, progress goes to stderr, claim
group by claim group (never to stdout).
"""

from __future__ import annotations

import argparse
import dataclasses
import math


def _dim(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if not 1 <= v <= 12:
        raise argparse.ArgumentTypeError(f"dimension must be between 1 and 12, got {v}")
    return v


def _timeout(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return v


def cmd_verify(args) -> int:
    """Run the verification for a scene; return the exit status."""
    from ..lattice_scene import is_lattice_scene

    if is_lattice_scene(args.scene):
        from . import lattice
        return lattice.verify(args)
    from ..particles_scene import is_particles_scene

    if is_particles_scene(args.scene):
        from . import particles
        return particles.verify(args)
    # Imported here: the verification layer is not needed by the other commands.
    from .common import (dump_json, effective_stages, resolve_order, resolve_stages, resolve_time_transform,
                         transformed_context)
    from ...errors import InputError
    from ...symbolic.scene import load_scene
    from ...symbolic.schemes import composition_for, discretize
    from ...symbolic.verify import verify

    from ...symbolic.nbody import FAMILIES as WH_FAMILIES

    if args.method in WH_FAMILIES:
        return _verify_splitting(args)
    # --time-transform over the scene's [run] time_transform: the transformed system K is verified.
    scene = resolve_time_transform(load_scene(args.scene), getattr(args, "time_transform", None))
    splittings = [m for m in scene.methods if m in WH_FAMILIES]
    if splittings and not args.method:
        others = [m for m in scene.methods if m not in WH_FAMILIES]
        if not others:   # a scene of Wisdom–Holman splittings only: the first one's claims
            args.method = splittings[0]
            return _verify_splitting(args)
        from .common import print_note
        print_note(f"the Wisdom–Holman splitting(s) {', '.join(splittings)} of this scene are verified with "
                   f"--method {splittings[0]}; verifying {', '.join(others)}")
        scene = dataclasses.replace(scene, methods=tuple(others))
    system = scene.run_system
    # --order/--composition over the scene's [run] order (one-line errors, exit 2).
    order, composition = resolve_order(scene, args.order, args.composition)
    methods = [args.method] if args.method else list(scene.methods)
    if args.method and args.method not in scene.methods:
        # Any applicable method may be verified, not only the scene's own.
        with transformed_context(scene):
            discretize(system, args.method)  # raises InputError / MethodNotApplicable
    if not methods:
        raise InputError(f"scene {scene.name!r} lists no methods; pass --method")
    # --stages over [run] stages, for the methods that take it (an error if none does).
    stages = resolve_stages(scene, methods, getattr(args, "stages", None))
    options = {m: scene.options(m, stages) for m in methods}
    from ...symbolic.compositions import PROCESSED_FAMILIES

    kw = dict(conjugacy_dim=args.conjugacy_dim, timeout=args.timeout, progress=True)
    if composition in PROCESSED_FAMILIES:
        # three modules: the kernel's report with the effective order certified first
        from ...symbolic.processing import processed_composition
        from ...symbolic.verify.processed import verify_processed

        proc = processed_composition(order, composition)
        with transformed_context(scene):
            bases = [discretize(system, m, **options[m]) for m in methods]
        reports = [verify_processed(b, proc, **kw) for b in bases]
        comp_json = {"family": composition, "order": order, "stages": proc.stages,
                     "processor_stages": proc.processor_stages, "processed": True}
    else:
        with transformed_context(scene):
            schemes = [discretize(system, m, order=order, composition=composition, **options[m]) for m in methods]
        reports = [verify(s, **kw) for s in schemes]
        comp = composition_for(order, composition)
        comp_json = None if comp is None else {"family": comp.family, "order": comp.order, "stages": comp.stages}
    ok = all(r.ok for r in reports)
    verdict = ("refuted" if any(r.refuted for r in reports) else "ok" if ok else
               "undecided" if any(r.undecided for r in reports) else "nothing verified")
    if args.json:
        certs = []
        for r in reports:
            for c in r.certificates:
                certs.append({**c.to_dict(), "method_name": r.title})
        print(dump_json({"ok": ok, "verdict": verdict, "scene": scene.name, "order": order,
                         "composition": comp_json,
                         "stages": {m: effective_stages(m, options[m]) for m in methods
                                    if effective_stages(m, options[m]) is not None} or None,
                         "time_transform": None if scene.transformed is None else
                         {"g": scene.time_transform, "system": system.name},
                         "certificates": certs,
                         "reports": [{"title": r.title, "ok": r.ok, "verdict": r.verdict,
                                      "seconds": round(r.seconds, 3)}
                                     for r in reports]}))
    else:
        for r in reports:
            if args.format == "markdown":
                print(r.markdown())
            elif args.format == "latex":
                print(r.latex())
            else:
                print(r)
    return {"ok": 0, "refuted": 1}.get(verdict, 3)


def _verify_splitting(args) -> int:
    """``verify SCENE --method saba3``: the Wisdom–Holman splitting's claims
    (:func:`methodgen.runtime.nbody.claims`)."""
    from .common import dump_json, refuse_for_splitting
    from ...symbolic.scene import load_scene
    from ...runtime.nbody import claims, wisdom_holman

    refuse_for_splitting(args.method, order=args.order, composition=args.composition,
                         stages=getattr(args, "stages", None), time_transform=getattr(args, "time_transform", None))
    scene = load_scene(args.scene)
    wh = wisdom_holman(scene, args.method)
    found = claims(wh)
    ok = not any(c["status"] == "refuted" for c in found)
    verdict = "ok" if ok else "refuted"
    if args.json:
        print(dump_json({"ok": ok, "verdict": verdict, "scene": scene.name, "method": wh.METHOD,
                         "certificates": found}))
    else:
        print(f"{wh.METHOD} on {scene.name}: {wh.splitting.source}; ε = {wh.epsilon:.3g}")
        for c in found:
            print(f"  [{c['status']}, {c['kind']}] {c['claim']}: {c['detail']}")
        print(f"verdict: {verdict}")
    return 0 if ok else 1


def add_parser(sub) -> None:
    """Register the ``verify`` subcommand on ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser("verify", help="prove (or refute) the lecture notes' claims for a scene's methods")
    p.add_argument("scene", help="built-in scene name or path to a scene TOML file")
    p.add_argument("--method", help="verify only this method (default: all of the scene's methods)")
    p.add_argument("--order", metavar="K",
                   help="verify the method composed to order K (4, 6, 8, 10; default: the scene's [run] order)")
    p.add_argument("--composition", metavar="FAMILY",
                   help="composition family for order > 2 (default: the scene's, else the order's default)")
    from .common import add_variant_args
    add_variant_args(p, "verify")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--format", choices=("text", "markdown", "latex"), default="text",
                   help="output format without --json (default: text)")
    p.add_argument("--conjugacy-dim", type=_dim, default=None,
                   help="dimension n for the Exercise 2.1 conjugacy proof (default: 2d)")
    p.add_argument("--timeout", type=_timeout, default=None, metavar="SECONDS",
                   help="time budget of each claim group; a claim over budget is 'undecided' "
                        "(default: 60)")
    p.set_defaults(func=cmd_verify)
