"""``methodgen run`` and ``methodgen verify`` on a particle scene (:mod:`methodgen.app.particles_scene`)."""

from __future__ import annotations

import sys

from ...errors import InputError
from .common import EXIT_NUMERICAL, dump_json, parse_params

#: the run options a particle run takes; any other given option is refused, naming these
_PARTICLES_RUN_OPTIONS = {"method", "h", "steps", "t_final", "param", "json", "scene", "func", "command",
                          "backend", "defaults_of", "order"}


def run(args) -> int:
    """``methodgen run PARTICLE_SCENE``: the report, or one line on stderr and a non-zero exit."""
    from ...symbolic.particle_scheme import PARTICLE_METHODS, SV_ORDERS
    from ..particles_scene import load_particles_scene, run_particles_scene

    defaults = args.defaults_of(args.scene)
    given = [k for k, v in vars(args).items() if k not in _PARTICLES_RUN_OPTIONS and v != defaults.get(k)]
    if given:
        flags = ", ".join("--" + k.replace("_", "-") for k in sorted(given))
        raise InputError(f"{flags}: not available for a particle scene; a particle run takes --method, --order, "
                         "--h, --steps, --t-final, --param NAME=VALUE (N=… for the size), --backend and --json")
    scene = load_particles_scene(args.scene)
    fam = scene.family
    values = parse_params(args.param, [fam.size.name, *fam.params])
    n = values.pop(fam.size.name, None)
    if n is not None:
        if n != int(n):
            raise InputError(f"--param {fam.size.name}: the size must be an integer, got {n:g}")
        n = int(n)
        fam.check_size(n)
    if args.method is not None and args.method not in PARTICLE_METHODS:
        raise InputError(f"--method {args.method!r}: particles run {' or '.join(PARTICLE_METHODS)}")
    order = None
    if args.order is not None:
        try:
            order = int(args.order)
        except ValueError:
            raise InputError(f"--order {args.order!r}: expected {', '.join(map(str, SV_ORDERS))}") from None
        if order not in SV_ORDERS:
            raise InputError(f"--order {order}: Störmer–Verlet for particles is composed to order "
                             f"{', '.join(map(str, SV_ORDERS))}")
    try:
        rep = run_particles_scene(args.scene, args.method, args.h, args.steps, size=n, params=values or None,
                                  order=order, t_final=args.t_final,
                                  backend="compiled" if args.backend == "numba" else "numpy")
    except Exception as exc:     # the module's ConvergenceError / NonFiniteError: one line, non-zero
        if type(exc).__name__ not in ("ConvergenceError", "NonFiniteError"):
            raise
        print(f"methodgen: stopped: {exc}", file=sys.stderr)
        if args.json:
            print(dump_json({"scene": scene.name, "success": False, "message": str(exc)}))
        return EXIT_NUMERICAL
    if args.json:
        print(dump_json(rep))
        return 0
    print(f"particles {rep['scene']}  method {rep['method']} (order {rep['order']})  backend {rep['backend']}  "
          f"N = {rep['N']}  h = {rep['h']:g}  steps = {rep['steps']}  (t = 0 .. {rep['t_final']:g})")
    print(f"{'invariant':>10} {'initial':>24} {'final':>24} {'max abs error':>14}")
    for k, v in rep["invariants"].items():
        print(f"{k:>10} {v['initial']:>24.17g} {v['final']:>24.17g} {v['max_abs_error']:>14.3e}")
    its = "" if rep["iterations_mean"] is None else f", {rep['iterations_mean']:.2f} iterations"
    print(f"build {rep['build_seconds']:.2f} s; {rep['seconds']:.2f} s for the steps "
          f"({rep['seconds_per_step'] * 1e3:.3g} ms a step{its})")
    return 0


def verify(args) -> int:
    """``methodgen verify PARTICLE_SCENE``: the methods' certificates, per template (any N)."""
    from ...symbolic.particle_scheme import certificates, discretize_particles, proved_invariants
    from ..particles_scene import load_particles_scene

    scene = load_particles_scene(args.scene)
    methods = [args.method] if getattr(args, "method", None) else list(scene.methods)
    out, ok, kept = [], True, {}
    for m in methods:
        scheme = discretize_particles(scene.family, m, scene.order if m == "stormer-verlet" else 2)
        certs = certificates(scheme)
        for c in certs:
            out.append({"method": m, "claim": c.claim, "status": c.status, "how": c.method})
            ok &= c.status == "proved"
        kept[m] = proved_invariants(scheme, certs)
    if getattr(args, "json", False):
        print(dump_json({"scene": scene.name, "certificates": out, "all_proved": ok, "proved_invariants": kept}))
    else:
        print(f"particles {scene.name}: certificates per one-body and pair template (independent of N)")
        for c in out:
            print(f"  [{c['status']}] {c['method']}: {c['claim']} ({c['how']})")
        for m, names in kept.items():
            print(f"  {m} keeps, proved at every {scene.family.size.name}: {', '.join(names) if names else 'nothing'}")
    return 0 if ok else EXIT_NUMERICAL
