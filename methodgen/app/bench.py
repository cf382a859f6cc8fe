"""Measuring the speed/accuracy trade: work-precision, long runs, Brouwer's law, solvers.

Everything here *measures*; nothing is asserted about time.  All rows of one
report come from one run on one machine.

* :func:`work_precision` — every method of a scene over a step-size ladder,
  next to the peers a Python user would pick instead: ``scipy.integrate.solve_ivp``
  (RK45, DOP853, Radau) over a tolerance ladder, and the same scheme solved with
  ``scipy.optimize.fsolve`` on a numpy residual (``lambdify`` of the scheme's
  equations: what one writes from the lecture notes without methodgen).  CPU
  time, global error at the final time against a reference, max energy error
  and max error of every monitored invariant/constraint.
* :func:`long_run` — the energy-error envelope over 10⁶ steps against DOP853 at
  a tolerance of similar cost, with the fitted growth exponent.
* :func:`brouwer` — RMS energy error over an ensemble of random phases of the
  harmonic oscillator (midpoint, h = 0.01): slope ≈ 0.5 over 10⁶ steps with
  round-off stopping + compensated summation + extended refinement; the
  default stepper without the refinement drifts after ~10⁵ steps.
* :func:`solver_variants` — Newton, simplified Newton, fixed point: iterations
  and µs per step.
* ``work_precision(..., peers=True)`` — methodgen's methods (either backend) over a
  step-size ladder scaled from the scene's h, next to heyoka and REBOUND
  (:mod:`methodgen.app.peers`) on the same problem, all against one reference: CPU
  time of the integration call (min of 3 runs), final error, max relative energy
  error, max invariant errors.  Every method runs at every order of ``orders``
  (default :data:`PEER_ORDERS` = 2, 4, 6, 8, 10; above 2 the symmetric composition
  of the order's default family, rows labelled ``method o8 (kahan-li)``), each order
  over its own step-size ladder (:func:`composed_steps`: from the step of equal cost
  to order 2 at 4h down until the final error is below 1e-12); ``targets`` names the
  cheapest run of each method at final error ≤ 1e-10 and relative energy error ≤ 1e-14.

References: the reference solution is exact where known (linear vector
fields: ``expm``; circular Kepler orbits: a rotation), otherwise DOP853 at
``rtol = 1e-13, atol = 1e-15`` (constrained scenes: on the index-1 ODE with the
multipliers eliminated).  With ``peers=True`` and heyoka installed, heyoka in long
double at ``tol = 1e-18`` replaces DOP853 (:func:`methodgen.app.peers.heyoka_reference`:
on Kepler e = 0.6 over T = 2000 it is within 7e-15 of the exact solution where
DOP853 is 3e-8 off; within 1e-14 of heyoka in quadruple precision on the outer
solar system over 2·10⁵ days and on Hénon–Heiles over 10⁴, where DOP853 is 1e-9
and 2e-8 off).

.. [1] E. Hairer, R. I. McLachlan, A. Razakarivony, "Achieving Brouwer's law with
   implicit Runge-Kutta methods", BIT 48 (2008) 231-243.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import numpy as np
import sympy as sp

from ..codegen.build import build, scene_module_path
from ..symbolic.derive import constraint_jacobian, gradient, separable_split, vector_field
from ..errors import InputError, MethodgenError, NumericalError
from ..symbolic.scene import Scene
from ..symbolic.schemes import SYMMETRIC_METHODS, composition_for, discretize, method_key
from ..symbolic.schemes.base import is_linear_field
from .stats import max_abs_error, max_value

__all__ = ["Reference", "reference", "work_precision", "long_run", "brouwer", "solver_variants",
           "ode_rhs", "PEER_FACTORS", "PEER_ORDERS", "composed_steps", "row_label", "targets",
           "frontier", "FRONTIER_LEVELS", "extended_scene"]

TOLERANCES = [10.0 ** -k for k in range(3, 14)]
QUICK_TOLERANCES = [1e-3, 1e-6, 1e-9]
#: ``--peers``: methodgen's step sizes as multiples of the scene's h (coarse to fine).
PEER_FACTORS = (4.0, 2.0, 1.0, 0.5, 0.25, 0.125, 0.0625)
QUICK_PEER_FACTORS = (2.0, 1.0)
#: ``--peers``: finer step sizes of a method are skipped after a run longer than this (CPU s).
PEER_RUN_BUDGET = 30.0
#: ``--peers``: the orders of methodgen's rows (above 2: symmetric compositions of the base
#: method, :data:`methodgen.symbolic.compositions.DEFAULT_FAMILY`); ``work_precision(orders=...)``.
PEER_ORDERS = (2, 4, 6, 8, 10)
#: ``--peers``: a composed method's step-size ladder stops once the final error is below this.
PEER_ERROR_FLOOR = 1e-12
#: ``--peers``: at most this many step sizes per composed method and order.
PEER_MAX_POINTS = 40
#: The targets of issue 14 (``wp["targets"]``): final error and max relative energy error.
TARGET_ERROR = 1e-10
TARGET_ENERGY = 1e-14
#: ``wp["frontier"]``: the final-error levels of the frontier table.
FRONTIER_LEVELS = (1e-4, 1e-6, 1e-8, 1e-10, 1e-12)
#: ``--peers`` on a scene with an ``[nbody]`` table of several free bodies: the Wisdom–Holman
#: splittings run (:mod:`methodgen.runtime.nbody`; with the corrector, except the classic one).
WH_PEER_FAMILIES = ("wisdom-holman", "sbab3", "sbab4", "sbab5")
#: Their step ladder: from the resolution limit (``MAX_STEP_FRACTION`` of the shortest period)
#: down by √2 per point, at most this many points.
WH_MAX_POINTS = 10
#: ``--quick``: points of the Wisdom–Holman ladder, a factor 2 apart: every other point of the
#: full ladder, down to top/16 (the full one: top/22.6), about 40 % of its work.
WH_QUICK_POINTS = 5


def _cpu() -> float:
    return time.process_time()


def _progress(iterable, enabled: bool, desc: str, total: int | None = None):
    """tqdm when enabled, installed, and stderr is a terminal; the plain iterable otherwise."""
    if not enabled or not sys.stderr.isatty():
        return iterable
    try:
        from tqdm import tqdm
    except ImportError:
        return iterable
    return tqdm(iterable, desc=desc, total=total, leave=False)


class _Say:
    """Progress lines of a long bench on stderr (``methodgen: bench: …``, elapsed and an
    estimate of what is left) where no tqdm bar shows it: ``progress`` on and stderr not a
    terminal (a log, CI).  ``total``: the number of announced items (for the estimate)."""

    def __init__(self, enabled: bool, total: int):
        self.on = bool(enabled) and not sys.stderr.isatty()
        self.total = max(int(total), 1)
        self.done = 0
        self.t0 = time.perf_counter()

    def __call__(self, text: str) -> None:
        if not self.on:
            return
        el = time.perf_counter() - self.t0
        left = ("" if self.done == 0 else
                f", about {el / self.done * max(self.total - self.done, 0):.0f} s left")
        self.done += 1
        print(f"methodgen: bench: {text} [{self.done}/{self.total}, {el:.0f} s{left}]",
              file=sys.stderr, flush=True)


# --- the ODE a peer integrates -------------------------------------------------------

#: Most steps of the longest run of a work-precision diagram (T over its smallest h): each of
#: its rows, the reference solution and the scipy rows run over the same T, and at 10 µs a
#: step 10^7 steps are minutes per row.
MAX_BENCH_STEPS = 10 ** 7


def check_length(T: float, h_min: float) -> None:
    """Refuse (:class:`InputError`) a work-precision final time ``T`` whose smallest step size
    ``h_min`` would take more than :data:`MAX_BENCH_STEPS` steps."""
    if not (math.isfinite(T) and T > 0):
        raise InputError(f"--t-final must be a positive finite time, got {T!r}")
    steps = T / h_min
    if steps > MAX_BENCH_STEPS:
        raise InputError(f"--t-final {T:g}: the work-precision runs down to h = {h_min:g} would take {steps:.3g} "
                         f"steps each, beyond the bench's limit of {MAX_BENCH_STEPS:.0e}; give --t-final at most "
                         f"{MAX_BENCH_STEPS * h_min:g} (or use --long / run for one long run)")


def field_is_finite(scene) -> bool:
    """Whether the vector field the peers integrate (:func:`ode_rhs`) is a finite number at
    ``scene.y0`` with ``scene.system``'s parameter values.  A parameter value that makes the
    field undefined (``1/m`` at ``m = 0`` is SymPy's ``zoo``, which lambdify cannot print)
    counts as not finite, never as an exception."""
    y0 = np.asarray(scene.y0, dtype=float)
    with np.errstate(all="ignore"):
        try:
            rhs, _ = ode_rhs(scene.system)
            f = np.asarray(rhs(0.0, y0), dtype=float)
        except (ZeroDivisionError, ValueError, OverflowError, FloatingPointError, KeyError, TypeError,
                NameError, np.linalg.LinAlgError):
            return False
    return bool(np.isfinite(f).all())


#: Most work of one work-precision diagram without ``--peers``, in step equivalents (at the limit
#: ``bench harmonic --quick --t-final 15000`` took 107 s on a shared 2-core machine): every row
#: runs over the same T, so a long T multiplies all of them.  ``--peers`` rows are bounded one
#: by one (:func:`check_length`) and show progress.
MAX_BENCH_WORK = 10 ** 7

#: Cost of a step of the rows other than methodgen's, in methodgen steps: fsolve's pure-Python
#: step (measured about 5x a generated numpy step), and each scipy row counted as the finest
#: methodgen row's number of steps (an estimate: their adaptive step counts are not known before).
FSOLVE_WEIGHT = 5


def check_work(T: float, methods: int, hs, fsolve_hs, scipy_rows: int) -> None:
    """Refuse (:class:`InputError`) a work-precision diagram whose estimated total work over all
    rows exceeds :data:`MAX_BENCH_WORK` step equivalents (see :data:`FSOLVE_WEIGHT`), naming
    the largest ``--t-final`` within it."""
    per_t = (methods * sum(1 / h for h in hs) + FSOLVE_WEIGHT * sum(1 / h for h in fsolve_hs)
             + scipy_rows / min(hs))
    work = T * per_t
    if work > MAX_BENCH_WORK:
        raise InputError(f"--t-final {T:g}: the work-precision rows would take about {work:.2g} steps in all "
                         f"({methods} methods x {len(hs)} step sizes, {len(fsolve_hs)} fsolve and {scipy_rows} "
                         f"scipy rows; an estimate), beyond the bench's limit of {MAX_BENCH_WORK:.0e}; give "
                         f"--t-final at most {MAX_BENCH_WORK / per_t:.3g} (or use --long / run for one long run)")


def check_initial_state(scene, own=None) -> None:
    """Refuse (:class:`InputError`) an initial state where the vector field is not finite (a
    singularity of H, e.g. Kepler at r = 0), or parameter values that make it so (``m = 0`` in
    ``p**2/(2*m)``, ``m = 1e-300`` overflowing): the reference solution and every method would
    fail there, after minutes of work, instead of one line now.

    ``own``: the same scene with the scene's own parameter values (before ``--param``).  When the
    parameters differ and the field is finite at y0 with ``own``'s, the parameters are named as
    the cause; when it is not finite with either, both y0 and the parameters are named.
    """
    if field_is_finite(scene):
        return
    y0 = list(map(float, scene.y0))
    values = dict(scene.system.param_values)
    changed = {} if own is None else {k: v for k, v in values.items()
                                      if own.system.param_values.get(k) != v}
    if changed:
        given = ", ".join(f"{k}={v:g}" for k, v in changed.items())
        if field_is_finite(own):
            raise InputError(f"the parameters {given} make the vector field not finite at y0 = {y0} (with the "
                             "scene's own values it is finite there: a division by zero or an overflow); give "
                             "other --param values")
        raise InputError(f"the vector field is not finite at y0 = {y0} with the parameters {given} (nor with the "
                         "scene's own parameter values): y0 is outside the domain of H (a singularity such as "
                         "r = 0); give another --y0, and check --param")
    raise InputError(f"the vector field is not finite at the initial state y0 = {y0} "
                     f"(parameters {values}): y0 is outside the domain of H "
                     "(a singularity such as r = 0); give another --y0")


def ode_rhs(system):
    """``(f, jac)`` numpy callables of the ODE y' = f(y) that peers integrate.

    Unconstrained: ``f = J∇H``.  Constrained (``H = ½pᵀM⁻¹p + U``): the index-1
    formulation ``q' = M⁻¹p``, ``p' = -∇U - Gᵀλ`` with
    ``λ = (G M⁻¹ Gᵀ)⁻¹ (q'ᵀ ∇²g q' - G M⁻¹ ∇U)`` from ``d²g/dt² = 0``.
    """
    ys = list(system.y)
    pv = [system.param_values[k] for k in system.param_names]
    subs = dict(zip(system.params, pv))
    if not system.constraints:
        f = vector_field(system).xreplace(subs)
    else:
        sep = separable_split(system)
        Minv = sep.Minv.xreplace(subs)
        q, p = sp.Matrix(system.q), sp.Matrix(system.p)
        G = constraint_jacobian(system).xreplace(subs)
        gradU = sp.Matrix([sp.diff(sep.U, s) for s in system.q]).xreplace(subs)
        qdot = Minv * p
        curv = sp.Matrix([(qdot.T * sp.hessian(g.xreplace(subs), system.q) * qdot)[0, 0]
                          for g in system.constraints])
        lam = sp.symbols(f"_lam0:{len(system.constraints)}")
        lamv = sp.Matrix(lam)
        A = G * Minv * G.T
        # Solve numerically per call (A is small) instead of inverting symbolically.
        fA = sp.lambdify([ys], A, "numpy")
        fb = sp.lambdify([ys], curv - G * Minv * gradU, "numpy")
        fG = sp.lambdify([ys], G, "numpy")
        fgu = sp.lambdify([ys], gradU, "numpy")
        fM = np.array(Minv, dtype=float)
        d = system.dim

        def rhs(t, y):
            lamv_ = np.linalg.solve(np.array(fA(y), dtype=float), np.array(fb(y), dtype=float).ravel())
            pdot = -np.array(fgu(y), dtype=float).ravel() - np.array(fG(y), dtype=float).T @ lamv_
            return np.concatenate([fM @ y[d:], pdot])

        return rhs, None
    fl = sp.lambdify([ys], list(f), "numpy")
    fj = sp.lambdify([ys], f.jacobian(sp.Matrix(ys)), "numpy")
    return (lambda t, y: np.array(fl(y), dtype=float)), (lambda t, y: np.array(fj(y), dtype=float))


# --- references -------------------------------------------------------------------------

@dataclass(frozen=True)
class Reference:
    """The reference solution at the final time and how it was obtained."""

    y: np.ndarray
    kind: str


def reference(system, y0: np.ndarray, T: float, *, heyoka: bool = False) -> Reference:
    """Exact final state where known, else DOP853 at rtol 1e-13 (documented in ``kind``).

    ``heyoka=True``: where no exact solution is known and heyoka is installed, heyoka in
    long double at tol 1e-18 (:func:`methodgen.app.peers.heyoka_reference`) instead of DOP853.
    """
    from scipy.integrate import solve_ivp
    from scipy.linalg import expm

    y0 = np.asarray(y0, dtype=float)
    if not system.constraints and is_linear_field(system):
        subs = {s: sp.Float(system.param_values[s.name]) for s in system.params}
        A = np.array(vector_field(system).jacobian(sp.Matrix(system.y)).xreplace(subs), dtype=float)
        return Reference(expm(A * T) @ y0, "exact (matrix exponential, linear vector field)")
    circ = _circular_kepler(system, y0, T)
    if circ is not None:
        return Reference(circ, "exact (circular Kepler orbit)")
    if heyoka:
        from . import peers
        if peers.import_peer("heyoka") is not None and not system.constraints \
                and np.finfo(np.longdouble).nmant > 52:
            return Reference(peers.heyoka_reference(system, y0, T),
                             f"heyoka (Taylor) in long double, tol={peers.REFERENCE_TOL:g}, high accuracy")
    rhs, jac = ode_rhs(system)
    sol = solve_ivp(rhs, (0.0, T), y0, method="DOP853", rtol=1e-13, atol=1e-15)
    if not sol.success:
        raise NumericalError(f"the DOP853 reference solution failed at t = {sol.t[-1]:.6g} of {T:g}: "
                             f"{sol.message}")
    return Reference(sol.y[:, -1], "DOP853 at rtol=1e-13, atol=1e-15")


def _circular_kepler(system, y0, T):
    """Exact solution if the system is Kepler-like (radial 1/r) and y0 is on a circular orbit."""
    from ..symbolic.derive import radial_profile
    sep = separable_split(system)
    rad = radial_profile(system)
    if system.constraints or sep is None or sep.Minv is None or rad is None or system.dim < 2:
        return None
    s, V = rad
    subs = {p: sp.Float(system.param_values[p.name]) for p in system.params}
    k_coef = sp.sympify(sp.simplify(-V * sp.sqrt(s)).xreplace(subs))
    if k_coef.free_symbols:
        return None
    m_inv = sp.Matrix(sep.Minv).xreplace(subs).applyfunc(sp.sympify)
    if not (m_inv - m_inv[0, 0] * sp.eye(system.dim)).is_zero_matrix:
        return None
    k, minv = float(k_coef), float(m_inv[0, 0])
    d = system.dim
    q, p = y0[:d], y0[d:]
    r = np.linalg.norm(q)
    v = p * minv
    if abs(q @ v) > 1e-14 * r * np.linalg.norm(v) or abs((v @ v) - k * minv / r) > 1e-14 * (v @ v):
        return None
    w = np.linalg.norm(v) / r
    e1, e2 = q / r, v / np.linalg.norm(v)
    qt = r * (math.cos(w * T) * e1 + math.sin(w * T) * e2)
    vt = r * w * (-math.sin(w * T) * e1 + math.cos(w * T) * e2)
    return np.concatenate([qt, vt / minv])


def extended_scene(scene: Scene) -> Scene:
    """A scene of a time-dependent H as the autonomous scene the methods integrate: system
    ``K = H(q, p, t) + e`` (:func:`methodgen.autonomise`), ``y0 = (q0, t0, p0, e0 = −H(q0, p0, t0))``
    (on K = 0, as ``module.initial_state`` starts a run).  Any other scene is returned as it is.
    A declared time transformation is left out, as the bench does for autonomous H (it measures
    the methods on the system in its own time)."""
    import dataclasses

    from ..symbolic.timetransform import autonomise

    if getattr(scene.system, "time", None) is None:
        return scene
    K = autonomise(scene.system)
    tt = K.time_transform
    user = scene.system
    H = sp.lambdify([*user.y, user.time, *user.params], user.H, "math")
    e0 = -float(H(*scene.y0, scene.t0, *(user.param_values[k] for k in user.param_names)))
    d = user.dim
    y0 = (*scene.y0[:d], float(scene.t0), *scene.y0[d:], e0)
    if not all(math.isfinite(v) for v in y0):
        raise InputError(f"H({', '.join(user.state_names)}, {tt.time}) is not finite at y0, t0 = {scene.t0}")
    return dataclasses.replace(scene, system=K, y0=y0, time_transform=None, transformed=None,
                               declared_fingerprint=K.fingerprint())


# --- measuring one trajectory -----------------------------------------------------------

def _errors(module, traj, y_ref, monitors=None):
    """Global error at the end, max energy error (absolute and relative), max error of each
    monitored quantity (the module's, and ``monitors(traj)``'s: total momenta of N-body scenes)."""
    inv = dict(module.invariants(traj))
    if monitors is not None:
        inv.update({k: v for k, v in monitors(traj).items() if k not in inv})
    out = {"error": max_abs_error(traj[-1], y_ref)}
    out["invariant_errors"] = {name: max_abs_error(v, v[0]) for name, v in inv.items()}
    out["energy_error"] = out["invariant_errors"].get("H", float("nan"))
    H0 = abs(float(inv["H"][0])) if "H" in inv else 0.0
    out["energy_rel_error"] = out["energy_error"] / H0 if H0 > 0 else float("nan")
    if hasattr(module, "constraint_residuals"):
        g, gv = module.constraint_residuals(traj)
        out["constraint_error"] = max_value(max_abs_error(g), max_abs_error(gv))
    # Every value that is not a number (null in --json) with the reason, so that a null never
    # reads as "no error": a quantity that stopped being finite, or no relative error (H(y0) = 0).
    nulls = {}
    if not math.isfinite(out["error"]):
        nulls["error"] = "the final state is not finite"
    for name, v in out["invariant_errors"].items():
        if not math.isfinite(v):
            nulls[f"invariant_errors.{name}"] = f"{name} is not finite along the run"
    if "H" not in inv:
        nulls["energy_error"] = "the module monitors no H"
    elif not math.isfinite(out["energy_error"]):
        nulls["energy_error"] = "H is not finite along the run"
    if not math.isfinite(out["energy_rel_error"]) and "energy_error" not in nulls:
        nulls["energy_rel_error"] = "H(y0) = 0: no relative error" if H0 == 0 else "H(y0) is not finite"
    elif "energy_error" in nulls:
        nulls["energy_rel_error"] = nulls["energy_error"]
    if "constraint_error" in out and not math.isfinite(out["constraint_error"]):
        nulls["constraint_error"] = "a constraint residual is not finite along the run"
    out["status"] = "non-finite" if any("not finite" in why for why in nulls.values()) else "ok"
    if nulls:
        out["nulls"] = nulls
    return out


def _generated_row(scene, method, module, y0, h, steps, ref):
    info = {}
    t0 = _cpu()
    traj = module.integrate(y0, h, steps, info=info, check_resolution=False)
    sec = _cpu() - t0
    its = info["newton_iterations"]
    return {"method": method, "kind": "methodgen", "h": h, "steps": steps, "seconds": sec,
            "us_per_step": sec / steps * 1e6, "newton_mean": float(its.mean()) if its.size else 0.0,
            **_errors(module, traj, ref.y)}


def _fsolve_row(scene, method, scheme, module, y0, h, steps, ref):
    """The same scheme as a numpy residual (lambdify) solved with scipy.optimize.fsolve."""
    from scipy.optimize import fsolve

    sy = scheme.system
    pv = [sy.param_values[k] for k in sy.param_names]
    z = list(scheme.unknowns)
    args = z + list(sy.y) + [scheme.h] + list(sy.params)
    res = sp.lambdify(args, list(scheme.residual), "numpy")
    inc = sp.lambdify(args, list(scheme.increment), "numpy")
    guess = sp.lambdify(list(sy.y) + [scheme.h] + list(sy.params), list(scheme.guess), "numpy")
    traj = np.empty((steps + 1, len(y0)))
    traj[0] = y = np.array(y0, dtype=float)
    t0 = _cpu()
    for n in range(steps):
        if z:
            zz = fsolve(lambda zz: res(*zz, *y, h, *pv), guess(*y, h, *pv))
        else:
            zz = []
        y = y + np.array(inc(*zz, *y, h, *pv), dtype=float)
        traj[n + 1] = y
    sec = _cpu() - t0
    return {"method": f"{method} (fsolve)", "kind": "fsolve", "h": h, "steps": steps, "seconds": sec,
            "us_per_step": sec / steps * 1e6, **_errors(module, traj, ref.y)}


def _ivp_row(system, module, solver, tol, y0, T, ref, rhs, jac):
    from scipy.integrate import solve_ivp

    kw = {"jac": jac} if (solver == "Radau" and jac is not None) else {}
    t0 = _cpu()
    sol = solve_ivp(rhs, (0.0, T), y0, method=solver, rtol=tol, atol=tol * 1e-2, **kw)
    sec = _cpu() - t0
    traj = sol.y.T
    return {"method": f"scipy {solver}", "kind": "scipy", "tol": tol, "steps": int(sol.t.size - 1),
            "nfev": int(sol.nfev), "seconds": sec, "success": bool(sol.success),
            **_errors(module, traj, ref.y)}


def work_precision(scene: Scene, methods=None, *, quick: bool = False, T: float | None = None,
                   progress: bool = False, peers: bool = False, backend: str = "numpy",
                   orders=None, solver: str | None = None, composition: str | None = None) -> dict:
    """Work-precision data for ``scene``: methodgen methods, fsolve and solve_ivp peers.

    Returns a dict with ``scene``, ``T``, ``reference`` and ``rows`` (one dict
    per run: method, kind, h or tol, seconds (CPU), error, energy_error,
    energy_rel_error, invariant_errors, …).

    ``backend``: of methodgen's rows (``"numba"``: the compiled loop, compiled before
    the timed call).  ``peers=True``: methodgen's methods over ``T`` (default: the
    scene's own run, ``h·steps``) at every order of ``orders`` (default
    :data:`PEER_ORDERS` = 2, 4, 6, 8, 10; above 2 the symmetric composition of the
    default family, :func:`methodgen.symbolic.compositions.composition`), over the step sizes of
    :func:`composed_steps`, next to heyoka and REBOUND where installed and applicable
    (:mod:`methodgen.app.peers`; otherwise a line in ``notes``).  A run that raises
    (no convergence, non-finite state at too large h) is a line in ``notes``, not a
    row.  ``solver``: the nonlinear solver of methodgen's rows (default: the module's).
    The fsolve and solve_ivp rows are left out there (pure-Python right-hand sides over
    long runs); every row's CPU time is the minimum of three runs (one when a run takes
    over 5 s: :func:`methodgen.app.peers.min_cpu`).  ``targets`` summarises the cheapest row
    of each method at the issue-14 targets (:func:`targets`).

    ``composition``: the family of the rows above order 2 where it has that order and applies
    (a splitting family, :mod:`methodgen.symbolic.splittings`, to ``stormer-verlet`` only; the
    others keep the order's default family); with ``peers`` only.

    Without ``peers``, ``orders`` must be None or ``(2,)`` (the scipy comparison is of
    the base methods).  A time-dependent H is benchmarked as its autonomous extension
    (:func:`extended_scene`): states, errors and the reference are on ``(q, t; p, e)``.
    """
    scene = extended_scene(scene)
    methods = list(methods or scene.methods)
    if peers:
        return _work_precision_peers(scene, methods, quick=quick, T=T, progress=progress, backend=backend,
                                     orders=orders, solver=solver, composition=composition)
    if composition is not None:
        raise InputError("composition= (--composition) chooses the family of the --peers rows above order 2; "
                         "without peers=True the base methods are compared")
    if orders is not None and tuple(orders) != (2,):
        raise InputError("orders above 2 (compositions) are benchmarked with peers=True (--peers) only")
    if solver is not None:
        raise InputError("solver= is for peers=True (--peers); the solver table compares them without it")
    from ..codegen.emit import resolve_backend
    backend = resolve_backend(backend)
    T = T if T is not None else (2.0 if quick else 20.0)
    y0 = np.array(scene.y0)
    hs = [0.1, 0.05, 0.025] if quick else [0.2, 0.1, 0.05, 0.025, 0.0125, 0.00625]
    check_length(T, min(hs))   # before the reference solution, which may take as long
    # (not the explicit methods: no residual for fsolve -- the projected one's solve is its own)
    first = next((m for m in methods if m not in ("stormer-verlet", "stormer-verlet-projected")), None)
    tols = QUICK_TOLERANCES if quick else TOLERANCES
    check_work(T, len(methods), [h for h in hs if h <= T],
               [] if first is None else [h for h in hs if h <= T][:2 if quick else 3], 3 * len(tols))
    ref = reference(scene.system, y0, T)
    hs = [h for h in hs if h <= T]
    rows = []
    jobs = [(m, h) for m in methods for h in hs]
    for method, h in _progress(jobs, progress, "methodgen"):
        module = build(scene.system, method, path=scene_module_path(scene, method, backend), backend=backend)
        if backend != "numpy":
            module.integrate(y0, h, 2, check_resolution=False)  # compile outside the timed region
        steps = int(round(T / h))
        try:
            rows.append(_generated_row(scene, method, module, y0, T / steps, steps, ref))
        except (RuntimeError, FloatingPointError) as exc:
            rows.append({"method": method, "kind": "methodgen", "h": h, "failed": str(exc)})
    # The fsolve peer on the scene's first implicit method, two step sizes (it is slow).
    if first is not None:
        scheme = discretize(scene.system, first)
        module = build(scene.system, first, path=scene_module_path(scene, first))
        for h in hs[:2] if quick else hs[:3]:
            steps = int(round(T / h))
            rows.append(_fsolve_row(scene, first, scheme, module, y0, T / steps, steps, ref))
    rhs, jac = ode_rhs(scene.system)
    module = build(scene.system, methods[0], path=scene_module_path(scene, methods[0]))
    for solver, tol in _progress([(s, t) for s in ("RK45", "DOP853", "Radau") for t in tols],
                                 progress, "scipy"):
        rows.append(_ivp_row(scene.system, module, solver, tol, y0, T, ref, rhs, jac))
    return {"scene": scene.name, "T": T, "reference": ref.kind, "rows": rows}


def row_label(method: str, order: int = 2, family: str | None = None) -> str:
    """A methodgen row's label: ``method`` at order 2, ``method o<K> (<family>)`` above."""
    return method if order == 2 else f"{method} o{order} ({family})"


def composed_steps(h: float, order: int, stages: int = 1, *, quick: bool = False) -> list[float]:
    """Candidate step sizes (coarse to fine) of an order-``order`` row of ``--peers``.

    Order 2: ``h`` × :data:`PEER_FACTORS` (``QUICK_PEER_FACTORS`` with ``quick``).
    Above: a composition of ``stages`` substeps costs ``stages`` base steps, so the
    ladder starts at the step of equal cost per unit time to order 2 at ``4h``
    (``4·stages·h``) and shrinks by ``10^(1/order)`` per point — one decade of error
    per point where the error is ``C·h^order`` — down to ``h/16`` (at most
    :data:`PEER_MAX_POINTS`).  The bench stops a ladder early once the final error is
    below :data:`PEER_ERROR_FLOOR`, on a round-off plateau, or after a run longer than
    :data:`PEER_RUN_BUDGET`.  ``quick``: the two equal-cost steps ``stages·h·(1, ½)``.
    """
    h = abs(float(h))
    if order == 2:
        return [h * f for f in (QUICK_PEER_FACTORS if quick else PEER_FACTORS)]
    if quick:
        return [h * stages, h * stages / 2]
    ratio = 10.0 ** (1.0 / order)
    top, bottom = 4.0 * stages * h, h * PEER_FACTORS[-1]
    n = min(PEER_MAX_POINTS, int(math.floor(math.log(top / bottom) / math.log(ratio))) + 1)
    return [top / ratio ** j for j in range(n)]


def targets(rows, error: float = TARGET_ERROR, energy: float = TARGET_ENERGY) -> dict:
    """The cheapest row of each method with final error ≤ ``error`` and max relative energy
    error ≤ ``energy`` (issue 14's targets), and the peers' reference rows.

    Returns ``{"error", "energy_rel_error", "best": [...], "heyoka": row or None,
    "ias15": row or None}``: ``best`` one entry per method label (methodgen rows; heyoka
    and REBOUND rows too), cheapest first; ``heyoka`` is heyoka's row at tol 1e-15,
    ``ias15`` IAS15's at ε = 1e-9 (REBOUND's default), whether or not they meet the targets.
    """
    def brief(r):
        keep = ("method", "kind", "order", "h", "tol", "steps", "seconds", "error", "energy_rel_error",
                "newton_mean")
        return {k: r[k] for k in keep if k in r}

    best: dict[str, dict] = {}
    for r in rows:
        if "seconds" not in r or "error" not in r:
            continue
        de = r.get("energy_rel_error")
        if not (r["error"] <= error and de is not None and de <= energy):
            continue
        if r["method"] not in best or r["seconds"] < best[r["method"]]["seconds"]:
            best[r["method"]] = r
    heyoka = next((r for r in rows if r.get("kind") == "heyoka" and r.get("tol") == 1e-15 and "seconds" in r), None)
    ias15 = next((r for r in rows if r.get("method") == "REBOUND IAS15" and r.get("tol") == 1e-9
                  and "seconds" in r), None)
    return {"error": error, "energy_rel_error": energy,
            "best": [brief(r) for r in sorted(best.values(), key=lambda r: r["seconds"])],
            "heyoka": brief(heyoka) if heyoka else None, "ias15": brief(ias15) if ias15 else None}


def _tool(row) -> str | None:
    """The tool a work-precision row belongs to, for :func:`frontier` (None: not compared)."""
    kind = row.get("kind")
    if kind == "methodgen":
        return "methodgen"
    if kind == "heyoka":
        return "heyoka"
    if kind == "rebound":
        return "REBOUND " + ("IAS15" if "IAS15" in str(row.get("method")) else "WHFast")
    return None


def frontier(rows, levels=FRONTIER_LEVELS, energy: float = TARGET_ENERGY) -> dict:
    """The cheapest configuration of each tool at each final-error level, and the ratio to ours.

    Parameters
    ----------
    rows : list of dict
        Work-precision rows (``kind``, ``method``, ``seconds``, ``error``,
        ``energy_rel_error``); rows without ``seconds`` or with a non-finite error
        (failed runs) never count.
    levels : sequence of float
        Final-error levels: a row qualifies for a level when its error is ≤ the level.
    energy : float
        The column ``methodgen, energy kept`` takes only methodgen's rows whose maximum
        relative energy error over every step is ≤ this (energy kept to round-off,
        *measured*, whatever the method claims).

    Returns
    -------
    dict
        ``{"levels", "tools", "energy_rel_error", "table"}``; ``table`` one entry per
        level: ``{"level", "best": {tool: brief row or None}, "ratio": {peer: our
        seconds / peer seconds or None}}``.  A ratio above 1 means the peer is faster.
        Tools: ``methodgen``, ``methodgen, energy kept``, then each peer present in
        ``rows`` (``heyoka``, ``REBOUND IAS15``, ``REBOUND WHFast``).
    """
    def brief(r):
        keep = ("method", "kind", "order", "h", "tol", "steps", "seconds", "error", "energy_rel_error")
        return {k: r[k] for k in keep if k in r}

    ok = [r for r in rows if "seconds" in r and isinstance(r.get("error"), (int, float))
          and math.isfinite(r["error"]) and _tool(r) is not None]
    peers = sorted({_tool(r) for r in ok} - {"methodgen"})
    ours_exact = "methodgen, energy kept"
    tools = ["methodgen", ours_exact] + peers
    table = []
    for level in levels:
        best: dict[str, dict | None] = {t: None for t in tools}
        for r in ok:
            if not r["error"] <= level:
                continue
            names = [_tool(r)]
            de = r.get("energy_rel_error")
            if names[0] == "methodgen" and de is not None and math.isfinite(de) and de <= energy:
                names.append(ours_exact)
            for t in names:
                if best[t] is None or r["seconds"] < best[t]["seconds"]:
                    best[t] = r
        ours = best["methodgen"]
        ratio = {t: (ours["seconds"] / best[t]["seconds"] if ours is not None and best[t] is not None
                     and best[t]["seconds"] > 0 else None) for t in peers}
        table.append({"level": level, "best": {t: brief(r) if r else None for t, r in best.items()},
                      "ratio": ratio})
    return {"levels": list(levels), "tools": tools, "energy_rel_error": energy, "table": table}


def _work_precision_peers(scene: Scene, methods, *, quick: bool, T: float | None, progress: bool,
                          backend: str, orders=None, solver: str | None = None,
                          composition: str | None = None) -> dict:
    """``work_precision(..., peers=True)``: see there and :mod:`methodgen.app.peers`."""
    from . import peers as pe
    from ..codegen.emit import resolve_backend

    orders = _check_orders(PEER_ORDERS if orders is None else orders)
    T = float(T if T is not None else scene.h * scene.steps)
    if not T > 0:
        raise InputError(f"the bench needs a positive final time, got T = {T:g} (h = {scene.h:g} times "
                         f"{scene.steps} steps); give --h > 0 or --t-final T > 0")
    check_length(T, abs(scene.h) * min(QUICK_PEER_FACTORS if quick else PEER_FACTORS))
    y0 = np.array(scene.y0)
    notes = []
    if np.finfo(np.longdouble).nmant <= 52 and pe.import_peer("heyoka") is not None:
        notes.append("numpy.longdouble is plain double here: the reference is DOP853, not heyoka")
    ref = reference(scene.system, y0, T, heyoka=True)
    monitors = pe.nbody_monitors(scene)
    base = build(scene.system, methods[0], path=scene_module_path(scene, methods[0]))

    def errors(traj):
        return _errors(base, traj, ref.y, monitors)

    used = resolve_backend(backend)
    if used != backend:
        notes.append(f"backend {backend} is not available: methodgen rows use {used}")
    rows = []
    jobs = []
    for method in methods:
        for order in orders:
            if order > 2 and method not in SYMMETRIC_METHODS:
                notes.append(f"{method}: not symmetric, so no composed rows (orders above 2 compose a "
                             f"symmetric method: {', '.join(SYMMETRIC_METHODS)})")
                break
            jobs.append((method, order))
    # Energy to round-off at explicit cost: Störmer–Verlet with the standard projection onto H
    # (methodgen.symbolic.projection), for the frontier's "energy kept" column, at the orders above 2
    # (unconstrained canonical systems; a time-transformed scene's own method is the log form's)
    projected = [] if ("stormer-verlet" not in methods or scene.system.constraints
                       or scene.transformed is not None) else [o for o in orders if o > 2]
    # An upper bound of the base steps of methodgen's rows (a ladder may stop early), said before
    # they start: these rows are bounded one by one (check_length), not in total.
    def family_for(method, order):
        from ..symbolic.compositions import ALL_FAMILIES
        from ..symbolic.splittings import SPLITTING_FAMILIES
        if composition is None or order not in ALL_FAMILIES.get(composition, ()):
            return None
        if composition in SPLITTING_FAMILIES and method != "stormer-verlet":
            return None
        return composition

    if composition is not None:
        from ..symbolic.compositions import ALL_FAMILIES
        if composition not in ALL_FAMILIES:
            raise InputError(f"unknown composition family {composition!r}; families: {', '.join(ALL_FAMILIES)}")
    estimate = 0
    for method, order in jobs + [("stormer-verlet", o) for o in projected]:
        st = _family_stages(order, family_for(method, order))[1]
        estimate += sum(st * max(1, round(T / h)) for h in composed_steps(scene.h, order, st, quick=quick))
    if progress:
        print(f"methodgen: note: the --peers rows of methodgen run at most about {estimate:.3g} steps in all "
              f"({len(jobs)} method/order pairs; a row under 5 s runs 3 times for its CPU minimum)",
              file=sys.stderr)
    n_wh = 0 if (scene.nbody is None or scene.nbody.centre_mass is not None) else 2 * len(WH_PEER_FAMILIES) - 1
    n_hy = len(pe.QUICK_HEYOKA_TOLERANCES if quick else pe.HEYOKA_TOLERANCES)
    say = _Say(progress, len(jobs) + len(projected) + n_wh + n_hy + 1)
    for method, order, project in _progress([(m, o, None) for m, o in jobs]
                                            + [("stormer-verlet", o, "energy-standard") for o in projected],
                                            progress, "methodgen"):
        family, stages, processed = _family_stages(order, family_for(method, order))
        if project is not None and processed:
            continue
        label = row_label(method, order, family) + (" + standard projection" if project else "")
        say(label)
        try:
            # a processed composition is three cache modules (path None), the others one file;
            # a projected one is the cache's (its key names the projection)
            path = None if (processed or project) else scene_module_path(
                scene, method_key(method, composition_for(order, family)), used)
            module = build(scene.system, method, path=path, backend=used, order=order, composition=family,
                           **({"project": project} if project else {}))
        except MethodgenError as exc:
            notes.append(f"{label}: not built ({' '.join(str(exc).split())})")
            continue
        use = solver if solver in getattr(module, "SOLVERS", ()) else None
        if solver is not None and use is None:
            notes.append(f"{label}: solver {solver!r} is not one of this module's "
                         f"({', '.join(getattr(module, 'SOLVERS', ()))}): its default is used")
        try:  # numba: compile outside the timed region (a failure at the scene's h is not the point)
            module.integrate(y0, abs(scene.h), 1, check_resolution=False, **_solver_kw(use))
        except (RuntimeError, FloatingPointError):
            pass
        best_error = math.inf
        ladder = composed_steps(scene.h, order, stages, quick=quick)
        for h in ladder:
            steps = max(1, int(round(T / h)))
            info = {}

            def run(every=1):
                # every timed repeat starts afresh: a compensation carried over from the
                # repeat before would start it from another state (1e-14 on Kepler)
                info.clear()
                return module.integrate(y0, T / steps, steps, info=info, check_resolution=False,
                                        save_every=every, **_solver_kw(use))

            try:
                if processed:
                    # The processor is paid per returned row: timed keeping the end state only (what
                    # a run for the final state costs), every step's errors from an untimed rerun
                    # (as for the peers' rows).  Same kernel states, same final row, bitwise.
                    sec, _ = pe.min_cpu(lambda: run(steps))
                    traj = run()
                else:
                    sec, traj = pe.min_cpu(run)
            except (RuntimeError, FloatingPointError) as exc:
                notes.append(f"{label}, h = {T / steps:.4g}: {type(exc).__name__}: "
                             f"{' '.join(str(exc).split())[:160]}")
                continue
            its = info["newton_iterations"]
            row = {"method": label, "kind": "methodgen", "base_method": method, "order": order,
                   "composition": family, "stages": stages, "backend": used, "h": T / steps, "steps": steps,
                   "processed": processed, **({"project": project} if project else {}),
                   "seconds": sec, "us_per_step": sec / steps * 1e6,
                   "newton_mean": float(its.mean()) if its.size else 0.0,
                   **_errors(module, traj, ref.y, monitors)}
            if use is not None:
                row["solver"] = use
            rows.append(row)
            del traj
            stop, best_error = _ladder_stop(row["error"], best_error, order > 2, label, T / steps, notes)
            if stop:
                break
            if sec > PEER_RUN_BUDGET and h != ladder[-1]:
                notes.append(f"{label}: step sizes below h = {T / steps:.4g} skipped "
                             f"(that run took {sec:.0f} s CPU)")
                break
    if scene.transformed is not None and scene.transformed.time_transform.form == "log":
        rows += _log_form_rows(scene, jobs, T, ref, monitors, base, used, quick, notes, progress, family_for)
    rows += _wisdom_holman_rows(scene, y0, T, ref, monitors, base, quick, notes, say)
    for name, fn in (("heyoka", pe.heyoka_rows), ("rebound", pe.rebound_rows)):
        if pe.import_peer(name) is None:
            notes.append(f"{name} is not installed: no {name} rows ({pe.INSTALL_HINT})")
            continue
        try:
            if name == "heyoka":
                tols = pe.QUICK_HEYOKA_TOLERANCES if quick else pe.HEYOKA_TOLERANCES
                if quick:
                    left = [t for t in pe.HEYOKA_TOLERANCES if t not in tols]
                    notes.append(f"--quick: heyoka at tol {', '.join(f'{t:g}' for t in tols)} only "
                                 f"(left out: {', '.join(f'{t:g}' for t in left)})")
                got = fn(scene, base, y0, T, ref.y, errors, tolerances=tols, say=say)
                if any("model.nbody" in r["method"] for r in got):
                    notes.append("heyoka runs its own N-body model (model.nbody: the peer's best "
                                 "formulation), not our translation of H's vector field")
                rows += got
            else:
                say(name)
                rows += fn(scene, base, y0, T, ref.y, errors)
        except pe.PeerUnsupported as exc:
            notes.append(str(exc))
    notes.append("scipy solve_ivp and fsolve rows are left out with --peers (run without --peers for them)")
    return {"scene": scene.name, "T": T, "reference": ref.kind, "backend": used, "peers": pe.versions(),
            "orders": list(orders), "solver": solver, "rows": rows, "notes": notes, "estimated_steps": estimate,
            "targets": targets(rows), "frontier": frontier(rows)}


def _ladder_stop(err: float, best: float, plateau: bool, label: str, h: float, notes: list) -> tuple[bool, float]:
    """``(stop, best)`` after a ``--peers`` row of final error ``err`` on a step-size ladder.

    Stop below :data:`PEER_ERROR_FLOOR`, or (``plateau``) once the error no longer decreases
    below 1e-8 — round-off (said in ``notes``); a non-finite error neither stops nor counts.
    ``best`` is the smallest error so far.
    """
    if not math.isfinite(err):
        return False, best
    if err <= PEER_ERROR_FLOOR:
        return True, best
    if plateau and best < 1e-8 and err > 0.5 * best:
        notes.append(f"{label}: stopped at h = {h:.4g}, the error no longer decreases ({err:.1e}; round-off)")
        return True, best
    return False, min(best, err)


def _wisdom_holman_rows(scene, y0, T, ref, monitors, base, quick, notes, say=None) -> list[dict]:
    """``--peers`` rows of the Wisdom–Holman splittings (:data:`WH_PEER_FAMILIES`) on a scene whose
    ``[nbody]`` table has several free bodies (none about a fixed centre: one body about a centre
    is solved exactly by the Kepler drift, which would not be a comparison).  Timed for the end
    state (``save_every=steps``), errors from an untimed run keeping every step (the same
    carried states, the same final row bitwise).  The corrected families run a second time with
    every returned state projected onto H and L (``project="energy-output"``) for the frontier's
    "energy kept" column; those are timed returning every step (``save_every=1``), so the time
    includes a projection per step, as the energy column's "at every step" means."""
    from . import peers as pe
    from ..errors import MethodgenError
    from ..runtime.nbody import MAX_STEP_FRACTION, wisdom_holman

    nb = scene.nbody
    if nb is None or nb.centre_mass is not None or len(nb.masses) < 2 or scene.transformed is not None:
        return []
    rows = []
    jobs = [(f, None) for f in WH_PEER_FAMILIES] + [(f, "energy-output") for f in WH_PEER_FAMILIES
                                                    if f != "wisdom-holman"]
    if quick:
        # the quick ladder is every other step of the full one, nearly its whole range (a ladder
        # of its two largest steps never reached the useful step: its 1e-10 row read "12x behind")
        notes.append(f"--quick: the Wisdom–Holman families run at h = top/2^k, k < {WH_QUICK_POINTS} "
                     f"(top: {MAX_STEP_FRACTION:g} of the shortest period; every other step of the full "
                     f"ladder, down to top/{2 ** (WH_QUICK_POINTS - 1)}), stopping at error "
                     f"{PEER_ERROR_FLOOR:g}; the full bench runs √2 strides down to "
                     f"top/{2 ** ((WH_MAX_POINTS - 1) / 2):.3g}")
    for family, project in jobs:
        corrected = family != "wisdom-holman"
        try:
            wh = wisdom_holman(scene, family, corrector=corrected, project=project)
            top = MAX_STEP_FRACTION * float(np.min(wh.periods(y0)))
        except MethodgenError as exc:
            notes.append(f"{family}: not run ({' '.join(str(exc).split())})")
            return rows
        label = f"{wh.METHOD} (Wisdom–Holman)"
        if say is not None:
            say(label + (f", projected ({project})" if project else ""))
        ladder = ([top / 2 ** k for k in range(WH_QUICK_POINTS)] if quick
                  else [top / 2 ** (k / 2) for k in range(WH_MAX_POINTS)])
        best = math.inf
        wh.integrate(y0, ladder[0], 1)     # load the compiled runtime outside the timed region
        for h in ladder:
            steps = max(1, int(math.ceil(T / h)))
            try:
                every = 1 if project else steps
                sec, _ = pe.min_cpu(lambda: wh.integrate(y0, T / steps, steps, save_every=every))
                traj = wh.integrate(y0, T / steps, steps)
            except (RuntimeError, FloatingPointError) as exc:
                notes.append(f"{label}, h = {T / steps:.4g}: {type(exc).__name__}: "
                             f"{' '.join(str(exc).split())[:160]}")
                continue
            row = {"method": label, "kind": "methodgen", "base_method": family, "order": 2,
                   "composition": None, "stages": wh.splitting.stages, "backend": wh.BACKEND,
                   "h": T / steps, "steps": steps, "processed": False, "seconds": sec,
                   **({"project": project} if project else {}),
                   "us_per_step": sec / steps * 1e6, "newton_mean": 0.0,
                   "epsilon": wh.epsilon, **_errors(base, traj, ref.y, monitors)}
            rows.append(row)
            del traj
            stop, best = _ladder_stop(row["error"], best, True, label, T / steps, notes)
            if stop:
                break
    return rows


def _family_stages(order: int, family: str | None) -> tuple[str | None, int, bool]:
    """``(family, base steps per step, processed)`` of a row: the composition's (None and 1 for
    order 2), or a processed composition's kernel (:mod:`methodgen.symbolic.processing`)."""
    from ..symbolic.compositions import PROCESSED_FAMILIES

    if family in PROCESSED_FAMILIES:
        from ..symbolic.processing import processed_composition

        try:
            return family, processed_composition(order, family).stages, True
        except ValueError as exc:
            raise InputError(str(exc)) from None
    comp = composition_for(order, family)
    return (comp.family if comp is not None else None), (comp.stages if comp is not None else 1), False


def _log_form_rows(scene, jobs, T, ref, monitors, base, used, quick, notes, progress,
                   family_for=lambda method, order: None) -> list[dict]:
    """``--peers`` rows of a scene with ``time_transform = "log"``: each method and order on the
    logarithmic Hamiltonian (its run system), fictive steps from :func:`composed_steps`, run to
    the physical time T by :func:`methodgen.runtime.physical_time.run_to_time` (whole fictive steps,
    then one step solved for t = T).  The error is at T; the energy and invariant errors are
    those of the final state (``errors_at_T_only``), not maxima along the run.  ``family_for``
    gives the composition family of a (method, order) as for the other rows (``--composition``)."""
    from . import peers as pe
    from ..runtime.physical_time import run_to_time

    system = scene.run_system
    rows = []
    notes.append("rows marked [log] integrate the logarithmic Hamiltonian in fictive time to the physical T "
                 "(h is a fictive step); their energy and invariant errors are at T only")
    from ..symbolic.compositions import PROCESSED_FAMILIES

    for method, order in _progress(jobs, progress, "methodgen [log]"):
        fam = family_for(method, order)
        if fam in PROCESSED_FAMILIES:   # run_to_time's last step is not a processed one
            notes.append(f"[log] rows: the processed {fam} composition is not run by run_to_time; "
                         f"order {order} uses its default family there")
            fam = None
        comp = composition_for(order, fam)
        family = comp.family if comp is not None else None
        stages = comp.stages if comp is not None else 1
        label = row_label(method, order, family) + " [log]"
        try:
            module = build(system, method, path=scene_module_path(scene, method_key(method, comp), used,
                                                                   system=system),
                           backend=used, order=order, composition=family)
            Y0 = module.initial_state(np.array(scene.y0), 0.0)
        except (MethodgenError, ValueError) as exc:
            notes.append(f"{label}: not built ({' '.join(str(exc).split())})")
            continue
        try:  # numba: compile outside the timed region
            module.integrate(Y0, abs(scene.h), 1, check_resolution=False)
        except (RuntimeError, FloatingPointError):
            pass
        for h in composed_steps(scene.h, order, stages, quick=quick):
            info = {}

            def run():
                info.clear()  # every timed repeat starts afresh (see above)
                return run_to_time(module, Y0, T, h, info=info, check_resolution=False)

            try:
                sec, Y = pe.min_cpu(run)
            except (RuntimeError, FloatingPointError, MethodgenError) as exc:
                notes.append(f"{label}, h = {h:.4g}: {type(exc).__name__}: {' '.join(str(exc).split())[:160]}")
                continue
            y, _ = module.physical_state(Y)
            traj = np.array([np.array(scene.y0, dtype=float), y])
            row = {"method": label, "kind": "methodgen", "base_method": method, "order": order,
                   "composition": family, "stages": stages, "backend": used, "h": h, "steps": info["steps"] + 1,
                   "seconds": sec, "us_per_step": sec / (info["steps"] + 1) * 1e6, "time_transform": "log",
                   "errors_at_T_only": True, "t_error": info["t_error"],
                   **_errors(base, traj, ref.y, monitors)}
            rows.append(row)
            if row["error"] <= PEER_ERROR_FLOOR:
                break
    return rows


def _solver_kw(solver):
    return {} if solver is None else {"solver": solver}


def _check_orders(orders) -> tuple[int, ...]:
    """``orders`` as a sorted tuple of distinct valid orders (an :class:`InputError` otherwise)."""
    from ..symbolic.compositions import ORDERS

    out = []
    for o in orders:
        if isinstance(o, bool) or not isinstance(o, (int, np.integer)) or int(o) not in ORDERS:
            raise InputError(f"orders must be among {', '.join(map(str, ORDERS))}, got {o!r}")
        out.append(int(o))
    if not out:
        raise InputError("no orders given")
    return tuple(sorted(set(out)))


# --- long runs --------------------------------------------------------------------------

def _envelope(t, err, windows=40):
    """Max |error| in log-spaced time windows: (t_window_end, max_err)."""
    edges = np.unique(np.geomspace(max(t[1], 1e-300), t[-1], windows + 1))
    te, me = [], []
    lo = 0.0
    for hi in edges:
        sel = (t > lo) & (t <= hi)
        if np.any(sel):
            te.append(float(hi))
            me.append(float(np.max(err[sel])))
        lo = hi
    return np.array(te), np.array(me)


def growth_exponent(t, err) -> float:
    """Slope of log(envelope) against log(t) over the second half of the windows."""
    te, me = _envelope(np.asarray(t), np.asarray(err))
    keep = me > 0
    te, me = te[keep], me[keep]
    half = len(te) // 2
    if len(te) - half < 3:
        return float("nan")
    return float(np.polyfit(np.log(te[half:]), np.log(me[half:]), 1)[0])


def _chunks(module, y0, h, steps: int, chunk: int, **kw):
    """``module.iterate`` with ``integrate``'s keywords (``check_resolution``): consecutive states
    in chunks, the first starting with ``y0``, one info dict carried through (as iterate does)."""
    done, y, first, info = 0, y0, True, {}
    while first or done < steps:
        n = min(chunk, steps - done)
        part = module.integrate(y, h, n, info=info, **kw)
        yield part if first else part[1:]
        y, done, first = part[-1], done + n, False


def long_run(scene: Scene, methods=None, *, steps: int = 1_000_000, h: float | None = None,
             progress: bool = False, check_resolution: bool = True) -> dict:
    """Energy-error envelope of the geometric methods and of DOP853 at a similar cost.

    ``check_resolution=False`` (``bench --no-check-resolution``) passes the same to the
    modules' ``integrate``: no refusal of a step size estimated to under-resolve the motion.
    """
    from scipy.integrate import solve_ivp

    scene = extended_scene(scene)
    methods = list(methods or scene.methods)
    h = h or scene.h
    y0 = np.array(scene.y0)
    T = h * steps
    out = {"scene": scene.name, "steps": steps, "h": h, "T": T, "rows": []}
    costs = []
    H0 = None
    for method in methods:
        module = build(scene.system, method, path=scene_module_path(scene, method))
        t0 = _cpu()
        err_parts, times = [], []
        done = 0
        for part in _progress(_chunks(module, y0, h, steps, 100_000, check_resolution=check_resolution),
                              progress, method,
                              total=math.ceil(steps / 100_000)):
            H = module.hamiltonian(part)
            if H0 is None:
                H0 = float(H[0])
            err_parts.append(np.abs(H - H0))
            times.append(h * (done + np.arange(len(part))))
            done += len(part) - (1 if done == 0 else 0)
        sec = _cpu() - t0
        costs.append(sec)
        t = np.concatenate(times)
        e = np.concatenate(err_parts)
        te, me = _envelope(t, e)
        out["rows"].append({"method": method, "seconds": sec, "max_energy_error": max_abs_error(e),
                            "growth_exponent": growth_exponent(t, e),
                            "envelope": {"t": te.tolist(), "max_error": me.tolist()}})
    # DOP853 at the tolerance whose cost is closest to the geometric methods' (measured on
    # a short interval and extrapolated linearly in time).
    rhs, _ = ode_rhs(scene.system)
    module = build(scene.system, methods[0], path=scene_module_path(scene, methods[0]))
    target = float(np.median(costs))
    probe_T = min(T, max(10.0, T / 100))
    best = None
    for tol in TOLERANCES:
        t0 = _cpu()
        solve_ivp(rhs, (0, probe_T), y0, method="DOP853", rtol=tol, atol=tol * 1e-2)
        est = (_cpu() - t0) * T / probe_T
        if best is None or abs(math.log(max(est, 1e-9) / target)) < abs(math.log(max(best[1], 1e-9) / target)):
            best = (tol, est)
    tol = best[0]
    t0 = _cpu()
    sol = solve_ivp(rhs, (0, T), y0, method="DOP853", rtol=tol, atol=tol * 1e-2)
    sec = _cpu() - t0
    H = module.hamiltonian(sol.y.T)
    e = np.abs(H - H[0])
    te, me = _envelope(sol.t, e)
    out["rows"].append({"method": f"scipy DOP853 (rtol={tol:g})", "seconds": sec,
                        "max_energy_error": max_abs_error(e), "growth_exponent": growth_exponent(sol.t, e),
                        "envelope": {"t": te.tolist(), "max_error": me.tolist()}})
    return out


# --- Brouwer's law ------------------------------------------------------------------------

def brouwer(*, ensemble: int = 100, steps: int = 100_000, h: float = 0.01, seed: int = 0,
            progress: bool = False, dyadic: bool = False, check_resolution: bool = True) -> dict:
    """RMS energy error over random phases of the harmonic oscillator, midpoint rule.

    Steppers from the same generated module, all on the batched integrator:

    1. the Brouwer stepper: round-off stopping, compensated summation and the
       extended-precision refinement (``integrate(..., extended=True)``);
    2. the default stepper: round-off stopping and compensated summation;
    3. a plain ``tol = 1e-12`` stop without compensation.

    The energy is that of the exact numerical state (including the carried
    compensation), evaluated in extended precision.  With a decimal h the
    default stepper keeps a small systematic drift (~1e-3 of the per-step
    round-off, from the rounding of the stage sums q + Δq/2 and p + Δp/2) that
    outgrows the √t random walk after ~10⁵ steps; the refinement removes it.
    With ``dyadic=True`` the default stepper is also run with the nearest power
    of two to h (2⁻⁷ for 0.01), where the bias does not arise.

    ``check_resolution``: passed to ``integrate`` (``bench --no-check-resolution``: False).

    Returns the RMS error curves and their log-log slopes fitted over the last
    two decades of t (≈ 0.5 for Brouwer's law, ≈ 1 for linear growth).  The
    refinement row is left out (with a note) where numpy.longdouble is plain
    double.
    """
    from ..symbolic.scene import load_scene
    scene = load_scene("harmonic")
    module = build(scene.system, "midpoint", path=scene_module_path(scene, "midpoint"))
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi, ensemble)
    Y0 = np.stack([np.cos(phase), np.sin(phase)], axis=1)

    def energy(Y, comp):
        # H = (q² + p²)/2 of the exact numerical state Y + comp, in extended precision:
        # a double-precision evaluation would put a floor of ~eps·H under the measurement.
        Z = Y.astype(np.longdouble) + comp.astype(np.longdouble)
        return (Z[:, 0] ** 2 + Z[:, 1] ** 2) / 2

    H0 = energy(Y0, np.zeros_like(Y0))
    out = {"ensemble": ensemble, "steps": steps, "h": h, "rows": []}
    record = np.unique(np.geomspace(10, steps, 40).astype(int))
    runs = []
    if module.EXTENDED_BITS > 53:
        runs.append(("round-off stop + compensated summation + extended refinement", h, {"extended": True}))
    else:
        out["note"] = (f"numpy.longdouble has {module.EXTENDED_BITS} bits here: "
                       "no extended-precision refinement row")
    runs += [("round-off stop + compensated summation", h, {}),
             ("tol=1e-12 stop, plain summation", h, {"tol": 1e-12, "compensated": False})]
    if dyadic:
        k = round(math.log2(h))
        runs.append((f"round-off stop + compensated summation, h = 2^{k}", 2.0 ** k, {}))
    for label, h, kw in runs:
        t0 = _cpu()
        Y = Y0.copy()
        info = {"compensation": np.zeros_like(Y0)}
        done = 0
        rms = []
        for target in _progress(record, progress, label):
            if target > done:
                Y = module.integrate(Y, h, int(target - done), info=info, check_resolution=check_resolution,
                                     **kw)[-1]
            done = target
            rms.append(float(np.sqrt(np.mean((energy(Y, info["compensation"]) - H0) ** 2))))
        sec = _cpu() - t0
        t = record * h
        rms = np.array(rms)
        keep = (rms > 0) & (t >= t[-1] / 100)
        slope = float(np.polyfit(np.log(t[keep]), np.log(rms[keep]), 1)[0]) if keep.sum() >= 3 else float("nan")
        out["rows"].append({"stepper": label, "h": h, "extended": bool(kw.get("extended")), "seconds": sec,
                            "slope": slope, "t": t.tolist(), "rms_energy_error": rms.tolist()})
    return out


