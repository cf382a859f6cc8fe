"""Lattice scene files: a lattice of symbolic size, its initial state as formulas, and a run.

Format (TOML; the built-in ones are in ``methodgen/symbolic/scenes/lattice``)::

    name = "sine-gordon"
    description = "..."
    [lattice]
    H = "Sum(p[i]**2/2, i, 1, N) + Sum((q[i % N + 1] - q[i])**2*N**2/(2*L**2), i, 1, N) + ..."
    q = "q"                       # optional field names (default q, p) and size name (N)
    p = "p"
    size = "N"
    # or, a skew lattice (one field, u' = S ∇H with S a skew stencil on the gradient g):
    # fields = ["u"]
    # skew = "(g[i+1] - g[i-1])*N**2/(2*L**2)"
    [params]
    L = 6.283185307179586
    [invariants]                  # optional: monitored sums of site terms
    mass = "Sum(q[i]**2 + p[i]**2, i, 1, N)"
    [initial]                     # each field at site i = 1 … N: a formula in i, N and the parameters
    q = "2*sin(2*pi*(i - 1)/N)"
    p = "0"
    [run]
    method = "avf"                # or a list; avf, midpoint
    order = 4                     # optional (1-D): 2, 4, 6, 8 -- the method composed symmetrically;
                                  # or per method: order = {avf = 4, midpoint = 2}
    N = 256                       # the size (--param N=4096 on the command line)
    h = 0.01
    steps = 1000

A 2-D periodic lattice names two sizes, ``size = ["N", "M"]`` in ``[lattice]``; its ``[initial]``
formulas are in ``i``, ``j`` (the site (i, j), 1-based), the sizes and the parameters; its ``[run]``
table gives each size by its name (``N = 128``; the second, ``M = 128``, may be left out: it is
then the first, a square grid, also when the first is changed by ``--param N=64``).

The file is data: parsed with ``tomllib``, checked key by key, its formulas parsed by the
whitelist parser (:func:`methodgen.problem.parse.parse_expr`) and evaluated from the parsed tree.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import InputError, SceneError
from . import scene_files as _files

__all__ = ["LatticeScene", "is_lattice_scene", "load_lattice_scene", "lattice_scene_names", "run_lattice_scene"]

_TOP = {"name": str, "description": str, "lattice": dict, "params": dict, "invariants": dict, "initial": dict,
        "run": dict}
_LATTICE = {"H": str, "q": str, "p": str, "size": (str, list), "fields": list, "skew": str}
_RUN = {"method": (str, list), "order": (int, dict), "N": int, "h": (int, float), "steps": int}


def lattice_scene_names() -> list[str]:
    """Names of the built-in lattice scenes, sorted."""
    return _files.names("lattice")


def is_lattice_scene(name_or_path) -> bool:
    """True for a built-in lattice scene's name or a TOML file with a ``[lattice]`` table."""
    return _files.is_kind("lattice", name_or_path)


@dataclass(frozen=True)
class LatticeScene:
    """A parsed lattice scene (see the module docstring)."""

    name: str
    description: str
    lattice: object
    initial: dict
    methods: tuple[str, ...]
    size: object               # N, or (N, M) for a 2-D lattice
    h: float
    steps: int
    source: str
    #: the composition order per method ([run] order; 2 where not given)
    orders: dict = None

    def order(self, method: str) -> int:
        """The scene's order of ``method`` (2 unless ``[run] order`` gives one)."""
        return (self.orders or {}).get(method, 2)

    def y0(self, n, params: dict | None = None) -> np.ndarray:
        """The initial state at size ``n``: ``(q[1..n], p[1..n])`` (a skew lattice's ``u[1..n]``) from
        the scene's formulas; for a 2-D lattice ``n = (N, M)`` and an array (2, N, M)."""
        import sympy as sp

        from ..problem.parse import parse_expr

        lat = self.lattice
        if getattr(lat, "dims", 1) == 2:
            return self._y0_2d(*n, params)
        lat.check_size(n)
        values = {**lat.params, **(params or {})}
        i = sp.Symbol("i", real=True)
        N = sp.Symbol(lat.size.name, real=True)
        symbols = {"i": i, lat.size.name: N, **{k: sp.Symbol(k, real=True) for k in values}}
        out = []
        for field in lat.fields:
            expr = parse_expr(self.initial.get(field, "0"), symbols, what=f"[initial] {field}")
            expr = expr.xreplace({symbols[k]: sp.Float(v) for k, v in values.items()}).xreplace({N: n})
            f = sp.lambdify([i], expr, modules="numpy")   # printed from the parsed tree, not the text
            out.append(np.broadcast_to(np.asarray(f(np.arange(1, n + 1, dtype=float)), dtype=float), (n,)))
        y = np.concatenate(out)
        if not np.all(np.isfinite(y)):
            raise InputError(f"the initial state of {self.name!r} at N = {n} is not finite")
        return y

    def _y0_2d(self, n: int, m: int, params: dict | None) -> np.ndarray:
        import sympy as sp

        from ..problem.parse import parse_expr

        lat = self.lattice
        lat.check_size(n, m)
        values = {**lat.params, **(params or {})}
        i, j = sp.Symbol("i", real=True), sp.Symbol("j", real=True)
        N, M = (sp.Symbol(s.name, real=True) for s in lat.sizes)
        symbols = {"i": i, "j": j, N.name: N, M.name: M, **{k: sp.Symbol(k, real=True) for k in values}}
        ii, jj = np.meshgrid(np.arange(1, n + 1, dtype=float), np.arange(1, m + 1, dtype=float), indexing="ij")
        out = []
        for field in lat.fields:
            expr = parse_expr(self.initial.get(field, "0"), symbols, what=f"[initial] {field}")
            expr = expr.xreplace({symbols[k]: sp.Float(v) for k, v in values.items()}).xreplace({N: n, M: m})
            f = sp.lambdify([i, j], expr, modules="numpy")   # printed from the parsed tree, not the text
            out.append(np.broadcast_to(np.asarray(f(ii, jj), dtype=float), (n, m)))
        y = np.stack(out)
        if not np.all(np.isfinite(y)):
            raise InputError(f"the initial state of {self.name!r} at {n} × {m} is not finite")
        return y


