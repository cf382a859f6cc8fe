"""A Poincaré section of a family module's run (a lattice or particle scene): what
``methodgen run SCENE --section TEXT`` reports for a scene of symbolic size.

The crossings are found and located by the family modules' one event location
(:func:`methodgen.runtime.events.poincare`, on the method's own map: each located state is one
step of the method from the step before, so it keeps what the method keeps); this module turns
them into the run's report, the same keys as an ordinary scene's section run.
"""

from __future__ import annotations

import time

import numpy as np

from ..errors import InputError


def run_family_section(module, y0, h: float, steps: int, text: str, *, params=None, arrays=None, plot=None,
                       title: str = "", **options) -> dict:
    """Every crossing of the section ``text`` within ``steps`` steps of ``h`` from ``y0``.

    Parameters
    ----------
    module : a lattice (1-D) or particle family's module
    y0 : numpy.ndarray, shape (n,)
    h : float
    steps : int
    text : str
        ``"lhs = rhs[, condition]"`` over the indexed fields, e.g. ``"y[2] = 0, py[2] > 0"``.
    params : dict, optional
    arrays : dict, optional
        A particle family's per-particle arrays (the text may name them too).
    plot : str, optional
        A file the section's points are drawn to (matplotlib).
    title : str
        The plot's title.
    **options
        Passed to the module's ``solve`` (``solver``, ``check_resolution`` …).

    Returns
    -------
    dict
        ``section``, ``crossings``, ``t_events`` (k,), ``y_events`` (k, n), ``max_abs_g`` (|g| at the
        located states), ``invariant_errors_at_crossings``, ``state_names``, ``steps_done``,
        ``seconds``, ``status``, ``success``, ``message`` (and ``plot``).

    Raises
    ------
    InputError
        A bad section (before the run), or a run that stopped on a failed step (its message).
    """
    from ..runtime.events import family_state_names, poincare, section_event

    y0 = np.asarray(y0, dtype=float)
    extra = {} if arrays is None else {"arrays": arrays}
    g = section_event(module, text, params=params, arrays=arrays)     # a bad section is refused before the run
    t0 = time.perf_counter()
    t, pts, sol = poincare(module, y0, h, text, crossings=None, t_max=steps * abs(float(h)), params=params,
                           **extra, **options)
    seconds = time.perf_counter() - t0

    def inv(y):
        return module.invariants(y, params, arrays) if arrays is not None else module.invariants(y, params)

    start = inv(y0)
    errs = {}
    for y in pts:
        for k, v in inv(y).items():
            errs[k] = max(errs.get(k, 0.0), abs(float(v) - float(start[k])))
    names = family_state_names(module, _sites(module, y0))
    rep = dict(section=text, crossings=int(len(pts)), steps_done=int(sol.nsteps), nsteps=int(sol.nsteps), h=float(sol.h),
               status="ok" if sol.status >= 0 else "numerical-error", success=sol.status >= 0,
               message=sol.message, seconds=seconds,
               max_abs_g=float(np.max(np.abs(g(t, pts)))) if len(pts) else None,
               invariant_errors_at_crossings=errs, state_names=names, t_events=t.tolist(),
               y_events=np.asarray(pts).tolist())
    if sol.status < 0:
        raise InputError(f"the section run stopped: {sol.message}")
    if plot is not None and names is not None:
        from .plots import section_figure

        fig = section_figure(pts, names, text, title=title)
        fig.savefig(plot)
        rep["plot"] = str(plot)
    return rep


def _sites(module, y0) -> int:
    """N of the flat state y0 of a family module."""
    if hasattr(module, "Q_FIELDS"):
        return len(y0) // (2 * int(module.DIM))
    return len(y0) // len(module.FIELD_NAMES)
