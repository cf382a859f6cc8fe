"""Plots: the notes' two figures, a run of any scene, a work-precision diagram.

Each ``plot_*`` function returns the :class:`matplotlib.figure.Figure` when called without
a ``path`` (to show in a notebook, adjust, or save as you like), and writes the file and
returns its path when given one (what the command line does).

matplotlib is an optional extra (``pip install "methodgen[plot]"``) and is
imported lazily inside the functions, so ``import methodgen.app.plots`` never
fails.  Figures are drawn on a bare :class:`matplotlib.figure.Figure` (the Agg
renderer, no pyplot): nothing global is switched, no window ever opens, and
it works on a headless machine.

Output is deterministic for a given matplotlib version: PNG/PDF metadata that
carries the date or the software version is dropped and SVG ids use a fixed
hash salt, so committed figures only change when the pictures do.  Pixel
size is fixed too (no ``bbox_inches="tight"``): ``figsize × dpi``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, MethodgenError

__all__ = ["PlotUnavailable", "FORMATS", "check_available", "plot_figure1", "plot_figure2", "write_figures",
           "plot_run", "plot_scene", "plot_work_precision", "default_pairs"]

FORMATS = ("png", "svg", "pdf")
DPI = 100
_INSTALL_HINT = 'plotting needs matplotlib: pip install "methodgen[plot]"'
# The exact trajectory is blue (as in the notes), so no method is.
_METHOD_COLORS = {"midpoint": "tab:red", "trapezoidal": "tab:orange", "kahan": "tab:green"}


class PlotUnavailable(MethodgenError):
    """matplotlib is not installed (the ``plot`` extra)."""


def _figure(figsize):
    """A new Agg-backed Figure without pyplot (no global state, headless)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise PlotUnavailable(_INSTALL_HINT) from None
    fig = Figure(figsize=figsize, dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def check_available() -> None:
    """Raise :class:`PlotUnavailable` (with the install hint) unless matplotlib can be imported.

    Call it before a long computation whose result is to be plotted, so a
    missing extra is reported at once rather than after the run.
    """
    _figure((1, 1))


def _format_of(path: Path, fmt: str | None) -> str:
    fmt = (fmt or path.suffix.lstrip(".") or "png").lower()
    if fmt not in FORMATS:
        raise InputError(f"unsupported plot format {fmt!r} for {path}; use one of {', '.join(FORMATS)}")
    return fmt


def _save(fig, path, fmt: str | None = None) -> Path:
    """Write ``fig`` reproducibly (no dates, no version strings, fixed SVG hash salt)."""
    import matplotlib

    path = Path(path)
    fmt = _format_of(path, fmt)
    meta = {"png": {"Software": None},
            "svg": {"Date": None, "Creator": None},
            "pdf": {"CreationDate": None, "ModDate": None, "Creator": None, "Producer": None}}[fmt]
    path.parent.mkdir(parents=True, exist_ok=True)
    with matplotlib.rc_context({"svg.hashsalt": "methodgen", "svg.fonttype": "path"}):
        fig.savefig(path, format=fmt, dpi=DPI, metadata=meta)
    return path


def _finish(fig, path, fmt: str | None = None):
    """``fig`` itself when ``path`` is None (to show, adjust or save as the caller likes), else
    the path it was written to (:func:`_save`)."""
    return fig if path is None else _save(fig, path, fmt)


def _bin_envelope(t: np.ndarray, v: np.ndarray, nbins: int = 1500):
    """Per-bin min and max of ``v`` (long runs: what the eye sees, at a fraction of the points)."""
    n = len(v)
    if n <= 2 * nbins:
        return t, v, v
    edges = np.linspace(0, n, nbins + 1).astype(int)
    lo = np.minimum.reduceat(v, edges[:-1])
    hi = np.maximum.reduceat(v, edges[:-1])
    tc = t[edges[:-1]]
    return tc, lo, hi


def _stride(a: np.ndarray, limit: int = 20000) -> np.ndarray:
    """At most ``limit`` rows, evenly spaced (scatter plots of very long runs)."""
    k = max(1, -(-len(a) // limit))
    return a[::k]


# --- Figure 1 ----------------------------------------------------------------------

def plot_figure1(data: dict, path=None, fmt: str | None = None, checks: dict | None = None):
    """Draw Figure 1 from :func:`methodgen.app.figures.figure1_data` into ``path`` (1000 × 450 px).

    Left: midpoint (black squares) and exact (red circles) at ``t = n·h``,
    numbered, on the exact ellipse.  Right: detail of the midpoint run
    (``h = 0.5``) against the exact trajectory.
    """
    from .figures import angles_per_step, normalising_map

    fig = _figure((10, 4.5))
    axl, axr = fig.subplots(1, 2)
    ell = data["ellipse"]
    left = data["left"]
    axl.plot(ell[:, 0], ell[:, 1], color="0.6", lw=1, label="exact trajectory (H = H(y₀))")
    mid, ex = left["midpoint"], left["exact"]
    axl.plot(ex[:, 0], ex[:, 1], "o", mfc="none", mec="red", ms=10, mew=1.5, label="exact, t = n·h")
    axl.plot(mid[:, 0], mid[:, 1], "s", color="black", ms=5, label=f"midpoint, h = {left['h']:g}")
    for n, (a, b) in enumerate(zip(mid, ex)):
        axl.annotate(str(n), a, xytext=(6, 5), textcoords="offset points", fontsize=9)
        axl.annotate(str(n), b, xytext=(-12, -13), textcoords="offset points", fontsize=9, color="red")
    axl.set_xlabel("q")
    axl.set_ylabel("p")
    axl.set_aspect("equal", adjustable="datalim")
    axl.legend(loc="lower left", fontsize=8)  # an empty corner: the ellipse leans right
    title = "H = ½ yᵀAy, A = [[10, 2], [2, 3]]: same ellipse, midpoint slower"
    if checks:
        c = checks["left"]
        title += f"\nangle/step {abs(c['angle']['measured_mean']):.6f} = 2·arctan(hω/2), exact hω = {abs(c['exact_angle']):.6f}"
    axl.set_title(title, fontsize=9)

    right = data["right"]
    rm = right["midpoint"]
    # Detail window: the midpoint points within a small angle (in the coordinates
    # where the ellipse is a circle) of the initial point.
    S = normalising_map(data["A"])
    z = rm @ S.T
    z0 = data["y0"] @ S.T
    rel = np.angle((z[:, 0] + 1j * z[:, 1]) / (z0[0] + 1j * z0[1]))
    win = np.abs(rel) < 0.12
    pts = rm[win]
    pad = 0.15 * max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]), 1e-3)
    axr.plot(ell[:, 0], ell[:, 1], color="red", lw=1, label="exact trajectory")
    axr.plot(pts[:, 0], pts[:, 1], "s", color="black", ms=4, mfc="none",
             label=f"midpoint, h = {right['h']:g}, t ∈ [0, {right['t'][-1]:g}]")
    axr.set_xlim(pts[:, 0].min() - pad, pts[:, 0].max() + pad)
    axr.set_ylim(pts[:, 1].min() - pad, pts[:, 1].max() + pad)
    axr.set_xlabel("q")
    axr.set_ylabel("p")
    axr.legend(loc="upper left", fontsize=8)
    rtitle = "detail: midpoint iterates on the exact trajectory"
    if checks:
        c = checks["right"]
        rtitle += f"\nmax |H−H₀|/H₀ = {c['energy_max_rel_error']:.1e}, angle/step dev {c['angle']['max_deviation']:.1e}"
    axr.set_title(rtitle, fontsize=9)
    return _finish(fig, path, fmt)