def load_lattice_scene(name_or_path) -> LatticeScene:
    """Read and check a lattice scene (a built-in name or a path).

    Raises
    ------
    SceneError
        Unknown or mistyped keys, a missing table, an unknown method, bad formulas.
    """
    from ..problem.lattice import Lattice
    from ..symbolic.lattice_scheme import LATTICE_METHODS

    data, path = _files.read("lattice", name_or_path, _TOP, "lattice")
    where = str(path)
    lt, run = data["lattice"], data["run"]
    _files.check_keys(lt, _LATTICE, f"{where} [lattice]")
    sizes = lt.get("size", "N")
    two_d = isinstance(sizes, list)
    if two_d and (len(sizes) != 2 or not all(isinstance(x, str) for x in sizes)):
        raise SceneError(f"{where} [lattice]: size is a name, or two names for a 2-D lattice (size = [\"N\", "
                         f"\"M\"]); got {sizes!r}")
    if two_d:
        # the [run] table gives each size by its name (the second may be left out: a square grid)
        run_keys = {k: v for k, v in _RUN.items() if k != "N"}
        run_keys.update({sizes[0]: int, sizes[1]: int})
        _files.check_keys(run, run_keys, f"{where} [run]")
        run = {**run, "N": run.get(sizes[0])}
    else:
        _files.check_keys(run, _RUN, f"{where} [run]")
    if "H" not in lt:
        raise SceneError(f"{where} [lattice]: H is missing")
    for k in ("N", "h", "steps"):
        if k not in run:
            raise SceneError(f"{where} [run]: {k} is missing")
    params = data.get("params", {})
    for k, v in params.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(f"{where} [params]: {k!r} must be a number, got {v!r}")
    invariants = data.get("invariants", {})
    initial = data.get("initial", {})
    for table, name in ((invariants, "invariants"), (initial, "initial")):
        for k, v in table.items():
            if not isinstance(v, str):
                raise SceneError(f"{where} [{name}]: {k!r} must be a formula (text), got {v!r}")
    name = data.get("name", path.stem)
    if "i" in params or lt.get("size") == "i" or (two_d and ({"i", "j"} & (set(params) | set(sizes)))):
        raise SceneError(f"{where}: 'i'{' and j are the site indices' if two_d else ' is the site index'} of the "
                         "[initial] formulas; give the parameter or the size another name")
    if ("fields" in lt) != ("skew" in lt) or ("skew" in lt and ({"q", "p"} & set(lt))):
        raise SceneError(f"{where} [lattice]: a skew lattice takes fields = [\"u\"] and skew = \"…\" (together, "
                         "without q and p); a canonical one q and p (optional)")
    if "fields" in lt and not all(isinstance(f, str) for f in lt["fields"]):
        raise SceneError(f"{where} [lattice]: fields must be a list of names, got {lt['fields']!r}")
    try:
        lat = Lattice(lt["H"], lt.get("q", "q"), lt.get("p", "p"), size=sizes, params=params,
                      name=name, invariants=invariants,
                      fields=tuple(lt["fields"]) if "fields" in lt else None, skew=lt.get("skew"))
    except InputError as exc:
        raise SceneError(f"{where}: {exc}") from None
    unknown = set(initial) - set(lat.fields)
    if unknown:
        raise SceneError(f"{where} [initial]: {', '.join(sorted(unknown))} is not a field; the fields are "
                         f"{', '.join(lat.fields)}")
    methods = run["method"] if isinstance(run.get("method", "avf"), list) else [run.get("method", "avf")]
    for m in methods:
        if m not in LATTICE_METHODS:
            raise SceneError(f"{where} [run]: method {m!r} is not available for a lattice; available: "
                             f"{', '.join(LATTICE_METHODS)}")
    orders = _orders(run.get("order", 2), methods, two_d, where)
    if run["steps"] < 1 or not (math.isfinite(run["h"]) and run["h"] > 0):
        raise SceneError(f"{where} [run]: steps must be ≥ 1 and h > 0")
    size = (run["N"], run.get(sizes[1], run["N"])) if two_d else run["N"]
    try:
        lat.check_size(size)
    except InputError as exc:
        raise SceneError(f"{where} [run]: {exc}") from None
    scene = LatticeScene(name, data.get("description", ""), lat, initial, tuple(methods), size,
                         float(run["h"]), run["steps"], where, orders)
    try:
        scene.y0((lat.nmin, lat.nmin) if two_d else lat.nmin)  # the formulas parse (whitelist) and evaluate
    except InputError as exc:
        raise SceneError(f"{where}: {exc}") from None
    return scene


