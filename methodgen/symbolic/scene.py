"""Scene files: one problem plus what the user wants done with it (TOML).

Format (see the docs, "Scene files", and the built-in scenes in ``methodgen/symbolic/scenes``)::

    name = "kepler"
    description = "..."
    [system]
    H = "..."; q = [...]; p = [...]; constraints = []
    # or a Poisson system y' = S(y)∇H (methodgen.PoissonSystem): y = [...] and
    # S = [["0", "-m3", "m2"], ...] (rows of strings, skew-symmetric) instead of q, p
    time = "t"                   # optional: H depends on the time t explicitly (the methods
                                 #   integrate K = H(q, p, t) + e on (q, t; p, e), methodgen.autonomise)
    [params]
    m = 1.0
    [run]
    method = "energy-momentum"   # or a list
    h = 0.01
    steps = 10000
    y0 = [...]                   # q then p
    order = 8                    # optional: 2 (default), 4, 6, 8 or 10 — above 2 the method
    composition = "kahan-li"     #   is composed symmetrically; optional family (default per order)
    stages = 3                   # optional: stages of gauss / energy-collocation (the methods
                                 #   that take it; a scene without one of them is an error)
    time_transform = "sqrt(x**2 + y**2 + z**2)"   # optional: integrate K = g(q)(H + e) instead
                                 #   (methodgen.time_transform); y0 stays in the original variables,
                                 #   h and steps are in fictive time; "log": the logarithmic
                                 #   Hamiltonian log(T + e) - log(-U) (explicit leapfrog, U < 0)
    t0 = 0.0                     # optional: the initial time (with [system] time or a time_transform)
    [invariants]                 # optional: quantities to monitor as first integrals
    P = "p1 + p2 + p3"           #   NAME = "expression" (whitelist parser; verify proves or
                                 #   refutes {I, H} = 0; methods claim only what they keep)
    [nbody]                      # optional: the scene is an N-body gravitational problem
    G = "G"                      # a number or a [params] name
    masses = ["m0", "m1"]        # one per body (3 coordinates each, in q order), p = m v
    centre_mass = "M"            # optional: a fixed attracting centre at the origin (one body only)

The ``[nbody]`` table is what ``methodgen bench --peers`` needs to hand the scene to
REBOUND; it is a declaration, checked against H before use (:mod:`methodgen.app.peers`).

A scene file is data: it is parsed with ``tomllib`` and validated key by key;
unknown keys and wrong types are errors that name the key and what is valid.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from ..errors import InputError, SceneError
from ..problem.problem import Hamiltonian

__all__ = ["Scene", "NBody", "load_scene", "scene_names", "builtin_scene_dir", "check_order",
           "check_stages", "stage_methods", "with_time_transform", "check_g_positive"]

_TOP = {"name": str, "description": str, "system": dict, "params": dict, "run": dict, "nbody": dict,
        "invariants": dict}
_SYSTEM = {"H": str, "q": list, "p": list, "constraints": list, "time": str, "y": list, "S": list}
_RUN = {"method": (str, list), "h": (int, float), "steps": int, "y0": list, "order": int,
        "composition": str, "stages": int, "time_transform": str, "t0": (int, float)}
_NBODY = {"G": (int, float, str), "masses": list, "centre_mass": (int, float, str)}


def builtin_scene_dir() -> Path:
    return Path(__file__).resolve().parent / "scenes"


def scene_names() -> list[str]:
    """Names of the built-in scenes, sorted."""
    return sorted(p.stem for p in builtin_scene_dir().glob("*.toml"))


@dataclass(frozen=True)
class NBody:
    """A scene's declaration that it is an N-body gravitational problem (the ``[nbody]`` table).

    Body ``b`` has coordinates ``q[3b:3b+3]`` and momenta ``p[3b:3b+3]`` (velocity
    ``p/m_b``); the declared Hamiltonian is
    ``Σ|p_b|²/(2m_b) − Σ_{a<b} G m_a m_b/|q_a − q_b| − Σ_b G M m_b/|q_b|`` (the last
    sum only with a fixed centre of mass ``M``).  Values are numbers or names of
    ``[params]`` (so parameter overrides carry over); :meth:`values` resolves them.
    """

    G: float | str
    masses: tuple[float | str, ...]
    centre_mass: float | str | None = None

    def values(self, params: dict) -> tuple[float, tuple[float, ...], float | None]:
        """``(G, masses, centre_mass)`` as numbers, names looked up in ``params``."""
        def num(v):
            return float(params[v]) if isinstance(v, str) else float(v)
        return (num(self.G), tuple(num(m) for m in self.masses),
                None if self.centre_mass is None else num(self.centre_mass))


@dataclass(frozen=True)
class Scene:
    """A validated scene.

    Attributes
    ----------
    name, description : str
    system : Hamiltonian
    methods : tuple of str
        The scene's method(s); the first is the default.
    h : float
    steps : int
    y0 : tuple of float, length 2d
    path : Path or None
    builtin : bool
    nbody : NBody or None
        The ``[nbody]`` declaration, if any.
    order : int
        ``[run].order``: 2 (the method itself, default) or 4, 6, 8, 10 (a symmetric
        composition of it, :func:`methodgen.discretize` ``order=``).
    composition : str or None
        ``[run].composition``: the composition family (None: the default for ``order``).
    stages : int or None
        ``[run].stages``: the stages of the scene's methods that take them (``gauss``,
        ``energy-collocation``); None: their default.  See :func:`check_stages`.
    time_transform : str or None
        ``[run].time_transform``: the text of g(q).  The scene's methods then integrate
        :attr:`run_system`, ``K = g(q)(H + e)`` (:func:`methodgen.time_transform`); ``y0``
        stays in the original variables (``module.initial_state(y0)`` maps it), ``h`` and
        ``steps`` are in fictive time.
    transformed : Hamiltonian or None
        ``K``, the time-transformed system (named ``<name>-tt``), when ``time_transform`` is set.
    t0 : float
        ``[run].t0``: the initial time (default 0) of a time-dependent H (``[system] time``)
        or of a time transformation's physical time.
    declared_fingerprint : str or None
        Fingerprint of the system the scene *file* integrates (its ``[run] time_transform``
        or none): a built-in scene's ``generated/`` modules are of that system only, a
        ``--time-transform`` override's live in the cache.
    """

    name: str
    description: str
    system: Hamiltonian
    methods: tuple[str, ...]
    h: float
    steps: int
    y0: tuple[float, ...]
    path: Path | None = None
    builtin: bool = False
    nbody: NBody | None = None
    order: int = 2
    composition: str | None = None
    stages: int | None = None
    time_transform: str | None = None
    t0: float = 0.0
    transformed: Hamiltonian | None = field(default=None, repr=False, compare=False)
    declared_fingerprint: str | None = field(default=None, repr=False, compare=False)

    @property
    def method(self) -> str:
        return self.methods[0]

    @property
    def run_system(self) -> Hamiltonian:
        """The system the scene's methods integrate: :attr:`transformed` if the scene has a
        time transformation, else :attr:`system` — for a time-dependent H its autonomous
        extension ``K = H + e`` (:func:`methodgen.autonomise`) — (``y0`` always belongs to
        :attr:`system`)."""
        if self.transformed is not None:
            return self.transformed
        from .timetransform import autonomise
        return autonomise(self.system)

    def options(self, method: str, stages: int | None = None) -> dict:
        """Method options of ``method`` in this scene: ``{"stages": s}`` for a method that
        takes stages when ``stages`` (or the scene's ``[run] stages``) is set, else ``{}``."""
        s = self.stages if stages is None else stages
        return {"stages": s} if s is not None and method in stage_methods() else {}


#: [system] keys with which a user gives a vector field instead of H (refused with the scope)
_FIELD_KEYS = frozenset({"f", "F", "rhs", "field", "ode", "odes", "dydt", "ydot", "vector_field", "xdot"})


def _check_keys(table: dict, allowed: dict, where: str) -> None:
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise SceneError(f"unknown key(s) {unknown} in {where}; valid keys are {sorted(allowed)}")
    for key, typ in allowed.items():
        if key in table:
            value = table[key]
            if isinstance(value, bool) or not isinstance(value, typ):
                want = (typ.__name__ if isinstance(typ, type) else
                        "number" if set(typ) == {int, float} else " or ".join(t.__name__ for t in typ))
                raise SceneError(f"{where}.{key} must be a {want}, got {type(value).__name__} {value!r}")


def _require(table: dict, key: str, where: str):
    if key not in table:
        raise SceneError(f"missing key {key!r} in {where}")
    return table[key]


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SceneError(f"{where} must be finite, got {value!r}")
    return value


def _orders(family: str) -> str:
    from .compositions import ALL_FAMILIES
    o = ALL_FAMILIES[family]
    return f"order{'s' if len(o) > 1 else ''} {', '.join(map(str, o))}"


def _families_text() -> str:
    from .compositions import ALL_FAMILIES
    return ", ".join(f"{f} ({_orders(f)})" for f in ALL_FAMILIES)


def check_order(order, composition=None, *, order_name: str = "order",
                composition_name: str = "composition", error=InputError) -> tuple[int, str | None]:
    """Validate an order and a composition family; return ``(order, family or None)``.

    Order 2 is the method itself; 4, 6, 8, 10 compose it symmetrically
    (:mod:`methodgen.symbolic.compositions`).  Every error (``error``, an
    :class:`~methodgen.errors.InputError` subclass) names the bad value, using
    ``order_name``/``composition_name`` (``[run].order``, ``--order``), and lists what
    is valid.  Whether the *method* can be composed (it must be symmetric of order 2
    on the system) is decided when it is discretised.
    """
    from .compositions import DEFAULT_FAMILY, ALL_FAMILIES, ORDERS

    orders = ", ".join(map(str, ORDERS))
    if isinstance(order, bool) or not isinstance(order, int) or order not in ORDERS:
        raise error(f"{order_name} must be one of {orders} (2: the method itself; above 2: a symmetric "
                    f"composition of it), got {order!r}")
    if composition is None or (order == 2 and composition == "base"):
        return order, None
    if not isinstance(composition, str) or composition not in ALL_FAMILIES:
        raise error(f"{composition_name}: unknown composition family {composition!r}; families: "
                    f"{_families_text()}")
    if order == 2:
        raise error(f"{composition_name} = {composition!r} needs {order_name} above 2 (order 2 is the "
                    f"method itself, not composed); the {composition} family has {_orders(composition)}")
    if order not in ALL_FAMILIES[composition]:
        have = [f for f, o in ALL_FAMILIES.items() if order in o]
        raise error(f"{composition_name}: the {composition} family has {_orders(composition)}, not "
                    f"{order}; families with order "
                    f"{order}: {', '.join(have)} (default {DEFAULT_FAMILY[order]})")
    return order, composition


def stage_methods() -> dict[str, tuple[int, ...]]:
    """The methods that take ``stages``, each with its valid values (``gauss``: 1..6, …)."""
    from .schemes import METHODS
    return {name: tuple(mod.STAGES) for name, mod in METHODS.items() if hasattr(mod, "STAGES")}


def _stages_text(takers: dict) -> str:
    from .schemes import METHODS
    return ", ".join(f"{m} (stages {v[0]}..{v[-1]}, default {METHODS[m].DEFAULT_STAGES})"
                     for m, v in takers.items())


def check_stages(stages, methods, *, name: str = "stages", error=InputError) -> int | None:
    """Validate a number of stages for ``methods``; return it (None when ``stages`` is None).

    ``stages`` applies to those of ``methods`` that take it (``gauss``: 1..6,
    ``energy-collocation``: 1..4); it must be valid for each of them, and at least one
    of ``methods`` must take it.  Every error (``error``) names ``name``, the value and
    what is valid.
    """
    if stages is None:
        return None
    takers = stage_methods()
    if isinstance(stages, bool) or not isinstance(stages, int):
        raise error(f"{name} must be a whole number of stages, got {stages!r}; valid: {_stages_text(takers)}")
    methods = tuple(methods)
    mine = {m: v for m, v in takers.items() if m in methods}
    if not mine:
        listed = ", ".join(methods) or "(none)"
        raise error(f"{name}: {listed} take{'s' if len(methods) == 1 else ''} no stages; stages apply "
                    f"to {_stages_text(takers)}")
    for m, valid in mine.items():
        if stages not in valid:
            raise error(f"{name} = {stages}: {m} takes stages {', '.join(map(str, valid))}, got {stages}")
    return stages


def with_time_transform(scene: Scene, g: str | None, *, error=InputError, name: str = "--time-transform"
                        ) -> Scene:
    """``scene`` with the time transformation ``g`` (text of g(q)); ``None`` or ``"none"``: none.

    ``g`` is parsed with the whitelist parser (:func:`methodgen.time_transform`), never
    evaluated; a bad g is ``error`` naming ``name``.  The transformed system is named
    ``<scene>-tt`` (its own module files and fingerprint).  ``"log"`` selects the
    logarithmic Hamiltonian ``log(T + e) − log(−U)`` instead (``time_transform(system,
    form="log")``, named ``<scene>-log``).
    """
    import dataclasses

    from .timetransform import time_transform

    if g is None or (isinstance(g, str) and g.strip().lower() == "none"):
        return dataclasses.replace(scene, time_transform=None, transformed=None)
    if not isinstance(g, str) or not g.strip():
        raise error(f"{name} must be a function g(q) of the coordinates "
                    f"({', '.join(s.name for s in scene.system.q)}), got {g!r}")
    try:
        if g.strip().lower() == "log":
            # the logarithmic Hamiltonian (explicit leapfrog; methodgen.symbolic.timetransform, form="log")
            K = time_transform(scene.system, form="log", name=f"{scene.name}-log")
        else:
            K = time_transform(scene.system, g, name=f"{scene.name}-tt")
    except InputError as exc:
        raise error(f"{name}: {exc}") from None
    return dataclasses.replace(scene, time_transform=g.strip(), transformed=K)


def check_g_positive(system: Hamiltonian, y0, params: dict | None = None, *, error=InputError,
                     name: str = "the time transformation") -> float:
    """``g(q0)`` of a time-transformed ``system`` at the original state ``y0``; an error unless
    it is finite and positive (dt/dτ = g: g ≤ 0 stops or reverses physical time)."""
    import sympy as sp

    tt = system.time_transform
    values = dict(system.param_values)
    values.update(params or {})
    subs = {s: sp.Float(float(v)) for s, v in zip(tt.original.y, y0)}
    subs.update({s: sp.Float(values[s.name]) for s in system.params})
    try:
        v = complex(sp.N(tt.g.xreplace(subs)))
    except (TypeError, ValueError, ZeroDivisionError):
        v = complex(math.nan)
    if not (math.isfinite(v.real) and math.isfinite(v.imag)):
        shown = "not finite"
    elif v.imag != 0:
        shown = "not real"
    else:
        shown = f"{v.real:g}"
    if (shown != f"{v.real:g}" or v.real <= 0) and tt.form == "log":
        from .derive import separable_split

        U = separable_split(tt.original).U     # the log form exists only for a separable H
        try:
            u = f"{float(sp.N(U.xreplace(subs))):g}"
        except (TypeError, ValueError, ZeroDivisionError):
            u = "not finite"
        raise error(f"{name.rstrip(':')}: the log form integrates log(-U) and needs U(q) < 0 along the motion; at y0 "
                    f"U = {u} (U = {U}); use a g(q) > 0 (Poincaré form) instead")
    if shown != f"{v.real:g}" or v.real <= 0:
        raise error(f"{name} g = {tt.g_source} is {shown} at y0; it must be positive along the motion "
                    "(dt/dτ = g)")
    return v.real


def parse_scene(data: dict, source: str, path: Path | None = None, builtin: bool = False) -> Scene:
    """Validate a parsed TOML document and build the :class:`Scene`."""
    _check_keys(data, _TOP, "the scene")
    name = _require(data, "name", "the scene")
    system_t = _require(data, "system", "the scene")
    if "H" not in system_t and set(system_t) & _FIELD_KEYS:
        raise SceneError(
            f"[system] gives a vector field ({', '.join(sorted(set(system_t) & _FIELD_KEYS))}) and no H: "
            "methodgen integrates Hamiltonian systems only -- H with q and p (canonical), or H with "
            "a skew-symmetric structure matrix S and state y (Poisson: y' = S(y)∇H(y)). A field "
            "that is not of that form (the ABC flow, a dissipative system) is out of scope: if you "
            "know an H and S with f = S∇H, give those; otherwise use a general ODE solver "
            "(scipy.integrate.solve_ivp), or for a divergence-free field a volume-preserving "
            "splitting method")
    _check_keys(system_t, _SYSTEM, "[system]")
    params_t = data.get("params", {})
    for k, v in params_t.items():
        _number(v, f"[params].{k}")
    run_t = data.get("run", {})
    # Before the type check, so that a wrong type also hears the valid orders and families.
    order, composition = check_order(run_t.get("order", 2), run_t.get("composition"),
                                     order_name="[run].order", composition_name="[run].composition",
                                     error=SceneError)
    if "stages" in run_t and (isinstance(run_t["stages"], bool) or not isinstance(run_t["stages"], int)):
        check_stages(run_t["stages"], (), name="[run].stages", error=SceneError)  # names what is valid
    _check_keys(run_t, _RUN, "[run]")
    for key in ("q", "p", "constraints"):
        for item in system_t.get(key, []):
            if not isinstance(item, str):
                raise SceneError(f"[system].{key} must be a list of strings, got item {item!r}")
    try:
        if "y" in system_t or "S" in system_t:
            system = _poisson_system(system_t, params_t, name, data.get("invariants"))
        else:
            system = Hamiltonian(_require(system_t, "H", "[system]"), q=_require(system_t, "q", "[system]"),
                                 p=_require(system_t, "p", "[system]"), params=params_t,
                                 constraints=system_t.get("constraints", []), name=name,
                                 invariants=_invariants_table(data.get("invariants")),
                                 time=system_t.get("time"))
    except SceneError:
        raise
    except InputError as exc:
        raise SceneError(f"{source}: {exc}") from None
    methods = _require(run_t, "method", "[run]")
    methods = (methods,) if isinstance(methods, str) else tuple(methods)
    if not methods or not all(isinstance(m, str) for m in methods):
        raise SceneError("[run].method must be a method name or a non-empty list of names")
    h = _number(_require(run_t, "h", "[run]"), "[run].h")
    if h == 0:
        raise SceneError("[run].h must be non-zero")
    steps = _require(run_t, "steps", "[run]")
    if steps < 0:
        raise SceneError(f"[run].steps must be >= 0, got {steps}")
    y0 = tuple(_number(v, f"[run].y0[{i}]") for i, v in enumerate(_require(run_t, "y0", "[run]")))
    if len(y0) != len(system.y):
        raise SceneError(f"[run].y0 has {len(y0)} values but the state ({', '.join(system.state_names)}) "
                         f"has {len(system.y)}")
    nbody = _parse_nbody(data["nbody"], system, params_t) if "nbody" in data else None
    stages = check_stages(run_t.get("stages"), methods, name="[run].stages", error=SceneError)
    t0 = _number(run_t.get("t0", 0.0), "[run].t0")
    if "t0" in run_t and getattr(system, "time", None) is None and "time_transform" not in run_t:
        raise SceneError("[run].t0 is the initial time of a time-dependent H: declare the time in "
                         '[system] (time = "t") or leave t0 out (an autonomous H does not see it)')
    scene = Scene(name=name, description=data.get("description", ""), system=system, methods=methods,
                  h=h, steps=steps, y0=y0, path=path, builtin=builtin, nbody=nbody, order=order,
                  composition=composition, stages=stages, t0=t0)
    if "time_transform" in run_t:
        scene = with_time_transform(scene, run_t["time_transform"], error=SceneError,
                                    name="[run].time_transform")
        if scene.transformed is None:
            raise SceneError('[run].time_transform = "none": leave the key out for no transformation')
        check_g_positive(scene.transformed, y0, error=SceneError, name="[run].time_transform:")
    import dataclasses
    return dataclasses.replace(scene, declared_fingerprint=scene.run_system.fingerprint())


def _poisson_system(system_t: dict, params_t: dict, name: str, invariants):
    """``[system] y = [...]``, ``S = [["...", ...], ...]`` (strings), ``H``: a
    :class:`~methodgen.problem.poisson.PoissonSystem` (q, p, constraints and time are refused with it)."""
    from ..problem.poisson import PoissonSystem

    mixed = sorted(k for k in ("q", "p", "constraints", "time") if k in system_t)
    if mixed:
        raise SceneError(f"[system] with y and S is a Poisson system y' = S(y)∇H; it takes no "
                         f"{', '.join(mixed)} (those describe canonical coordinates)")
    y = _require(system_t, "y", "[system] (a Poisson system needs y and S)")
    S = _require(system_t, "S", "[system] (a Poisson system needs y and S)")
    for item in y:
        if not isinstance(item, str):
            raise SceneError(f"[system].y must be a list of strings, got item {item!r}")
    for i, row in enumerate(S):
        if not isinstance(row, list) or not all(isinstance(e, str) for e in row):
            raise SceneError(f'[system].S must be a list of rows of strings (S = [["0", "-m3", "m2"], ...]), '
                             f"got row {i}: {row!r}")
    return PoissonSystem(_require(system_t, "H", "[system]"), y=y, S=S, params=params_t, name=name,
                         invariants=_invariants_table(invariants))


def _invariants_table(table: dict | None) -> dict | None:
    """``[invariants]``: ``NAME = "expression"`` (strings only; checked by :class:`Hamiltonian`)."""
    if table is None:
        return None
    for key, value in table.items():
        if not isinstance(value, str):
            raise SceneError(f'[invariants].{key} must be a string expression (NAME = "p1 + p2"), '
                             f"got {type(value).__name__} {value!r}")
    return dict(table)


def _parse_nbody(table: dict, system: Hamiltonian, params: dict) -> NBody:
    """Validate ``[nbody]``: numbers or parameter names, one mass per 3 coordinates."""
    _check_keys(table, _NBODY, "[nbody]")

    def value(v, where):
        if isinstance(v, str):
            if v not in params:
                raise SceneError(f"{where} names {v!r}, which is not in [params] ({', '.join(params) or 'none'})")
            return v
        if _number(v, where) <= 0:
            raise SceneError(f"{where} must be positive, got {v!r}")
        return float(v)

    G = value(_require(table, "G", "[nbody]"), "[nbody].G")
    masses = tuple(value(m, f"[nbody].masses[{i}]") for i, m in enumerate(_require(table, "masses", "[nbody]")))
    if system.constraints:
        raise SceneError("[nbody] describes free bodies; a constrained scene cannot have one")
    if 3 * len(masses) != system.dim:
        raise SceneError(f"[nbody].masses has {len(masses)} bodies (3 coordinates each) but the scene has "
                         f"{system.dim} coordinates")
    centre = table.get("centre_mass")
    if centre is not None:
        centre = value(centre, "[nbody].centre_mass")
        if len(masses) != 1:
            raise SceneError("[nbody].centre_mass (a fixed centre) needs exactly one body: with more, "
                             "the bodies would pull the centre")
    return NBody(G=G, masses=masses, centre_mass=centre)


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a built-in scene by name, or a scene file by path.

    Raises
    ------
    SceneError
        Unknown scene, unreadable file, TOML syntax error, or invalid content.
    """
    text_name = str(name_or_path)
    builtin = builtin_scene_dir() / f"{text_name}.toml"
    if "/" not in text_name and not text_name.endswith(".toml") and builtin.is_file():
        path, is_builtin = builtin, True
    else:
        path, is_builtin = Path(name_or_path), False
        if not path.is_file():
            raise SceneError(f"no built-in scene or file named {text_name!r}; built-in scenes: "
                             f"{', '.join(scene_names())}")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: invalid TOML: {exc}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneError(f"cannot read scene {path}: {exc}") from None
    scene = parse_scene(data, str(path), path, is_builtin)
    if is_builtin and scene.name != text_name:
        raise SceneError(f"built-in scene file {path} declares name {scene.name!r}")
    return scene