# --- solver variants -------------------------------------------------------------------------

def solver_variants(scene: Scene, methods=None, *, steps: int = 2000, check_resolution: bool = True) -> dict:
    """Iterations and µs per step of each nonlinear solver, per implicit method, at the scene's h.

    ``check_resolution``: passed to ``integrate`` (``bench --no-check-resolution``: False); with
    it a step size estimated to under-resolve the motion is a row ``failed`` saying so.
    """
    scene = extended_scene(scene)
    methods = list(methods or scene.methods)
    y0 = np.array(scene.y0)
    rows = []
    for method in methods:
        module = build(scene.system, method, path=scene_module_path(scene, method))
        for solver in module.SOLVERS:
            info = {}
            t0 = time.perf_counter()
            try:
                traj = module.integrate(y0, scene.h, steps, solver=solver, info=info,
                                        check_resolution=check_resolution)
            except (RuntimeError, FloatingPointError) as exc:
                rows.append({"method": method, "solver": solver, "failed": str(exc)})
                continue
            sec = time.perf_counter() - t0
            H = module.hamiltonian(traj)
            rows.append({"method": method, "solver": solver,
                         "mean_iterations": float(info["newton_iterations"].mean()),
                         "us_per_step": sec / steps * 1e6,
                         "max_energy_error": max_abs_error(H, H[0])})
    return {"scene": scene.name, "steps": steps, "h": scene.h, "rows": rows}