def _orders(order, methods, two_d: bool, where: str) -> dict:
    """``[run] order`` (one number, or a table per method) as {method: order}, checked."""
    from ..symbolic.lattice_scheme import LATTICE_ORDERS

    orders = _files.run_orders(order, methods, LATTICE_ORDERS, where, "a lattice method is")
    for m, k in orders.items():
        if two_d and k != 2:
            raise SceneError(f"{where} [run]: order {k} for {m}: a 2-D lattice runs order 2 only")
    return orders


def run_lattice_scene(name_or_path, method=None, h=None, steps=None, *, size=None, params=None,
                      t_final=None, solver="simplified", check_resolution=True, backend="numpy", progress=None,
                      section=None, plot=None, order=None, composition=None) -> dict:
    """Build (or load) the scene's module and run it; a report as a dict (JSON-ready).

    ``size``: N for this run (default the scene's; a 2-D lattice's (N, M), or N for N × N);
    ``params``: parameter values for this run; ``backend``: "numpy" or "compiled"
    (:func:`methodgen.codegen.lattice_emit.build_lattice`).  ``section`` (``"q[1] = 0, p[1] > 0"``,
    a 1-D lattice): a Poincaré section instead -- every crossing within the steps, each located on
    the method's own map (:func:`methodgen.app.family_section.run_family_section`); ``plot``: a file
    to draw it to.  ``order`` (2, 4, 6, 8; default the scene's ``[run] order`` of the method, else
    2) and ``composition`` (a family): the method composed symmetrically to that order.
    """
    from ..codegen.lattice_emit import build_lattice

    scene = load_lattice_scene(name_or_path)
    method = method or scene.methods[0]
    two_d = getattr(scene.lattice, "dims", 1) == 2
    n = scene.size if size is None else size
    if two_d and not isinstance(n, (tuple, list)):
        n = (n, n)
    scene.lattice.check_size(n)
    h = scene.h if h is None else float(h)
    steps = scene.steps if steps is None else int(steps)
    if t_final is not None:
        steps = max(1, math.ceil(t_final / h - 1e-12))
        h = t_final / steps
    t0 = time.perf_counter()
    order = scene.order(method) if order is None else order
    module = build_lattice(scene.lattice, method, backend=backend, progress=progress, order=order,
                           composition=composition)
    build_seconds = time.perf_counter() - t0
    y0 = scene.y0(n, params)
    if section is not None:
        from .family_section import run_family_section

        if two_d:
            raise InputError("--section: a 2-D lattice takes no text sections (its state has no flat names); "
                             "give its module's solve(..., events=...) a callable g(t, y) with y of shape (2, N, M)")
        meta = dict(scene=scene.name, method=method, order=module.ORDER, backend=backend, dims=1, N=n,
                    build_seconds=build_seconds)
        return {**meta, **run_family_section(module, y0, h, steps, section, params=params, plot=plot,
                                             title=f"{scene.name}, {method}, N = {n}, h = {h:g}", solver=solver,
                                             check_resolution=check_resolution), "steps": steps}
    # the invariant errors over ≤ ~1000 rows (≤ ~100 on a 2-D lattice: each row is a whole grid)
    every = max(1, steps // (100 if two_d else 1000))
    t0 = time.perf_counter()
    info: dict = {}
    rows = module.integrate(y0, h, steps, params, save_every=every, info=info, solver=solver,
                            check_resolution=check_resolution)
    seconds = time.perf_counter() - t0
    values = [module.invariants(r, params) for r in rows]
    inv = {k: {"initial": values[0][k], "final": values[-1][k],
               "max_abs_error": max(abs(v[k] - values[0][k]) for v in values)} for k in module.INVARIANT_NAMES}
    sizes = dict(N=n[0], M=n[1]) if two_d else dict(N=n)     # (the values of the sizes, whatever their names)
    return dict(scene=scene.name, method=method, order=getattr(module, "ORDER", 2), backend=backend, dims=2 if two_d else 1, **sizes, h=h, steps=steps, t_final=h * steps, success=True,
                build_seconds=build_seconds, seconds=seconds, seconds_per_step=seconds / steps,
                newton_iterations_mean=float(np.mean(info["newton_iterations"])), invariants=inv,
                traits=dict(module.TRAITS), module_file=str(module.__file__), y_final=rows[-1].ravel().tolist())
