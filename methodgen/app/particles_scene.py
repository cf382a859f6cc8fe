"""Particle scene files: a particle family of symbolic size, its initial state as formulas, and a run.

Format (TOML; the built-in ones are in ``methodgen/symbolic/scenes/particles``)::

    name = "nbody-ring"
    description = "..."
    [particles]
    H = "Sum((px[i]**2 + py[i]**2)/(2*m[i]), i, 1, N) - Sum(Sum(G*m[i]*m[j]/sqrt(...), j, i + 1, N), i, 1, N)"
    q = ["x", "y"]                # position fields, their momenta, per-particle arrays, the size
    p = ["px", "py"]
    arrays = ["m"]
    size = "N"
    [params]
    G = 1.0
    [initial]                     # each field and array at particle i = 1 … N: a formula in i, N, params
    x = "(1 + 3*(i - 2)/(N - 1))*cos(2.39996*i)"
    [initial.first]               # optional: formulas for particle 1 (a central body)
    x = "0"
    [run]
    method = ["stormer-verlet", "energy-momentum"]
    order = {stormer-verlet = 8, energy-momentum = 2}   # composition orders (2, 4, 6, 8) per method;
                                  # one number: the same for every method; a method not named: 2
    N = 21                        # the size (--param N=51 on the command line)
    h = 0.01
    steps = 1000
    barycentric = true            # shift the initial state to the centre-of-mass frame (needs an array "m")

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

__all__ = ["ParticleScene", "is_particles_scene", "load_particles_scene", "particles_scene_names",
           "run_particles_scene"]

_TOP = {"name": str, "description": str, "particles": dict, "params": dict, "initial": dict, "run": dict}
_PARTICLES = {"H": str, "q": list, "p": list, "arrays": list, "size": str}
_RUN = {"method": (str, list), "order": (int, dict), "N": int, "h": (int, float), "steps": int, "barycentric": bool}


def particles_scene_names() -> list[str]:
    """Names of the built-in particle scenes, sorted."""
    return _files.names("particles")


def is_particles_scene(name_or_path) -> bool:
    """True for a built-in particle scene's name or a TOML file with a ``[particles]`` table."""
    return _files.is_kind("particles", name_or_path)


@dataclass(frozen=True)
class ParticleScene:
    """A parsed particle scene (see the module docstring)."""

    name: str
    description: str
    family: object
    initial: dict
    first: dict
    methods: tuple[str, ...]
    orders: dict
    size: int
    h: float
    steps: int
    barycentric: bool
    source: str

    @property
    def order(self) -> int:
        """The composition order of the scene's first method."""
        return self.orders[self.methods[0]]

    def state(self, n: int, params: dict | None = None) -> tuple[np.ndarray, dict]:
        """``(y0, arrays)`` at size ``n``: the state (q[1..n], p[1..n]) particle-major and the
        per-particle arrays, from the scene's formulas (the first particle's own where given),
        shifted to the centre-of-mass frame where ``barycentric``."""
        import sympy as sp

        from ..problem.parse import parse_expr

        fam = self.family
        fam.check_size(n)
        values = {**fam.params, **(params or {})}
        i = sp.Symbol("i", real=True)
        N = sp.Symbol(fam.size.name, real=True)
        symbols = {"i": i, fam.size.name: N, **{k: sp.Symbol(k, real=True) for k in values}}
        idx = np.arange(1, n + 1, dtype=float)

        def column(name):
            out = np.zeros(n)
            # (the [initial] formulas only where [initial.first] does not give the first particle's)
            rest = slice(1, None) if name in self.first else slice(None)
            for table, rows, label in ((self.initial, rest, "[initial]"),
                                       (self.first, slice(0, 1), "[initial.first]")):
                if name not in table:
                    continue
                expr = parse_expr(table[name], symbols, what=f"{label} {name}")
                expr = expr.xreplace({symbols[k]: sp.Float(v) for k, v in values.items()}).xreplace({N: n})
                f = sp.lambdify([i], expr, modules="numpy")    # printed from the parsed tree, not the text
                out[rows] = np.broadcast_to(np.asarray(f(idx[rows]), dtype=float), idx[rows].shape)
            return out

        Q = np.stack([column(f) for f in fam.q_names], axis=1)
        P = np.stack([column(f) for f in fam.p_names], axis=1)
        arrays = {a: column(a) for a in fam.array_names}
        if self.barycentric:
            m = arrays["m"]
            Q -= (m @ Q) / m.sum()
            P -= np.outer(m, P.sum(axis=0)) / m.sum()
        y = np.concatenate([Q.reshape(-1), P.reshape(-1)])
        if not (np.all(np.isfinite(y)) and all(np.all(np.isfinite(a)) for a in arrays.values())):
            raise InputError(f"the initial state of {self.name!r} at N = {n} is not finite")
        return y, arrays


