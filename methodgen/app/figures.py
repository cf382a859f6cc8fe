"""The lecture notes' two figures as data, and their captions as checked claims.

Everything here is plain numpy / SymPy (no matplotlib): :mod:`methodgen.app.plots`
draws what these functions return, and the tests check the same numbers the
figures show.

Figure 1 (notes §1.2)
    Linear Hamiltonian ``H = ½ yᵀAy``, ``A = [[10, 2], [2, 3]]``.  Implicit
    midpoint preserves quadratic invariants, so its iterates stay on the exact
    ellipse; in the coordinates ``z = A^{1/2} y`` that make the ellipse a circle
    the exact flow rotates by ``hω`` per step (``ω = √det A``) and the midpoint
    map — the Cayley transform of ``hJA`` — by ``2·arctan(hω/2)``: same
    trajectory, slower speed.

Figure 2 (notes §2)
    Hénon–Heiles-like cubic ``H = ½(q² + p²) + q²p − p³/3``: midpoint,
    trapezoidal and Kahan with ``h = 0.5`` on ``[0, 10 000]``.  The energy errors
    stay bounded (no drift), Kahan's is the largest, and Kahan's modified energy
    ``H̃ = H + h/3 ∇Hᵀ (I − h/2 f′)⁻¹ f`` (Celledoni, McLachlan, Owren, Quispel,
    J. Phys. A 46 (2013)) is conserved to round-off.
"""

from __future__ import annotations

import math

import numpy as np

from ..codegen.build import build, scene_module_path
from ..symbolic.scene import load_scene

__all__ = [
    "LINEAR_A", "FIG2_METHODS",
    "linear_exact", "normalising_map", "angles_per_step", "midpoint_angle", "check_angular_speed",
    "figure1_data", "figure1_checks",
    "energy_drift", "modified_energy_function", "figure2_data", "figure2_checks",
]

#: The matrix of Figure 1, ``H = ½ yᵀ A y`` with ``y = (q, p)``.
LINEAR_A = np.array([[10.0, 2.0], [2.0, 3.0]])

#: Methods of Figure 2, in the order of the notes.
FIG2_METHODS = ("midpoint", "trapezoidal", "kahan")

# Tolerances of the caption checks.  Round-off, not modelling error: the
# midpoint iterates of a linear system lie on the ellipse and rotate by the
# closed-form angle up to a few ulps per step (the Newton solve stops at 4 eps).
ANGLE_TOL = 1e-13          # radians, per step
ENERGY_TOL_LINEAR = 1e-13  # relative, whole run
# Kahan's modified energy is conserved by the map exactly; along a floating
# point run it random-walks with the per-step rounding, ~ eps·√N·|H̃|.
MODIFIED_ENERGY_TOL = 1e-12  # relative to |H̃(y0)|, whole run
# "No drift": the largest energy error in the last tenth of the run is at most
# this multiple of the largest in the first tenth (a bounded oscillation gives ~1).
DRIFT_FACTOR = 1.5


# --- Figure 1 ---------------------------------------------------------------------

def _linear_system_matrix(A: np.ndarray) -> np.ndarray:
    """``JA`` with ``q' = ∂H/∂p``, ``p' = −∂H/∂q``, i.e. ``J = [[0, 1], [−1, 0]]``."""
    J = np.array([[0.0, 1.0], [-1.0, 0.0]])
    return J @ A


def linear_exact(A: np.ndarray, y0, t) -> np.ndarray:
    """Exact solution ``exp(tJA) y0`` of the linear system, at the times ``t``.

    ``JA`` is trace-free with determinant ``det A``, so ``(JA)² = −ω² I`` and
    ``exp(tJA) = cos(ωt) I + sin(ωt)/ω · JA`` — closed form, no ``expm`` error.

    Parameters
    ----------
    A : ndarray, shape (2, 2)
        Symmetric positive definite.
    y0 : array_like, shape (2,)
    t : array_like, shape (m,)

    Returns
    -------
    ndarray, shape (m, 2)
    """
    A = np.asarray(A, dtype=float)
    w = math.sqrt(np.linalg.det(A))
    t = np.asarray(t, dtype=float)[:, None]
    y0 = np.asarray(y0, dtype=float)
    return np.cos(w * t) * y0 + np.sin(w * t) / w * (_linear_system_matrix(A) @ y0)


