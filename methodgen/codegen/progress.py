"""Progress of long work: one report per phase (derive, lower, render, write, load, compile …).

A *reporter* is any callable ``progress(phase: str, elapsed: float, done: bool)``:
called with ``done=False`` and ``elapsed=0.0`` when a phase starts and with
``done=True`` and the phase's wall time in seconds when it ends (also when it
fails).  :func:`phase` is how the pipeline reports; it costs nothing when
nobody listens.

* The API is silent by default: pass ``progress=`` to :func:`methodgen.build`
  (a callable, or :func:`tqdm_reporter` for tqdm bars), or :func:`install` a
  reporter for the whole process.
* The CLI installs :class:`StderrReporter`: a line on stderr when a phase has
  run for more than 2 s (``$METHODGEN_PROGRESS_SECONDS`` changes the threshold;
  0 reports every phase, ``inf`` none; anything but seconds ≥ 0 is refused) and
  a line with its time when it ends after more than that.  A slow derivation is then never silent.  As an estimate, the line of a
  running phase gives the time the same phase of the same module took the last
  time it was reported (kept in ``progress-times.json`` in the cache).
"""

from __future__ import annotations

import contextvars
import json
import os
import re
import sys
import tempfile
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from ..errors import InputError

__all__ = ["phase", "install", "installed", "StderrReporter", "tqdm_reporter", "tqdm_steps", "threshold_from_env",
           "stderr_reporting", "about", "subject", "PHASES"]

#: The phases the pipeline reports, in the order a cold build runs them.
PHASES = ("derive", "lower", "render", "write", "load", "compile")

Reporter = Callable[[str, float, bool], None]

#: The file in the cache with the last reported time of each phase (the estimates).
HISTORY_FILE = "progress-times.json"
_HISTORY_KEEP = 500


#: The name of the modules of unnamed systems (``system_<signature>_<method>.py``): it names no system.
_ANONYMOUS = "system"


def _history_key(name: str, about_text: str) -> str:
    """``phase:module`` ("" without a module) for the estimates of :class:`StderrReporter`.

    The module's file name without its 12-hex signature, so that the same system
    after a generator change keeps its estimate — except for unnamed systems
    (``system_<signature>_…``), whose signature is all that tells them apart.
    """
    if not about_text:
        return ""
    named = re.match(r"(?P<name>.+?)_[0-9a-f]{12}_", about_text)
    if named is not None and named.group("name") == _ANONYMOUS:
        return f"{name}:{about_text}"
    return f"{name}:{re.sub(r'_[0-9a-f]{12}(?=_)', '', about_text)}"

_installed: Reporter | None = None

#: What the phases are about (a module file name), for reporters that print lines.
_subject: contextvars.ContextVar[str] = contextvars.ContextVar("methodgen_progress_subject", default="")


def install(reporter: Reporter | None) -> Reporter | None:
    """Make ``reporter`` the process-wide default (None: silent again); returns the previous one."""
    global _installed
    previous, _installed = _installed, reporter
    return previous


def installed() -> Reporter | None:
    """The process-wide reporter (None when silent)."""
    return _installed


@contextmanager
def about(text: str) -> Iterator[None]:
    """Within the block, phases are about ``text`` (e.g. the module's file name; see :func:`subject`)."""
    token = _subject.set(text)
    try:
        yield
    finally:
        _subject.reset(token)


def subject() -> str:
    """What the current phases are about (``""`` outside :func:`about`)."""
    return _subject.get()


@contextmanager
def phase(name: str, progress: Reporter | None = None) -> Iterator[None]:
    """Report the phase ``name`` to ``progress`` (default: the installed reporter), start and end.

    ``progress=True``: a line on stderr per phase (a :class:`StderrReporter` reporting every
    phase), as ``solve(progress=True)`` writes one for the steps; ``False``: silent."""
    if progress is True:
        progress = StderrReporter(0.0)
    elif progress is False:
        yield
        return
    elif progress is not None and not callable(progress):
        raise InputError(f"progress must be True, False, None or a callable (phase, elapsed, done), "
                         f"got {progress!r}")
    report = progress if progress is not None else _installed
    if report is None:
        yield
        return
    t0 = time.perf_counter()
    report(name, 0.0, False)
    try:
        yield
    finally:
        report(name, time.perf_counter() - t0, True)


