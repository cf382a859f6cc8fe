"""``methodgen run SCENE``: integrate a scene and report its invariants, Newton
statistics and timing (:func:`run_scene` is the report as a dict)."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ...codegen.build import build, scene_module_path
from ...codegen.emit import BACKENDS
from ...errors import InputError
from ..limits import check_memory, check_steps, steps_for_time
from ...codegen.progress import about, phase
from ..._version import __version__
from ...runtime.trajfile import check_suffix, open_writer, require_h5py
from ...symbolic.scene import check_g_positive, load_scene
from ...symbolic.compositions import PROCESSED_FAMILIES
from ...symbolic.schemes import METHODS, composition_for, method_key, scheme_options
from ...symbolic.nbody import FAMILIES as WH_FAMILIES
from ..stats import ErrorMax
from .common import (EXIT_INPUT, EXIT_NUMERICAL, NUMERICAL_ERRORS, add_order_args, add_resolution_arg, add_variant_args,
                     apply_overrides, check_output_file, refuse_for_splitting, cli_advice, dump_json, effective_stages, finite_or_none, parse_params, parse_y0, positive_int,
                     print_note, resolve_order, section_lines, resolve_stages, resolve_time_transform, step_size,
                     transformed_context)


def _check_splitting_args(method, order, composition, stages, extended, scene) -> None:
    """Refuse what a Wisdom–Holman splitting does not take (one line naming the option)."""
    refuse_for_splitting(method, order=order, composition=composition, stages=stages, extended=extended)
    if scene.transformed is not None:
        raise InputError(f"the Wisdom–Holman splitting {method} integrates the [nbody] Hamiltonian itself, "
                         "not a time transformation of it (pass --time-transform none)")


class RunFailure(Exception):
    """A run stopped early; carries the report so far and the saved file."""

    def __init__(self, exc: BaseException, report: dict, saved: Path | None, code: int,
                 saved_rows: int | None = None, note: str | None = None):
        super().__init__(str(exc))
        self.exc, self.report, self.saved, self.code = exc, report, saved, code
        self.saved_rows, self.note = saved_rows, note


def _invariant_stats(module, traj, acc: dict | None, offset: int = 0, params: dict | None = None,
                     stride: int = 1, last: int | None = None) -> dict:
    """Update the running max errors of every monitored invariant with ``traj`` (rows of states).

    ``acc`` maps each name to ``{"initial", "final", "error"}``, ``error`` an
    :class:`~methodgen.app.stats.ErrorMax` (NaN never disappears into the maximum: the
    first step at which an invariant is not finite is recorded, to be reported as
    null with a status).  ``offset`` is the step index of ``traj[0]``, ``stride`` the
    steps between rows (``--save-every``: the maxima are then over the kept states), ``last``
    the step of the last row (``min(i·k, steps)``: a step is never reported past it).
    """
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # NaN is tracked below
        inv = module.invariants(traj) if params is None else module.invariants(traj, params)
    acc = {} if acc is None else acc
    for name in module.INVARIANT_NAMES:
        vals = np.asarray(inv[name], dtype=float).reshape(len(traj), -1)
        if name not in acc:
            acc[name] = {"initial": float(vals[0, 0]) if vals.size else math.nan, "error": ErrorMax()}
        entry = acc[name]
        if len(vals):
            with np.errstate(invalid="ignore", over="ignore"):
                entry["error"].update(vals - entry["initial"], offset=offset, stride=stride, last=last)
            entry["final"] = float(vals[-1, 0])
    return acc


def _time_transform_report(scene, module, h, y_final, steps_done, report_inv) -> dict | None:
    """``{"g", "t0", "t_final", "tau_final", "H_phys_max_abs_error"}`` of a time-transformed run, else None.

    ``t_final`` is the physical time reached (the state's t), ``tau_final = h * steps``
    the fictive time; ``H_phys`` is the original Hamiltonian (on K = 0, H = −e).
    """
    tt = getattr(module, "TIME_TRANSFORM", None)
    if not tt or _time_dependent(scene):
        return None
    t_end = float(y_final[list(module.STATE_NAMES).index(tt["time"])])
    h_phys = report_inv.get("H_phys") or {}
    if tt.get("form") == "log":
        return {"g": tt["g"], "form": "log", "t0": getattr(scene, "t0", 0.0), "t_final": t_end,
                "tau_final": h * steps_done, "H_phys_max_abs_error": h_phys.get("max_abs_error")}
    return {"g": getattr(scene, "time_transform", None) or tt["g"], "t0": getattr(scene, "t0", 0.0),
            "t_final": t_end, "tau_final": h * steps_done, "H_phys_max_abs_error": h_phys.get("max_abs_error")}


def _time_dependent(scene) -> bool:
    """The scene's H depends on its declared time and is integrated as K = H + e (no time transformation)."""
    return getattr(scene.system, "time", None) is not None and getattr(scene, "transformed", None) is None


def _time_dependent_report(scene, module, y_final) -> dict | None:
    """``{"time", "energy", "K", "t0", "t_final", "state_names", "y_final"}`` of a run of a
    time-dependent H (integrated as K = H + e on (q, t; p, e)), else None; the last two are the
    extended state (the report's own ``y_final`` is in the original variables)."""
    tt = getattr(module, "TIME_TRANSFORM", None)
    if not tt or not _time_dependent(scene):
        return None
    names = list(module.STATE_NAMES)
    return {"time": tt["time"], "energy": tt["energy"], "K": str(getattr(module, "HAMILTONIAN", "")),
            "t0": scene.t0, "t_final": float(y_final[names.index(tt["time"])]),
            "state_names": names, "y_final": [float(v) for v in y_final]}


def _claim(module, name: str) -> dict:
    """What the method promises for a monitored quantity (from the module's TRAITS):
    ``"exact"`` (kept to round-off; ``methodgen verify`` proves it), ``"approximate"`` (kept
    to a stated approximation error) or ``"monitored"`` (no promise)."""
    traits = getattr(module, "TRAITS", {}) or {}
    if name in traits.get("preserved", ()):
        return {"claim": "exact"}
    if name in traits.get("approximate", ()):
        return {"claim": "approximate"}
    return {"claim": "monitored"}


#: An invariant whose initial value is below this times the state's scale starts at 0.
_ZERO_SCALE = 1e-12


def _report(scene, method, h, steps, module, y_final, inv_acc, its, seconds, steps_done, params=None,
            stages=None) -> dict:
    report_inv = {}
    problems = []
    # the state's scale: an invariant whose start is at round-off level of it "starts at 0"
    scale = max([1.0] + [abs(float(v)) for v in y_final if math.isfinite(float(v))])
    for name, v in (inv_acc or {}).items():
        init, abs_err, bad = v["initial"], v["error"].finite_max, v["error"].nonfinite_step
        if bad is not None:
            # Not a number: reported as null with the reason, never as an error of 0.
            before = v["error"].finite_before
            report_inv[name] = {"initial": init, "final": v.get("final", init), "max_abs_error": None,
                                "max_rel_error": None, "status": "non-finite", "first_nonfinite_step": bad}
            if before is not None:
                # --save-every: only kept states are seen; it became non-finite in (before, bad].
                report_inv[name]["last_finite_step"] = before
            problems.append(f"{name} is not finite at step {bad}"
                            + (f" ({name}(y0) = {init})" if bad == 0 else "")
                            + (f" (the first kept state where it is not; it was finite at step {before}, the "
                               "states between are not kept)" if before is not None else ""))
            continue
        if abs(init) <= _ZERO_SCALE * scale:
            # A quantity that starts at 0 (total momentum at rest, a constraint): no relative
            # error -- only the absolute one means something (shown as "—", null in --json).
            rel = None
        else:
            rel = finite_or_none(abs_err / abs(init))
        report_inv[name] = {"initial": init, "final": v.get("final", init), "max_abs_error": abs_err,
                            "max_rel_error": rel, "status": "ok", **_claim(module, name)}
    y_final = [float(v) for v in y_final]
    if not all(math.isfinite(v) for v in y_final):
        problems.append("the final state is not finite")
    tt = _time_transform_report(scene, module, h, y_final, steps_done, report_inv)
    td = _time_dependent_report(scene, module, y_final)
    names = list(module.STATE_NAMES)
    if td is not None:   # states in the original variables (q then p, like y0), the time apart
        y_final = [v for n, v in zip(names, y_final) if n not in (td["time"], td["energy"])]
        names = [n for n in names if n not in (td["time"], td["energy"])]
    return {
        "scene": scene.name,
        "method": method,
        "order": int(getattr(module, "ORDER", 2)),
        "composition": getattr(module, "COMPOSITION", None),   # {family, order, stages} or None
        "stages": stages,                                      # gauss / energy-collocation, else None
        # {g, t0, t_final (physical), tau_final (fictive), H_phys_max_abs_error} or None
        "time_transform": tt,
        # time-dependent H: {time, energy, K, t0, t_final, state_names, y_final (extended)} or None
        "time_dependent": td,
        "status": "non-finite" if problems else "ok",
        "status_detail": "; ".join(problems) or None,
        "h": h,
        "steps": steps,
        "steps_done": steps_done,
        # The physical time reached: h * steps, or with a time transformation or a time-dependent H
        # the state's t (from t0).
        "t0": getattr(scene, "t0", 0.0),
        "t_final": td["t_final"] if td is not None else h * steps_done if tt is None else tt["t_final"],
        "y0": list(scene.y0),
        "params": dict(scene.system.param_values) if params is None else dict(params),
        "y_final": y_final,
        "state_names": names,
        "invariants": report_inv,
        "newton": {"mean_iterations": its.mean,
                   "max_iterations": its.max,
                   # a projected method's iterations are its projection's (Φ_h evaluations)
                   "solver": "projection" if getattr(module, "PROJECTED", None)
                   else getattr(module, "DEFAULT_SOLVER", None)},
        "seconds": seconds,
        "us_per_step": seconds / steps_done * 1e6 if steps_done else 0.0,
        "module": str(getattr(module, "__file__", "")),
        "backend": getattr(module, "BACKEND", "numpy"),
        # the names of a module's Solution (mod.solve), for the same facts
        "success": not problems,
        "message": "; ".join(problems) if problems else f"{steps_done} steps of h = {h!r}",
        "nsteps": steps_done,
        "invariant_errors": {name: v.get("max_abs_error") for name, v in report_inv.items()},
    }


class _Iterations:
    """Mean and maximum of the Newton iterations per step, chunk after chunk (8 bytes a step
    would not fit in memory over a long run; the module's per-chunk array is dropped)."""

    def __init__(self):
        self.count, self.total, self.max = 0, 0, 0

    def add(self, iterations) -> None:
        its = np.asarray(iterations)
        if its.size:
            self.count += int(its.size)
            self.total += int(its.sum())
            self.max = max(self.max, int(its.max()))

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else 0.0


def _check_size(scene, steps: int, h: float, t_final, every: int, save, chunk, plot=None) -> None:
    """Refuse, before any work, a run beyond :data:`~methodgen.app.limits.MAX_STEPS` or whose
    states kept at once do not fit in memory (all of them without ``--save``, one chunk with it;
    all of them again with ``--plot``, which draws the whole trajectory read back from the file)."""
    what = (f"--t-final {t_final:g} with h = {h:g}" if t_final is not None and steps != scene.steps
            else f"--steps {steps}")
    check_steps(steps, what)
    width = len(scene.run_system.y)
    at_once = min(steps, chunk or steps) if save and not plot else steps
    # the states kept (8 bytes a value) and the module's per-step iteration counts of a chunk
    need = 8 * (at_once // every + 2) * width + 8 * min(steps, chunk or steps)
    if plot and save:
        hint = "--plot draws every kept state (read back from the file): pass --save-every K to keep fewer"
    elif save:
        hint = "pass --chunk N to write the states N steps at a time"
    else:
        hint = ("pass --save FILE.npz --chunk N to write them in chunks"
                + (", or --save-every K to keep fewer" if every == 1 else ""))
    check_memory(need, f"{what} holds {at_once // every + 1:.3g} states of {width} values and "
                       f"{min(steps, chunk or steps):.3g} steps' Newton counts at once", hint)


def run_scene(scene_name: str, method: str | None = None, h: float | None = None,
              steps: int | None = None, save: str | None = None, chunk: int | None = None,
              interrupted_path: str | None = None, plot: str | None = None,
              backend: str = "numpy", extended: bool = False, y0=None, params: dict | None = None,
              t_final: float | None = None, order=None, composition: str | None = None,
              stages=None, time_transform: str | None = None, save_every: int | None = None,
              check_resolution: bool = True, section: str | None = None) -> dict:
    """Run a scene and return the report dictionary (the ``--json`` object).

    With ``save`` the trajectory is written in chunks of ``chunk`` steps (memory stays
    bounded) to an ``.npz``, or with ``save`` = ``FILE.h5`` to an HDF5 file of the open
    format ``methodgen-trajectory`` 1 (:mod:`methodgen.runtime.trajfile`; needs h5py).  If the run is interrupted (Ctrl-C)
    or fails numerically, the states computed so far are saved — to ``save`` or
    to ``interrupted_path`` — and :class:`RunFailure` is raised.  If writing
    fails (disk full), every chunk written before is kept as a readable file
    and :class:`RunFailure` says where.  With ``plot``
    the run is drawn (phase portrait, invariant errors, constraint residuals).
    With ``extended`` each step is refined in extended precision
    (``integrate(..., extended=True)``: round-off that follows Brouwer's law).
    ``y0``, ``params`` ({name: value}) and ``t_final`` override the scene's initial
    state, parameter values (passed to the module at run time: nothing is
    re-derived) and final time: with ``h``, ``steps = ⌈(t_final − t0)/h⌉`` and
    ``h = (t_final − t0)/steps`` (ends at ``t_final`` exactly with a step no larger than the one
    given, reported as ``h_requested`` when it differs; :func:`methodgen.app.limits.steps_for_time`,
    the rule of a sweep's ``t_final`` too); the sign of ``h`` must be that of ``t_final − t0``
    (t0: a time-dependent H's, else 0).
    ``order`` (2, 4, 6, 8, 10) and ``composition`` (a family) override the scene's
    ``[run] order``/``composition`` (:func:`resolve_order`): above 2 the method is
    composed symmetrically, its own module (and cache file) is used.
    ``stages`` overrides ``[run] stages`` (gauss, energy-collocation: :func:`resolve_stages`).
    ``time_transform`` (text of g(q); ``"none"``: none) overrides ``[run] time_transform``:
    the run integrates K = g(q)(H + e) from ``initial_state(y0)`` (y0 in the original
    variables), ``h``/``steps`` in fictive time; ``t_final`` (a physical time) is then
    refused, and the report's ``t_final`` is the physical time reached.
    ``save_every`` = k keeps every k-th state (and the last): what ``save`` writes, what is
    plotted and what the invariant errors are the maximum over (``integrate(..., save_every=k)``).
    ``t_final`` with ``steps`` (and no ``h``) takes ``h = (t_final − t0) / steps``.
    ``check_resolution=False`` (``--no-check-resolution``) passes the same to the module's
    ``integrate``: no refusal of a step size estimated to under-resolve the motion.
    ``section`` (``"x = 0, px > 0"``): the run is a Poincaré section instead (every crossing in
    the ``steps`` steps, located on the method's own map: :func:`methodgen.runtime.events.poincare`);
    the report says how many, their largest |g| and the invariants' errors at them, and
    ``plot`` draws them.
    Refused before any work (:class:`InputError`): more than :data:`~methodgen.app.limits.MAX_STEPS`
    steps, or more states kept at once than fit in half the machine's memory.
    """
    if extended and backend != "numpy":
        raise InputError("--extended needs the numpy backend (the compiled backend is float64 only)")
    if save is not None:
        save = str(check_output_file(save, "--save"))
        if check_suffix(save, "--save") == "hdf5":   # .npz or .h5, else refused before any work
            require_h5py()                            # a missing h5py too
    if interrupted_path is not None and check_suffix(interrupted_path, "interrupted_path") == "hdf5":
        require_h5py()
    if plot is not None:
        # Checked like --save, before any work: a missing folder is not created, a folder or an
        # empty name is refused (an empty --plot used to be ignored, a folder failed after the run).
        plot = str(check_output_file(plot, "--plot"))
        from ..plots import check_available
        check_available()  # a missing matplotlib is reported before the run, not after
    scene = resolve_time_transform(load_scene(scene_name), time_transform)
    method = method or scene.method
    splitting = method in WH_FAMILIES
    if section is not None and (splitting or save is not None or extended):
        raise InputError("--section runs a generated module's solve(): not with a Wisdom–Holman splitting, "
                         "--save or --extended")
    if splitting:
        # Wisdom–Holman: its own runtime (methodgen.runtime.nbody), no generated module
        _check_splitting_args(method, order, composition, stages, extended, scene)
        order, composition, options = 2, None, {}
    elif method not in METHODS:
        raise InputError(f"unknown method {method!r}; known methods: {', '.join(METHODS)}; for an [nbody] "
                         f"scene also the Wisdom–Holman splittings: {', '.join(WH_FAMILIES)}")
    else:
        order, composition = resolve_order(scene, order, composition)
        options = scene.options(method, resolve_stages(scene, [method], stages))
    # a processed composition is three modules in the cache (methodgen.symbolic.processing), no one scheme
    processed = composition in PROCESSED_FAMILIES
    key = (method if splitting else
           method_key(method, None, scheme_options(method, options)) + f"-order{order}-{composition}"
           if processed else method_key(method, composition_for(order, composition), scheme_options(method, options)))
    h_given = h is not None
    h = scene.h if h is None else h
    h_requested = None   # --h when --t-final rounds it to whole steps
    scene, params = apply_overrides(scene, y0, params)
    if t_final is not None:
        if scene.transformed is not None:
            # the log form's g is -1/U ("g = log" read as a formula)
            what = ("the logarithmic Hamiltonian (time transformation \"log\", dt = dτ/(-U(q)))"
                    if scene.time_transform == "log" else
                    f"the time transformation g = {scene.time_transform} (dt = g(q) dτ)")
            raise InputError(f"--t-final is a physical time, but with {what} h and steps are in fictive "
                             "time τ (the physical time is known only after the run); give --steps instead "
                             "— the report gives the physical time reached (the API's "
                             "methodgen.runtime.physical_time.run_to_time lands on a physical time)")
        if not math.isfinite(t_final):
            raise InputError(f"--t-final must be a finite time, got {t_final!r}")
        # The time to run: from t0 (a time-dependent H's declared start, else 0) to T.
        t_start = scene.t0 if _time_dependent(scene) else 0.0
        span = t_final - t_start
        if span == 0:
            raise InputError(f"--t-final {t_final:g} is the start time t0 = {t_start:g}: nothing to run")
        if steps is not None:
            # h = (T - t0)/N, as numpy.linspace(t0, T, N + 1) spaces the times.
            if h_given:
                raise InputError("give two of --h, --steps, --t-final, not all three (with --t-final T "
                                 "--steps N, h = (T - t0)/N)")
            if steps < 1:
                raise InputError(f"--steps must be at least 1 with --t-final, got {steps}")
            h = span / steps
        else:
            # steps = ceil((T - t0)/h), h_used = (T - t0)/steps: ends at T exactly (limits.steps_for_time,
            # the rule a sweep's t_final follows too); the h asked for is reported as h_requested.
            h_requested = h
            steps, h = steps_for_time(span, h, f"--t-final {t_final:g}"
                                      + (f" from t0 = {t_start:g}" if t_start else ""))
        t_final = span   # the time run (for the size check's message)
    steps = scene.steps if steps is None else steps
    every = 1 if save_every is None else int(save_every)
    if isinstance(save_every, bool) or every < 1:
        raise InputError(f"--save-every must be a positive integer, got {save_every!r}")
    _check_size(scene, steps, h, t_final, every, save, chunk, plot)
    system = scene.run_system
    if scene.transformed is not None:
        check_g_positive(system, scene.y0, params)
    if splitting:
        from ...runtime.nbody import wisdom_holman
        module = wisdom_holman(scene, method, params=params)
        params = None    # the masses are the integrator's constants (checked against these values)
    else:
        with transformed_context(scene):
            module = build(system, method, path=None if processed else scene_module_path(scene, key, backend, system=system),
                           backend=backend, order=order, composition=composition, **options)
    if extended and getattr(module, "PROJECTED", None):
        # the projected loop has no long-double refinement (integrate() refuses extended=True)
        raise InputError(f"--extended is not available for a projected method ({method}): its "
                         f"solve keeps {', '.join(module.PROJECTED)} to round-off in double; "
                         "run it without --extended")
    if extended and module.EXTENDED_BITS <= 53:
        raise InputError(f"--extended needs a long double wider than double; numpy.longdouble has "
                         f"{module.EXTENDED_BITS} bits on this platform")
    y = np.array(scene.y0)
    if getattr(module, "TIME_TRANSFORM", None):
        y = module.initial_state(y, scene.t0, params)   # the extended state on K = 0 (e = -H(y0, t0))
    n_stages = effective_stages(method, options)
    if getattr(module, "BACKEND", "numpy") == "numba":
        # Compile (or load from the machine-code cache) before the timed region.
        try:
            # about the module: its line names it, and the estimate is the last compile of that module
            with about(Path(module.__file__).name), phase("compile"):
                module.step(y, h, params)
        except (RuntimeError, FloatingPointError, ValueError):
            pass
    if section is not None:
        return _run_section(scene, module, method, order, composition, backend, y, h, steps, params, section, plot,
                            check_resolution)
    chunk = steps if not chunk else chunk
    # chunks end on kept steps, so chunk after chunk the rows stay every-th states
    chunk = -(-chunk // every) * every
    stride = {} if every == 1 else {"save_every": every}
    writer = None
    meta = dict(scene=scene.name, method=method, order=order, composition=composition or "", h=h,
                state_names=list(module.STATE_NAMES),
                # g(q) of a time transformation ("" without): the states are then extended,
                # (q, t, p, e), their column t the physical time; h is a fictive step.
                time_transform=scene.time_transform or "",
                # what the rows cover after a failure or a kill (methodgen.runtime.runio.extent)
                steps=steps, time_column=(getattr(module, "TIME_TRANSFORM", None) or {}).get("time", ""),
                methodgen_version=__version__)
    # provenance: what was integrated, by which module, and what the method claims
    for name, attr in (("hamiltonian", "HAMILTONIAN"), ("signature", "SIGNATURE")):
        if isinstance(getattr(module, attr, None), str):
            meta[name] = getattr(module, attr)
    if isinstance(getattr(module, "TRAITS", None), dict):
        meta["claims"] = json.dumps(module.TRAITS, default=str)
    if n_stages is not None:
        meta["stages"] = n_stages
    if every > 1:
        meta["save_every"] = every   # row i is the state after min(i * save_every, steps) steps
    kept: list[np.ndarray] = []
    inv_acc = None
    its = _Iterations()   # a running summary: the counts of a long run do not fit in memory
    done = 0
    seconds = 0.0
    first = True
    # One info dict through all chunks (as the module's iterate() does): each call starts
    # from the compensation and solver state the one before left, so chunking does not
    # change the result.
    info: dict = {}
    if save:
        # A path that cannot be written is a StorageError here (exit 2), before any work.
        writer = open_writer(save, meta=meta)
        for note in writer.recovered:
            print_note(note)
    try:
        while first or done < steps:
            n = min(chunk, steps - done)
            t0 = time.perf_counter()
            try:
                part = module.integrate(y, h, n, params, info=info, extended=extended,
                                        check_resolution=check_resolution, **stride)
            finally:
                seconds += time.perf_counter() - t0
            rows = part if first else part[1:]
            inv_acc = _invariant_stats(module, part, inv_acc, offset=done, params=params, stride=every,
                                       last=done + n)
            its.add(info.get("newton_iterations", ()))
            if writer is not None:
                writer.append(rows)
            elif save is None:
                kept.append(rows)
            y = part[-1]
            done += n
            first = False
    except BaseException as exc:
        partial = getattr(exc, "trajectory", None)
        numeric = type(exc).__name__ in NUMERICAL_ERRORS
        if numeric and done and isinstance(getattr(exc, "step", None), int):
            # The module names the step within this chunk (--chunk): name the run's step.
            step = exc.step
            exc.step = done + step
            exc.args = (str(exc).replace(f"at step {step}", f"at step {done + step}", 1),) + exc.args[1:]
        # A failed write of the --save file (disk full): keep what is on disk, say where.
        io_fault = isinstance(exc, OSError) and writer is not None and writer.failed is not None
        if not (numeric or io_fault or isinstance(exc, KeyboardInterrupt)):
            if writer is not None:
                writer.abort()
            raise
        if io_fault:
            rows = np.zeros((0,) + y.shape)
        elif partial is not None and len(partial):
            rows = partial if first else partial[1:]
            inv_acc = _invariant_stats(module, partial, inv_acc, offset=done, params=params, stride=every)
            done += (len(partial) - 1) * every   # the last kept state is the one reported
            y = partial[-1]
        else:
            rows = np.zeros((0,) + y.shape)
        if inv_acc is None:  # failed before a chunk was done (e.g. y0 outside the domain of H)
            inv_acc = _invariant_stats(module, np.asarray(y, dtype=float)[None], None, offset=done,
                                       params=params)
        target = writer
        note = None
        if target is None and (interrupted_path or isinstance(exc, KeyboardInterrupt)):
            try:
                target = open_writer(interrupted_path or f"{scene.name}_{key}_partial.npz".replace("-", "_"),
                                     meta=meta)
                for k in kept:
                    target.append(k)
            except (OSError, InputError) as wexc:  # the partial file cannot be written: say so, keep the report
                note = f"the computed states were not saved: {wexc}"
                if target is not None and target.failed is None:
                    target.abort()
                    target = None
        saved = saved_rows = None
        if target is not None:
            try:
                if len(rows):
                    target.append(rows)
            except OSError:
                pass  # target.failed is set: close() keeps the complete chunks
            try:
                saved_rows = target.saved_rows
                saved = target.close(complete=False,   # steps_done, t_final: what the rows cover
                                     reason="write-error" if io_fault else type(exc).__name__)
            except OSError as cexc:
                note, saved_rows = str(cexc), None
        rep = _report(scene, method, h, steps, module, y, inv_acc, its, seconds, done, params, stages=n_stages)
        code = (130 if isinstance(exc, KeyboardInterrupt)
                else EXIT_INPUT if getattr(exc, "initial_state", False) else EXIT_NUMERICAL)
        raise RunFailure(exc, rep, saved, code, saved_rows, note) from None
    rep = _report(scene, method, h, steps, module, y, inv_acc, its, seconds, done, params, stages=n_stages)
    if h_requested is not None and h_requested != h:
        rep["h_requested"] = h_requested   # --t-final T --h H: h = (T - t0)/ceil((T - t0)/H) ends at T
    if every > 1:
        rep["save_every"] = every   # invariant errors are maxima over the kept states
    if writer is not None:
        complete = rep["status"] == "ok"
        rep["saved"] = str(writer.close(steps_done=done, complete=complete,
                                        reason="complete" if complete else "non-finite"))
    if plot:
        from ..plots import plot_run
        if writer is not None:
            from ...runtime.trajfile import load_trajectory
            traj, _ = load_trajectory(rep["saved"])
        else:
            traj = np.concatenate(kept)
        cons = module.constraint_residuals(traj) if hasattr(module, "constraint_residuals") else None
        rep["plot"] = str(plot_run(module, traj, plot, scene_name=scene.name, method=key, h=h * every,
                                   constraint_residuals=cons))
    return rep


def _num(x, spec: str, width: int) -> str:
    if x is not None and math.isfinite(x):
        return format(x, f"{width}{spec}")
    return format("nan" if x is None else str(x), f">{width}")


def _order_text(rep: dict) -> str:
    comp = rep.get("composition")
    order = f"order {rep.get('order')}"
    return f"{order} ({comp['family']} composition, {comp['stages']} stages)" if comp else order


def _print_run(rep: dict) -> None:
    tt, td = rep.get("time_transform"), rep.get("time_dependent")
    method = rep["method"] + (f" ({rep['stages']} stages)" if rep.get("stages") is not None else "")
    t0 = rep.get("t0", 0.0)
    span = (f"(t = {t0:g} .. {_num(rep['t_final'], 'g', 1)})" if tt is None else
            f"(fictive τ = 0 .. {tt['tau_final']:g}, physical t = {t0:g} .. {_num(tt['t_final'], 'g', 1)})")
    print(f"scene {rep['scene']}  method {method}  {_order_text(rep)}  h = {rep['h']:g}  "
          f"steps = {rep['steps']}  {span}")
    if tt is not None and tt.get("form") == "log":
        print(f"time transformation on: logarithmic Hamiltonian; integrates Λ = log(T + e) - log(-U) (the H "
              f"row below is -Λ), h and steps in fictive time τ, dt = g dτ with g = {tt['g']}; physical time "
              f"reached t = {_num(tt['t_final'], '.10g', 1)}")
    elif tt is not None:
        print(f"time transformation on: g = {tt['g']}; integrates K = g(q)(H + e) (the H row below), "
              f"h and steps in fictive time τ, dt = g dτ; physical time reached t = "
              f"{_num(tt['t_final'], '.10g', 1)}")
    if td is not None:
        t, e = td["time"], td["energy"]
        print(f"time-dependent H: integrates K = H + {e} on the extended phase space ({t} a coordinate, "
              f"{e} its momentum; the H row below is K); H_phys is H(q, p, {t}) along the run (not "
              f"conserved: dH/d{t} = ∂H/∂{t}; H_phys = -{e} where K = 0)")
    print(f"module: {rep['module']}")
    print(f"{'invariant':>10} {'initial':>22} {'final':>22} {'max abs error':>14} {'max rel error':>14}")
    for name, v in rep["invariants"].items():
        if v.get("status") == "non-finite":
            err_s = f"{'non-finite':>14}"
            rel_s = f"{'-':>14}"
        else:
            err_s = f"{v['max_abs_error']:14.3e}"
            rel = v["max_rel_error"]
            rel_s = f"{rel:14.3e}" if rel is not None else f"{'—':>14}"   # starts at 0: no relative error
        print(f"{name:>10} {_num(v['initial'], '.15g', 22)} {_num(v['final'], '.15g', 22)} {err_s} {rel_s}")
    if tt is not None:
        err = tt.get("H_phys_max_abs_error")
        print(f"max |ΔH_phys| = {_num(err, '.3e', 1)}  (H_phys: the original energy H(q, p); on K = 0, "
              "H_phys = -e)")
    nw = rep["newton"]
    stages = f" ({rep['composition']['stages']} stages)" if rep.get("composition") else ""
    # "auto" iterates the fixed point and runs Newton's method only where that is slow.
    what = ("solver iterations (auto: fixed point, Newton where it contracts slowly)"
            if nw.get("solver") == "auto" else
            "symmetric projection iterations (each one base step)" if nw.get("solver") == "projection"
            else "Newton iterations")
    print(f"{what} per step{stages}: mean {nw['mean_iterations']:.2f}, max {nw['max_iterations']}")
    print(f"wall time {rep['seconds']:.3f} s, {rep['us_per_step']:.2f} µs/step")
    names = rep["state_names"]
    print("y_final: " + ", ".join(f"{n}={v:.15g}" for n, v in zip(names, rep["y_final"]))
          + (f"; {td['time']}={_num(td['t_final'], '.15g', 1)}" if td is not None else ""))


def _run_section(scene, module, method, order, composition, backend, y, h, steps, params, text, plot,
                 check_resolution) -> dict:
    """The Poincaré section of ``run --section``: every crossing within ``steps`` steps."""
    from ...runtime.events import poincare, section_event

    section_event(module, text, params=params)       # a bad section is refused before the run
    t0 = time.perf_counter()
    t, pts, sol = poincare(module, y, h, text, crossings=None, t_max=steps * abs(h), params=params,
                           check_resolution=check_resolution)
    seconds = time.perf_counter() - t0
    g = section_event(module, text, params=params)
    inv0 = {k: float(v) for k, v in module.invariants(np.asarray(y, dtype=float), params).items()}
    errs = {}
    if len(pts):
        at = module.invariants(pts, params)
        errs = {k: float(np.max(np.abs(at[k] - inv0[k]))) for k in inv0}
    rep = dict(scene=scene.name, method=method, order=order, composition=composition, backend=backend, h=sol.h,
               steps=steps, steps_done=int(sol.nsteps), nsteps=int(sol.nsteps), section=text, crossings=int(len(pts)),
               status="ok" if sol.status >= 0 else "numerical-error", success=sol.status >= 0, message=sol.message,
               seconds=seconds, max_abs_g=float(np.max(np.abs(g(t, pts)))) if len(pts) else None,
               invariant_errors_at_crossings=errs, state_names=list(module.STATE_NAMES),
               t_events=t.tolist(), y_events=pts.tolist())
    if plot is not None:
        from ..plots import section_figure
        fig = section_figure(pts, list(module.STATE_NAMES), text, title=f"{scene.name}, {method}, h = {sol.h:g}")
        fig.savefig(plot)
        rep["plot"] = plot
    if sol.status < 0:
        raise InputError(f"the section run stopped: {sol.message}")
    return rep


def _cli_overrides(args):
    """--y0 and --param validated against the scene (one-line errors naming the bad item)."""
    if args.y0 is None and not args.param:
        return None, None
    scene = load_scene(args.scene)
    y0 = parse_y0(args.y0, len(scene.y0)) if args.y0 is not None else None
    params = parse_params(args.param, list(scene.system.param_values)) or None
    return y0, params


def cmd_run(args) -> int:
    from ..lattice_scene import is_lattice_scene
    from ..particles_scene import is_particles_scene

    if is_lattice_scene(args.scene):
        from . import lattice
        return lattice.run(args)
    if is_particles_scene(args.scene):
        from . import particles
        return particles.run(args)
    try:
        y0, params = _cli_overrides(args)
        rep = run_scene(args.scene, args.method, args.h, args.steps, save=args.save, chunk=args.chunk,
                        plot=args.plot, backend=args.backend, extended=args.extended, y0=y0,
                        params=params, t_final=args.t_final, order=args.order,
                        composition=args.composition, stages=args.stages,
                        time_transform=args.time_transform, save_every=args.save_every,
                        check_resolution=args.check_resolution, section=args.section)
    except RunFailure as fail:
        what = "interrupted" if fail.code == 130 else "stopped"
        if fail.saved:
            n = fail.saved_rows if fail.saved_rows is not None else fail.report["steps_done"] + 1
            where = f"; saved {n} states to {fail.saved}"
        else:
            where = f"; {fail.note}" if fail.note else ""
        msg = cli_advice(fail.exc) or type(fail.exc).__name__  # one line, whatever the text
        print(f"methodgen: {what} at step {fail.report['steps_done']}: {msg}{where}", file=sys.stderr)
        if args.json:
            status = ("interrupted" if fail.code == 130 else "io-error" if isinstance(fail.exc, OSError)
                      else "non-finite" if type(fail.exc).__name__ == "NonFiniteError" else "numerical-error")
            print(dump_json({**fail.report, "status": status, "error": str(fail.exc), "success": False,
                             "message": str(fail.exc), "saved": str(fail.saved) if fail.saved else None}))
        return fail.code
    if args.json:
        print(dump_json(rep))
    elif "section" in rep:
        print("\n".join(section_lines(rep)))
        return 0
    else:
        _print_run(rep)
        if "saved" in rep:
            print(f"trajectory saved to {rep['saved']}")
        if "plot" in rep:
            print(f"plot written to {rep['plot']}")
    if rep["status"] != "ok":
        # The run finished but its numbers are not numbers: never a silent success.
        print(f"methodgen: error: the run left the domain of the Hamiltonian: {rep['status_detail']}",
              file=sys.stderr)
        return EXIT_NUMERICAL
    return 0


def add_parser(sub) -> None:
    """Register ``run`` on ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser("run", help="run a scene and report invariants, Newton statistics and timing")
    p.add_argument("scene", help="built-in scene name or path to a scene TOML file")
    p.add_argument("--method", help="method (default: the scene's first method)")
    add_order_args(p)
    add_variant_args(p, "run")
    p.add_argument("--h", type=step_size, help="step size (default: the scene's)")
    p.add_argument("--steps", type=positive_int, help="number of steps (default: the scene's)")
    p.add_argument("--t-final", type=float, metavar="T",
                   help="final time: with --h H, steps = ceil((T - t0)/H) of h = (T - t0)/steps <= H, ending "
                        "at T (the report gives h and h_requested; H must have the sign of T - t0, t0 = 0 "
                        "unless H depends on time); with --steps N, h = (T - t0)/N (as numpy.linspace); not with a time transformation (its steps are in "
                        "fictive time)")
    add_resolution_arg(p)
    p.add_argument("--y0", metavar="V1,V2,...", help="initial state, q then p (default: the scene's)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="parameter value for this run (repeatable; passed at run time, nothing re-derived)")
    p.add_argument("--plot", metavar="FILE", help="draw phase portrait, invariant errors (log scale) and "
                                                  "constraint residuals to FILE (.png/.svg/.pdf; needs methodgen[plot])")
    p.add_argument("--backend", choices=BACKENDS, default="numpy",
                   help="numpy, or numba: compiled integration loop (needs methodgen[fast] or llvmlite alone; "
                        "compiled once, cached on disk)")
    p.add_argument("--extended", action="store_true",
                   help="refine each step in extended precision (long double): removes the small "
                        "systematic round-off drift of long runs (Brouwer's law); slower")
    p.add_argument("--save", metavar="FILE.npz|FILE.h5",
                   help="write the trajectory in chunks to an .npz, or to an .h5: HDF5 of the open format "
                        "methodgen-trajectory 1, read by h5py, netCDF4 and xarray (needs methodgen[hdf5])")
    p.add_argument("--chunk", type=positive_int, metavar="N",
                   help="with --save: steps per chunk (memory stays bounded; default: one chunk)")
    p.add_argument("--save-every", type=positive_int, metavar="K",
                   help="keep every K-th state (and the last): what --save writes and --plot draws; the "
                        "invariant errors are then maxima over the kept states (default 1)")
    p.add_argument("--section", metavar="'X = 0, PX > 0'",
                   help="a Poincaré section instead of the trajectory: every crossing of the surface "
                        "(lhs = rhs, and an optional side) in --steps steps, each located on the method's "
                        "own map; --plot draws them")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    # (a lattice scene refuses the options it does not take: those that differ from these)
    p.set_defaults(func=cmd_run, defaults_of=lambda scene: vars(p.parse_args([scene])))