# --- Figure 2 ----------------------------------------------------------------------

def plot_figure2(data: dict, path=None, fmt: str | None = None, checks: dict | None = None):
    """Draw Figure 2 from :func:`methodgen.app.figures.figure2_data` into ``path`` (1000 × 800 px).

    One phase portrait per method against the level set of H through y₀
    (blue; the exact trajectory), and a panel with the energy error of each
    method against time (per-bin min/max envelope of ``H(y_n) − H(y₀)``).
    """
    runs, errs, t = data["runs"], data["energy_error"], data["t"]
    methods = list(runs)
    fig = _figure((10, 8))
    axes = fig.subplots(2, 2).ravel()
    allpts = np.concatenate([r for r in runs.values()])
    lo, hi = allpts.min(axis=0), allpts.max(axis=0)
    pad = 0.08 * (hi - lo)
    qg = np.linspace(lo[0] - pad[0], hi[0] + pad[0], 400)
    pg = np.linspace(lo[1] - pad[1], hi[1] + pad[1], 400)
    Q, P = np.meshgrid(qg, pg)
    Hg = data["H"](np.stack([Q, P], axis=-1))
    for ax, m in zip(axes[:3], methods):
        r = _stride(runs[m])
        ax.plot(r[:, 0], r[:, 1], ".", ms=1, color=_METHOD_COLORS.get(m, "black"), rasterized=True,
                label=f"{m}, h = {data['h']:g}")
        ax.contour(Q, P, Hg, levels=[data["H0"]], colors="blue", linewidths=0.8)
        ax.plot([], [], color="blue", lw=0.8, label="exact: H = H(y₀)")
        ax.set_xlabel("q")
        ax.set_ylabel("p")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(loc="upper right", fontsize=8)
        ttl = f"{m}"
        if checks:
            ttl += f": max |H−H₀| = {checks['drift'][m]['max']:.2e}"
        ax.set_title(ttl, fontsize=9)
    ax = axes[3]
    # Largest first so the smaller bands stay visible on top.
    for m in sorted(methods, key=lambda m: -np.max(np.abs(errs[m]))):
        tc, elo, ehi = _bin_envelope(t, errs[m])
        ax.fill_between(tc, elo, ehi, color=_METHOD_COLORS.get(m, None), alpha=0.6, lw=0, label=m,
                        rasterized=True)
    ax.set_xlabel("t")
    ax.set_ylabel("H(yₙ) − H(y₀)")
    ax.legend(loc="upper right", fontsize=8)
    ttl = "energy error: bounded, Kahan's largest"
    if checks and "modified_energy" in checks:
        ttl += f"\nKahan's modified energy: max rel. drift {checks['modified_energy']['max_rel_drift']:.1e}"
    ax.set_title(ttl, fontsize=9)
    fig.suptitle("H = ½(q² + p²) + q²p − p³/3, h = %g on [0, %g]" % (data["h"], t[-1]), fontsize=10)
    return _finish(fig, path, fmt)


