"""Bounds on the size of a run, checked before any work: refused with a one-line reason.

A run whose states do not fit in memory, or whose step count no one could wait
for, is bad input: it is refused at once, naming the limit and the way around it
(``--save`` in chunks, ``--save-every``), instead of failing after a derivation
with a numpy traceback or running for months without a word.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from ..errors import InputError

#: Most steps of one run (or sweep task): 10^12 steps take more than a day even at
#: 0.1 µs/step, and from 2^53 on ``h * steps`` no longer tells the steps apart.
MAX_STEPS = 10 ** 12

#: Share of the machine's memory the states kept at once may take (the rest: the
#: module's own arrays, the copies a plot or a save makes, the other processes).
MEMORY_SHARE = 0.5


def memory_limit() -> int | None:
    """Bytes of memory this process can have: physical memory, or a smaller cgroup limit (None: unknown)."""
    limits = []
    try:
        limits.append(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):  # pragma: no cover - not POSIX
        pass
    for f in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(f).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 1 << 60:  # "max" or a huge number: no limit
            limits.append(int(text))
    return min(limits) if limits else None


def fmt_bytes(n: float) -> str:
    """``n`` bytes in decimal units (``"1.5 GB"``)."""
    for unit in ("bytes", "kB", "MB", "GB", "TB", "PB"):
        if n < 1000 or unit == "PB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} EB"  # pragma: no cover


def check_steps(steps: int, what: str) -> None:
    """Refuse more than :data:`MAX_STEPS` steps; ``what`` says where the number came from."""
    if steps > MAX_STEPS:
        raise InputError(f"{what} asks for {steps:.3g} steps, beyond the limit of {MAX_STEPS:.0e} steps per "
                         "run (more than a day even at 0.1 µs/step); take a larger h or a shorter time")


def check_memory(need: int, what: str, hint: str, limit: int | None = None) -> None:
    """Refuse a run that needs ``need`` bytes at once if that exceeds :data:`MEMORY_SHARE`
    of :func:`memory_limit` (``limit``: that value, for tests).

    ``what`` names the request (e.g. ``"--steps 10000000000 keeps 1e+10 states"``), ``hint``
    the way around it.
    """
    limit = memory_limit() if limit is None else limit
    if limit is not None and need > MEMORY_SHARE * limit:
        raise InputError(f"{what}: about {fmt_bytes(need)} of memory, more than half of this machine's "
                         f"{fmt_bytes(limit)}; {hint}")


def steps_for_time(span: float, h: float, what: str = "--t-final") -> tuple[int, float]:
    """``(steps, h_used)`` of a run over the time ``span`` (T − t0) with step size ``h``: one rule
    for ``run --t-final`` and a sweep's ``t_final``.

    ``steps = ⌈span / h⌉`` (the nearest whole number when ``span / h`` is whole to 1e-9) and
    ``h_used = span / steps``: the run ends at T exactly, with a step no larger than ``h``
    (``|h_used| <= |h|``; the report gives both).  The sign of ``h`` must be that of ``span``
    (a negative h runs backward, to a T before t0); ``what`` names the request in the one-line
    :class:`InputError` otherwise.
    """
    if not (math.isfinite(span) and span != 0):
        raise InputError(f"{what}: the time to run (T - t0 = {span!r}) must be finite and non-zero")
    if not (math.isfinite(h) and h != 0):
        raise InputError(f"{what}: h must be finite and non-zero, got {h!r}")
    if (span > 0) != (h > 0):
        raise InputError(f"{what}: h = {h:g} runs {'backward' if h < 0 else 'forward'} in time but T - t0 = "
                         f"{span:g}; give h of the sign of T - t0 ({'positive' if span > 0 else 'negative'})")
    ratio = span / h
    if not math.isfinite(ratio):
        raise InputError(f"{what} with h = {h:g} is more steps than a number can hold")
    n = round(ratio)
    if abs(ratio - n) > 1e-9 * max(1.0, ratio):
        n = math.ceil(ratio)
    n = max(1, int(n))
    return n, span / n