# --- generation cost ----------------------------------------------------------------------

def nbody_system(n_bodies: int, G: float = 1.0, masses=None, name: str | None = None):
    """N bodies in 3D with pairwise gravity: ``H = Σ|p_b|²/(2m_b) - Σ G m_a m_b / r_ab``.

    Parameters ``G`` and ``m0`` … (``masses``, default all 1); body b is ``(xb, yb, zb)``,
    ``(pxb, pyb, pzb)``, as the ``[nbody]`` table expects.
    """
    from ..problem.problem import Hamiltonian

    q, p = [], []
    for b in range(n_bodies):
        q += [f"x{b}", f"y{b}", f"z{b}"]
        p += [f"px{b}", f"py{b}", f"pz{b}"]
    T = " + ".join(f"(px{b}**2 + py{b}**2 + pz{b}**2)/(2*m{b})" for b in range(n_bodies))
    U = " - ".join(f"G*m{a}*m{b}/sqrt((x{a} - x{b})**2 + (y{a} - y{b})**2 + (z{a} - z{b})**2)"
                   for a in range(n_bodies) for b in range(a + 1, n_bodies))
    masses = [1.0] * n_bodies if masses is None else list(masses)
    params = {"G": G, **{f"m{b}": float(masses[b]) for b in range(n_bodies)}}
    return Hamiltonian(f"{T} - {U}", q=q, p=p, params=params, name=name or f"nbody{n_bodies}")


