"""``methodgen sweep SPEC [--scheduler ADDRESS | --workers N] [--json] [--csv FILE] [--retries K]
[--no-check-resolution]``.

Runs a parameter sweep (:mod:`methodgen.app.sweep`): in-process by default, on a
local Dask cluster with ``--workers N``, on a running Dask cluster with
``--scheduler ADDRESS``.  ``--json`` prints exactly one JSON object on stdout;
``--csv FILE`` also writes the rows as CSV.  Exit status: 0 when every task
produced a result (a numerical error such as a non-converging Newton iteration
*is* a result, and so is an invariant that stopped being a number: status
``numerical-error``, ``non-finite`` in the table), 1 when some task failed even
after ``--retries`` re-runs, 2 for bad input (spec, options, a spec whose memory
estimate exceeds the machine or whose steps exceed
:data:`~methodgen.app.limits.MAX_STEPS`, dask not installed, scheduler unreachable,
a ``--csv`` path that cannot be written), 3 when the disk is full writing ``--csv``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

from ..stats import max_value
from .common import add_resolution_arg, check_output_file, cli_advice, dump_json, fmt


def _count(minimum: int):
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"expected an integer >= {minimum}, got {v}")
        return v
    return parse


def _print_report(rep: dict) -> None:
    """The human-readable table (one line per task) and a summary line."""
    params = list(rep["spec"]["params"])
    head = f"{'method':<18} {'h':>9} " + "".join(f"{p:>9} " for p in params)
    head += f"{'batch':>5} {'traj':>5} {'status':<15} {'energy err':>10} {'inv err':>10} {'final err':>10} " \
            f"{'Newton':>6} {'CPU s':>8}"
    print(f"sweep of {rep['scene']}: {rep['tasks']} tasks")
    print(head)
    for r in rep["rows"]:
        bad = r.get("nonfinite") or {}
        # A quantity that stopped being a number is shown as "non-finite", never as an error of 0.
        nonfinite = {k: float("nan") for k in bad}
        others = [nonfinite.get(k, v) for k, v in r["invariant_errors"].items() if k != "H"]
        others.append(nonfinite.get("constraints", r["constraint_error"]))
        energy = nonfinite.get("H", r["energy_error"])
        line = f"{r['method']:<18} {r.get('h_used', r['h']):9.4g} " + "".join(f"{r['params'][p]:9.4g} " for p in params)
        line += f"{r['batch']:5d} {r['trajectories']:5d} {r['status']:<15} {fmt(energy):>10} " \
                f"{fmt(max_value(*others) if any(v is not None for v in others) else None):>10} " \
                f"{fmt(r['final_error']):>10} " \
                f"{fmt(r['newton_mean'], '.2f'):>6} {fmt(r['cpu_seconds'], '.3f'):>8}"
        print(line)
        if r["error"]:
            print(f"{'':<18} {cli_advice(r['error'])[:200]}")
    if any(r.get("h_used", r["h"]) != r["h"] for r in rep["rows"]):
        print("h: the step used, t_final/steps with steps = ceil(t_final/h) of the spec's h (ends at t_final; "
              "--json gives h and h_used)")
    eng = rep["engine"]
    where = "in-process" if eng["kind"] == "in-process" else f"{eng['kind']} ({eng['workers']} workers)"
    rate = rep["trajectory_steps_per_second"]
    print(f"{rep['ok']} ok, {rep['numerical_errors']} numerical errors, {rep['failed']} failed; "
          f"{rep['trajectory_steps']} trajectory-steps in {rep['wall_seconds']:.2f} s wall "
          f"({fmt(rate, '.3g')} steps/s, {rep['cpu_seconds']:.2f} CPU s) {where}")


def cmd_sweep(args) -> int:
    """Run the sweep of ``args.spec``; return the exit status."""
    # Imported here: the other commands do not need the sweep layer.
    from ...codegen.emit import write_atomic
    from ..sweep import load_spec, run_sweep, rows_to_csv

    if args.csv is not None:
        # Checked before the run, which may take hours, not after it (an empty name is refused,
        # not ignored).
        args.csv = str(check_output_file(args.csv, "--csv"))
    spec = load_spec(args.spec)
    if not args.check_resolution:   # --no-check-resolution over the spec's check_resolution
        spec = dataclasses.replace(spec, check_resolution=False)
    rep = run_sweep(spec, scheduler=args.scheduler, workers=args.workers, retries=args.retries,
                    progress=not args.json)
    if args.csv:
        # A StorageError (one line naming the file and the cause) if it fails: exit 2 for a
        # path that cannot be used, 3 for a full disk.
        write_atomic(args.csv, rows_to_csv(rep))
    if args.json:
        print(dump_json(rep))
    else:
        _print_report(rep)
        if args.csv:
            print(f"rows written to {args.csv}")
    if rep["failed"]:
        print(f"methodgen: {rep['failed']} of {rep['tasks']} sweep tasks failed after "
              f"{args.retries} retries (rows with status \"failed\")", file=sys.stderr)
        return 1
    return 0


def add_parser(sub) -> None:
    """Register the ``sweep`` subcommand on ``sub`` (an argparse subparsers object)."""
    p = sub.add_parser("sweep", help="run a parameter study (methods × h × parameters × initial "
                                     "conditions) in-process or on Dask")
    p.add_argument("spec", help="sweep spec TOML file (see examples/sweep_kepler.toml)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on an existing Dask cluster (e.g. tcp://host:8786); needs methodgen[distributed]")
    where.add_argument("--workers", type=_count(1), metavar="N",
                       help="run on a local Dask cluster of N worker processes; needs methodgen[distributed]")
    p.add_argument("--retries", type=_count(0), default=2, metavar="K",
                   help="re-run a failed task up to K times before reporting it (default 2)")
    p.add_argument("--csv", metavar="FILE", help="also write the rows as CSV to FILE")
    add_resolution_arg(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_sweep)
