"""Command line: ``methodgen run | verify | sweep | bench | generate | figures | scenes | methods``.

One module per command (``run``, ``verify``, ``sweep``, ``bench``, ``generate``,
``figures``, ``scenes``), each registering its sub-parser with ``add_parser``;
the helpers they share are in :mod:`methodgen.app.cli.common`, which imports no
command.  This module only wires them into :func:`make_parser` and :func:`main`.

Every command that reports numbers takes ``--json`` and then prints exactly one
JSON object on stdout and nothing else there (never ``NaN``/``Infinity``: a
value that is not a number is ``null``, and the object holding it says why: a
``status`` (run, sweep: ``non-finite`` with the first step) or, in a bench row,
``nulls`` = {field: reason}).  Errors a
user can cause print one line ``methodgen: error: …`` on stderr and exit
non-zero, without a traceback: 2 for bad input (including a path that cannot be
used: missing folder, no permission, a file in the way, an untrusted cache), 3
for a numerical failure (Newton did not converge, non-finite state or
invariant) or a fault of the running system (disk full), 1 for a failed
``generate --check``.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

from ..._version import __version__
from ...codegen.progress import stderr_reporting
from ...errors import BAD_PATH_ERRNOS, MethodgenError, NumericalError, StorageError
from . import bench, figures, generate, run, scenes, sweep, verify
from .common import (EXIT_INPUT, EXIT_NUMERICAL, NUMERICAL_ERRORS, Parser, cli_advice, join_negative_values,
                     one_line_warning, oserror_line)

__all__ = ["main", "make_parser", "EXIT_INPUT", "EXIT_NUMERICAL"]


def make_parser() -> argparse.ArgumentParser:
    """The ``methodgen`` parser: each command module registers its sub-parser(s)."""
    parser = Parser(prog="methodgen", description="Geometric integrators generated from your Hamiltonian.")
    parser.add_argument("--version", action="version", version=f"methodgen {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    # The order of `methodgen --help`.
    for command in (run, verify, figures, sweep, bench, generate, scenes):
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the command; return the exit status (see the module docstring)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = make_parser().parse_args(join_negative_values([str(a) for a in argv]))
    warnings.showwarning = one_line_warning
    try:
        with stderr_reporting():   # a line per phase that runs over 2 s (methodgen.codegen.progress)
            return args.func(args)
    except StorageError as exc:
        # A path that cannot be used is bad input (2); a full disk is a fault of the run (3).
        print(f"methodgen: error: {exc}", file=sys.stderr)
        return EXIT_INPUT if exc.bad_path else EXIT_NUMERICAL
    except NumericalError as exc:
        # A computation of methodgen's own failed on valid input (a reference solution).
        print(f"methodgen: error: {' '.join(str(exc).split())}", file=sys.stderr)
        return EXIT_NUMERICAL
    except MethodgenError as exc:
        print(f"methodgen: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except (RuntimeError, FloatingPointError) as exc:
        # ConvergenceError / NonFiniteError / ResolutionError of generated modules.
        if type(exc).__name__ in NUMERICAL_ERRORS:
            print(f"methodgen: error: {cli_advice(exc)}", file=sys.stderr)
            # an initial state or parameter outside the domain of H is bad input
            return EXIT_INPUT if getattr(exc, "initial_state", False) else EXIT_NUMERICAL
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
        print(f"methodgen: error: {oserror_line(exc)}", file=sys.stderr)
        return EXIT_INPUT if exc.errno in BAD_PATH_ERRNOS else EXIT_NUMERICAL


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
