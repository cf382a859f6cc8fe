"""``methodgen generate [SCENE ...] [--check]``: (re)generate the built-in scenes' modules
into ``generated/`` (or ``--out``), or check that they are in sync (exit 1 if not)."""

from __future__ import annotations

import json
from pathlib import Path

from ...codegen.build import build, generated_dir, scene_module_path, scene_system_name, scene_targets, target_key
from ...codegen.emit import BACKENDS, emit_source, file_status, module_filename, signature, write_atomic
from ...errors import InputError
from ...codegen.progress import about
from ...symbolic.scene import load_scene, scene_names
from ...symbolic.schemes import discretize
from .common import expand_user, add_order_args, add_variant_args, resolve_order, resolve_stages, resolve_time_transform, \
    transformed_context


def _targets(names: list[str], order=None, composition=None, stages=None, time_transform=None):
    """``(scene, method, order, family, options, declared)`` to generate: the scenes' own (each
    method, with ``[run] stages``, and composed to ``[run] order`` if declared, of the scene's
    system or its declared time transformation), or each method at ``--order``/``--composition``/
    ``--stages``/``--time-transform``.  ``declared``: the scene declares this system and these
    options (a time transformation or number of stages it does not declare is not ``generated/``'s)."""
    for name in names or scene_names():
        own = load_scene(name)
        scene = resolve_time_transform(own, time_transform)
        same_system = scene.run_system.fingerprint() == own.run_system.fingerprint()
        if order is None and composition is None and stages is None:
            items = scene_targets(scene)
        else:
            o, c = resolve_order(scene, order, composition)
            s = resolve_stages(scene, scene.methods, stages)
            items = [(method, o, c, scene.options(method, s)) for method in scene.methods]
        for method, o, c, opts in items:
            yield scene, method, o, c, opts, same_system and opts == own.options(method)


def _composed_files(names: list[str], backend: str) -> dict:
    """File name → ``(scene, method, order, family, options, True)`` of every composed module a
    built-in scene could have (each method × family × order): such a file in ``generated/`` (from
    ``methodgen generate --order``) is regenerated and checked like the scenes' own."""
    from ...symbolic.compositions import ALL_FAMILIES, PROCESSED_FAMILIES

    out = {}
    for name in names or scene_names():
        scene = load_scene(name)
        for method in scene.methods:
            for family, orders in ALL_FAMILIES.items():
                if family in PROCESSED_FAMILIES:   # three cache modules, never one file in generated/
                    continue
                for o in orders:
                    opts = scene.options(method)
                    key = target_key(method, o, family, opts)
                    out[module_filename(scene_system_name(scene), key, backend)] = (scene, method, o, family,
                                                                                    opts, True)
    return out


def cmd_generate(args) -> int:
    if args.out is not None and not str(args.out).strip():
        # An empty --out is a mistake (an unset shell variable), not "the checkout's generated/".
        raise InputError("--out needs a folder name, got ''; leave --out out to write the checkout's generated/")
    if args.backend != "numpy" and not args.out:
        raise InputError("generated/ holds the numpy modules only; pass --out DIR with --backend numba")
    out = expand_user(args.out, "--out") if args.out else generated_dir()
    if out is None:
        raise InputError("no generated/ folder found (not a source checkout); pass --out DIR")
    expected = set()
    problems, written, same = [], [], []
    stages, g = getattr(args, "stages", None), getattr(args, "time_transform", None)
    own_set = args.order is None and args.composition is None and stages is None and g is None
    targets = list(_targets(args.scenes, args.order, args.composition, stages, g))
    for scene, *_ in targets:
        if not scene.builtin:
            raise InputError(f"{scene.name} is not a built-in scene; use the Python API "
                             "methodgen.generate for your own scenes")
    if own_set and out.is_dir():
        # Composed modules written by `generate --order` stay in sync too.
        names = {module_filename(scene_system_name(s), target_key(m, o, c, opts), args.backend)
                 for s, m, o, c, opts, _ in targets}
        composed = _composed_files(args.scenes, args.backend)
        targets += [composed[f.name] for f in sorted(out.glob("*.py"))
                    if f.name in composed and f.name not in names]
    for scene, method, order, family, opts, declared in targets:
        key = target_key(method, order, family, opts)
        system = scene.run_system
        sig = signature(system, key, args.backend)
        if args.out is None and not declared:
            # A time transformation or number of stages the scene does not declare: the module
            # belongs to the per-user cache (as for `run`), never to the committed generated/.
            path = scene_module_path(scene, key, args.backend, system=system)
            status = file_status(path, sig)
            if status == "ok":
                same.append(path)
            elif args.check:
                problems.append(f"{path}: {status} (the scene does not declare this variant: its module "
                                "lives in the cache)")
            else:
                with transformed_context(scene):
                    build(system, method, path=path, backend=args.backend, order=order, composition=family,
                          **opts)
                written.append(path)
            continue
        path = out / module_filename(scene_system_name(scene), key, args.backend)
        expected.add(path.name)
        with transformed_context(scene), about(path.name):   # progress lines name the module
            scheme = discretize(system, method, order=order, composition=family, **opts)
            source = emit_source(scheme, sig, backend=args.backend)
        current = path.read_text(encoding="utf-8") if path.is_file() else None
        if current == source:
            same.append(path)
            continue
        if args.check:
            problems.append(f"{path}: {'missing' if current is None else 'differs from what the generator emits today'}")
        else:
            write_atomic(path, source)
            written.append(path)
    if args.check and not args.scenes and own_set:
        for extra in sorted(out.glob("*.py")):
            other_backend = extra.name.endswith("_numba.py") != (args.backend == "numba")
            if extra.name not in expected and not other_backend:
                problems.append(f"{extra}: not generated from any built-in scene")
    if args.json:
        print(json.dumps({"ok": not problems, "problems": problems, "written": [str(p) for p in written],
                          "unchanged": [str(p) for p in same]}))
    else:
        for p in written:
            print(f"wrote {p}")
        for p in problems:
            print(p)
        if args.check and not problems:
            print(f"generated/ is in sync ({len(same)} modules)")
    return 1 if problems else 0


def add_parser(sub) -> None:
    """Register ``generate`` on ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser("generate", help="(re)generate the modules of the built-in scenes into generated/")
    p.add_argument("scenes", nargs="*", help="scene names (default: all built-in scenes)")
    p.add_argument("--check", action="store_true", help="only check that the files are in sync; exit 1 if not")
    p.add_argument("--out", help="output folder (default: the checkout's generated/)")
    p.add_argument("--backend", choices=BACKENDS, default="numpy",
                   help="numpy (the committed generated/ modules) or numba (needs --out)")
    add_order_args(p, generate=True)
    add_variant_args(p, "generate")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_generate)