def write_figures(out, fmt: str = "png", *, fig1: dict | None = None, fig2: dict | None = None) -> dict:
    """Compute, check and draw both figures into the folder ``out``.

    Parameters
    ----------
    out : path-like
        Output folder (created).
    fmt : {"png", "svg", "pdf"}
    fig1, fig2 : dict, optional
        Keyword arguments for :func:`~methodgen.app.figures.figure1_data` /
        :func:`~methodgen.app.figures.figure2_data` (shortened runs in tests).

    Returns
    -------
    dict
        ``files`` (paths written) and ``checks`` (``figure1``, ``figure2``).
    """
    from . import figures

    fmt = fmt.lower()
    if fmt not in FORMATS:
        raise InputError(f"unsupported format {fmt!r}; use one of {', '.join(FORMATS)}")
    check_available()  # fail early, before the computation
    out = Path(out)
    d1 = figures.figure1_data(**(fig1 or {}))
    c1 = figures.figure1_checks(d1)
    f1 = plot_figure1(d1, out / f"figure1_linear.{fmt}", fmt, c1)
    d2 = figures.figure2_data(**(fig2 or {}))
    c2 = figures.figure2_checks(d2)
    f2 = plot_figure2(d2, out / f"figure2_henon_heiles.{fmt}", fmt, c2)
    return {"files": [f1, f2], "checks": {"figure1": c1, "figure2": c2}}


# --- any scene ---------------------------------------------------------------------

def default_pairs(dof: int) -> list[tuple[int, int]]:
    """Coordinate pairs (state indices) for phase portraits: (q, p) in 1-DOF;
    otherwise the configuration plane (q₁, q₂) and (qᵢ, pᵢ) for the first two i."""
    if dof == 1:
        return [(0, 1)]
    return [(0, 1)] + [(i, dof + i) for i in range(min(dof, 2))]


