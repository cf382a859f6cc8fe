"""Helpers every command shares: exit codes, the argument parser class, argument types,
JSON without NaN, ``--y0``/``--param`` parsing, the ``--order``/``--stages``/``--time-transform``
resolution, and one-line warnings and errors.

Nothing here imports a command module: the commands import from here.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import re
import sys
from pathlib import Path

import numpy as np

from ...errors import InputError, MethodNotApplicable
from ...symbolic.scene import check_order, check_stages, with_time_transform
from ...symbolic.schemes import METHODS


EXIT_INPUT = 2
EXIT_NUMERICAL = 3


class Parser(argparse.ArgumentParser):
    """argparse with methodgen's exit status for bad input, and no abbreviated options
    (``--y`` for ``--y0`` would slip past :func:`join_negative_values`, and a new option
    would silently change what an abbreviation means)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message):  # argparse's own errors: usage + exit 2, no traceback
        self.print_usage(sys.stderr)
        self.exit(EXIT_INPUT, f"methodgen: error: {message}\n")


def finite_or_none(x: float):
    """``x`` as a float, or None if it is NaN or infinite."""
    x = float(x)
    return x if math.isfinite(x) else None


def positive_int(text: str) -> int:
    """argparse type: a non-negative integer (read with ``int()``)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {v}")
    return v


def step_size(text: str) -> float:
    """argparse type: a finite, non-zero step size h (read with ``float()``)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if v == 0 or not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"h must be finite and non-zero, got {text}")
    return v


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
    return finite_or_none(x)


def dump_json(obj) -> str:
    """One JSON object: non-finite numbers become null, never ``NaN``/``Infinity``."""
    return json.dumps(json_clean(obj), allow_nan=False, default=_json_default)


def section_lines(rep: dict) -> list:
    """The text report of a Poincaré section run (``run --section``): the crossings, the largest
    |g| at them and the invariants' errors there (and where the plot went)."""
    errs = ", ".join(f"{k} {v:.2e}" for k, v in rep["invariant_errors_at_crossings"].items()) or "—"
    g = "—" if rep["max_abs_g"] is None else f"{rep['max_abs_g']:.2e}"
    size = f" (N = {rep['N']})" if "N" in rep else ""
    out = [f"{rep['scene']}, {rep['method']}{size}: {rep['crossings']} crossings of {rep['section']!r} in "
           f"{rep['steps_done']} steps of h = {rep['h']:g} ({rep['seconds']:.2f} s); max |g| {g}; "
           f"invariant errors at the crossings: {errs}"]
    if "plot" in rep:
        out.append(f"plot written to {rep['plot']}")
    return out


def refuse_for_splitting(method: str, **flags) -> None:
    """One-line InputError for the first option given (not None) that a Wisdom–Holman splitting
    does not take: ``flags`` maps option names (``order`` → ``--order``) to their values."""
    why = {"order": "its accuracy is chosen by the family: saba1…saba6, sbab1…sbab6",
           "extended": "no long-double refinement: the compensated sums already reach 1e-12 on the outer "
                       "solar system", "time_transform": "it integrates the [nbody] Hamiltonian itself"}
    for name, value in flags.items():
        if value is not None and value is not False:
            raise InputError(f"--{name.replace('_', '-')} does not apply to the Wisdom–Holman splitting {method} "
                             f"({why.get(name, why['order'])})")


NUMERICAL_ERRORS = ("ConvergenceError", "NonFiniteError", "ResolutionError", "KeplerConvergenceError")


def cli_advice(text: str) -> str:
    """A generated module's message on one line, its Python advice put in command-line terms:
    ``check_resolution=False`` is ``--no-check-resolution`` on run, sweep and bench."""
    text = " ".join(str(text).split())
    return text.replace("pass check_resolution=False", "pass --no-check-resolution")


def print_note(text: str) -> None:
    print(f"methodgen: note: {text}", file=sys.stderr)


def finite_number(text: str, what: str) -> float:
    """A real number from command-line text (float(), never eval), finite."""
    try:
        v = float(text)
    except ValueError:
        raise InputError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(v):
        raise InputError(f"{what}: {text!r} is not finite")
    return v


def check_output_file(text, option: str) -> Path:
    """The path of an output file (``--save``, ``--csv``, ``--plot``) checked before any work: a file name
    (not empty, not a folder) in a folder that exists and can be written.  The folder is never
    created: a typo in it would otherwise scatter results.  One-line :class:`InputError` else."""
    if text is None or not str(text).strip():
        raise InputError(f"{option} needs a file name, got {str(text or '')!r}")
    text = str(text)
    path = expand_user(text, option)
    if text.endswith(("/", os.sep)) or path.is_dir():
        example = {"--plot": "run.png", "--csv": "rows.csv"}.get(option, "run.npz")
        raise InputError(f"{option} {text}: is a folder; give a file name in it, e.g. {path / example}")
    folder = path.parent
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{option} {text}: {folder} is a file, not a folder")
    if not folder.is_dir():
        raise InputError(f"{option} {text}: the folder {folder} does not exist (it is not created; make it "
                         "first)")
    if not os.access(folder, os.W_OK):
        raise InputError(f"{option} {text}: {folder} is not a writable folder")
    return path


