"""Run a time-transformed module to a given *physical* time.

A time-transformed system (:func:`methodgen.time_transform`, Poincaré or log form) is
integrated with a fixed step in the fictive time τ; the physical time ``t`` is a coordinate
of the state and no step lands on a requested ``T``.  :func:`run_to_time` integrates whole
fictive steps while ``t ≤ T`` and then one last step of the same method with a fictive step
``σ ∈ (0, h]`` solved so that ``t = T`` (a safeguarded secant iteration on ``σ ↦ t(σ)``,
which increases while dt/dτ > 0).  The last step is a step of the method like the others,
shorter: its local error is at most that of a full step (measured: Kepler, order 10, T = 2000,
the error at T equals that of the last whole step at its own t, 1.1e-11 (e = 0.6); 3e-14 against
1.5e-14 (e = 0.99)), and ``t`` lands on ``T`` to 2 units in the last place of max(|T|, 1)
(reported as ``info["t_error"]``; a last step that cannot land there raises RuntimeError).  No interpolation is involved.  The calls hand on the compensation of
the stage sums, so the run in calls is the run in one piece.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError

__all__ = ["run_to_time"]

#: Steps of the first probing chunk (the rate dt/dτ is unknown before it).
_FIRST_CHUNK = 64

#: What one call's info hands the next: its end state's compensation, solver state and force
#: (the run in calls is the run in one piece), and that the end state was checked (numba
#: modules skip the initial check of a state their loop checked).
_CARRIED = ("compensation", "solver_state", "force", "checked")


def run_to_time(module, Y0, t_final: float, h: float, params=None, *, check_resolution: bool = True,
                info: dict | None = None, max_steps: int = 10**9) -> np.ndarray:
    """The state of a time-transformed ``module`` at the physical time ``t_final``.

    Parameters
    ----------
    module : module
        A generated module of a time-transformed system (``module.TIME_TRANSFORM``).
    Y0 : array_like, shape (n_state,)
        The extended initial state, e.g. ``module.initial_state(y0, t0)``.
    t_final : float
        The physical time to reach, ``> t(Y0)``.
    h : float
        The fictive step, ``> 0``.
    params : optional
        Passed to ``module.integrate``.
    check_resolution : bool
        Passed to ``module.integrate``.
    info : dict, optional
        Filled with ``steps`` (whole fictive steps), ``sigma`` (the last fictive step),
        ``t_error`` (``t − t_final`` of the returned state), ``calls`` (integrate calls)
        and ``tau`` (the fictive time run).
    max_steps : int
        Refuse runs that would need more whole steps than this.

    Returns
    -------
    numpy.ndarray, shape (n_state,)
        The extended state with ``t = t_final`` (to round-off).

    Raises
    ------
    InputError
        Not a time-transformed module, a bad ``h`` or ``t_final``, or more than
        ``max_steps`` steps needed.
    RuntimeError
        The last step cannot land on ``t_final`` within 2 ulp of max(|t_final|, 1).
    """
    tt = getattr(module, "TIME_TRANSFORM", None)
    if not tt:
        raise InputError("run_to_time needs the module of a time-transformed system (TIME_TRANSFORM is None)")
    it = list(module.STATE_NAMES).index(tt["time"])
    Y = np.array(Y0, dtype=float)
    if Y.shape != (len(module.STATE_NAMES),):
        raise InputError(f"Y0 must be one extended state of shape ({len(module.STATE_NAMES)},), got {Y.shape}")
    h = float(h)
    if not (math.isfinite(h) and h > 0):
        raise InputError(f"h must be a finite fictive step > 0, got {h!r}")
    T = float(t_final)
    t0 = float(Y[it])
    if not (math.isfinite(T) and T > t0):
        raise InputError(f"t_final must be finite and after the initial time t = {t0!r}, got {t_final!r}")
    if isinstance(max_steps, bool) or not isinstance(max_steps, (int, np.integer)) or max_steps < 1:
        raise InputError(f"max_steps must be an integer >= 1, got {max_steps!r}")
    kw = dict(params=params, check_resolution=check_resolution)
    # What one integrate() call hands the next (compensation of the stage sums, solver state,
    # first-same-as-last force), so that the run in calls is the run in one piece; kept per
    # accepted state, since a call that crosses T is discarded.  Measured without it (Kepler,
    # order 10, T = 2000): the state at T moved by 5e-12 (e = 0.6) and 7.5e-12 (e = 0.99, where
    # the error grew from 3e-14 to 1.6e-12) -- the rounding each call dropped.
    carry: dict = {}
    steps = calls = 0

    def advance(Y, carry, n, every):
        nonlocal calls
        run = dict(carry)
        out = module.integrate(Y, h, n, save_every=every, info=run, **kw)
        calls += 1
        return out, {k: run[k] for k in _CARRIED if k in run}

    # No chunk runs past max_steps + 1 whole steps in all (the refusal comes before the work,
    # not after chunks that grew to 3 times the steps so far).
    chunk = _cap(_FIRST_CHUNK, 0, max_steps)
    # Whole steps in chunks that stay below T: each chunk aims at 90 % of the steps the mean
    # rate so far predicts, and at most 3 times the steps so far (the first chunks see a part
    # of an orbit only: dt/dτ varies along it), so a chunk rarely crosses T.
    while True:
        out, after = advance(Y, carry, chunk, chunk)
        if out[-1, it] > T:
            break                        # this chunk crosses T: look inside it below
        Y, carry = out[-1], after
        steps += chunk
        if steps > max_steps:
            raise InputError(f"t_final = {T!r} needs more than max_steps = {max_steps} fictive steps of h = {h!r}")
        rate = (Y[it] - t0) / steps
        if not rate > 0:
            raise InputError(f"the physical time does not advance (t = {Y[it]!r} after {steps} steps)")
        left = (T - Y[it]) / rate
        chunk = min(max(1, int(0.9 * left)), 3 * steps) if left > 16 else _FIRST_CHUNK
        chunk = _cap(chunk, steps, max_steps)
    # The crossing chunk: halves until it is short, then every state of it.
    while chunk > 2 * _FIRST_CHUNK:
        half = chunk // 2
        out, after = advance(Y, carry, half, half)
        if out[-1, it] <= T:
            Y, carry, steps, chunk = out[-1], after, steps + half, chunk - half
        else:
            chunk = half
    rows, _ = advance(Y, carry, chunk, 1)
    n = int(np.searchsorted(rows[:, it], T, side="right")) - 1   # last row with t <= T
    if n > 0:                            # again, to carry the state of row n on
        out, carry = advance(Y, carry, n, n)
        Y = out[-1]
    steps += n
    sigma = 0.0
    if Y[it] != T:
        if n + 1 >= len(rows):           # pragma: no cover - the chunk's end is past T
            raise RuntimeError("run_to_time: the crossing step was not found")
        Y, sigma, k = _last_step(module, Y, carry, rows[n + 1, it], T, h, it, kw)
        calls += k
        tol = _t_tolerance(T)
        if not abs(Y[it] - T) <= tol:
            # t(σ) jumped over T by more than the tolerance (not continuous at this resolution):
            # the state is not the state at T -- say so rather than return it
            raise RuntimeError(f"run_to_time: the last step (after {steps} whole steps, fictive step "
                               f"σ = {sigma!r}) ends at t = {float(Y[it])!r}, {float(Y[it] - T):.3g} from "
                               f"t_final = {T!r} (tolerance {tol:.3g}) after {k} trials")
    if info is not None:
        info.update(steps=steps, sigma=sigma, t_error=float(Y[it] - T), calls=calls, tau=steps * h + sigma)
    return Y


def _cap(chunk: int, steps: int, max_steps: int) -> int:
    """``chunk`` cut so that ``steps + chunk`` stays within ``max_steps + 1`` whole steps."""
    return min(chunk, max_steps + 1 - steps)


def _t_tolerance(T: float) -> float:
    """How close the last step lands on ``T``: 2 units in the last place of max(|T|, 1)."""
    return float(2 * np.spacing(max(abs(T), 1.0)))


def _last_step(module, Y, carry, t_hi, T, h, it, kw):
    """The step of fictive size σ ∈ (0, h) from ``Y`` that ends at ``t = T``: Illinois false
    position on ``t(σ) − T`` (bracketed: ``t(0) < T < t(h) = t_hi``), to a few ulps of T."""
    lo, flo = 0.0, float(Y[it]) - T
    hi, fhi = h, float(t_hi) - T
    best, fbest = None, math.inf
    side = 0
    tol = _t_tolerance(T)
    for k in range(1, 61):
        s = (lo * fhi - hi * flo) / (fhi - flo)
        if not lo < s < hi:
            s = 0.5 * (lo + hi)
        Z = module.integrate(Y, s, 1, info=dict(carry), **kw)[-1]
        f = float(Z[it]) - T
        if abs(f) < fbest:
            best, fbest = (Z, s), abs(f)
        if abs(f) <= tol or hi - lo <= 4 * np.finfo(float).eps * h:
            break
        if f < 0:
            lo, flo = s, f
            if side == -1:
                fhi *= 0.5
            side = -1
        else:
            hi, fhi = s, f
            if side == 1:
                flo *= 0.5
            side = 1
    return best[0], best[1], k