def module_pairs(module) -> list[tuple[int, int]]:
    """:func:`default_pairs` for the layout of ``module``'s state: the log form's exchanged
    state ``(p…, e, q…, t)`` gets the configuration plane (x, y) and (qᵢ, pᵢ) too, not the
    momentum plane and (pᵢ, qᵢ) its column order would give."""
    names = tuple(module.STATE_NAMES)
    tt = getattr(module, "TIME_TRANSFORM", None) or {}
    if tt.get("form") != "log":
        return default_pairs(len(names) // 2)
    d0 = len(names) // 2 - 1                 # physical degrees of freedom
    q0 = d0 + 1                              # first coordinate column
    if d0 == 1:
        return [(q0, 0)]
    return [(q0, q0 + 1)] + [(q0 + i, i) for i in range(min(d0, 2))]


def _resolve_pair(pair, names) -> tuple[int, int]:
    out = []
    for c in pair:
        if isinstance(c, str):
            if c not in names:
                raise InputError(f"unknown coordinate {c!r}; state names are {', '.join(names)}")
            out.append(list(names).index(c))
        else:
            c = int(c)
            if not 0 <= c < len(names):
                raise InputError(f"coordinate index {c} out of range 0..{len(names) - 1}")
            out.append(c)
    return tuple(out)


def plot_run(module, traj, path=None, *, scene_name: str, method: str, h: float,
             constraint_residuals=None, pairs=None, fmt: str | None = None):
    """Phase portrait(s), invariant errors and constraint residuals of one run.

    Parameters
    ----------
    module : module
        The generated module (``STATE_NAMES``, ``INVARIANT_NAMES``, ``invariants``).
    traj : ndarray, shape (steps+1, 2d)
    path : path-like, optional
        Output file; the format is taken from the suffix (png, svg, pdf) unless ``fmt``.
        Without it the Figure is returned and nothing is written.
    scene_name, method : str
    h : float
    constraint_residuals : tuple of ndarray, optional
        ``(g, G M⁻¹ p)`` along ``traj``, e.g. ``module.constraint_residuals(traj)``.
    pairs : sequence of (int or str, int or str), optional
        Coordinate pairs for the phase portraits (default :func:`default_pairs`).

    Returns
    -------
    Path or matplotlib.figure.Figure
        ``path``, or the Figure without one; the image is ``4·ncols × 7.5`` inches at
        100 dpi, ``ncols`` = max(number of pairs, number of error panels).
    """
    if path is not None:
        _format_of(Path(path), fmt)  # bad input fails before any drawing
    traj = np.asarray(traj, dtype=float)
    if traj.ndim != 2 or len(traj) < 1:
        raise InputError("plot_run needs a trajectory of shape (steps+1, 2d)")
    names = tuple(module.STATE_NAMES)
    pairs = [_resolve_pair(p, names) for p in (pairs or module_pairs(module))]
    nbottom = 2 if constraint_residuals is not None else 1
    ncols = max(len(pairs), nbottom)
    fig = _figure((4 * ncols, 7.5))
    axes = fig.subplots(2, ncols, squeeze=False)
    t = h * np.arange(len(traj))
    pts = _stride(traj)
    for ax, (i, j) in zip(axes[0], pairs):
        ax.plot(pts[:, i], pts[:, j], lw=0.6, color="black", rasterized=len(pts) > 2000)
        ax.plot(traj[0, i], traj[0, j], "o", color="red", ms=4, label="start")
        ax.set_xlabel(names[i])
        ax.set_ylabel(names[j])
        ax.set_title(f"{names[i]}–{names[j]}", fontsize=9)
        ax.legend(loc="upper right", fontsize=8)
    for ax in axes[0][len(pairs):]:
        ax.set_axis_off()

    ax = axes[1][0]
    inv = module.invariants(traj)
    drew = False
    for name in module.INVARIANT_NAMES:
        v = np.asarray(inv[name], dtype=float)
        err = np.abs(v - v[0])
        tc, _, emax = _bin_envelope(t, err)
        emax = np.where(emax > 0, emax, np.nan)  # log scale: an exact zero is not drawable
        if np.isfinite(emax).any():
            ax.plot(tc, emax, lw=0.8, label=f"|{name} − {name}₀|")
            drew = True
        else:
            ax.plot([], [], label=f"{name}: error exactly 0")
    if drew:
        ax.set_yscale("log")
    # a time-transformed run steps in the fictive time τ (the physical t is a state column)
    ax.set_xlabel("τ (fictive time)" if getattr(module, "TIME_TRANSFORM", None) else "t")
    ax.set_ylabel("absolute error")
    ax.set_title("invariant errors", fontsize=9)
    ax.legend(loc="lower right", fontsize=8)

    if constraint_residuals is not None:
        ax = axes[1][1]
        for label, r in zip(("|g(q)|", "|G M⁻¹ p|"), constraint_residuals):
            r = np.abs(np.asarray(r, dtype=float)).reshape(len(traj), -1).max(axis=1)
            tc, _, rmax = _bin_envelope(t, r)
            rmax = np.where(rmax > 0, rmax, np.nan)
            ax.plot(tc, rmax, lw=0.8, label=label)
        if np.isfinite(ax.get_lines()[0].get_ydata()).any():
            ax.set_yscale("log")
        ax.set_xlabel("t")
        ax.set_ylabel("max residual")
        ax.set_title("constraint residuals", fontsize=9)
        ax.legend(loc="lower right", fontsize=8)
    for ax in axes[1][nbottom:]:
        ax.set_axis_off()
    fig.suptitle(f"{scene_name} — {method}, h = {h:g}, {len(traj) - 1} steps", fontsize=10)
    return _finish(fig, path, fmt)


def plot_scene(scene_name: str, path=None, *, method: str | None = None, h: float | None = None,
               steps: int | None = None, traj=None, pairs=None, fmt: str | None = None):
    """:func:`plot_run` for a scene (built-in name or TOML path), integrating it unless ``traj`` is given.

    Parameters
    ----------
    scene_name : str
    path : path-like, optional
        Without it the Figure is returned and nothing is written.
    method, h, steps : optional
        Default: the scene's.
    traj : ndarray, optional
        An existing trajectory of this scene/method/h (then nothing is integrated).
    """
    from ..codegen.build import build, scene_module_path
    from ..symbolic.scene import load_scene

    check_available()
    scene = load_scene(scene_name)
    method = method or scene.method
    h = scene.h if h is None else h
    steps = scene.steps if steps is None else steps
    module = build(scene.system, method, path=scene_module_path(scene, method))
    if traj is None:
        traj = module.integrate(np.array(scene.y0), h, steps)
    res = module.constraint_residuals(traj) if hasattr(module, "constraint_residuals") else None
    return plot_run(module, traj, path, scene_name=scene.name, method=method, h=h,
                    constraint_residuals=res, pairs=pairs, fmt=fmt)


def plot_work_precision(rows, path=None, fmt: str | None = None, title: str | None = None,
                        energy: bool | None = None, targets: dict | None = None):
    """Work-precision diagram: error against CPU time, log–log, one line per method.

    Parameters
    ----------
    rows : iterable of dict
        Keys ``method``, ``seconds``, ``error`` (and ``kind``, ``energy_rel_error``;
        ``base_method`` and ``order`` for methodgen's rows of ``bench --peers``: one
        colour per base method, one marker per order).
        Rows without ``seconds`` or ``error`` (failed runs) and rows with
        non-positive or non-finite values (not drawable on log axes) are left out.
    path : path-like, optional
        Without it the Figure is returned and nothing is written.
    energy : bool, optional
        Add a second panel, the max relative energy error against CPU time.  Default:
        when there are peer rows (``methodgen bench --peers``: kinds ``heyoka``,
        ``rebound``).  800 × 600 px with one panel, 1400 × 600 px with two.
    targets : dict, optional
        ``{"error": e, "energy_rel_error": de}`` (``bench``'s ``targets``): dotted
        horizontal lines at these levels.
    """
    rows = list(rows)
    if energy is None:
        energy = any(r.get("kind") in _PEER_STYLES for r in rows)
    groups: dict[str, list] = {}
    kinds: dict[str, str] = {}
    family: dict[str, tuple] = {}
    for r in rows:
        if r.get("seconds") is None or r.get("error") is None:  # a failed run (bench: "failed" rows)
            continue
        s, e = float(r["seconds"]), float(r["error"])
        if np.isfinite(s) and np.isfinite(e) and s > 0 and e > 0:
            de = r.get("energy_rel_error")
            de = float(de) if de is not None else float("nan")
            groups.setdefault(str(r["method"]), []).append((s, e, de))
            kinds[str(r["method"])] = str(r.get("kind", "methodgen"))
            if r.get("order") is not None:
                family[str(r["method"])] = (str(r.get("base_method", r["method"])), int(r["order"]))
    if not groups:
        raise InputError("no drawable rows (need positive, finite seconds and error)")
    fig = _figure((14, 6) if energy else (8, 6))
    axes = fig.subplots(1, 2) if energy else [fig.subplots()]
    # Distinct colours: the fixed method colours first, then unused tab10 colours;
    # reference solvers (scipy, fsolve: bench's "kind") dashed with other markers,
    # peers (heyoka, REBOUND) dashed with their own markers.  Composed methods (rows
    # with an order): the colour of their base method, a marker per order.
    fixed = {**_METHOD_COLORS, **_PEER_COLORS}
    spare = [c for c in (f"tab:{n}" for n in ("blue", "purple", "brown", "pink", "gray", "olive", "cyan"))
             if c not in fixed.values()]
    colors: dict[str, str] = {}

    def color_of(name):
        if name not in colors:
            colors[name] = fixed.get(name) or spare[sum(c in spare for c in colors.values()) % len(spare)]
        return colors[name]

    for m, pts in groups.items():
        pts.sort(key=lambda x: x[0])
        s, e, de = (np.array([p[i] for p in pts]) for i in range(3))
        kind = kinds[m]
        if m in family:
            base, order = family[m]
            color = color_of(base)
            style = _ORDER_MARKERS.get(order, "o") + "-"
        else:
            color = color_of(m)
            ref = kind != "methodgen" or m.startswith("scipy")
            style = _PEER_STYLES.get(kind, "^--" if ref else "o-")
        axes[0].plot(s, e, style, lw=1, ms=4, label=m, color=color)
        if energy:
            # An energy error of exactly 0 is not drawable on a log axis: drawn at 1e-17.
            de = np.where(de > 0, de, 1e-17)
            axes[1].plot(s, de, style, lw=1, ms=4, label=m, color=color)
    levels = (None, None) if not targets else (targets.get("error"), targets.get("energy_rel_error"))
    for ax, ylabel, level in zip(axes, ("error at the final time", "max relative energy error"), levels):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("CPU time of the integration [s]")
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
        if level:
            ax.axhline(level, ls=":", lw=1, color="0.3", label=f"target {level:g}")
        if len(groups) <= 12:
            ax.legend(fontsize=8)
    if len(groups) > 12:  # many curves (bench --peers --orders): one legend beside the panels
        handles, labels = axes[0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside right upper", fontsize=7)
    lo, hi = axes[0].get_ylim()
    if hi > 1e2 and lo < 1e-2:  # unresolved runs (errors far above 1) would squeeze the curves
        axes[0].set_ylim(lo, 1e2)
    axes[0].set_title(title or "work-precision", fontsize=10)
    if energy:
        axes[1].set_title("energy", fontsize=10)
    return _finish(fig, path, fmt)


#: Markers of methodgen's rows by order (``bench --peers --orders``); lines are solid.
_ORDER_MARKERS = {2: "o", 4: "v", 6: "^", 8: "P", 10: "*"}

#: Line styles of the peers of ``methodgen bench --peers`` (by row ``kind``).
_PEER_STYLES = {"heyoka": "s--", "rebound": "D--"}
#: Colours of the peers (by row ``method``): none of them is used for methodgen's methods.
_PEER_COLORS = {"heyoka (Taylor)": "black", "heyoka (Taylor) model.nbody": "black", "REBOUND IAS15": "tab:olive", "REBOUND WHFast": "tab:gray"}


def section_figure(points, names, section: str, *, title: str | None = None):
    """A Poincaré section's located states drawn in the plane of the first coordinate the
    section's equation does not name and its momentum (q then p in ``names``).

    Parameters
    ----------
    points : array_like, shape (k, n)
        The located states (:func:`methodgen.runtime.events.poincare`).
    names : sequence of str
        The state's component names (n), coordinates first.
    section : str
        The section's text, ``"lhs = rhs[, condition]"`` (for the choice of plane and the title).

    Returns
    -------
    matplotlib.figure.Figure
        Without pyplot (save it with ``fig.savefig``; the CLI's ``--plot`` does).
    """
    import re

    pts = np.asarray(points, dtype=float).reshape(-1, len(names))
    dof = len(names) // 2
    surface = section.split(",")[0]
    used = {n for n in names if re.search(rf"(?<![A-Za-z0-9_]){re.escape(n)}(?![A-Za-z0-9_])", surface)}
    i = next((k for k in range(dof) if names[k] not in used), 0)
    fig = _figure((5.0, 4.5))
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(pts[:, i], pts[:, dof + i], ".", ms=1.5, color="C0")
    ax.set_xlabel(names[i])
    ax.set_ylabel(names[dof + i])
    ax.set_title((title + "\n" if title else "") + f"section {section} ({len(pts)} crossings)", fontsize=9)
    return fig
