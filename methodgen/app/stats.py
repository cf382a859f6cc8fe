"""Running maxima of errors that never lose a NaN: one helper for every report (run, sweep, bench).

Python's ``max(x, nan)`` returns ``x`` and ``max(nan, x)`` returns ``nan``: folded
into a running maximum, a quantity that stopped being a number would be reported
as its last finite error (even as 0) or not, depending on the order of the
arguments.  Here the maximum is taken over the finite values only and the first
non-finite one is recorded beside it, so a report can say "not finite from step
k" (and print null / "non-finite"), never a number.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass
class ErrorMax:
    """The running maximum of absolute errors, and where the first non-finite one was.

    Attributes
    ----------
    finite_max : float
        Maximum over the finite errors folded in so far (0 before any).
    nonfinite_step : int or None
        Step index of the first row holding a non-finite error (None: every error was finite).
    finite_before : int or None
        With rows kept every ``stride > 1`` steps: the step of the kept row before that one
        (the error became non-finite in ``(finite_before, nonfinite_step]``); None when the
        first non-finite row is a row 0 or rows are every step.
    """

    finite_max: float = 0.0
    nonfinite_step: int | None = None
    finite_before: int | None = None

    def update(self, errors, offset: int = 0, stride: int = 1, last: int | None = None) -> "ErrorMax":
        """Fold in ``errors`` (rows: one per step; any further axes are reduced).

        ``offset`` is the step index of row 0 and ``stride`` the steps between
        rows (states kept every ``stride`` steps).  ``last`` is the step of the last
        row when it is not on the grid (``save_every``: the last kept state is the one
        after ``min(i·stride, steps)`` steps): row steps are capped there, so a report
        never names a step past the end of the run.  Returns ``self``.
        """
        err = np.abs(np.asarray(errors, dtype=float))
        if err.ndim == 0:
            err = err.reshape(1, 1)
        err = err.reshape(len(err), -1)
        if not len(err):
            return self
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(err).all(axis=1)
        if bad.any() and self.nonfinite_step is None:
            row = int(np.argmax(bad))

            def step(r):
                k = offset + stride * r
                return k if last is None else min(k, last)

            self.nonfinite_step = step(row)
            if stride > 1 and row > 0:
                self.finite_before = step(row - 1)
        good = err[~bad]
        if good.size:
            self.finite_max = max(self.finite_max, float(good.max()))
        return self

    @property
    def finite(self) -> bool:
        """Every error folded in was a number."""
        return self.nonfinite_step is None

    @property
    def value(self) -> float:
        """The maximum error, or NaN once any error was not finite (reported as null / "non-finite")."""
        return self.finite_max if self.nonfinite_step is None else math.nan


def max_abs_error(values, reference=0.0) -> float:
    """``max |values - reference|``, NaN if any of it is not finite (a NaN or ±inf is never dropped)."""
    return ErrorMax().update(np.asarray(values, dtype=float) - reference).value


def max_value(*values: float) -> float:
    """The largest of ``values``, NaN if any is NaN (unlike the builtin ``max``); None entries are skipped."""
    vals = [float(v) for v in values if v is not None]
    if any(math.isnan(v) for v in vals):
        return math.nan
    return max(vals) if vals else math.nan
