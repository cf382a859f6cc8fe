"""Parameter sweeps: methods × step sizes × parameter values × initial-condition batches.

A sweep is described by a TOML *spec* (data: parsed with :mod:`tomllib` and
validated key by key, never evaluated)::

    scene = "kepler"            # built-in name, or path to a scene TOML (relative to the spec)
    methods = ["energy-momentum", "midpoint"]   # default: the scene's methods
    h = [0.02, 0.01, 0.005]     # a number or a list; default: the scene's h
    steps = 1000                # or t_final = 10.0 (then ceil(t_final/h) steps of t_final/steps <= h); default: the scene's
    check_resolution = true     # optional; false lets large h run past the h·ω guard
    [params]                    # optional: values per parameter (cartesian product)
    k = [1.0, 1.5]
    [initial]                   # optional ensemble of initial conditions
    count = 100                 # perturbed copies of the scene's y0 (0 or 1: y0 itself)
    spread = 1e-3               # standard deviation of the Gaussian perturbation (absolute)
    seed = 0
    batch = 250                 # trajectories per task (default 500)

The tasks are the cartesian product method × h × parameter values × batches
of initial conditions.  Each task loads the generated module (shipped as
source text, so a remote worker needs neither the scene file nor a
derivation), integrates its batch, and returns one plain row: max energy
and invariant errors, the final-state error against :func:`methodgen.app.bench.reference`
when the ensemble is the unperturbed ``y0``, Newton statistics, CPU seconds
and trajectory-steps.

The execution engine is pluggable and separate from the task code:
in-process (default; no dask needed), a ``distributed.LocalCluster``
(``workers=N``) or an existing Dask scheduler (``scheduler=ADDRESS``).  The
same functions run on every engine, so the rows are bitwise identical apart
from ``cpu_seconds``.  A numerical failure (``ConvergenceError``,
``NonFiniteError``, ``ResolutionError``) is a result (``status =
"numerical-error"``); any other exception, or a lost worker, is a task
failure: retried ``retries`` times (Dask's ``retries=``), then reported as a
row with ``status = "failed"`` — never dropped.
"""

from __future__ import annotations

import csv
import io
import itertools
import math
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

import numpy as np

from ..errors import InputError, MethodgenError
from .limits import MAX_STEPS, fmt_bytes, memory_limit, steps_for_time
from .stats import ErrorMax

__all__ = ["SpecError", "EngineError", "SweepSpec", "Task", "load_spec", "parse_spec", "plan_sweep",
           "run_sweep", "run_task", "compute_reference", "rows_to_csv"]

#: Float64 values one integration chunk may hold (32 MB): bounds a task's memory
#: whatever its batch × steps.
CHUNK_VALUES = 1 << 22

#: Trajectories per task when ``[initial].batch`` is not given.
DEFAULT_BATCH = 500

_NUMERICAL = ("ConvergenceError", "NonFiniteError", "ResolutionError")


class SpecError(InputError):
    """A sweep spec that cannot be read or does not follow the spec format."""


class EngineError(MethodgenError):
    """The requested execution engine is unavailable (dask not installed, scheduler unreachable)."""


# --- the spec ---------------------------------------------------------------------------

#: key -> (accepted TOML types, what the error message says is valid)
_TOP = {"scene": ((str,), "a string (built-in scene name or scene file path)"),
        "methods": ((str, list), "a method name or a list of names"),
        "h": ((int, float, list), "a number or a list of numbers"),
        "steps": ((int,), "an integer"),
        "t_final": ((int, float), "a number"),
        "check_resolution": ((bool,), "a boolean"),
        "params": ((dict,), "a table of parameter = number or list of numbers"),
        "initial": ((dict,), "a table")}
