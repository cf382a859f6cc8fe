"""``methodgen run`` and ``methodgen verify`` on a lattice scene (:mod:`methodgen.app.lattice_scene`)."""

from __future__ import annotations

from ...errors import InputError
from .common import check_output_file, parse_params
from .family import run_and_report, verify_and_report

#: the run options a lattice run takes; any other given option is refused, naming these
_LATTICE_RUN_OPTIONS = {"method", "h", "steps", "t_final", "param", "json", "scene", "func", "command",
                        "check_resolution", "backend", "defaults_of", "section", "plot", "order", "composition"}


def _order(args):
    """``--order`` (command-line text, read with ``int()``) checked against the lattice orders, or None."""
    from ...symbolic.lattice_scheme import LATTICE_ORDERS

    text = getattr(args, "order", None)
    if text is None:
        return None
    try:
        order = int(str(text).strip())
    except ValueError:
        order = None
    if order not in LATTICE_ORDERS:
        raise InputError(f"--order {text}: a lattice method (avf, midpoint) is composed symmetrically to order "
                         f"{', '.join(map(str, LATTICE_ORDERS))}")
    return order


def run(args) -> int:
    """``methodgen run LATTICE_SCENE``: the report, or one line on stderr and a non-zero exit."""
    from ..lattice_scene import load_lattice_scene, run_lattice_scene

    defaults = args.defaults_of(args.scene)     # the run parser's defaults (methodgen.app.cli.run)
    given = [k for k, v in vars(args).items() if k not in _LATTICE_RUN_OPTIONS and v != defaults.get(k)]
    if given:
        flags = ", ".join("--" + k.replace("_", "-") for k in sorted(given))
        raise InputError(f"{flags}: not available for a lattice scene; a lattice run takes --method, --order, "
                         "--composition, --h, "
                         "--steps, --t-final, --param NAME=VALUE (N=… for the size), --backend, --no-check-resolution, "
                         "--section (with --plot) and --json")
    if args.plot is not None and args.section is None:
        raise InputError("--plot: a lattice run draws a Poincaré section only (--section 'q[1] = 0, p[1] > 0')")
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
    order = _order(args)
    composition = getattr(args, "composition", None)

    def header(rep):
        size = f"{' × '.join(sizes)} = {rep['N']} × {rep['M']}" if len(sizes) == 2 else f"N = {rep['N']}"
        method = rep["method"] if rep.get("order", 2) == 2 else f"{rep['method']} (order {rep['order']})"
        return (f"lattice {rep['scene']}  method {method}  backend {rep['backend']}  {size}  h = {rep['h']:g}  "
                f"steps = {rep['steps']}  (t = 0 .. {rep['t_final']:g})")

    return run_and_report(
        args, scene.name,
        lambda: run_lattice_scene(args.scene, args.method, args.h, args.steps, size=size, params=values or None,
                                  t_final=args.t_final, check_resolution=args.check_resolution,
                                  backend="compiled" if args.backend == "numba" else "numpy",
                                  section=args.section, order=order, composition=composition,
                                  plot=None if args.plot is None else str(check_output_file(args.plot, "--plot"))),
        header, lambda rep: f", {rep['newton_iterations_mean']:.2f} Newton iterations")


def verify(args) -> int:
    """``methodgen verify LATTICE_SCENE``: the method's certificates, per site term (any N)."""
    from ..lattice_scene import load_lattice_scene
    from ...symbolic.lattice_scheme import certificates, discretize_lattice, proved_invariants

    scene = load_lattice_scene(args.scene)
    order = _order(args)
    composition = getattr(args, "composition", None)
    methods = [args.method] if getattr(args, "method", None) else list(scene.methods)
    orders = {m: scene.order(m) if order is None else order for m in methods}

    def certify(m):
        # the certificates are the stage map's (the same at every order); what they prove kept,
        # a composition of such maps keeps
        scheme = discretize_lattice(scene.lattice, m, orders[m], composition)
        certs = certificates(scheme)
        return certs, proved_invariants(scheme, certs)

    every = " × ".join(x.name for x in getattr(scene.lattice, "sizes", (scene.lattice.size,)))
    title = f"lattice {scene.name}: certificates per site term (independent of N)"
    composed = {m: k for m, k in orders.items() if k != 2}
    if composed:
        title += ("; of the order-2 step, each stage of the composition (" + ", ".join(
            f"{m} order {k}" for m, k in composed.items()) + "): its order is shown numerically only "
            "(error ratios on halving h), not certified")
    return verify_and_report(args, scene.name, methods, certify, title, every)