def load_particles_scene(name_or_path) -> ParticleScene:
    """Read and check a particle scene (a built-in name or a path).

    Raises
    ------
    SceneError
        Unknown or mistyped keys, a missing table, an unknown method or order, bad formulas.
    """
    from ..problem.particles import Particles
    from ..symbolic.particle_scheme import ORDERS, PARTICLE_METHODS

    data, path = _files.read("particles", name_or_path, _TOP, "particle")
    where = str(path)
    pt, run = data["particles"], data["run"]
    _files.check_keys(pt, _PARTICLES, f"{where} [particles]")
    _files.check_keys(run, _RUN, f"{where} [run]")
    for k in ("H", "q", "p"):
        if k not in pt:
            raise SceneError(f"{where} [particles]: {k} is missing")
    for k in ("N", "h", "steps"):
        if k not in run:
            raise SceneError(f"{where} [run]: {k} is missing")
    params = data.get("params", {})
    for k, v in params.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(f"{where} [params]: {k!r} must be a number, got {v!r}")
    initial = dict(data.get("initial", {}))
    first = initial.pop("first", {})
    if not isinstance(first, dict):
        raise SceneError(f"{where} [initial]: 'first' is the table [initial.first] of the first particle's formulas")
    for table, label in ((initial, "[initial]"), (first, "[initial.first]")):
        for k, v in table.items():
            if not isinstance(v, str):
                raise SceneError(f"{where} {label}: {k!r} must be a formula (text), got {v!r}")
    if "i" in params or pt.get("size") == "i":
        raise SceneError(f"{where}: 'i' is the particle index of the [initial] formulas; give the parameter or "
                         "the size another name")
    name = data.get("name", path.stem)
    try:
        fam = Particles(pt["H"], pt["q"], pt["p"], size=pt.get("size", "N"), arrays=pt.get("arrays", []),
                        params=params, name=name)
    except InputError as exc:
        raise SceneError(f"{where}: {exc}") from None
    names = set(fam.q_names) | set(fam.p_names) | set(fam.array_names)
    for table, label in ((initial, "[initial]"), (first, "[initial.first]")):
        unknown = set(table) - names
        if unknown:
            raise SceneError(f"{where} {label}: {', '.join(sorted(unknown))} is not a field or an array; they are "
                             f"{', '.join(sorted(names))}")
    methods = run["method"] if isinstance(run.get("method", "stormer-verlet"), list) else \
        [run.get("method", "stormer-verlet")]
    for m in methods:
        if m not in PARTICLE_METHODS:
            raise SceneError(f"{where} [run]: method {m!r} is not available for particles; available: "
                             f"{', '.join(PARTICLE_METHODS)}")
    orders = _files.run_orders(run.get("order", 2), methods, ORDERS, where, "the particle methods are")
    if run["steps"] < 1 or not (math.isfinite(run["h"]) and run["h"] > 0):
        raise SceneError(f"{where} [run]: steps must be ≥ 1 and h > 0")
    barycentric = run.get("barycentric", False)
    if barycentric and "m" not in fam.array_names:
        raise SceneError(f"{where} [run]: barycentric = true needs the masses as the array 'm'")
    try:
        fam.check_size(run["N"])
    except InputError as exc:
        raise SceneError(f"{where} [run]: {exc}") from None
    scene = ParticleScene(name, data.get("description", ""), fam, initial, first, tuple(methods), orders,
                          run["N"], float(run["h"]), run["steps"], barycentric, where)
    try:
        scene.state(fam.nmin)      # the formulas parse (whitelist) and evaluate
    except InputError as exc:
        raise SceneError(f"{where}: {exc}") from None
    return scene


def run_particles_scene(name_or_path, method=None, h=None, steps=None, *, size=None, params=None, order=None,
                        t_final=None, backend="numpy", progress=None, section=None, plot=None) -> dict:
    """Build (or load) the scene's module and run it; a report as a dict (JSON-ready).

    ``size``: N for this run (default the scene's); ``order``: the method's composition order (2, 4,
    6, 8; default the scene's for the method, else 2); ``backend``: "numpy" or "compiled"
    (:func:`methodgen.codegen.particle_emit.build_particles`).  ``section`` (``"y[2] = 0, py[2] > 0"``):
    a Poincaré section instead -- every crossing within the steps, each located on the method's own
    map (:func:`methodgen.app.family_section.run_family_section`); ``plot``: a file to draw it to.
    """
    from ..codegen.particle_emit import build_particles

    scene = load_particles_scene(name_or_path)
    method = method or scene.methods[0]
    n = scene.size if size is None else size
    scene.family.check_size(n)
    order = scene.orders.get(method, 2) if order is None else int(order)
    h = scene.h if h is None else float(h)
    steps = scene.steps if steps is None else int(steps)
    if t_final is not None:
        steps = max(1, math.ceil(t_final / h - 1e-12))
        h = t_final / steps
    t0 = time.perf_counter()
    module = build_particles(scene.family, method, order=order, backend=backend, progress=progress)
    build_seconds = time.perf_counter() - t0
    y0, arrays = scene.state(n, params)
    meta = dict(scene=scene.name, method=method, order=module.ORDER, backend=backend, N=n, build_seconds=build_seconds)
    if section is not None:
        from .family_section import run_family_section

        return {**meta, **run_family_section(module, y0, h, steps, section, params=params, arrays=arrays, plot=plot,
                                             title=f"{scene.name}, {method}, N = {n}, h = {h:g}"), "steps": steps}
    every = max(1, steps // 1000)
    info: dict = {}
    t0 = time.perf_counter()
    rows = module.integrate(y0, h, steps, params, arrays=arrays, save_every=every, info=info)
    seconds = time.perf_counter() - t0
    values = [module.invariants(r, params, arrays) for r in rows]
    inv = {k: {"initial": values[0][k], "final": values[-1][k],
               "max_abs_error": max(abs(v[k] - values[0][k]) for v in values)} for k in module.INVARIANT_NAMES}
    its = info.get("iterations")
    return dict(scene=scene.name, method=method, order=module.ORDER, backend=backend, N=n, h=h, steps=steps,
                t_final=h * steps, success=True, build_seconds=build_seconds, seconds=seconds,
                seconds_per_step=seconds / steps,
                iterations_mean=float(np.mean(its)) if method == "energy-momentum" and its is not None else None,
                invariants=inv, traits=dict(module.TRAITS), module_file=str(module.__file__),
                y_final=rows[-1].ravel().tolist())