def _check_threshold(value: float, what: str) -> float:
    if not value >= 0:   # also NaN
        raise InputError(f"{what} must be a number of seconds >= 0 (0: report every phase; inf: "
                         f"never), got {value!r}")
    return value


def threshold_from_env(default: float = 2.0) -> float:
    """``$METHODGEN_PROGRESS_SECONDS`` as a threshold in seconds (``default`` when unset or empty).

    ``inf`` reports nothing.

    Raises
    ------
    InputError
        A value that is not a number of seconds ≥ 0 (negative, NaN, text).
    """
    what = "METHODGEN_PROGRESS_SECONDS"
    text = os.environ.get(what, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{what} must be a number of seconds >= 0 (0: report every phase; inf: never), "
                         f"got {text!r}") from None
    return _check_threshold(value, what)


@contextmanager
def stderr_reporting(threshold: float | None = None) -> Iterator[StderrReporter]:
    """Install a :class:`StderrReporter` for the ``with`` block (the CLI's commands run inside one).

    ``threshold`` defaults to :func:`threshold_from_env`; the previous reporter is
    put back afterwards.
    """
    reporter = StderrReporter(threshold_from_env() if threshold is None else threshold, history=True)
    previous = install(reporter)
    try:
        yield reporter
    finally:
        install(previous)


class StderrReporter:
    """Lines ``methodgen: <phase> <subject> …`` on a stream for phases longer than ``threshold`` s.

    When a phase is still running after ``threshold`` seconds a line says so (from
    a timer thread, so a derivation that takes minutes is visible while it runs);
    when it ends after more than ``threshold`` seconds a line gives its time.
    ``threshold=0`` reports every phase, at its start and its end.

    With ``history`` (True: ``progress-times.json`` in the per-user cache; or a
    path) the time of each reported phase is kept, per phase and module (its file
    name without the signature), and the line of a running phase adds
    ``… s last time`` when the same phase of the same module was reported before.
    """

    def __init__(self, threshold: float = 2.0, stream=None, history: bool | str | os.PathLike = False):
        self.threshold = _check_threshold(float(threshold), "the progress threshold")
        self.stream = stream
        # One timer per running phase, by thread, phase and subject: phases of two threads (or
        # two modules) never cancel each other's timer.
        self._timers: dict[tuple[int, str, str], threading.Timer] = {}
        self._lock = threading.Lock()
        self._history = history

    def _history_file(self) -> Path | None:
        if not self._history:
            return None
        if self._history is True:
            from .store import cache_dir

            return cache_dir() / HISTORY_FILE
        return Path(self._history)

    def _estimate(self, key: str) -> float | None:
        path = self._history_file()
        if path is None or not key:
            return None
        try:
            value = json.loads(path.read_text(encoding="utf-8")).get(key)
        except (OSError, ValueError, AttributeError):
            return None
        return float(value) if isinstance(value, (int, float)) and value >= 0 else None

    def _remember(self, key: str, elapsed: float) -> None:
        path = self._history_file()
        if path is None or not key or not path.parent.is_dir():
            return
        tmp = None
        try:
            try:
                times = json.loads(path.read_text(encoding="utf-8"))
                times = times if isinstance(times, dict) else {}
            except (OSError, ValueError):
                times = {}
            times.pop(key, None)
            times[key] = round(elapsed, 1)
            times = dict(list(times.items())[-_HISTORY_KEEP:])   # the most recent ones
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                json.dump(times, fh, sort_keys=False)
            os.replace(tmp, path)
        except OSError:  # an estimate is not worth a failure
            if tmp is not None:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass

    def _write(self, text: str) -> None:
        stream = self.stream if self.stream is not None else sys.stderr
        with self._lock:
            try:
                stream.write(f"methodgen: {text}\n")
                stream.flush()
            except (OSError, ValueError):  # stderr closed: progress is not worth a failure
                pass

    def _running(self, name: str, what: str, key: str) -> None:
        notes = [f"still running after {self.threshold:g} s"] if self.threshold > 0 else []
        last = self._estimate(key)
        if last is not None:
            notes.append(f"{last:.1f} s last time")
        self._write(f"{name}{what} …" + (f" ({'; '.join(notes)})" if notes else ""))

    @staticmethod
    def _slot(name: str) -> tuple:
        """The timer of phase ``name`` here: by thread, phase and subject (what the phase is about)."""
        return (threading.get_ident(), name, subject())

    def __call__(self, name: str, elapsed: float, done: bool) -> None:
        what = f" {subject()}" if subject() else ""
        key = _history_key(name, subject())
        slot = self._slot(name)
        if not done:
            if self.threshold <= 0:
                self._running(name, what, key)
                return
            if self.threshold > threading.TIMEOUT_MAX:   # inf: never (a Timer cannot wait that long)
                return
            timer = threading.Timer(self.threshold, self._running, args=(name, what, key))
            timer.daemon = True
            with self._lock:
                self._timers[slot] = timer
            timer.start()
            return
        with self._lock:
            timer = self._timers.pop(slot, None)
        if timer is not None:
            timer.cancel()
        if elapsed >= self.threshold:
            self._write(f"{name}{what} done in {elapsed:.1f} s")
            self._remember(key, elapsed)


