"""``methodgen run`` and ``methodgen verify`` on a lattice scene (:mod:`methodgen.app.lattice_scene`)."""

from __future__ import annotations

import sys

from ...errors import InputError
from .common import EXIT_NUMERICAL, dump_json, parse_params

#: the run options a lattice run takes; any other given option is refused, naming these
_LATTICE_RUN_OPTIONS = {"method", "h", "steps", "t_final", "param", "json", "scene", "func", "command",
                        "check_resolution", "backend", "defaults_of"}


def run(args) -> int:
    """``methodgen run LATTICE_SCENE``: the report, or one line on stderr and a non-zero exit."""
    from ..lattice_scene import load_lattice_scene, run_lattice_scene

    defaults = args.defaults_of(args.scene)     # the run parser's defaults (methodgen.app.cli.run)
    given = [k for k, v in vars(args).items() if k not in _LATTICE_RUN_OPTIONS and v != defaults.get(k)]
    if given:
        flags = ", ".join("--" + k.replace("_", "-") for k in sorted(given))
        raise InputError(f"{flags}: not available for a lattice scene; a lattice run takes --method, --h, "
                         "--steps, --t-final, --param NAME=VALUE (N=… for the size), --backend, --no-check-resolution and --json")
    scene = load_lattice_scene(args.scene)
    sizes = [s.name for s in getattr(scene.lattice, "sizes", (scene.lattice.size,))]
    names = [*sizes, *scene.lattice.params]
    values = parse_params(args.param, names)
    given = [values.pop(s, None) for s in sizes]
    for s, v in zip(sizes, given):
        if v is not None and v != int(v):
            raise InputError(f"--param {s}: the size must be an integer, got {v:g}")
    given = [None if v is None else int(v) for v in given]
    if len(sizes) == 1:
        size = given[0]
    elif given == [None, None]:
        size = None
    else:   # a 2-D lattice: the second size follows the first where not given (a square grid)
        first = scene.size[0] if given[0] is None else given[0]
        size = (first, given[1] if given[1] is not None else (first if given[0] is not None else scene.size[1]))
    if args.method is not None and args.method not in scene.methods and args.method not in ("avf", "midpoint"):
        raise InputError(f"--method {args.method!r}: a lattice runs avf or midpoint")
    try:
        rep = run_lattice_scene(args.scene, args.method, args.h, args.steps, size=size, params=values or None,
                                t_final=args.t_final, check_resolution=args.check_resolution,
                                backend="compiled" if args.backend == "numba" else "numpy")
    except Exception as exc:     # the module's ConvergenceError / NonFiniteError: one line, non-zero
        if type(exc).__name__ not in ("ConvergenceError", "NonFiniteError", "ResolutionError"):
            raise
        print(f"methodgen: stopped: {exc}", file=sys.stderr)
        if args.json:
            print(dump_json({"scene": scene.name, "success": False, "message": str(exc)}))
        return EXIT_NUMERICAL
    if args.json:
        print(dump_json(rep))
        return 0
    size = f"{' × '.join(sizes)} = {rep['N']} × {rep['M']}" if len(sizes) == 2 else f"N = {rep['N']}"
    print(f"lattice {rep['scene']}  method {rep['method']}  backend {rep['backend']}  {size}  h = {rep['h']:g}  steps = {rep['steps']}"
          f"  (t = 0 .. {rep['t_final']:g})")
    print(f"{'invariant':>10} {'initial':>24} {'final':>24} {'max abs error':>14}")
    for k, v in rep["invariants"].items():
        print(f"{k:>10} {v['initial']:>24.17g} {v['final']:>24.17g} {v['max_abs_error']:>14.3e}")
    print(f"build {rep['build_seconds']:.2f} s; {rep['seconds']:.2f} s for the steps "
          f"({rep['seconds_per_step'] * 1e3:.3g} ms a step, {rep['newton_iterations_mean']:.2f} Newton iterations)")
    return 0


def verify(args) -> int:
    """``methodgen verify LATTICE_SCENE``: the method's certificates, per site term (any N)."""
    from ..lattice_scene import load_lattice_scene
    from ...symbolic.lattice_scheme import certificates, discretize_lattice, proved_invariants

    scene = load_lattice_scene(args.scene)
    methods = [args.method] if getattr(args, "method", None) else list(scene.methods)
    out, ok, kept = [], True, {}
    for m in methods:
        scheme = discretize_lattice(scene.lattice, m)
        certs = certificates(scheme)
        for c in certs:
            out.append({"method": m, "claim": c.claim, "status": c.status, "how": c.method})
            ok &= c.status == "proved"
        kept[m] = proved_invariants(scheme, certs)
    if getattr(args, "json", False):
        print(dump_json({"scene": scene.name, "certificates": out, "all_proved": ok, "proved_invariants": kept}))
    else:
        print(f"lattice {scene.name}: certificates per site term (independent of N)")
        for c in out:
            print(f"  [{c['status']}] {c['method']}: {c['claim']} ({c['how']})")
        for m, names in kept.items():
            every = " × ".join(x.name for x in getattr(scene.lattice, "sizes", (scene.lattice.size,)))
            print(f"  {m} keeps, proved at every {every}: {', '.join(names) if names else 'none of the invariants'}")
    return 0 if ok else EXIT_NUMERICAL