def expand_user(text: str, what: str) -> Path:
    """``Path(text).expanduser()``, a one-line :class:`InputError` naming ``what`` when the home
    folder in it cannot be found (``~nosuchuser/x``: pathlib raises RuntimeError)."""
    try:
        return Path(text).expanduser()
    except RuntimeError as exc:
        raise InputError(f"{what} {text}: cannot expand ~ ({exc.args[0] if exc.args else exc}: no such user, "
                         "or no home folder); give the path without ~") from None


#: Options whose value may start with "-": a number, a comma list of numbers (-inf, -nan
#: included), or an expression (``--time-transform -x``, refused later with a reason).
NEGATIVE_VALUE_OPTIONS = ("--y0", "--h", "--t-final", "--time-transform")

_NEGATIVE_VALUE = re.compile(r"-([0-9.]|inf|nan)", re.IGNORECASE)


def join_negative_values(argv: list[str], options=NEGATIVE_VALUE_OPTIONS) -> list[str]:
    """``--y0 -1,0`` as ``--y0=-1,0``: argparse takes a value that starts with ``-`` for an
    option unless it is a plain negative number; a comma list, ``-1e3``, ``-inf,0`` or
    ``-nan`` is not.  ``--time-transform`` takes any value that starts with ``-`` (an
    expression).  Abbreviated options are refused by :class:`Parser`, so these are the
    only spellings."""
    out: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if argv[i:i + 1] == ["--"]:   # everything after "--" is positional
            out.extend(argv[i:])
            break
        nxt = argv[i + 1] if i + 1 < len(argv) else None
        takes = nxt is not None and (
            (a == "--time-transform" and nxt.startswith("-") and nxt not in ("-h", "--help")
             and not nxt.startswith("--"))
            or _NEGATIVE_VALUE.match(nxt) is not None)
        if a in options and takes:
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def parse_y0(text: str, n: int) -> list[float]:
    """``"v1,v2,..."`` → n finite floats (q then p)."""
    parts = [t.strip() for t in text.split(",")]
    if len(parts) != n:
        raise InputError(f"--y0 needs {n} comma-separated values (q then p), got {len(parts)}")
    return [finite_number(t, f"--y0 entry {i + 1}") for i, t in enumerate(parts)]


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
        out[name] = finite_number(value.strip(), f"--param {name}")
    return out


def apply_overrides(scene, y0, params):
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
    ``[run] stages``, validated for ``methods`` (:func:`methodgen.symbolic.scene.check_stages`:
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
        if getattr(scene.transformed.time_transform, "form", "poincare") == "log":
            raise MethodNotApplicable(f"with the logarithmic Hamiltonian (time transformation \"log\") the system "
                                      f"is K = log(-U(q)) - log(T(p) + e) on (p, e; q, t): {exc}") from None
        raise MethodNotApplicable(f"with the time transformation g = {scene.time_transform} the system is "
                                  f"K = g(q)(H + e): {exc}") from None


def effective_stages(method: str, options: dict) -> int | None:
    """The number of stages a run of ``method`` uses (its default unless ``options`` say), or None."""
    mod = METHODS.get(method)
    if mod is None or not hasattr(mod, "STAGES"):
        return None
    return int(options.get("stages", mod.DEFAULT_STAGES))


def fmt(x, spec: str = ".2e") -> str:
    """A table cell: ``-`` for no value, ``non-finite`` for NaN/±inf (never a number), else ``x``."""
    if x is None:
        return "-"
    if not math.isfinite(x):
        return "non-finite"
    return format(x, spec)


def add_order_args(p, generate: bool = False) -> None:
    """``--order K`` and ``--composition F`` (validated by the command: one-line errors, exit 2)."""
    what = ("generate the scenes' methods composed to this order instead of the scenes' own modules"
            if generate else "order: 2 (the method itself) or 4, 6, 8, 10, a symmetric composition of it "
                             "(default: the scene's [run] order, else 2)")
    p.add_argument("--order", metavar="K", help=what)
    from ...symbolic.compositions import ALL_FAMILIES
    p.add_argument("--composition", metavar="FAMILY",
                   help=f"composition family for order > 2: {', '.join(ALL_FAMILIES)} (default: the scene's, "
                        "else the default of the order; `methodgen methods` lists them)")


def add_resolution_arg(p) -> None:
    """``--no-check-resolution``: ``check_resolution=False`` for the generated modules' ``integrate``."""
    p.add_argument("--no-check-resolution", dest="check_resolution", action="store_false",
                   help="do not refuse a step size h estimated to under-resolve the motion "
                        "(integrate(..., check_resolution=False)); the run is then yours to judge")


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


def one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Warnings on the command line: one line each (``methodgen: warning: …``), no source excerpt."""
    stream = sys.stderr if file is None else file
    try:
        stream.write(f"methodgen: warning: {' '.join(str(message).split())}\n")
    except OSError:  # pragma: no cover - stderr gone
        pass


def oserror_line(exc: OSError) -> str:
    cause = exc.strerror or str(exc) or type(exc).__name__
    where = exc.filename if exc.filename is not None else None
    return f"{where}: {cause}" if where else cause
