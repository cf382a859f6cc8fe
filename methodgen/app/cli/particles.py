"""``methodgen run`` and ``methodgen verify`` on a particle scene (:mod:`methodgen.app.particles_scene`)."""

from __future__ import annotations

from ...errors import InputError
from .common import check_output_file, parse_params
from .family import run_and_report, verify_and_report

#: the run options a particle run takes; any other given option is refused, naming these
_PARTICLES_RUN_OPTIONS = {"method", "h", "steps", "t_final", "param", "json", "scene", "func", "command",
                          "backend", "defaults_of", "section", "plot", "order"}


def run(args) -> int:
    """``methodgen run PARTICLE_SCENE``: the report, or one line on stderr and a non-zero exit."""
    from ...symbolic.particle_scheme import ORDERS, PARTICLE_METHODS
    from ..particles_scene import load_particles_scene, run_particles_scene

    defaults = args.defaults_of(args.scene)
    given = [k for k, v in vars(args).items() if k not in _PARTICLES_RUN_OPTIONS and v != defaults.get(k)]
    if given:
        flags = ", ".join("--" + k.replace("_", "-") for k in sorted(given))
        raise InputError(f"{flags}: not available for a particle scene; a particle run takes --method, --order, "
                         "--h, --steps, --t-final, --param NAME=VALUE (N=… for the size), --backend, --section (with --plot) "
                         "and --json")
    if args.plot is not None and args.section is None:
        raise InputError("--plot: a particle run draws a Poincaré section only (--section 'y[2] = 0, py[2] > 0')")
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
            raise InputError(f"--order {args.order!r}: expected {', '.join(map(str, ORDERS))}") from None
        if order not in ORDERS:
            raise InputError(f"--order {order}: the particle methods ({', '.join(PARTICLE_METHODS)}) are composed "
                             f"to order {', '.join(map(str, ORDERS))} (symmetric compositions of their order-2 step)")
    def header(rep):
        return (f"particles {rep['scene']}  method {rep['method']} (order {rep['order']})  backend {rep['backend']}  "
                f"N = {rep['N']}  h = {rep['h']:g}  steps = {rep['steps']}  (t = 0 .. {rep['t_final']:g})")

    return run_and_report(
        args, scene.name,
        lambda: run_particles_scene(args.scene, args.method, args.h, args.steps, size=n, params=values or None,
                                    order=order, t_final=args.t_final,
                                    backend="compiled" if args.backend == "numba" else "numpy",
                                    section=args.section,
                                  plot=None if args.plot is None else str(check_output_file(args.plot, "--plot"))),
        header, lambda rep: "" if rep["iterations_mean"] is None else f", {rep['iterations_mean']:.2f} iterations")


def verify(args) -> int:
    """``methodgen verify PARTICLE_SCENE``: the methods' certificates, per template (any N)."""
    from ...symbolic.particle_scheme import certificates, discretize_particles, proved_invariants
    from ..particles_scene import load_particles_scene

    scene = load_particles_scene(args.scene)
    given = getattr(args, "order", None)
    if given is not None:
        try:
            given = int(given)
        except ValueError:
            raise InputError(f"--order {given!r}: expected 2, 4, 6 or 8") from None

    def certify(m):
        # (the certificates hold for every stage size, so for every order; --order names the scheme listed)
        scheme = discretize_particles(scene.family, m, scene.orders.get(m, 2) if given is None else given)
        certs = certificates(scheme)
        return certs, proved_invariants(scheme, certs)

    return verify_and_report(args, scene.name, [args.method] if getattr(args, "method", None) else list(scene.methods),
                             certify, f"particles {scene.name}: certificates per one-body and pair template "
                             "(independent of N)", scene.family.size.name)