_INITIAL = {"count": ((int,), "an integer"), "spread": ((int, float), "a number"),
            "seed": ((int,), "an integer"), "batch": ((int,), "an integer")}


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep spec.

    Attributes
    ----------
    scene : Scene
        The loaded scene.
    scene_text : str
        The scene file's TOML text (shipped to workers, which may not have the file).
    methods : tuple of str
    h : tuple of float
        Step sizes, all > 0.
    steps : int or None
        Steps per run (exclusive with ``t_final``).
    t_final : float or None
        Final time; then each h runs ``ceil(t_final / h)`` steps of ``h_used = t_final / steps``
        (no larger than h, ending at t_final; :func:`methodgen.app.limits.steps_for_time`, as ``run``).
    params : tuple of (str, tuple of float)
        Swept parameters in the scene's parameter order, each with its values.
    count, batch, seed : int
    spread : float
    check_resolution : bool
    """

    scene: Any
    scene_text: str
    methods: tuple[str, ...]
    h: tuple[float, ...]
    steps: int | None
    t_final: float | None
    params: tuple[tuple[str, tuple[float, ...]], ...] = ()
    count: int = 0
    spread: float = 0.0
    seed: int = 0
    batch: int = DEFAULT_BATCH
    check_resolution: bool = True

    def to_dict(self) -> dict:
        """The normalised spec as plain data (what the JSON report echoes)."""
        return {"scene": self.scene.name, "methods": list(self.methods), "h": list(self.h),
                "steps": self.steps, "t_final": self.t_final, "check_resolution": self.check_resolution,
                "params": {k: list(v) for k, v in self.params},
                "initial": {"count": self.count, "spread": self.spread, "seed": self.seed,
                            "batch": self.batch}}


def _check_table(table: Mapping, allowed: dict, where: str) -> None:
    """Unknown keys and wrong types are errors naming the key and what is valid."""
    unknown = sorted(set(table) - set(allowed))
    if unknown:
        raise SpecError(f"unknown key(s) {unknown} in {where}; valid keys are {sorted(allowed)}")
    for key, (types, want) in allowed.items():
        if key not in table:
            continue
        value = table[key]
        # bool is an int subclass: `steps = true` must not pass as 1.
        if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
            raise SpecError(f"{where}: {key} must be {want}, got {type(value).__name__} {value!r}")


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(f"{where} must be a number, got {type(value).__name__} {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise SpecError(f"{where} must be finite, got {value!r}")
    return value


def _number_list(value, where: str, positive: bool = False) -> tuple[float, ...]:
    """A number or a non-empty list of distinct numbers (duplicates would be duplicate tasks)."""
    items = value if isinstance(value, list) else [value]
    if not items:
        raise SpecError(f"{where} must not be an empty list")
    out = tuple(_number(v, f"{where}[{i}]" if isinstance(value, list) else where)
                for i, v in enumerate(items))
    if positive:
        for i, v in enumerate(out):
            if v <= 0:
                raise SpecError(f"{where} values must be > 0, got {v!r}")
    if len(set(out)) != len(out):
        raise SpecError(f"{where} has duplicate values {list(out)}")
    return out


def _resolve_scene(name: str, base: Path | None):
    """Built-in scene by name, else a scene file (relative paths: against the spec's folder)."""
    from ..symbolic.scene import builtin_scene_dir, load_scene

    if "/" not in name and not name.endswith(".toml") and (builtin_scene_dir() / f"{name}.toml").is_file():
        return load_scene(name)
    path = Path(name)
    if not path.is_absolute() and base is not None and (base / path).is_file():
        path = base / path
    return load_scene(path)


def parse_spec(data: Mapping, base: Path | None = None, source: str = "the sweep spec") -> SweepSpec:
    """Validate a parsed spec document and return the :class:`SweepSpec`.

    Parameters
    ----------
    data : mapping
        The TOML document as parsed by :mod:`tomllib` (or an equivalent dict).
    base : Path, optional
        Folder against which a relative scene path is resolved (the spec's folder).
    source : str
        How the spec is named in error messages.

    Raises
    ------
    SpecError, SceneError
        Unknown keys, wrong types, invalid values, unknown scene/method/parameter.
    """
    from ..symbolic.schemes import METHODS

    if not isinstance(data, Mapping):
        raise SpecError(f"{source} must be a table, got {type(data).__name__}")
    _check_table(data, _TOP, source)
    if "scene" not in data:
        raise SpecError(f"{source}: missing key 'scene' (a built-in scene name or a scene file path)")
    scene = _resolve_scene(data["scene"], base)
    if (getattr(scene, "transformed", None) is not None or getattr(scene, "stages", None) is not None
            or getattr(scene.system, "time", None) is not None):
        # Not silently ignored: a sweep would run the untransformed system / the default stages.
        what = ("a time transformation ([run] time_transform)" if scene.transformed is not None else
                "a time-dependent H ([system] time)" if getattr(scene.system, "time", None) is not None else
                "a number of stages ([run] stages)")
        raise SpecError(f"{source}: scene {scene.name!r} declares {what}, which sweeps do not support yet; "
                        "use `methodgen run` (--time-transform, --stages) or a scene without it")
    if scene.path is None:  # pragma: no cover - load_scene always records the file
        raise SpecError(f"scene {scene.name!r} has no file to ship to workers")
    scene_text = Path(scene.path).read_text(encoding="utf-8")

    methods = data.get("methods", list(scene.methods))
    methods = [methods] if isinstance(methods, str) else methods
    if not methods:
        raise SpecError(f"{source}: methods must not be an empty list")
    for i, m in enumerate(methods):
        if not isinstance(m, str):
            raise SpecError(f"{source}: methods[{i}] must be a string, got {m!r}")
        if m not in METHODS:
            raise SpecError(f"{source}: unknown method {m!r}; known methods: {', '.join(METHODS)}")
    if len(set(methods)) != len(methods):
        raise SpecError(f"{source}: methods has duplicates {methods}")

    hs = _number_list(data["h"], f"{source}: h", positive=True) if "h" in data else (abs(scene.h),)

    if "steps" in data and "t_final" in data:
        raise SpecError(f"{source}: give either steps or t_final, not both")
    steps = t_final = None
    if "t_final" in data:
        t_final = _number(data["t_final"], f"{source}: t_final")
        if t_final <= 0:
            raise SpecError(f"{source}: t_final must be > 0, got {t_final!r}")
    else:
        steps = data.get("steps", scene.steps)
        if steps < 0:
            raise SpecError(f"{source}: steps must be >= 0, got {steps}")
    # Every task runs in bounded memory (in chunks), but not in bounded time: refuse a step
    # count no one could wait for before any work, not after hours without a word.
    most = steps if t_final is None else max(t_final / h for h in hs)
    if most > MAX_STEPS:
        raise SpecError(f"{source}: " + (f"steps = {steps}" if t_final is None else
                                         f"t_final = {t_final:g} with h = {min(hs):g}")
                        + f" is {most:.3g} steps per trajectory, beyond the limit of {MAX_STEPS:.0e} (more than a "
                        "day even at 0.1 µs/step); take fewer steps, a larger h or a shorter t_final")

    params_t = data.get("params", {})
    known = scene.system.param_names
    unknown = sorted(set(params_t) - set(known))
    if unknown:
        raise SpecError(f"{source}: unknown parameter(s) {unknown} in [params]; the scene "
                        f"{scene.name!r} has parameters {list(known)}")
    # Scene order, not spec order: the task keys must not depend on how the TOML was written.
    params = tuple((k, _number_list(params_t[k], f"{source}: [params].{k}")) for k in known if k in params_t)

    initial = data.get("initial", {})
    _check_table(initial, _INITIAL, f"{source}: [initial]")
    count = initial.get("count", 0)
    if count < 0:
        raise SpecError(f"{source}: [initial].count must be >= 0, got {count}")
    spread = _number(initial.get("spread", 0.0), f"{source}: [initial].spread")
    if spread < 0:
        raise SpecError(f"{source}: [initial].spread must be >= 0, got {spread!r}")
    seed = initial.get("seed", 0)
    if seed < 0:
        raise SpecError(f"{source}: [initial].seed must be >= 0, got {seed}")
    batch = initial.get("batch", DEFAULT_BATCH)
    if batch < 1:
        raise SpecError(f"{source}: [initial].batch must be >= 1, got {batch}")

    _check_memory(len(scene.y0), len(methods) * len(hs) * math.prod(len(v) for _, v in params),
                  count, batch, source)

    return SweepSpec(scene=scene, scene_text=scene_text, methods=tuple(methods), h=hs, steps=steps,
                     t_final=t_final, params=params, count=count, spread=spread, seed=seed, batch=batch,
                     check_resolution=data.get("check_resolution", True))


def memory_estimate(state_size: int, combos: int, count: int, batch: int) -> int:
    """Bytes a sweep needs at once, roughly (an estimate to refuse impossible sizes, not a budget).

    The ensemble of initial states is built on the driver (the draw, the
    perturbed copy and a projection: 3 arrays of ``count × state`` doubles);
    every task and its row take a few kB; one task's working set is its
    integration chunk (≤ :data:`CHUNK_VALUES` doubles, a few copies) plus
    Newton's per-trajectory vectors and Jacobians.
    """
    n = max(count, 1)
    tasks = combos * -(-n // batch)
    per_traj = 8 * (10 * state_size + 4 * state_size ** 2)
    return 3 * 8 * n * state_size + 4096 * tasks + 4 * 8 * CHUNK_VALUES + 2 * min(batch, n) * per_traj


def _check_memory(state_size: int, combos: int, count: int, batch: int, source: str) -> None:
    limit = memory_limit()
    need = memory_estimate(state_size, combos, count, batch)
    if limit is not None and need > limit:
        raise SpecError(
            f"{source}: this sweep needs about {fmt_bytes(need)} of memory ({max(count, 1)} initial states "
            f"of {state_size} values, {combos} method/h/parameter combinations in batches of {batch}), more "
            f"than this machine has ({fmt_bytes(limit)}); reduce [initial].count or split the sweep")


def load_spec(path) -> SweepSpec:
    """Read and validate a sweep spec TOML file.

    Raises
    ------
    SpecError
        Missing/unreadable file, TOML syntax error, or invalid content.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"cannot read sweep spec {path}: {exc}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"{path}: invalid TOML: {exc}") from None
    return parse_spec(data, base=path.resolve().parent, source=str(path))


# --- tasks ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class ModuleSource:
    """A generated module as shipped to a worker.

    Attributes
    ----------
    method, signature : str
    path : str
        Where the driver has it (workers on the same machine load it from there).
    filename : str
        File name under the worker's cache when ``path`` is not usable there.
    source : str
        The complete file text (content-hash header included).
    """

    method: str
    signature: str
    path: str
    filename: str
    source: str


@dataclass(frozen=True)
class RefJob:
    """One reference solution: the unperturbed y0 of the scene with ``params`` up to time ``T``.

    ``y0`` (length 2d) is projected onto the constraint manifold of ``params``
    for constrained scenes, exactly as the tasks' states are.
    """

    key: str
    scene_text: str
    params: tuple[tuple[str, float], ...]
    y0: tuple[float, ...]
    T: float


@dataclass(frozen=True)
class Task:
    """One unit of work: a batch of trajectories for one (method, h, parameter values).

    Attributes
    ----------
    key : tuple
        ``(method, h, parameter values…, batch)``: rows are sorted by it.
    name : str
        Human-readable key, e.g. ``"midpoint h=0.01 k=1.5 batch=0"``.
    method : str
    h : float
        Step size as given in the spec.
    h_used : float
        The step size integrated with (``t_final / steps`` when the spec gives ``t_final``).
    steps : int
    params : tuple of (str, float)
        All parameter values (scene defaults overridden by the swept ones).
    swept : tuple of str
        Names of the swept parameters.
    batch : int
        Index of the batch within the ensemble.
    y0 : numpy.ndarray, shape (n, 2d)
        Initial states of the batch (n ≤ ``[initial].batch``), already projected
        onto the constraint manifold for constrained scenes.
    check_resolution : bool
    ref : str or None
        Key of the :class:`RefJob` whose result this task compares against.
    """

    key: tuple
    name: str
    method: str
    h: float
    h_used: float
    steps: int
    params: tuple[tuple[str, float], ...]
    swept: tuple[str, ...]
    batch: int
    y0: np.ndarray = field(compare=False)
    check_resolution: bool = True
    ref: str | None = None


@dataclass
class Plan:
    """Everything a sweep executes: the tasks, the modules they need and the reference jobs."""

    spec: SweepSpec
    tasks: list[Task]
    modules: dict[str, ModuleSource]
    refs: dict[str, RefJob]


def initial_states(spec: SweepSpec) -> np.ndarray:
    """The ensemble of initial states, shape (max(count, 1), 2d).

    ``count`` ≤ 1: the scene's y0 itself.  Otherwise ``count`` copies of y0
    plus independent N(0, spread²) perturbations of every component, drawn
    from ``numpy.random.default_rng(seed)`` — the same ensemble for every
    method, h and parameter value (common random numbers: differences between
    rows are the methods', not the draw's).
    """
    y0 = np.asarray(spec.scene.y0, dtype=float)
    if spec.count <= 1:
        return y0[None, :].copy()
    rng = np.random.default_rng(spec.seed)
    return y0 + spec.spread * rng.standard_normal((spec.count, y0.size))


def _fmt_value(v: float) -> str:
    return repr(float(v))


def plan_sweep(spec: SweepSpec) -> Plan:
    """Build (or reuse) the modules on the driver and expand the spec into tasks.

    Building here, before any worker is involved, turns an inapplicable
    method into an immediate :class:`~methodgen.errors.MethodNotApplicable`
    instead of one failed row per task, and lets workers skip the derivation.
    """
    from ..codegen.build import build, scene_module_path
    from ..codegen.emit import untagged
    from ..symbolic.schemes import composition_for, method_key

    scene = spec.scene
    modules: dict[str, ModuleSource] = {}
    built = {}
    # The scene's [run] order/composition: composed methods use their own modules (issue 14).
    comp = composition_for(scene.order, scene.composition)
    for method in spec.methods:
        module = built[method] = build(scene.system, method, path=scene_module_path(scene, method_key(method, comp)),
                                       order=scene.order, composition=scene.composition)
        path = Path(module.__file__)
        modules[method] = ModuleSource(method=method, signature=module.SIGNATURE, path=str(path),
                                       filename=f"{path.stem}_{module.SIGNATURE[:12]}.py",
                                       # Without the cache's key line: keys are per user.
                                       source=untagged(path.read_text(encoding="utf-8")))
    Y = initial_states(spec)
    projector = built[spec.methods[0]] if scene.system.constraints else None
    with_reference = spec.count <= 1
    names = [k for k, _ in spec.params]
    defaults = dict(scene.system.param_values)
    tasks: list[Task] = []
    refs: dict[str, RefJob] = {}
    for method, h, values in itertools.product(spec.methods, spec.h,
                                               itertools.product(*(v for _, v in spec.params))):
        if spec.t_final is not None:
            # ceil(t_final/h) steps of t_final/steps <= h, as `run --t-final` (limits.steps_for_time)
            steps, h_used = steps_for_time(spec.t_final, h, f"t_final = {spec.t_final:g}")
            T = spec.t_final
        else:
            steps, h_used = spec.steps, h
            T = h * steps
        full = {**defaults, **dict(zip(names, values))}
        params = tuple((k, full[k]) for k in scene.system.param_names)
        Yp = Y if projector is None else _project(projector, Y, full, names, values)
        ref_key = None
        if with_reference:
            ref_key = "ref " + " ".join(f"{k}={_fmt_value(v)}" for k, v in params) + f" T={_fmt_value(T)}"
            refs.setdefault(ref_key, RefJob(ref_key, spec.scene_text, params, tuple(map(float, Yp[0])), T))
        batches = [Yp[i:i + spec.batch] for i in range(0, len(Yp), spec.batch)]
        label = " ".join([method, f"h={_fmt_value(h)}"] + [f"{k}={_fmt_value(v)}" for k, v in zip(names, values)])
        for b, y0 in enumerate(batches):
            tasks.append(Task(key=(method, h, *values, b), name=f"{label} batch={b}", method=method, h=h,
                              h_used=h_used, steps=steps, params=params, swept=tuple(names), batch=b,
                              y0=y0, check_resolution=spec.check_resolution, ref=ref_key))
    return Plan(spec=spec, tasks=tasks, modules=modules, refs=refs)


def _project(module, Y: np.ndarray, params: dict, names, values) -> np.ndarray:
    """Initial states projected onto the constraint manifold of ``params``.

    Perturbed states, and y0 itself under other parameter values (another
    pendulum length), are off the manifold, where the constrained methods
    refuse to start.  Projecting once here gives every method the same states.
    """
    try:
        return module.project(Y, params)
    except ValueError as exc:
        where = ", ".join(f"{k} = {v!r}" for k, v in zip(names, values)) or "the scene's parameters"
        raise SpecError(f"the initial states cannot be projected onto the constraint manifold "
                        f"({where}): {exc}") from None


# --- worker side: these functions run wherever the engine puts them ------------------------

_MODULES: dict[str, Any] = {}
_MODULES_LOCK = threading.Lock()


def load_shipped_module(src: ModuleSource):
    """Import the generated module of ``src`` in this process (once per process).

    Uses the driver's file when it exists here and is intact with the right
    signature (workers on the driver's machine); otherwise writes the shipped
    source into this machine's cache (atomically, so workers sharing a cache
    do not race; tagged with this user's key) and imports that.
    """
    from ..codegen.emit import cache_dir, file_status, load_module, write_module

    with _MODULES_LOCK:  # threaded workers: import each module once
        module = _MODULES.get(src.signature)
        if module is None:
            path = Path(src.path)
            if file_status(path, src.signature) != "ok":
                path = cache_dir() / src.filename
                if file_status(path, src.signature) != "ok":
                    write_module(path, src.source)
            module = load_module(path, expected_signature=src.signature)   # checked on the bytes run
            _MODULES[src.signature] = module
        return module


def compute_reference(job: RefJob) -> dict:
    """Reference final state for ``job`` (:func:`methodgen.app.bench.reference`).

    Returns
    -------
    dict
        ``{"y": list of float (2d,), "kind": str}``.
    """
    from .bench import reference
    from ..symbolic.scene import parse_scene

    data = tomllib.loads(job.scene_text)
    data["params"] = dict(job.params)
    scene = parse_scene(data, f"scene {data.get('name')!r} (shipped)")
    ref = reference(scene.system, np.asarray(job.y0, dtype=float), job.T)
    return {"y": [float(v) for v in ref.y], "kind": ref.kind}


def _finite(x) -> float | None:
    """JSON has no inf/nan: a non-finite measurement is reported as null."""
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


class _Stats:
    """Running maxima of |I(t) - I(0)| per invariant (and constraint residuals) over a batch.

    Each is a :class:`~methodgen.app.stats.ErrorMax`: a NaN or ±inf is recorded with its step,
    never lost in the maximum (the builtin ``max(x, nan)`` returns ``x``).
    """

    def __init__(self, module, params: dict, Y0: np.ndarray):
        self.module, self.params = module, params
        self.inv0 = module.invariants(Y0, params)  # name -> (batch,)
        self.err = {name: ErrorMax() for name in module.INVARIANT_NAMES}
        self.constraint = ErrorMax() if hasattr(module, "constraint_residuals") else None

    def update(self, traj: np.ndarray, offset: int) -> None:
        """Fold in a trajectory piece of shape (n, batch, 2d) whose row 0 is after ``offset`` steps."""
        if not len(traj):
            return
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):  # tracked by ErrorMax
            inv = self.module.invariants(traj, self.params)
            for name, vals in inv.items():
                self.err.setdefault(name, ErrorMax()).update(vals - self.inv0[name], offset=offset)
            if self.constraint is not None:
                g, gv = self.module.constraint_residuals(traj, self.params)
                rows = len(traj)
                both = np.concatenate([np.reshape(g, (rows, -1)), np.reshape(gv, (rows, -1))], axis=1)
                self.constraint.update(both, offset=offset)

    def nonfinite(self) -> dict[str, int]:
        """``{name: first step}`` of every monitored quantity that stopped being a number."""
        out = {k: e.nonfinite_step for k, e in self.err.items() if not e.finite}
        if self.constraint is not None and not self.constraint.finite:
            out["constraints"] = self.constraint.nonfinite_step
        return out


def run_task(task: Task, src: ModuleSource, ref: dict | None = None) -> dict:
    """Integrate one task's batch and return its row (plain data).

    Parameters
    ----------
    task : Task
        ``task.y0`` has shape (batch, 2d).
    src : ModuleSource
        The generated module of ``task.method``.
    ref : dict, optional
        ``{"y": (2d,), "kind": str}`` from :func:`compute_reference`.

    Returns
    -------
    dict
        The row; ``status`` is ``"ok"`` or ``"numerical-error"`` (then ``error``
        holds the message and the measurements cover the steps before it).

    Raises
    ------
    Exception
        Anything non-numerical (a bug, a broken installation): the engine
        retries the task and reports it as failed.
    """
    module = load_shipped_module(src)
    params = dict(task.params)
    numerical = tuple(getattr(module, n) for n in _NUMERICAL)
    Y = np.array(task.y0, dtype=float)
    status, error = "ok", None
    n_traj, dim = Y.shape
    chunk = max(1, min(task.steps, CHUNK_VALUES // (n_traj * dim)))
    stats = _Stats(module, params, Y)
    iters: list[np.ndarray] = []
    info: dict = {}
    done = 0
    cpu = 0.0
    # One trajectory goes through the module's scalar path: the batched path has a fixed
    # cost per step (~0.5-1 ms) that only pays off from a few hundred trajectories.
    single = n_traj == 1
    while status == "ok" and done < task.steps:
        n = min(chunk, task.steps - done)
        # thread_time: the CPU of this task alone, also on a threaded worker running others.
        t0 = time.thread_time()
        try:
            # info carries the compensated-summation remainder from chunk to chunk, so
            # chunking does not change the result.
            part = module.integrate(Y[0] if single else Y, task.h_used, n, params, info=info,
                                    check_resolution=task.check_resolution)
        except numerical as exc:
            cpu += time.thread_time() - t0
            partial = getattr(exc, "trajectory", None)
            if partial is not None and len(partial):
                partial = np.asarray(partial).reshape(len(partial), n_traj, dim)
                stats.update(partial, offset=done)
                done += len(partial) - 1
                Y = partial[-1]
            status, error = "numerical-error", f"{type(exc).__name__}: {exc}"
            break
        cpu += time.thread_time() - t0
        part = part.reshape(n + 1, n_traj, dim)
        stats.update(part[1:], offset=done + 1)
        iters.append(np.asarray(info.get("newton_iterations", np.zeros(0))))
        Y = part[-1]
        done += n
    its = np.concatenate(iters) if iters else np.zeros(0)
    bad = stats.nonfinite()
    if bad and status == "ok":
        # The steps ran but their numbers are not numbers: a numerical error, never "ok" with 0.
        status = "numerical-error"
        error = "NonFiniteError: " + "; ".join(f"{k} is not finite at step {v}" for k, v in bad.items())
    final_error = None
    if ref is not None and status == "ok":
        final_error = float(np.max(np.abs(Y - np.asarray(ref["y"]))))
    swept = set(task.swept)
    # A run that failed before its first step measured nothing: null, not a perfect 0.
    measured = done > 0 or task.steps == 0
    return {
        "task": task.name,
        "status": status,
        "error": error,
        "method": task.method,
        "h": task.h,
        "h_used": task.h_used,
        "steps": task.steps,
        "steps_done": done,
        "t_final": task.h_used * task.steps,
        "params": {k: v for k, v in task.params if k in swept},
        "batch": task.batch,
        "trajectories": n_traj,
        "trajectory_steps": n_traj * done,
        # null when not measured or not a number (then "nonfinite" names the first step).
        "energy_error": _finite(stats.err["H"].value) if measured and "H" in stats.err else None,
        "invariant_errors": {k: _finite(e.value) if measured else None for k, e in stats.err.items()},
        "constraint_error": _finite(stats.constraint.value) if measured and stats.constraint else None,
        "nonfinite": bad or None,
        "final_error": _finite(final_error),
        "reference": ref["kind"] if ref is not None else None,
        "newton_mean": float(its.mean()) if its.size else None,
        "newton_max": int(its.max()) if its.size else None,
        "cpu_seconds": cpu,
    }


def failed_row(task: Task, exc: BaseException, attempts: int) -> dict:
    """The row of a task that failed ``attempts`` times: reported, never dropped."""
    return {"task": task.name, "status": "failed", "error": f"{type(exc).__name__}: {exc}",
            "attempts": attempts, "method": task.method, "h": task.h, "h_used": task.h_used,
            "steps": task.steps, "steps_done": 0, "t_final": task.h_used * task.steps,
            "params": {k: v for k, v in task.params if k in set(task.swept)}, "batch": task.batch,
            "trajectories": int(len(task.y0)), "trajectory_steps": 0, "energy_error": None,
            "invariant_errors": {}, "constraint_error": None, "nonfinite": None, "final_error": None,
            "reference": None,
            "newton_mean": None, "newton_max": None, "cpu_seconds": None}


# --- engines -------------------------------------------------------------------------------------

class _Progress:
    """tqdm when installed, else a one-line counter; only ever on stderr."""

    def __init__(self, total: int, enabled: bool):
        self.bar, self.enabled, self.total, self.done = None, enabled, total, 0
        if not enabled:
            return
        try:
            from tqdm import tqdm
        except ImportError:
            return
        self.bar = tqdm(total=total, desc="sweep", leave=False, file=sys.stderr)

    def step(self) -> None:
        self.done += 1
        if self.bar is not None:
            self.bar.update(1)
        elif self.enabled:
            print(f"\rsweep: {self.done}/{self.total} tasks", end="", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
        elif self.enabled:
            print(file=sys.stderr)


def _attempt(fn, retries: int):
    """Call ``fn`` up to ``retries + 1`` times; return ``(value, None)`` or ``(None, last exception)``."""
    exc = None
    for _ in range(retries + 1):
        try:
            return fn(), None
        except Exception as e:  # a task failure of any kind is reported as a row, not raised
            exc = e
    return None, exc


def _run_in_process(plan: Plan, retries: int, progress: _Progress) -> list[dict]:
    refs: dict[str, tuple] = {}
    rows = []
    for task in plan.tasks:
        ref, exc = None, None
        if task.ref is not None:
            if task.ref not in refs:
                refs[task.ref] = _attempt(lambda: compute_reference(plan.refs[task.ref]), retries)
            ref, exc = refs[task.ref]
        if exc is None:
            row, exc = _attempt(lambda: run_task(task, plan.modules[task.method], ref), retries)
        rows.append(row if exc is None else failed_row(task, exc, retries + 1))
        progress.step()
    return rows


def _import_distributed():
    try:
        import distributed
    except ImportError as exc:
        raise EngineError("--workers/--scheduler run on Dask, which is not installed "
                          f"({exc}); install it with: pip install 'methodgen[distributed]' "
                          "(or run the sweep in-process, without --workers/--scheduler)") from None
    return distributed


def _run_dask(plan: Plan, client, retries: int, progress: _Progress) -> list[dict]:
    """Submit every task (and reference) to ``client``; gather rows as they complete."""
    from distributed import as_completed

    run_id = uuid.uuid4().hex[:12]  # unique keys: other sweeps may share the scheduler
    # Each module's source goes to a worker once, not once per task.
    sources = {m: client.scatter(src, hash=False) for m, src in plan.modules.items()}
    ref_futs = {k: client.submit(compute_reference, job, key=f"methodgen-ref-{run_id}-{i}",
                                 retries=retries, pure=False)
                for i, (k, job) in enumerate(plan.refs.items())}
    futures = {}
    for i, task in enumerate(plan.tasks):
        fut = client.submit(run_task, task, sources[task.method],
                            ref_futs[task.ref] if task.ref is not None else None,
                            key=f"methodgen-sweep-{run_id}-{i}", retries=retries, pure=False)
        futures[fut] = task
    rows = []
    try:
        for fut in as_completed(list(futures)):
            task = futures[fut]
            if fut.status == "finished":
                rows.append(fut.result())
            else:
                # An exception in the task (after its retries), in its reference, or a
                # worker lost too often (KilledWorker): a reported row.
                rows.append(failed_row(task, fut.exception(), retries + 1))
            progress.step()
    finally:
        client.cancel(list(futures) + list(ref_futs.values()) + list(sources.values()))
    return rows


def _summarize(plan: Plan, rows: list[dict], engine: dict, wall: float, setup: float) -> dict:
    order = {t.name: t.key for t in plan.tasks}
    rows.sort(key=lambda r: order[r["task"]])
    steps = sum(r["trajectory_steps"] for r in rows)
    return {
        "scene": plan.spec.scene.name,
        "spec": plan.spec.to_dict(),
        "engine": engine,
        "tasks": len(rows),
        "ok": sum(r["status"] == "ok" for r in rows),
        "numerical_errors": sum(r["status"] == "numerical-error" for r in rows),
        "failed": sum(r["status"] == "failed" for r in rows),
        "trajectory_steps": steps,
        "cpu_seconds": sum(r["cpu_seconds"] or 0.0 for r in rows),
        "setup_seconds": setup,
        "wall_seconds": wall,
        "trajectory_steps_per_second": steps / wall if wall > 0 else None,
        "rows": rows,
    }


def run_sweep(spec, scheduler: str | None = None, workers: int | None = None, retries: int = 2,
              *, progress: bool = False) -> dict:
    """Run a sweep and return its report.

    Parameters
    ----------
    spec : SweepSpec, mapping or path-like
        A validated spec, a parsed spec document, or a spec TOML file.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    workers : int, optional
        Start a local Dask cluster of this many single-threaded worker processes.
        Without ``scheduler`` and ``workers`` the sweep runs in this process
        (Dask is not imported).  A script that starts a local cluster needs the
        ``if __name__ == "__main__":`` guard (worker processes are spawned).
    retries : int
        How often a failed task is re-run before it is reported as failed.
    progress : bool
        Show progress on stderr (only when stderr is a terminal).

    Returns
    -------
    dict
        ``scene``, ``spec`` (normalised), ``engine``, counts (``tasks``, ``ok``,
        ``numerical_errors``, ``failed``), ``trajectory_steps``,
        ``cpu_seconds`` (sum over tasks), ``setup_seconds`` (module build and
        cluster start), ``wall_seconds`` (execution), ``trajectory_steps_per_second``
        and ``rows`` (one dict per task, sorted by the task key
        ``(method, h, parameter values, batch)``).

    Raises
    ------
    SpecError, SceneError, MethodNotApplicable
        Invalid spec.
    EngineError
        Dask not installed, both ``scheduler`` and ``workers``, or the scheduler unreachable.
    """
    if scheduler is not None and workers is not None:
        raise EngineError("give either a scheduler address or a number of workers, not both")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise EngineError(f"workers must be a positive integer, got {workers!r}")
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise EngineError(f"retries must be a non-negative integer, got {retries!r}")
    if not isinstance(spec, SweepSpec):
        spec = parse_spec(spec) if isinstance(spec, Mapping) else load_spec(spec)
    # Fail on a missing dask before the (possibly long) module generation.
    distributed = _import_distributed() if (scheduler or workers) else None
    t0 = time.perf_counter()
    plan = plan_sweep(spec)
    bar = _Progress(len(plan.tasks), progress and sys.stderr.isatty())
    try:
        if distributed is None:
            engine = {"kind": "in-process", "workers": 1, "scheduler": None}
            setup = time.perf_counter() - t0
            t1 = time.perf_counter()
            rows = _run_in_process(plan, retries, bar)
            return _summarize(plan, rows, engine, time.perf_counter() - t1, setup)
        if workers is not None:
            # Processes, one thread each: the integration loops are Python (GIL-bound), so
            # threads would not run tasks in parallel.
            cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                               dashboard_address=None, worker_dashboard_address=None)
            engine = {"kind": "local-cluster", "workers": workers, "scheduler": cluster.scheduler_address}
        else:
            cluster = None
            engine = {"kind": "scheduler", "workers": None, "scheduler": scheduler}
        try:
            try:
                # Connect timeout: Dask's distributed.comm.timeouts.connect (default 30 s).
                client = distributed.Client(cluster if cluster is not None else scheduler)
            except (OSError, TimeoutError) as exc:
                raise EngineError(f"cannot connect to the Dask scheduler at {scheduler}: {exc}") from None
            with client:
                if cluster is None:
                    engine["workers"] = len(client.scheduler_info().get("workers", {}))
                setup = time.perf_counter() - t0
                t1 = time.perf_counter()
                rows = _run_dask(plan, client, retries, bar)
                wall = time.perf_counter() - t1
        finally:
            if cluster is not None:
                cluster.close()
        return _summarize(plan, rows, engine, wall, setup)
    finally:
        bar.close()


# --- output ---------------------------------------------------------------------------------------

def rows_to_csv(report: dict) -> str:
    """The report's rows as CSV text: one line per task, nested values flattened.

    Columns: the row's scalar fields, ``param_<name>`` per swept parameter and
    ``inv_<name>`` per monitored invariant (max abs error); empty cells for None.
    """
    rows = report["rows"]
    params = list(report["spec"]["params"])
    invs = sorted({k for r in rows for k in r["invariant_errors"]})
    head = ["task", "status", "method", "h", "h_used", "steps", "steps_done", "t_final"]
    head += [f"param_{k}" for k in params]
    head += ["batch", "trajectories", "trajectory_steps", "energy_error"]
    head += [f"inv_{k}" for k in invs]
    head += ["constraint_error", "final_error", "reference", "newton_mean", "newton_max", "cpu_seconds",
             "attempts", "error"]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(head)
    for r in rows:
        flat = {**r, **{f"param_{k}": r["params"].get(k) for k in params},
                **{f"inv_{k}": r["invariant_errors"].get(k) for k in invs}}
        # repr keeps every digit of a float (CSV consumers get the exact numbers).
        w.writerow(["" if flat.get(c) is None else (repr(flat[c]) if isinstance(flat[c], float) else flat[c])
                    for c in head])
    return buf.getvalue()