def normalising_map(A: np.ndarray) -> np.ndarray:
    """``A^{1/2}`` (symmetric square root): ``z = A^{1/2} y`` turns the ellipse ``H = c`` into a circle."""
    lam, V = np.linalg.eigh(np.asarray(A, dtype=float))
    return (V * np.sqrt(lam)) @ V.T


def angles_per_step(traj: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Signed angle between consecutive states in the coordinates ``z = A^{1/2} y``.

    Measured from the data only (``atan2`` of the cross and dot products of
    consecutive ``z``), so it is exactly what a map does per step, whatever
    formula we believe in.  Negative = clockwise, the direction of the exact flow.
    """
    z = np.asarray(traj, dtype=float) @ normalising_map(A).T
    a, b = z[:-1], z[1:]
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    dot = np.einsum("ij,ij->i", a, b)
    return np.arctan2(cross, dot)


def midpoint_angle(A: np.ndarray, h: float) -> float:
    """Closed-form signed angle per step of implicit midpoint: ``−2·arctan(hω/2)``, ``ω = √det A``.

    In ``z`` coordinates ``A^{1/2} J A^{1/2} = ω J`` (``MᵀJM = det(M) J`` in 2-D),
    so the exact flow is the clockwise rotation by ``hω`` and the midpoint map,
    its Cayley transform, the rotation by ``2·arctan(hω/2)``.
    """
    w = math.sqrt(float(np.linalg.det(np.asarray(A, dtype=float))))
    return -2.0 * math.atan(h * w / 2.0)


def check_angular_speed(traj: np.ndarray, A: np.ndarray, expected_angle: float,
                        tol: float = ANGLE_TOL) -> dict:
    """Does ``traj`` rotate by ``expected_angle`` per step (in ``z = A^{1/2} y``) to within ``tol``?

    Returns
    -------
    dict
        ``measured_mean``, ``expected``, ``max_deviation``, ``tol``, ``passed``.
    """
    ang = angles_per_step(traj, A)
    dev = float(np.max(np.abs(ang - expected_angle))) if ang.size else 0.0
    return {"measured_mean": float(np.mean(ang)) if ang.size else float("nan"),
            "expected": float(expected_angle), "max_deviation": dev, "tol": tol,
            "passed": bool(ang.size and dev <= tol)}


def _linear_midpoint_module():
    scene = load_scene("linear")
    return build(scene.system, "midpoint", path=scene_module_path(scene, "midpoint")), scene


def figure1_data(h_left: float = 1.0, n_left: int = 4, h_right: float = 0.5,
                 t_right: float = 200.0, y0=None) -> dict:
    """Data of Figure 1.

    Parameters
    ----------
    h_left, n_left : float, int
        Left panel: ``n_left`` midpoint steps of size ``h_left`` and the exact
        solution at ``t = n·h_left`` (the notes: ``h = 1``, ``n = 0 … 4``).
    h_right, t_right : float
        Right panel: midpoint with ``h_right`` on ``[0, t_right]`` (the notes: 0.5, 200).
    y0 : array_like, optional
        Initial state; default the ``linear`` scene's ``(1, 0)``.

    Returns
    -------
    dict
        ``A``, ``omega``, ``y0``, ``left`` (``h``, ``midpoint``, ``exact``),
        ``right`` (``h``, ``midpoint``, ``t``), ``ellipse`` (dense exact orbit).
    """
    module, scene = _linear_midpoint_module()
    y0 = np.array(scene.y0 if y0 is None else y0, dtype=float)
    A = LINEAR_A
    w = math.sqrt(np.linalg.det(A))
    # h·ω ≈ 5 on purpose (the figure shows the aliased rotation): no ResolutionWarning.
    left_mid = module.integrate(y0, h_left, n_left, check_resolution=False)
    left_exact = linear_exact(A, y0, h_left * np.arange(n_left + 1))
    n_right = int(round(t_right / h_right))
    right_mid = module.integrate(y0, h_right, n_right)
    ellipse = linear_exact(A, y0, np.linspace(0.0, 2 * math.pi / w, 721))
    return {"A": A, "omega": w, "y0": y0,
            "left": {"h": h_left, "midpoint": left_mid, "exact": left_exact},
            "right": {"h": h_right, "midpoint": right_mid, "t": h_right * np.arange(n_right + 1)},
            "ellipse": ellipse,
            "H": lambda y: 0.5 * np.einsum("...i,ij,...j->...", y, A, y)}


def figure1_checks(data: dict) -> dict:
    """The Figure 1 caption as numbers: same ellipse (H to round-off), slower, at the closed-form speed.

    Returns
    -------
    dict
        Per panel (``left``, ``right``): ``energy_max_rel_error``, ``angle``
        (see :func:`check_angular_speed`), ``exact_angle`` (``−hω``, what the
        exact flow does per step), ``slower`` (``|midpoint| < |exact|``) and
        ``passed``; and ``passed`` overall.
    """
    A, H = data["A"], data["H"]
    out = {}
    for panel in ("left", "right"):
        d = data[panel]
        traj, h = d["midpoint"], d["h"]
        H0 = H(traj[0])
        eH = float(np.max(np.abs(H(traj) - H0)) / abs(H0))
        ang = check_angular_speed(traj, A, midpoint_angle(A, h))
        exact_angle = -h * data["omega"]
        # The exact angle per step may exceed π (h = 1: hω ≈ 5.10), so compare speeds,
        # not wrapped angles.
        slower = abs(ang["expected"]) < abs(exact_angle)
        out[panel] = {"h": h, "steps": len(traj) - 1, "energy_max_rel_error": eH,
                      "energy_tol": ENERGY_TOL_LINEAR, "angle": ang, "exact_angle": exact_angle,
                      "slower": slower,
                      "passed": bool(eH <= ENERGY_TOL_LINEAR and ang["passed"] and slower)}
    out["passed"] = all(out[k]["passed"] for k in ("left", "right"))
    return out


# --- Figure 2 ---------------------------------------------------------------------

def energy_drift(err: np.ndarray, factor: float = DRIFT_FACTOR) -> dict:
    """Bounded or drifting?  Compare ``max |err|`` over the first and the last tenth of the run.

    Parameters
    ----------
    err : ndarray, shape (N+1,)
        Energy error ``H(y_n) − H(y_0)`` along the run.
    factor : float
        Allowed ratio last/first; a bounded oscillating error gives about 1,
        a linear drift about 9 (× the oscillation), a growing one more.

    Returns
    -------
    dict
        ``max``, ``first_tenth``, ``last_tenth``, ``ratio``, ``factor``, ``bounded``.
    """
    a = np.abs(np.asarray(err, dtype=float))
    n = len(a)
    k = max(1, n // 10)
    first, last = float(np.max(a[:k])), float(np.max(a[n - k:]))
    ratio = last / first if first > 0 else (1.0 if last == 0 else math.inf)
    return {"max": float(np.max(a)), "first_tenth": first, "last_tenth": last, "ratio": ratio,
            "factor": factor, "bounded": bool(np.isfinite(a).all() and ratio <= factor)}


def _modified_energy_expr_local(system):
    """``H + h/3 ∇Hᵀ (I − h/2 f′)⁻¹ f`` with ``f = J∇H`` (CMOQ 2013), derived here with SymPy."""
    import sympy as sp

    from ..symbolic.derive import gradient, vector_field
    from ..symbolic.schemes.base import STEP

    y = sp.Matrix(system.y)
    f = vector_field(system)
    A = sp.eye(len(y)) - STEP / 2 * f.jacobian(y)
    return system.H + STEP / 3 * (gradient(system).T * A.LUsolve(f))[0, 0]


def modified_energy_function(system=None):
    """Kahan's modified energy as a numpy function ``Ht(Y, h)`` (``Y`` shape (..., 2d)).

    Uses the verification layer's SymPy expression
    (:func:`methodgen.symbolic.verify.kahan.modified_energy_expr`, which the ``verify``
    command certifies symbolically) and lambdifies it.

    Returns
    -------
    (callable, sympy.Expr)
    """
    import sympy as sp

    from ..symbolic.schemes.base import STEP

    if system is None:
        system = load_scene("henon-heiles").system
    try:
        from ..symbolic.verify.kahan import modified_energy_expr
    except ImportError:  # verification layer not installed (e.g. a trimmed install): same formula here
        modified_energy_expr = _modified_energy_expr_local
    expr = modified_energy_expr(system)
    syms = list(system.y) + [STEP]
    f = sp.lambdify(syms, expr, "numpy")

    def Ht(Y, h):
        Y = np.asarray(Y, dtype=float)
        return np.asarray(f(*np.moveaxis(Y, -1, 0), h), dtype=float)

    return Ht, expr


def figure2_data(h: float = 0.5, t_final: float = 10_000.0, methods=FIG2_METHODS, y0=None) -> dict:
    """Data of Figure 2: the three runs, their energy errors and the Kahan modified energy.

    Parameters
    ----------
    h, t_final : float
        The notes: 0.5 and 10 000 (20 000 steps).
    methods : sequence of str
    y0 : array_like, optional
        Default the ``henon-heiles`` scene's ``(0, 0.5)``.

    Returns
    -------
    dict
        ``h``, ``t``, ``y0``, ``H0``, ``runs`` {method: trajectory},
        ``energy_error`` {method: H(y_n) − H(y_0)}, ``modified_energy`` (H̃ along
        the Kahan run, if Kahan is among the methods), ``modified_energy_expr``
        (str), ``H`` (numpy function of states).
    """
    scene = load_scene("henon-heiles")
    y0 = np.array(scene.y0 if y0 is None else y0, dtype=float)
    steps = int(round(t_final / h))
    runs, errs = {}, {}
    module = None
    for m in methods:
        module = build(scene.system, m, path=scene_module_path(scene, m))
        traj = module.integrate(y0, h, steps)
        runs[m] = traj
        H = module.hamiltonian(traj)
        errs[m] = H - H[0]
    out = {"h": h, "t": h * np.arange(steps + 1), "y0": y0,
           "H0": float(module.hamiltonian(y0)) if module is not None else float("nan"),
           "runs": runs, "energy_error": errs, "H": module.hamiltonian if module is not None else None}
    if "kahan" in runs:
        Ht, expr = modified_energy_function(scene.system)
        out["modified_energy"] = Ht(runs["kahan"], h)
        out["modified_energy_expr"] = str(expr)
    return out


def figure2_checks(data: dict, factor: float = DRIFT_FACTOR, tol: float = MODIFIED_ENERGY_TOL) -> dict:
    """The Figure 2 caption as numbers.

    Returns
    -------
    dict
        ``drift`` {method: :func:`energy_drift`}, ``all_bounded``,
        ``kahan_largest`` (Kahan's max energy error exceeds every other
        method's), ``modified_energy`` (``max_rel_drift``, ``tol``, ``passed``),
        ``passed``.
    """
    drift = {m: energy_drift(e, factor) for m, e in data["energy_error"].items()}
    out = {"drift": drift, "all_bounded": all(d["bounded"] for d in drift.values())}
    if "kahan" in drift and len(drift) > 1:
        out["kahan_largest"] = all(drift["kahan"]["max"] > d["max"] for m, d in drift.items() if m != "kahan")
    if "modified_energy" in data:
        Ht = data["modified_energy"]
        rel = float(np.max(np.abs(Ht - Ht[0])) / abs(Ht[0]))
        out["modified_energy"] = {"initial": float(Ht[0]), "max_rel_drift": rel, "tol": tol,
                                  "passed": bool(rel <= tol)}
    out["passed"] = bool(out["all_bounded"] and out.get("kahan_largest", True)
                         and out.get("modified_energy", {"passed": True})["passed"])
    return out
