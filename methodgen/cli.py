"""Command line: ``methodgen run | generate | scenes | methods``.

Every command that reports numbers takes ``--json`` and then prints exactly one
JSON object on stdout and nothing else there (never ``NaN``/``Infinity``: a
value that is not a number is ``null``, with a ``status`` saying why).  Errors a
user can cause print one line ``methodgen: error: …`` on stderr and exit
non-zero, without a traceback: 2 for bad input (including a path that cannot be
used: missing folder, no permission, a file in the way, an untrusted cache), 3
for a numerical failure (Newton did not converge, non-finite state or
invariant) or a fault of the running system (disk full), 1 for a failed
``generate --check``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from . import __version__
from .build import build, generated_dir, scene_module_path, scene_system_name, scene_targets, target_key
from .emit import BACKENDS, emit_source, file_status, module_filename, signature, write_atomic
from .errors import BAD_PATH_ERRNOS, InputError, MethodgenError, MethodNotApplicable, StorageError
from .scene import check_g_positive, check_order, check_stages, load_scene, scene_names, with_time_transform
from .progress import phase, stderr_reporting
from .runio import ChunkWriter
from .schemes import METHODS, SYMMETRIC_METHODS, composition_for, discretize, method_key, scheme_options

EXIT_INPUT = 2
EXIT_NUMERICAL = 3


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse's own errors: usage + exit 2, no traceback
        self.print_usage(sys.stderr)
        self.exit(EXIT_INPUT, f"methodgen: error: {message}\n")


def _finite_or_none(x: float):
    x = float(x)
    return x if math.isfinite(x) else None


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {v}")
    return v


def _step(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if v == 0 or not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"h must be finite and non-zero, got {text}")
    return v


# --- run -----------------------------------------------------------------------

class RunFailure(Exception):
    """A run stopped early; carries the report so far and the saved file."""

    def __init__(self, exc: BaseException, report: dict, saved: Path | None, code: int,
                 saved_rows: int | None = None, note: str | None = None):
        super().__init__(str(exc))
        self.exc, self.report, self.saved, self.code = exc, report, saved, code
        self.saved_rows, self.note = saved_rows, note


def json_clean(obj):
    """``obj`` with every NaN/±inf float replaced by None (JSON has neither; ``allow_nan=False`` holds).

    The reports say *why* a value is null in a ``status`` field next to it.
    """
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_clean(v) for v in obj]
    if isinstance(obj, np.generic):
        return json_clean(obj.item())
    if isinstance(obj, np.ndarray):
        return json_clean(obj.tolist())
    if isinstance(obj, Path):
        return str(obj)
    return obj


def _json_default(x):
    """Anything else that is a number (as ``default=float`` used to accept), finite or null."""
    return _finite_or_none(x)


def dump_json(obj) -> str:
    """One JSON object: non-finite numbers become null, never ``NaN``/``Infinity``."""
    return json.dumps(json_clean(obj), allow_nan=False, default=_json_default)


def _invariant_stats(module, traj, acc: dict | None, offset: int = 0, params: dict | None = None,
                     stride: int = 1) -> dict:
    """Update running max errors of every monitored invariant with ``traj`` (rows of states).

    ``offset`` is the step index of ``traj[0]``, ``stride`` the steps between rows (``--save-every``:
    the maxima are then over the kept states).  NaN never disappears into a
    maximum (the builtin ``max(x, nan)`` returns x): the first step at which
    an invariant is not finite is recorded, and the maximum is taken over the
    finite values only, to be reported as null with a status.
    """
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # NaN is tracked below
        inv = module.invariants(traj) if params is None else module.invariants(traj, params)
    acc = {} if acc is None else acc
    for name in module.INVARIANT_NAMES:
        vals = np.asarray(inv[name], dtype=float).reshape(len(traj), -1)
        if name not in acc:
            acc[name] = {"initial": float(vals[0, 0]) if vals.size else math.nan, "max_abs_error": 0.0,
                         "nonfinite_step": None}
        entry = acc[name]
        if len(vals):
            err = np.abs(vals - entry["initial"])
            bad = ~np.isfinite(err).all(axis=1)
            if bad.any() and entry["nonfinite_step"] is None:
                entry["nonfinite_step"] = offset + stride * int(np.argmax(bad))
            good = err[~bad]
            if good.size:
                entry["max_abs_error"] = max(entry["max_abs_error"], float(good.max()))
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
        init, abs_err, bad = v["initial"], v["max_abs_error"], v.get("nonfinite_step")
        if bad is not None:
            # Not a number: reported as null with the reason, never as an error of 0.
            report_inv[name] = {"initial": init, "final": v.get("final", init), "max_abs_error": None,
                                "max_rel_error": None, "status": "non-finite", "first_nonfinite_step": bad}
            problems.append(f"{name} is not finite at step {bad}"
                            + (f" ({name}(y0) = {init})" if bad == 0 else ""))
            continue
        if abs(init) <= _ZERO_SCALE * scale:
            # A quantity that starts at 0 (total momentum at rest, a constraint): no relative
            # error -- only the absolute one means something (shown as "—", null in --json).
            rel = None
        else:
            rel = _finite_or_none(abs_err / abs(init))
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
        "newton": {"mean_iterations": float(its.mean()) if its.size else 0.0,
                   "max_iterations": int(its.max()) if its.size else 0,
                   "solver": getattr(module, "DEFAULT_SOLVER", None)},
        "seconds": seconds,
        "us_per_step": seconds / steps_done * 1e6 if steps_done else 0.0,
        "module": str(getattr(module, "__file__", "")),
        "backend": getattr(module, "BACKEND", "numpy"),
    }


_NUMERICAL = ("ConvergenceError", "NonFiniteError", "ResolutionError")


def _note(text: str) -> None:
    print(f"methodgen: note: {text}", file=sys.stderr)


def _finite(text: str, what: str) -> float:
    """A real number from command-line text (float(), never eval), finite."""
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise InputError(f"{what}: {text!r} is not finite")
    return v


def parse_y0(text: str, n: int) -> list[float]:
    """``"v1,v2,..."`` → n finite floats (q then p)."""
    parts = [t.strip() for t in text.split(",")]
    if len(parts) != n:
        raise InputError(f"--y0 needs {n} comma-separated values (q then p), got {len(parts)}")
    return [_finite(t, f"--y0 entry {i + 1}") for i, t in enumerate(parts)]


def parse_params(items, names) -> dict[str, float]:
    """``["NAME=VALUE", ...]`` → {name: value}; unknown names and bad values are errors."""
    out: dict[str, float] = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise InputError(f"--param {item!r}: expected NAME=VALUE")
        if name not in names:
            valid = ", ".join(names) or "none"
            raise InputError(f"--param {name!r}: unknown parameter; this scene has: {valid}")
        out[name] = _finite(value.strip(), f"--param {name}")
    return out


def _overrides(scene, y0, params):
    """The scene with ``y0`` replaced, and the full parameter dict to pass at run time."""
    import dataclasses
    if y0 is not None:
        y0 = [float(v) for v in y0]
        if len(y0) != len(scene.y0) or not all(math.isfinite(v) for v in y0):
            raise InputError(f"y0 needs {len(scene.y0)} finite values (q then p), got {y0}")
        scene = dataclasses.replace(scene, y0=tuple(y0))
    values = dict(scene.system.param_values)
    for name, v in (params or {}).items():
        if name not in values:
            raise InputError(f"unknown parameter {name!r}; this scene has: {', '.join(values) or 'none'}")
        values[name] = float(v)
    return scene, (values if params else None)


def _steps_for(t_final: float, h: float) -> int:
    if not (math.isfinite(t_final) and t_final > 0):
        raise InputError(f"--t-final must be a positive finite time, got {t_final!r}")
    steps = t_final / abs(h)
    n = round(steps)
    if abs(steps - n) > 1e-9 * max(1.0, steps):
        n = math.ceil(steps)   # the last step ends at or just after t_final; the report says where
    return max(1, int(n))


def resolve_order(scene, order=None, composition=None) -> tuple[int, str | None]:
    """``(order, family or None)`` of a run: ``--order``/``--composition`` over the scene's ``[run]``.

    ``order`` may be the command-line text (read with ``int()``, never evaluated).
    An ``order`` other than the scene's drops the scene's family (the new order's
    default is used unless ``composition`` is given).  Invalid values are an
    :class:`InputError` naming the value and listing the valid ones.
    """
    if order is not None and not isinstance(order, int):
        try:
            order = int(str(order).strip())
        except ValueError:
            pass  # check_order names the text and the valid orders
    if order is None:
        order = scene.order
    if composition is None and order == scene.order:
        composition = scene.composition
    return check_order(order, composition, order_name="--order", composition_name="--composition")


def resolve_stages(scene, methods, stages=None) -> int | None:
    """``--stages`` (command-line text, read with ``int()``, never evaluated) over the scene's
    ``[run] stages``, validated for ``methods`` (:func:`methodgen.scene.check_stages`:
    a one-line :class:`InputError` naming the value and what is valid)."""
    if stages is None:
        return scene.stages
    if not isinstance(stages, int):
        try:
            stages = int(str(stages).strip())
        except ValueError:
            pass  # check_stages names the text and the valid values
    return check_stages(stages, methods, name="--stages")


def resolve_time_transform(scene, g=None):
    """The scene with ``--time-transform G`` over its ``[run] time_transform`` (``none``: without)."""
    return scene if g is None else with_time_transform(scene, g, name="--time-transform")


@contextlib.contextmanager
def transformed_context(scene):
    """A method that does not apply to a time-transformed system says so: it was asked for K."""
    try:
        yield
    except MethodNotApplicable as exc:
        if scene.transformed is None:
            raise
        raise MethodNotApplicable(f"with the time transformation g = {scene.time_transform} the system is "
                                  f"K = g(q)(H + e): {exc}") from None


def effective_stages(method: str, options: dict) -> int | None:
    """The number of stages a run of ``method`` uses (its default unless ``options`` say), or None."""
    mod = METHODS.get(method)
    if mod is None or not hasattr(mod, "STAGES"):
        return None
    return int(options.get("stages", mod.DEFAULT_STAGES))


def run_scene(scene_name: str, method: str | None = None, h: float | None = None,
              steps: int | None = None, save: str | None = None, chunk: int | None = None,
              interrupted_path: str | None = None, plot: str | None = None,
              backend: str = "numpy", extended: bool = False, y0=None, params: dict | None = None,
              t_final: float | None = None, order=None, composition: str | None = None,
              stages=None, time_transform: str | None = None, save_every: int | None = None) -> dict:
    """Run a scene and return the report dictionary (the ``--json`` object).

    With ``save`` the trajectory is written to an ``.npz`` in chunks of
    ``chunk`` steps (memory stays bounded).  If the run is interrupted (Ctrl-C)
    or fails numerically, the states computed so far are saved — to ``save`` or
    to ``interrupted_path`` — and :class:`RunFailure` is raised.  If writing
    fails (disk full), every chunk written before is kept as a readable file
    and :class:`RunFailure` says where.  With ``plot``
    the run is drawn (phase portrait, invariant errors, constraint residuals).
    With ``extended`` each step is refined in extended precision
    (``integrate(..., extended=True)``: round-off that follows Brouwer's law).
    ``y0``, ``params`` ({name: value}) and ``t_final`` override the scene's initial
    state, parameter values (passed to the module at run time: nothing is
    re-derived) and final time (``steps = round(t_final / h)``; not with ``steps``).
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
    """
    if extended and backend != "numpy":
        raise InputError("--extended needs the numpy backend (numba has no long double)")
    if plot:
        from .plots import check_available
        check_available()  # a missing matplotlib is reported before the run, not after
    scene = resolve_time_transform(load_scene(scene_name), time_transform)
    method = method or scene.method
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; known methods: {', '.join(METHODS)}")
    order, composition = resolve_order(scene, order, composition)
    options = scene.options(method, resolve_stages(scene, [method], stages))
    key = method_key(method, composition_for(order, composition), scheme_options(method, options))
    h = scene.h if h is None else h
    scene, params = _overrides(scene, y0, params)
    if t_final is not None:
        if steps is not None:
            raise InputError("give either --steps or --t-final, not both")
        if scene.transformed is not None:
            raise InputError(f"--t-final is a physical time, but with the time transformation g = "
                             f"{scene.time_transform} h and steps are in fictive time τ (dt = g(q) dτ: the "
                             "physical time is known only after the run); give --steps instead — the "
                             "report gives the physical time reached")
        if _time_dependent(scene):
            if not (math.isfinite(t_final) and t_final > scene.t0):
                raise InputError(f"--t-final is the final time of the time-dependent H; it must be after "
                                 f"t0 = {scene.t0:g}, got {t_final!r}")
            t_final = t_final - scene.t0
        steps = _steps_for(t_final, h)
    steps = scene.steps if steps is None else steps
    system = scene.run_system
    if scene.transformed is not None:
        check_g_positive(system, scene.y0, params)
    with transformed_context(scene):
        module = build(system, method, path=scene_module_path(scene, key, backend, system=system),
                       backend=backend, order=order, composition=composition, **options)
    if extended and module.EXTENDED_BITS <= 53:
        raise InputError(f"--extended needs a long double wider than double; numpy.longdouble has "
                         f"{module.EXTENDED_BITS} bits on this platform")
    y = np.array(scene.y0)
    if getattr(module, "TIME_TRANSFORM", None):
        y = module.initial_state(y, scene.t0, params)   # the extended state on K = 0 (e = -H(y0, t0))
    n_stages = effective_stages(method, options)
    if getattr(module, "BACKEND", "numpy") == "numba":
        # Compile (or load from numba's disk cache) before the timed region.
        try:
            with phase("compile"):
                module.step(y, h, params)
        except (RuntimeError, FloatingPointError, ValueError):
            pass
    every = 1 if save_every is None else int(save_every)
    if isinstance(save_every, bool) or every < 1:
        raise InputError(f"--save-every must be a positive integer, got {save_every!r}")
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
                # what the rows cover after a failure or a kill (methodgen.runio.extent)
                steps=steps, time_column=(getattr(module, "TIME_TRANSFORM", None) or {}).get("time", ""))
    if n_stages is not None:
        meta["stages"] = n_stages
    if every > 1:
        meta["save_every"] = every   # row i is the state after min(i * save_every, steps) steps
    kept: list[np.ndarray] = []
    inv_acc = None
    its_all: list[np.ndarray] = []
    done = 0
    seconds = 0.0
    first = True
    # One info dict through all chunks (as the module's iterate() does): each call starts
    # from the compensation and solver state the one before left, so chunking does not
    # change the result.
    info: dict = {}
    if save:
        # A path that cannot be written is a StorageError here (exit 2), before any work.
        writer = ChunkWriter(save, meta=meta)
        for note in writer.recovered:
            _note(note)
    try:
        while first or done < steps:
            n = min(chunk, steps - done)
            t0 = time.perf_counter()
            try:
                part = module.integrate(y, h, n, params, info=info, extended=extended, **stride)
            finally:
                seconds += time.perf_counter() - t0
            rows = part if first else part[1:]
            inv_acc = _invariant_stats(module, part, inv_acc, offset=done, params=params, stride=every)
            its_all.append(info.get("newton_iterations", np.zeros(0)))
            if writer is not None:
                writer.append(rows)
            elif save is None:
                kept.append(rows)
            y = part[-1]
            done += n
            first = False
    except BaseException as exc:
        partial = getattr(exc, "trajectory", None)
        numeric = type(exc).__name__ in _NUMERICAL
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
                target = ChunkWriter(interrupted_path or f"{scene.name}_{key}_partial.npz".replace("-", "_"),
                                     meta=meta)
                for k in kept:
                    target.append(k)
            except OSError as wexc:  # the partial file cannot be written: say so, keep the report
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
        its = np.concatenate(its_all) if its_all else np.zeros(0)
        rep = _report(scene, method, h, steps, module, y, inv_acc, its, seconds, done, params, stages=n_stages)
        code = 130 if isinstance(exc, KeyboardInterrupt) else EXIT_NUMERICAL
        raise RunFailure(exc, rep, saved, code, saved_rows, note) from None
    its = np.concatenate(its_all) if its_all else np.zeros(0)
    rep = _report(scene, method, h, steps, module, y, inv_acc, its, seconds, done, params, stages=n_stages)
    if every > 1:
        rep["save_every"] = every   # invariant errors are maxima over the kept states
    if writer is not None:
        complete = rep["status"] == "ok"
        rep["saved"] = str(writer.close(steps_done=done, complete=complete,
                                        reason="complete" if complete else "non-finite"))
    if plot:
        from .plots import plot_run
        if writer is not None:
            from .runio import load_trajectory
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
    if tt is not None:
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
            if nw.get("solver") == "auto" else "Newton iterations")
    print(f"{what} per step{stages}: mean {nw['mean_iterations']:.2f}, max {nw['max_iterations']}")
    print(f"wall time {rep['seconds']:.3f} s, {rep['us_per_step']:.2f} µs/step")
    names = rep["state_names"]
    print("y_final: " + ", ".join(f"{n}={v:.15g}" for n, v in zip(names, rep["y_final"]))
          + (f"; {td['time']}={_num(td['t_final'], '.15g', 1)}" if td is not None else ""))


def _cli_overrides(args):
    """--y0 and --param validated against the scene (one-line errors naming the bad item)."""
    if args.y0 is None and not args.param:
        return None, None
    scene = load_scene(args.scene)
    y0 = parse_y0(args.y0, len(scene.y0)) if args.y0 is not None else None
    params = parse_params(args.param, list(scene.system.param_values)) or None
    return y0, params


def cmd_run(args) -> int:
    try:
        y0, params = _cli_overrides(args)
        rep = run_scene(args.scene, args.method, args.h, args.steps, save=args.save, chunk=args.chunk,
                        plot=args.plot, backend=args.backend, extended=args.extended, y0=y0,
                        params=params, t_final=args.t_final, order=args.order,
                        composition=args.composition, stages=args.stages,
                        time_transform=args.time_transform, save_every=args.save_every)
    except RunFailure as fail:
        what = "interrupted" if fail.code == 130 else "stopped"
        if fail.saved:
            n = fail.saved_rows if fail.saved_rows is not None else fail.report["steps_done"] + 1
            where = f"; saved {n} states to {fail.saved}"
        else:
            where = f"; {fail.note}" if fail.note else ""
        msg = " ".join(str(fail.exc).split()) or type(fail.exc).__name__  # one line, whatever the text
        print(f"methodgen: {what} at step {fail.report['steps_done']}: {msg}{where}", file=sys.stderr)
        if args.json:
            status = ("interrupted" if fail.code == 130 else "io-error" if isinstance(fail.exc, OSError)
                      else "non-finite" if type(fail.exc).__name__ == "NonFiniteError" else "numerical-error")
            print(dump_json({**fail.report, "status": status, "error": str(fail.exc),
                             "saved": str(fail.saved) if fail.saved else None}))
        return fail.code
    if args.json:
        print(dump_json(rep))
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


# --- generate ------------------------------------------------------------------

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
    from .compositions import FAMILIES

    out = {}
    for name in names or scene_names():
        scene = load_scene(name)
        for method in scene.methods:
            for family, orders in FAMILIES.items():
                for o in orders:
                    opts = scene.options(method)
                    key = target_key(method, o, family, opts)
                    out[module_filename(scene_system_name(scene), key, backend)] = (scene, method, o, family,
                                                                                    opts, True)
    return out


def cmd_generate(args) -> int:
    if args.backend != "numpy" and not args.out:
        raise InputError("generated/ holds the numpy modules only; pass --out DIR with --backend numba")
    out = Path(args.out) if args.out else generated_dir()
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
        with transformed_context(scene):
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


# --- bench ----------------------------------------------------------------------------

def _fmt(x, spec=".2e"):
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def _print_bench(rep: dict) -> None:
    wp = rep.get("work_precision")
    if wp:
        print(f"work-precision on {wp['scene']}, t = 0 .. {wp['T']:g}; reference: {wp['reference']}")
        for note in wp.get("notes", []):  # bench --peers: a peer missing or not applicable
            print(f"  note: {note}")
        w = max([28] + [len(str(r["method"])) for r in wp["rows"]])  # composed rows: "em o10 (family)"
        print(f"{'method':<{w}} {'h / tol':>9} {'steps':>7} {'CPU s':>9} {'error':>10} {'energy err':>10} "
              f"{'rel. dE':>9} {'inv/constr':>10} {'Newton':>6}")
        for r in wp["rows"]:
            if "failed" in r:
                print(f"{r['method']:<{w}} {r.get('h', r.get('tol', 0)):9.3g}  failed: {r['failed'][:60]}")
                continue
            par = r.get("h", r.get("tol"))
            others = [v for k, v in r["invariant_errors"].items() if k != "H"]
            if "constraint_error" in r:
                others.append(r["constraint_error"])
            print(f"{r['method']:<{w}} {par:9.3g} {r['steps']:7d} {r['seconds']:9.4f} {_fmt(r['error']):>10} "
                  f"{_fmt(r['energy_error']):>10} {_fmt(r.get('energy_rel_error'), '.1e'):>9} "
                  f"{_fmt(max(others) if others else None):>10} {_fmt(r.get('newton_mean'), '.2f'):>6}")
        tg = wp.get("targets")
        if tg:  # bench --peers: the cheapest run of each method at the issue-14 targets
            print(f"\ncheapest run with final error <= {tg['error']:g} and rel. dE <= {tg['energy_rel_error']:g}:")
            for r in tg["best"] or []:
                par = r.get("h", r.get("tol"))
                print(f"  {r['method']:<{w}} {par:9.3g} {r['seconds']:9.4f} s  error {_fmt(r['error'])}  "
                      f"rel. dE {_fmt(r.get('energy_rel_error'), '.1e')}")
            if not tg["best"]:
                print("  (none)")
            for name, r in (("heyoka tol 1e-15", tg.get("heyoka")), ("IAS15 eps 1e-9", tg.get("ias15"))):
                if r:
                    print(f"  for comparison, {name}: {r['seconds']:.4f} s, error {_fmt(r['error'])}, "
                          f"rel. dE {_fmt(r.get('energy_rel_error'), '.1e')}")
    sv = rep.get("solvers")
    if sv:
        print(f"\nnonlinear solvers on {sv['scene']} (h = {sv['h']:g}, {sv['steps']} steps)")
        print(f"{'method':<18} {'solver':<12} {'iterations':>10} {'µs/step':>9} {'energy err':>10}")
        for r in sv["rows"]:
            if "failed" in r:
                print(f"{r['method']:<18} {r['solver']:<12} failed: {r['failed'][:70]}")
            else:
                print(f"{r['method']:<18} {r['solver']:<12} {r['mean_iterations']:10.2f} {r['us_per_step']:9.1f} "
                      f"{_fmt(r['max_energy_error']):>10}")
    lr = rep.get("long")
    if lr:
        print(f"\nlong run on {lr['scene']}: {lr['steps']} steps of h = {lr['h']:g} (t = 0 .. {lr['T']:g})")
        print(f"{'method':<28} {'CPU s':>9} {'max energy err':>14} {'growth exponent':>16}")
        for r in lr["rows"]:
            print(f"{r['method']:<28} {r['seconds']:9.2f} {_fmt(r['max_energy_error']):>14} "
                  f"{_fmt(r['growth_exponent'], '.2f'):>16}")
    br = rep.get("brouwer")
    if br:
        print(f"\nBrouwer's law: harmonic oscillator, midpoint, h = {br['h']:g}, {br['ensemble']} random "
              f"phases, {br['steps']} steps")
        if br.get("note"):
            print(f"  note: {br['note']}")
        for r in br["rows"]:
            print(f"  {r['stepper']:<62} RMS energy error slope {r['slope']:.2f} "
                  f"(final {r['rms_energy_error'][-1]:.2e}, {r['seconds']:.1f} s)")


def _bench_orders(text: str) -> tuple[int, ...]:
    """``bench --orders``: comma-separated orders among 2, 4, 6, 8, 10 (an argparse error otherwise)."""
    from .compositions import ORDERS

    out = []
    for part in text.split(","):
        part = part.strip()
        try:
            k = int(part)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected comma-separated orders among {','.join(map(str, ORDERS))}, got {part!r}") from None
        if k not in ORDERS:
            raise argparse.ArgumentTypeError(
                f"order {k} is not available: orders are {','.join(map(str, ORDERS))} "
                "(2: the base method; above: symmetric compositions)")
        out.append(k)
    return tuple(sorted(set(out)))


def _with_param_values(system, values: dict):
    """A copy of ``system`` whose parameter defaults are ``values`` (the other parameters kept).

    Its fingerprint differs, so its modules are generated into the cache under their own
    signature (``generated/`` is never touched by an override).
    """
    new = object.__new__(type(system))
    for slot in type(system).__slots__:
        if hasattr(system, slot):
            object.__setattr__(new, slot, getattr(system, slot))
    object.__setattr__(new, "param_values", {**system.param_values, **values})
    return new


def _bench_overrides(scene, args):
    """``bench --y0/--param/--h`` applied to the scene (validated like ``run``'s, one-line errors).

    Unlike ``run`` (which passes parameters at run time), bench also derives reference
    solutions and peers' models from the system, so the parameters become the system's
    defaults here.
    """
    import dataclasses
    y0_text, items, h = getattr(args, "y0", None), getattr(args, "param", None), getattr(args, "h", None)
    if y0_text is not None:
        scene = dataclasses.replace(scene, y0=tuple(parse_y0(y0_text, len(scene.y0))))
    if items:
        values = parse_params(items, list(scene.system.param_values))
        scene = dataclasses.replace(scene, system=_with_param_values(scene.system, values))
    if h is not None:
        scene = dataclasses.replace(scene, h=float(h))
    return scene


def cmd_bench(args) -> int:
    from . import bench

    scene = _bench_overrides(load_scene(args.scene), args)
    orders = getattr(args, "orders", None)
    if orders is not None and not args.peers and orders != (2,):
        raise InputError("--orders above 2 (compositions) are benchmarked with --peers; "
                         "without --peers the base methods are compared with scipy")
    solver = getattr(args, "solver", None)
    if solver is not None and not args.peers:
        raise InputError("--solver applies to the --peers rows; without --peers the solver table compares them")
    methods = args.methods or list(scene.methods)
    for m in methods:
        if m not in METHODS:
            raise InputError(f"unknown method {m!r}; known methods: {', '.join(METHODS)}")
    progress = not args.json
    rep: dict = {"scene": scene.name, "quick": bool(args.quick)}
    if not args.only_extras:
        if args.t_final is not None and not (math.isfinite(args.t_final) and args.t_final > 0):
            raise InputError(f"--t-final must be a positive number, got {args.t_final}")
        rep["work_precision"] = bench.work_precision(scene, methods, quick=args.quick, progress=progress,
                                                     peers=args.peers, backend=args.backend, T=args.t_final,
                                                     orders=orders, solver=solver)
        rep["solvers"] = bench.solver_variants(scene, methods, steps=300 if args.quick else 2000)
    if args.long:
        rep["long"] = bench.long_run(scene, methods, steps=args.long_steps or (20_000 if args.quick else 1_000_000),
                                     progress=progress)
    if args.brouwer:
        rep["brouwer"] = bench.brouwer(ensemble=args.ensemble,
                                       steps=args.brouwer_steps or (10_000 if args.quick else 1_000_000),
                                       progress=progress, dyadic=not args.quick)
    if args.plot:
        if "work_precision" not in rep:
            raise InputError("--plot draws the work-precision diagram; drop --only-extras")
        from .plots import plot_work_precision
        wp = rep["work_precision"]
        title = f"{scene.name}: work-precision"
        if args.peers:
            title += f", t = 0 .. {wp['T']:g}, methodgen backend {wp.get('backend', args.backend)}"
        rep["plot"] = str(plot_work_precision(wp["rows"], args.plot, title=title, targets=wp.get("targets")))
    if args.json:
        print(dump_json(rep))
    else:
        _print_bench(rep)
        if "plot" in rep:
            print(f"work-precision diagram written to {rep['plot']}")
    return 0


# --- listings ---------------------------------------------------------------------

def cmd_scenes(args) -> int:
    rows = []
    for name in scene_names():
        s = load_scene(name)
        rows.append({"name": s.name, "description": s.description, "methods": list(s.methods),
                     "dim": getattr(s.system, "dim", None),   # None: a Poisson system (see "state")
                     "state": len(s.system.y), "constraints": len(s.system.constraints),
                     "order": s.order, "composition": s.composition, "stages": s.stages,
                     "time_transform": s.time_transform})
    if args.json:
        print(json.dumps({"scenes": rows}))
    else:
        for r in rows:
            print(f"{r['name']:<20} {', '.join(r['methods']):<32} {r['description']}")
    return 0


def cmd_methods(args) -> int:
    from .compositions import DEFAULT_FAMILY, FAMILIES, ORDERS

    # "composable": symmetric of order 2 on every system it applies to, so --order K works;
    # the others only where the scheme is symmetric of order 2 for the system.
    rows = [{"name": name, "summary": mod.SUMMARY, "composable": name in SYMMETRIC_METHODS}
            for name, mod in METHODS.items()]
    high = [o for o in ORDERS if o > 2]
    comp = {"orders": list(ORDERS), "families": {f: list(o) for f, o in FAMILIES.items()},
            "default_family": {str(o): DEFAULT_FAMILY[o] for o in high},
            "composable": [r["name"] for r in rows if r["composable"]]}
    if args.json:
        print(json.dumps({"methods": rows, "compositions": comp}))
    else:
        for r in rows:
            print(f"{r['name']:<18} {r['summary']}")
        others = [r["name"] for r in rows if not r["composable"]]
        print(f"\nhigher order: --order {'/'.join(map(str, high))} (scene: [run] order) composes a "
              f"symmetric order-2 method symmetrically; the method's exact invariants and symplecticity "
              f"are kept")
        print(f"  composable: {', '.join(comp['composable'])}"
              + (f"; {', '.join(others)} only where symmetric of order 2 for the system" if others else ""))
        print("  families (--composition, [run] composition): "
              + ", ".join(f"{f} ({', '.join(map(str, o))})" for f, o in FAMILIES.items()))
        print("  default: " + ", ".join(f"order {o} {DEFAULT_FAMILY[o]}" for o in high))
    return 0


def _add_order_args(p, generate: bool = False) -> None:
    """``--order K`` and ``--composition F`` (validated by the command: one-line errors, exit 2)."""
    what = ("generate the scenes' methods composed to this order instead of the scenes' own modules"
            if generate else "order: 2 (the method itself) or 4, 6, 8, 10, a symmetric composition of it "
                             "(default: the scene's [run] order, else 2)")
    p.add_argument("--order", metavar="K", help=what)
    from .compositions import FAMILIES
    p.add_argument("--composition", metavar="FAMILY",
                   help=f"composition family for order > 2: {', '.join(FAMILIES)} (default: the scene's, "
                        "else the default of the order; `methodgen methods` lists them)")


def add_variant_args(p, command: str = "run") -> None:
    """``--stages S`` and ``--time-transform G`` (validated by the command: one-line errors, exit 2)."""
    p.add_argument("--stages", metavar="S",
                   help="stages of gauss (1..6, order 2S) and energy-collocation (1..4, order 2S) "
                        "(default: the scene's [run] stages, else 2); an error for other methods")
    where = {"run": "the run integrates", "verify": "verify", "generate": "generate"}[command]
    p.add_argument("--time-transform", metavar="G",
                   help=f"{where} K = g(q)(H + e), the Poincaré time transformation with g = G, e.g. "
                        "'sqrt(x**2 + y**2 + z**2)' (default: the scene's [run] time_transform; 'none': "
                        "without); y0 stays in the original variables, h and steps are in fictive time")


def make_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="methodgen", description="Geometric integrators generated from your Hamiltonian.")
    parser.add_argument("--version", action="version", version=f"methodgen {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("run", help="run a scene and report invariants, Newton statistics and timing")
    p.add_argument("scene", help="built-in scene name or path to a scene TOML file")
    p.add_argument("--method", help="method (default: the scene's first method)")
    _add_order_args(p)
    add_variant_args(p, "run")
    p.add_argument("--h", type=_step, help="step size (default: the scene's)")
    p.add_argument("--steps", type=_positive_int, help="number of steps (default: the scene's)")
    p.add_argument("--t-final", type=float, metavar="T",
                   help="final time instead of --steps (steps = T/h, rounded; the report gives t_final); "
                        "not with a time transformation (its steps are in fictive time)")
    p.add_argument("--y0", metavar="V1,V2,...", help="initial state, q then p (default: the scene's)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="parameter value for this run (repeatable; passed at run time, nothing re-derived)")
    p.add_argument("--plot", metavar="FILE", help="draw phase portrait, invariant errors (log scale) and "
                                                  "constraint residuals to FILE (.png/.svg/.pdf; needs methodgen[plot])")
    p.add_argument("--backend", choices=BACKENDS, default="numpy",
                   help="numpy, or numba: compiled integration loop (needs methodgen[fast]; "
                        "compiled once, cached on disk)")
    p.add_argument("--extended", action="store_true",
                   help="refine each step in extended precision (long double): removes the small "
                        "systematic round-off drift of long runs (Brouwer's law); slower")
    p.add_argument("--save", metavar="FILE.npz", help="write the trajectory to an .npz (in chunks)")
    p.add_argument("--chunk", type=_positive_int, metavar="N",
                   help="with --save: steps per chunk (memory stays bounded; default: one chunk)")
    p.add_argument("--save-every", type=_positive_int, metavar="K",
                   help="keep every K-th state (and the last): what --save writes and --plot draws; the "
                        "invariant errors are then maxima over the kept states (default 1)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_run)

    # --- verify: registered by methodgen.verify_cli (owned by the verification layer) ---
    from .verify_cli import add_parser as add_verify_parser
    add_verify_parser(sub)
    # --- end verify ---

    # --- figures: registered by methodgen.figures_cli (owned by the plotting layer) ---
    from .figures_cli import add_parser as add_figures_parser
    add_figures_parser(sub)
    # --- end figures ---

    # --- sweep: registered by methodgen.sweep_cli (owned by the sweep layer) ---
    from .sweep_cli import add_parser as add_sweep_parser
    add_sweep_parser(sub)
    # --- end sweep ---

    p = sub.add_parser("bench", help="measure speed against accuracy: work-precision vs scipy, "
                                     "solver variants, long runs, Brouwer's law")
    p.add_argument("scene", help="built-in scene name or path to a scene TOML file")
    p.add_argument("--methods", nargs="+", metavar="M", help="methods (default: the scene's)")
    p.add_argument("--quick", action="store_true", help="a small configuration (seconds)")
    p.add_argument("--long", action="store_true", help="also the long run (energy-error envelope)")
    p.add_argument("--long-steps", type=_positive_int, metavar="N", help="steps of the long run (default 10^6)")
    p.add_argument("--brouwer", action="store_true",
                   help="also the Brouwer experiment (harmonic oscillator ensemble, midpoint)")
    p.add_argument("--brouwer-steps", type=_positive_int, metavar="N",
                   help="steps (default 10^6, about 10 min; 10^4 with --quick)")
    p.add_argument("--ensemble", type=_positive_int, default=100, help="ensemble size (default 100)")
    p.add_argument("--only-extras", action="store_true",
                   help="skip the work-precision and solver tables (run only --long/--brouwer)")
    p.add_argument("--plot", metavar="FILE", help="write the work-precision diagram")
    p.add_argument("--peers", action="store_true",
                   help="heyoka and REBOUND on the same problem, in the same table and plot "
                        "(methodgen[peers]; a missing one is a note); step sizes scaled from the scene's h")
    p.add_argument("--backend", choices=BACKENDS, default="numpy",
                   help="backend of methodgen's rows (numba: compiled loop, compiled before timing)")
    p.add_argument("--t-final", type=float, metavar="T",
                   help="final time of the work-precision runs (default 20; with --peers the scene's h*steps)")
    p.add_argument("--orders", type=_bench_orders, metavar="K,K,...",
                   help="with --peers: orders of methodgen's rows, each method at each order (default 2,4,6,8,10; "
                        "above 2 the symmetric composition of the order's default family, step sizes per order "
                        "down to a final error of 1e-12); without --peers only 2")
    p.add_argument("--solver", choices=("newton", "simplified", "fixed-point", "reuse", "auto"),
                   help="with --peers: nonlinear solver of methodgen's rows (default: the module's)")
    p.add_argument("--y0", metavar="V1,V2,...", help="initial state, q then p (default: the scene's)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="parameter value (repeatable; the system is derived with it: its modules go to the cache)")
    p.add_argument("--h", type=_step, help="the scene's step size for this bench (with --peers the step-size ladder is scaled from it)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_bench)

    p = sub.add_parser("generate", help="(re)generate the modules of the built-in scenes into generated/")
    p.add_argument("scenes", nargs="*", help="scene names (default: all built-in scenes)")
    p.add_argument("--check", action="store_true", help="only check that the files are in sync; exit 1 if not")
    p.add_argument("--out", help="output folder (default: the checkout's generated/)")
    p.add_argument("--backend", choices=BACKENDS, default="numpy",
                   help="numpy (the committed generated/ modules) or numba (needs --out)")
    _add_order_args(p, generate=True)
    add_variant_args(p, "generate")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("scenes", help="list the built-in scenes")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_scenes)

    p = sub.add_parser("methods", help="list the methods")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_methods)
    return parser


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings on the command line: one line each (``methodgen: warning: …``), no source excerpt."""
    stream = sys.stderr if file is None else file
    try:
        stream.write(f"methodgen: warning: {' '.join(str(message).split())}\n")
    except OSError:  # pragma: no cover - stderr gone
        pass


def _oserror_line(exc: OSError) -> str:
    cause = exc.strerror or str(exc) or type(exc).__name__
    where = exc.filename if exc.filename is not None else None
    return f"{where}: {cause}" if where else cause


def main(argv: list[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    warnings.showwarning = _one_line_warning
    try:
        with stderr_reporting():   # a line per phase that runs over 2 s (methodgen.progress)
            return args.func(args)
    except StorageError as exc:
        # A path that cannot be used is bad input (2); a full disk is a fault of the run (3).
        print(f"methodgen: error: {exc}", file=sys.stderr)
        return EXIT_INPUT if exc.bad_path else EXIT_NUMERICAL
    except MethodgenError as exc:
        print(f"methodgen: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except (RuntimeError, FloatingPointError) as exc:
        # ConvergenceError / NonFiniteError / ResolutionError of generated modules.
        if type(exc).__name__ in _NUMERICAL:
            print(f"methodgen: error: {' '.join(str(exc).split())}", file=sys.stderr)
            return EXIT_NUMERICAL
        raise
    except KeyboardInterrupt:
        print("methodgen: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # Output piped into e.g. `head`: stop quietly, as Unix tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except OSError as exc:
        # Any other file-system fault that was not turned into a StorageError where it
        # happened: still one line naming the path and the cause, never a traceback.
        print(f"methodgen: error: {_oserror_line(exc)}", file=sys.stderr)
        return EXIT_INPUT if exc.errno in BAD_PATH_ERRNOS else EXIT_NUMERICAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
