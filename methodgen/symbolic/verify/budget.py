"""A wall-clock time budget that interrupts pure-Python (SymPy) computations.

``with budget(seconds) as b: ...`` raises :class:`BudgetExceeded` inside the
block once ``seconds`` have passed.  It uses ``SIGALRM``
(``signal.setitimer(ITIMER_REAL, seconds, 0.25)``):

* :class:`BudgetExceeded` derives from :class:`BaseException`, not
  :class:`Exception`, so the many ``except Exception:`` blocks inside SymPy
  cannot swallow it; and the timer re-fires every 0.25 s while the block is
  still running, in case a bare ``except:`` swallowed it anyway.
* Python runs signal handlers between bytecodes, so a computation stuck inside
  one long C call (a huge gmpy2/FLINT multiplication) is interrupted only when
  that call returns.
* On exit the previous ``SIGALRM`` handler and interval timer are restored.
  Budgets nest: an inner budget never extends an outer one (the earlier
  deadline wins, and the exception names the budget that ran out), and a timer
  that was already running when the budget began still fires at its deadline
  (its handler is called from ours).
* Outside the main thread, or where ``SIGALRM``/``setitimer`` do not exist
  (Windows), the block runs **without a limit**; ``b.enforced`` is then False.
"""

from __future__ import annotations

import math
import signal
import threading
import time

__all__ = ["BudgetExceeded", "budget", "budget_supported", "REFIRE"]

REFIRE = 0.25            # seconds between repeated alarms once a budget has run out
_SLACK = 1e-3            # timers may fire a hair early


class BudgetExceeded(BaseException):
    """The time budget of a :func:`budget` block ran out.

    Derives from :class:`BaseException` so that ``except Exception:`` does not
    catch it.  ``.budget`` is the :class:`budget` that ran out.
    """

    def __init__(self, b: "budget"):
        super().__init__(f"time budget of {b.seconds:g} s exceeded")
        self.budget = b


def budget_supported() -> bool:
    """True when a budget can be enforced here (POSIX ``SIGALRM``, main thread)."""
    return (hasattr(signal, "SIGALRM") and hasattr(signal, "setitimer")
            and threading.current_thread() is threading.main_thread())


_ACTIVE: list["budget"] = []    # enforced budgets, outermost first


def _on_alarm(signum, frame):
    now = time.monotonic()
    for b in list(_ACTIVE):                 # the outermost expired budget unwinds everything inside it
        if now >= b.deadline - _SLACK:
            b.expired = True
            raise BudgetExceeded(b)
    for b in list(_ACTIVE):                 # a timer that was running before some budget began
        if b._foreign_due(now):
            b._prev_fired = True
            _arm(now)
            b._call_prev(signum, frame)
            return
    _arm(now)                               # spurious or early alarm: wait for the next deadline


def _arm(now: float | None = None) -> None:
    """Set the interval timer to the earliest pending deadline of the active budgets."""
    if not _ACTIVE:
        return
    now = time.monotonic() if now is None else now
    deadlines = [b.deadline for b in _ACTIVE]
    deadlines += [b._prev_deadline for b in _ACTIVE
                  if b._prev_deadline is not None and not b._prev_fired]
    signal.setitimer(signal.ITIMER_REAL, max(min(deadlines) - now, 1e-4), REFIRE)


class budget:
    """Context manager: raise :class:`BudgetExceeded` in the block after ``seconds``.

    Parameters
    ----------
    seconds : float
        A positive, finite number of seconds.

    Attributes
    ----------
    enforced : bool
        False outside the main thread or without ``SIGALRM`` (no limit then).
    expired : bool
        True once the budget ran out.
    """

    def __init__(self, seconds: float):
        seconds = float(seconds)
        if not (math.isfinite(seconds) and seconds > 0):
            raise ValueError(f"a time budget must be a positive finite number of seconds, got {seconds!r}")
        self.seconds = seconds
        self.enforced = False
        self.expired = False
        self.deadline = math.inf
        self._prev_handler = None
        self._prev_deadline: float | None = None
        self._prev_interval = 0.0
        self._prev_fired = False
        self._entered = False

    # --- the timer that was running before this budget -------------------------
    def _foreign_due(self, now: float) -> bool:
        return (self._prev_deadline is not None and not self._prev_fired
                and self._prev_handler is not _on_alarm and now >= self._prev_deadline - _SLACK)

    def _call_prev(self, signum, frame) -> None:
        h = self._prev_handler
        if callable(h):
            h(signum, frame)
        elif h == signal.SIG_DFL:       # what would have happened without us: the process ends
            signal.signal(signal.SIGALRM, signal.SIG_DFL)
            signal.raise_signal(signal.SIGALRM)

    # --- context manager --------------------------------------------------------
    def __enter__(self) -> "budget":
        if not budget_supported():
            return self
        now = time.monotonic()
        self.deadline = now + self.seconds
        self._prev_handler = signal.getsignal(signal.SIGALRM)
        delay, interval = signal.getitimer(signal.ITIMER_REAL)
        self._prev_interval = interval
        self._prev_deadline = now + delay if delay > 0 else None
        if self._prev_handler is _on_alarm:
            self._prev_deadline = None      # an outer budget: it is on _ACTIVE and re-armed from there
        self.enforced = self._entered = True
        _ACTIVE.append(self)
        signal.signal(signal.SIGALRM, _on_alarm)
        _arm(now)
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        if not self._entered:
            return False
        self._entered = False
        # Leave _ACTIVE first, so that an alarm arriving now cannot raise for this budget.
        if self in _ACTIVE:
            _ACTIVE.remove(self)
        signal.setitimer(signal.ITIMER_REAL, 0, 0)
        signal.signal(signal.SIGALRM, self._prev_handler if self._prev_handler is not None
                      else signal.SIG_DFL)
        if _ACTIVE and self._prev_handler is _on_alarm:
            _arm()                          # back to the enclosing budget's deadline
        elif self._prev_deadline is not None:
            now = time.monotonic()
            if self._prev_fired:            # its handler already ran; keep its period, if any
                if self._prev_interval > 0:
                    signal.setitimer(signal.ITIMER_REAL, self._prev_interval, self._prev_interval)
            else:
                signal.setitimer(signal.ITIMER_REAL, max(self._prev_deadline - now, 1e-4),
                                 self._prev_interval)
        return False                        # never swallow: the caller decides what to do

    def __repr__(self) -> str:
        return f"budget({self.seconds:g} s{', expired' if self.expired else ''})"