def nbody_initial(n_bodies: int) -> np.ndarray:
    """Bodies on a circle (radius 1) in the xy plane, tangential velocities, slightly perturbed."""
    ang = 2 * np.pi * np.arange(n_bodies) / n_bodies
    q = np.stack([np.cos(ang), np.sin(ang), 0.05 * np.sin(3 * ang)], axis=1)
    v = 0.5 * np.stack([-np.sin(ang), np.cos(ang), np.zeros(n_bodies)], axis=1)
    v -= v.mean(axis=0)
    return np.concatenate([q.ravel(), v.ravel()])


def generation_cost(bodies=(2, 3, 4, 5, 6, 7, 8), methods=("energy-momentum", "midpoint"), *,
                    directory=None, steps: int = 200, verify: bool = False, progress: bool = False) -> dict:
    """Derive / (verify) / lower+emit time, file size and µs per step for the N-body family.

    ``derive_s`` + ``emit_s`` is what :func:`methodgen.build` spends before the module loads (numpy
    backend).  Measured (energy-momentum): 2 bodies 0.43 + 1.04 s, 8 bodies 0.87 + 1.02 s (1.3×); a
    fresh process's build and first step, 1.56 and 2.47 s.
    """
    import tempfile
    from pathlib import Path

    from ..codegen.emit import emit_source, load_module, signature, write_atomic

    directory = Path(directory or tempfile.mkdtemp(prefix="methodgen-nbody-"))
    rows = []
    for n in _progress(list(bodies), progress, "N-body"):
        system = nbody_system(n)
        for method in methods:
            t0 = time.perf_counter()
            # what build() derives; the lowering (in emit_s) takes from the scheme what the module
            # needs (forcing the expanded symbolic Jacobian here, as this used to, cost 10 of the
            # 13.7 s of 8 bodies, energy-momentum, where build's first use is 2.5 s)
            scheme = discretize(system, method)
            t_derive = time.perf_counter() - t0
            t_verify = None
            if verify:
                from ..symbolic.verify import verify as run_verify
                t0 = time.perf_counter()
                run_verify(scheme)
                t_verify = time.perf_counter() - t0
            t0 = time.perf_counter()
            src = emit_source(scheme, signature(system, method))
            path = directory / f"nbody{n}_{method.replace('-', '_')}.py"
            write_atomic(path, src)
            t_emit = time.perf_counter() - t0
            module = load_module(path)
            y0 = nbody_initial(n)
            # A speed measurement: the guard is off (close encounters of the bodies
            # would stop the run; the energy error is reported, not judged).
            row = {"bodies": n, "method": method, "derive_s": t_derive, "verify_s": t_verify,
                   "emit_s": t_emit, "total_s": t_derive + (t_verify or 0.0) + t_emit,
                   "file_kb": path.stat().st_size / 1024}
            try:
                module.integrate(y0, 0.01, 2, check_resolution=False)
                t0 = time.perf_counter()
                traj = module.integrate(y0, 0.01, steps, check_resolution=False)
                row["us_per_step"] = (time.perf_counter() - t0) / steps * 1e6
                H = module.hamiltonian(traj)
                row["energy_error"] = max_abs_error(H, H[0])
            except (RuntimeError, FloatingPointError) as exc:
                row["run_failed"] = str(exc)[:200]
            rows.append(row)
    return {"rows": rows, "directory": str(directory)}