def tqdm_reporter(**kwargs) -> Reporter:
    """A reporter that shows each phase as a tqdm bar (elapsed time); needs ``pip install tqdm``.

    ``kwargs`` go to :class:`tqdm.tqdm` (e.g. ``leave=False``, ``file=...``).

    Raises
    ------
    ImportError
        tqdm is not installed (one line saying how to install it).
    """
    try:
        from tqdm import tqdm
    except ImportError:
        raise ImportError("progress bars need tqdm: pip install tqdm") from None
    bars: dict = {}

    def report(name: str, elapsed: float, done: bool) -> None:
        if not done:
            bars[name] = tqdm(total=1, desc=name, bar_format="{desc}: {elapsed}", **kwargs)
            return
        bar = bars.pop(name, None)
        if bar is not None:
            bar.update(1)
            bar.close()

    return report


def tqdm_steps(**kwargs):
    """A progress callback for a generated module's ``solve(..., progress=...)``: a tqdm bar
    over the steps; needs ``pip install tqdm``.

    The module calls it as ``callback(done, total)`` after each chunk of steps (``done`` and
    ``total`` in steps); the bar closes when ``done == total`` or, after a failed step, when the
    next run starts a new bar.  ``kwargs`` go to :class:`tqdm.tqdm` (``desc=``, ``leave=``,
    ``file=`` …).

    Returns
    -------
    callable
        ``callback(done: int, total: int) -> None``.

    Raises
    ------
    ImportError
        tqdm is not installed (one line saying how to install it).

    Examples
    --------
    >>> sol = mod.solve(y0, (0.0, 1e4), 0.01, progress=methodgen.codegen.progress.tqdm_steps())  # doctest: +SKIP
    """
    try:
        from tqdm import tqdm
    except ImportError:
        raise ImportError("progress bars need tqdm: pip install tqdm (or pass progress=True for a "
                          "plain line on stderr)") from None
    state: dict = {"bar": None}

    def callback(done: int, total: int) -> None:
        bar = state["bar"]
        if bar is not None and done == total and bar.n <= done < bar.total:
            bar.total = total        # the run ended early (a failure, a terminal event)
        if bar is None or bar.total != total or done < bar.n:
            if bar is not None:
                bar.close()
            bar = state["bar"] = tqdm(total=total, unit="step", **kwargs)
        bar.update(done - bar.n)
        if done >= total:
            bar.close()
            state["bar"] = None

    return callback
