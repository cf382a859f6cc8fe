"""Claims about the step map itself: symplecticity (claims 7, 8) and symmetry (claim 9).

* Exact route: when the step map's Jacobian ``Φ'`` does not depend on the
  unknowns (explicit methods; implicit ones whose residual is linear in the
  unknowns and the state, i.e. linear vector fields), ``Φ' = I + ∂Δy/∂y0 -
  ∂Δy/∂z (∂R/∂z)⁻¹ ∂R/∂y0`` is computed symbolically and ``Φ'ᵀJΦ' - J`` is
  reduced to 0.
* Numerical route otherwise: ``Φ'`` from 60-digit central differences of the
  scheme's own step (Newton to full precision) at a few rational points; a
  defect far above the error bound is a refutation at an exact rational point
  (y0, h), evaluated in high precision (and said so).
"""

from __future__ import annotations

import random
import time
from typing import NamedTuple

import mpmath as mp
import sympy as sp

from ..derive import separable_split
from .common import system_domain
from .exact import certify, fmt_point
from .numeric import DPS, Stepper, param_point, random_state
from .report import NUMERICAL, REFUTED, Certificate

__all__ = ["symplectic_matrix", "step_jacobian", "symplectic_certificate", "splitting_symplectic", "explicit_symmetry",
           "residual_symmetry", "NUM_TOL"]

#: Tolerance of the 60-digit numerical checks (errors of the method itself are ~1e-38).
NUM_TOL = 1e-30
H_SAMPLE = sp.Rational(1, 10)


def symplectic_matrix(n: int) -> sp.Matrix:
    d = n // 2
    return sp.Matrix(sp.BlockMatrix([[sp.zeros(d), sp.eye(d)], [-sp.eye(d), sp.zeros(d)]]))


def step_jacobian(scheme) -> sp.Matrix | None:
    """Φ' symbolically when it is free of the unknowns (else None)."""
    y = sp.Matrix(scheme.system.y)
    inc = scheme.increment
    I = sp.eye(len(y))
    if not scheme.unknowns:
        return I + inc.jacobian(y)
    z = sp.Matrix(scheme.unknowns)
    Rz, Ry = scheme.residual.jacobian(z), scheme.residual.jacobian(y)
    Iz, Iy = inc.jacobian(z), inc.jacobian(y)
    fs = set(scheme.unknowns) | set(scheme.system.y)
    if any(M.free_symbols & fs for M in (Rz, Ry, Iz, Iy)):
        return None
    return I + Iy - Iz * Rz.LUsolve(Ry)


def _shear_lemma(d: int) -> bool:
    """``[[I, 0], [S, I]]`` and ``[[I, S], [0, I]]`` are symplectic for a generic symmetric d×d S."""
    if d not in _SHEAR:
        S = sp.Matrix(d, d, lambda i, j: sp.Symbol(f"_S{min(i, j) + 1}_{max(i, j) + 1}", real=True))
        I, Z, J = sp.eye(d), sp.zeros(d), symplectic_matrix(2 * d)
        ok = True
        for P in (sp.BlockMatrix([[I, Z], [S, I]]), sp.BlockMatrix([[I, S], [Z, I]])):
            P = sp.Matrix(P)
            ok = ok and all(sp.expand(e) == 0 for e in (P.T * J * P - J))
        _SHEAR[d] = ok
    return _SHEAR[d]


_SHEAR: dict[int, bool] = {}


class Splitting(NamedTuple):
    """A kick–drift splitting recomposed from ``H = T(p) + U(q)`` (:func:`recompose_splitting`)."""

    sep: object
    q: list
    p: list
    gradU: sp.Matrix
    gradT: sp.Matrix


def recompose_splitting(scheme) -> Splitting | None:
    """Recompose the stages recorded in ``scheme.structure`` (``{"kind": "splitting", "stages":
    [("kick", a), ("drift", b), ...]}``) from ``H = T(p) + U(q)`` and check that they *are*
    the scheme's increment; None when there is no such record, H is not separable, or the
    recomposition differs (then no structural argument may use the stages)."""
    st = scheme.structure or {}
    if st.get("kind") != "splitting":
        return None
    system = scheme.system
    sep = separable_split(system)
    if sep is None:
        return None
    qs, ps = list(system.q), list(system.p)
    gradU = sp.Matrix([sp.diff(sep.U, s) for s in qs])
    gradT = sp.Matrix([sp.diff(sep.T, s) for s in ps])
    q, p = sp.Matrix(qs), sp.Matrix(ps)
    for kind, a in st["stages"]:
        if kind == "kick":
            p = p - a * gradU.xreplace(dict(zip(qs, q)))
        elif kind == "drift":
            q = q + a * gradT.xreplace(dict(zip(ps, p)))
        else:
            return None
    inc = list(q - sp.Matrix(qs)) + list(p - sp.Matrix(ps))
    from .structural import _same
    if not all(_same(x, y) for x, y in zip(inc, scheme.increment)):
        return None
    return Splitting(sep, qs, ps, gradU, gradT)


def splitting_symplectic(scheme, claim: str) -> Certificate | None:
    """Explicit splitting methods: the step is a composition of symplectic shears (or None).

    The scheme records its stages (``structure = {"kind": "splitting", "stages":
    [("kick", a), ("drift", b), ...]}``).  The composition of the kicks
    ``(q, p) ↦ (q, p - a∇U(q))`` and drifts ``(q, p) ↦ (q + b∇T(p), p)`` is recomputed
    here from ``H = T(p) + U(q)`` and checked to *be* the scheme's increment; each
    stage's Jacobian is a shear ``[[I, 0], [-a∇²U, I]]`` / ``[[I, b∇²T], [0, I]]`` whose
    block is symmetric (checked: the Hessians are symmetric), and shears with a
    symmetric block are symplectic (proved for a generic symmetric block).  A product
    of symplectic matrices is symplectic (chain rule), so Φ' is.
    """
    t0 = time.perf_counter()
    st = scheme.structure or {}
    rec = recompose_splitting(scheme)
    if rec is None:
        return None
    system = scheme.system
    sep, qs, ps = rec.sep, rec.q, rec.p
    hess = [sp.hessian(sep.U, qs), sp.hessian(sep.T, ps)]
    d = system.dim
    if any(sp.expand(Hm[i, j] - Hm[j, i]) != 0 for Hm in hess for i in range(d) for j in range(i + 1, d)):
        return None
    if not _shear_lemma(d):
        return None
    names = " ∘ ".join(f"{k}({a})" for k, a in reversed(st["stages"]))
    return Certificate(claim + " (composition of symplectic shears)", "proved", "Φ'ᵀJΦ' - J",
                       r"\Phi'^T J \Phi' - J",
                       f"structural: Φ = {names} with kick(a): p -= a∇U(q), drift(b): q += b∇T(p) "
                       "(recomposed and checked equal to the scheme's increment); each stage's Jacobian "
                       "is a shear with a symmetric Hessian block (checked), and such shears are "
                       f"symplectic (proved for a generic symmetric {d}×{d} block, expand); products "
                       "of symplectic matrices are symplectic", time.perf_counter() - t0,
                       "symplecticity (section 1.2)", {"structural": True})


def _cayley_lemma(n: int) -> bool:
    """``(I + A)ᵀJ(I + A) = (I - A)ᵀJ(I - A)`` for ``A = JS/2``, S a generic symmetric n×n matrix."""
    if n not in _CAYLEY:
        S = sp.Matrix(n, n, lambda i, j: sp.Symbol(f"_S{min(i, j) + 1}_{max(i, j) + 1}", real=True))
        J = symplectic_matrix(n)
        A = J * S / 2
        I = sp.eye(n)
        _CAYLEY[n] = all(sp.expand(e) == 0 for e in ((I + A).T * J * (I + A) - (I - A).T * J * (I - A)))
    return _CAYLEY[n]


_CAYLEY: dict[int, bool] = {}


def midpoint_symplectic(scheme, claim: str) -> Certificate | None:
    """The midpoint rule ``y1 = y0 + hJ∇H(ȳ)`` is symplectic: Φ' is a Cayley transform (or None).

    Checked: the scheme's ∇̄H is ∇H at ȳ = (y0 + y1)/2 (structurally) and its Hessian S is
    symmetric.  Differentiating the equation gives ``(I - A) Φ' = I + A`` with
    ``A = (h/2) J S(ȳ)``, so ``Φ' = (I + A)(I - A)⁻¹`` (the factors commute) and
    ``Φ'ᵀJΦ' = (I - A)⁻ᵀ (I + A)ᵀJ(I + A) (I - A)⁻¹ = J`` by the lemma
    ``(I + A)ᵀJ(I + A) = (I - A)ᵀJ(I - A)`` — proved for a generic symmetric S (h absorbed).
    """
    from ..derive import gradient
    from .structural import _same
    t0 = time.perf_counter()
    if scheme.method != "midpoint" or scheme.discrete_gradient is None:
        return None
    system = scheme.system
    y0, y1 = list(system.y), list(scheme.y1)
    mid = {a: (a + b) / 2 for a, b in zip(y0, y1)}
    grad = gradient(system)
    if not all(_same(g, c.xreplace(mid)) for g, c in zip(scheme.discrete_gradient, grad)):
        return None
    Hs = sp.hessian(system.H, y0)
    n = len(y0)
    if any(sp.expand(Hs[i, j] - Hs[j, i]) != 0 for i in range(n) for j in range(i + 1, n)):
        return None
    if not _cayley_lemma(n):
        return None
    return Certificate(claim + " (Cayley transform)", "proved", "Φ'ᵀJΦ' - J", r"\Phi'^T J \Phi' - J",
                       "structural: ∇̄H = ∇H(ȳ) (checked on the scheme), so (I - A)Φ' = I + A with "
                       "A = (h/2)J∇²H(ȳ), ∇²H symmetric (checked); (I + A)ᵀJ(I + A) = (I - A)ᵀJ(I - A) "
                       f"for a generic symmetric {n}×{n} S (expand), hence Φ'ᵀJΦ' = J where I - A is "
                       "invertible (the step is defined)", time.perf_counter() - t0,
                       "symplecticity (section 1.2)", {"structural": True})


def collocation_symplectic(scheme, claim: str) -> Certificate | None:
    """Gauss collocation: symplectic because its coefficients satisfy b_i a_ij + b_j a_ji = b_i b_j
    (proved exactly in rational arithmetic by :mod:`.collocation`) [HLW06, Thm VI.4.3].

    The claim is the method's (exact coefficients); the module runs them rounded to float64,
    which satisfy the condition to ~1e-17 (the float64 certificate states it)."""
    st = scheme.structure or {}
    if st.get("kind") != "collocation":
        return None
    from .collocation import gauss_certificates

    t0 = time.perf_counter()
    symp = next(c for c in gauss_certificates(st["stages"]) if c.claim.startswith("symplectic"))
    return Certificate(claim + " (Runge–Kutta coefficients: b_i a_ij + b_j a_ji = b_i b_j)", symp.status,
                       symp.expression, "", "symplecticity condition of the coefficients (exact, rational) "
                       "+ HLW06 Thm VI.4.3", time.perf_counter() - t0, "HLW06 Thm VI.4.3",
                       {"coefficients": "float64 in the module (condition holds to ~1e-17)"})


def symplectic_certificate(scheme, points: int = 3, seed: int = 3) -> Certificate:
    """``Φ'ᵀ J Φ' = J``: exact when Φ' is computable in closed form, else 60-digit numerical."""
    t0 = time.perf_counter()
    system = scheme.system
    n = 2 * system.dim
    J = symplectic_matrix(n)
    claim = f"{scheme.method}: the step map is symplectic, Φ'ᵀ J Φ' = J"
    cert = (splitting_symplectic(scheme, claim) or midpoint_symplectic(scheme, claim)
            or collocation_symplectic(scheme, claim))
    if cert is not None:
        return cert
    P = step_jacobian(scheme)
    if P is not None:
        expr = P.T * J * P - J
        return certify(claim + " (Φ' in closed form)", expr, system_domain(system),
                       "symplecticity (section 1.2)")
    rng = random.Random(seed)
    step = Stepper(scheme, H_SAMPLE)
    worst, pts = mp.mpf(0), []
    Jm = mp.matrix(J.tolist())
    with mp.workdps(DPS):
        for _ in range(points):
            y0 = random_state(system, rng)
            cols = [step.derivative(y0, [1 if i == j else 0 for i in range(n)]) for j in range(n)]
            Pm = mp.matrix(n, n)
            for j, c in enumerate(cols):
                for i in range(n):
                    Pm[i, j] = c[i]
            D = Pm.T * Jm * Pm - Jm
            defect = max(abs(D[i, j]) for i in range(n) for j in range(n))
            pts.append({"y0": fmt_point(dict(zip(system.y, y0))), "defect": mp.nstr(defect, 5)})
            worst = max(worst, defect)
    det = {"h": str(H_SAMPLE), "params": fmt_point(param_point(system)), "sample_points": pts,
           "tolerance": NUM_TOL, "digits": DPS,
           "how": "Φ' by central differences (ε = 1e-22) of the scheme's step solved by 60-digit Newton"}
    if worst > 1e-15:
        det["evaluation"] = ("exact rational (y0, h); y1 and Φ' in 60-digit arithmetic: the defect is "
                             "> 1e-15, far above the evaluation error (< 1e-35)")
        det["counterexample"] = pts[[float(mp.mpf(p["defect"])) for p in pts].index(
            max(float(mp.mpf(p["defect"])) for p in pts))]
        return Certificate(claim, REFUTED, "Φ'ᵀJΦ' - J", r"\Phi'^T J \Phi' - J",
                           "60-digit evaluation at rational points", time.perf_counter() - t0,
                           "symplecticity", det)
    det["passed"] = bool(worst <= NUM_TOL)
    return Certificate(claim, NUMERICAL, "Φ'ᵀJΦ' - J", r"\Phi'^T J \Phi' - J",
                       "60-digit evaluation at rational points", time.perf_counter() - t0,
                       "symplecticity", det)


def explicit_symmetry(scheme) -> Certificate:
    """Explicit maps: ``Φ_{-h}(Φ_h(y0)) - y0`` reduced to 0."""
    system, h = scheme.system, scheme.h
    y = list(system.y)
    y1 = [a + b for a, b in zip(y, scheme.increment)]
    back = scheme.increment.subs({h: -h, **dict(zip(y, y1))}, simultaneous=True)
    expr = sp.Matrix([a + b - c for a, b, c in zip(y1, back, y)])
    return certify(f"{scheme.method}: symmetric, Φ_(-h)(Φ_h(y0)) = y0", expr,
                   system_domain(system), "symmetry (claim 9)")


def residual_symmetry(scheme) -> Certificate:
    """Unknowns = full increments Δy: ``R(-z; y0+z, -h) + R(z; y0, h) ≡ 0``.

    If z solves the forward equations then -z solves the adjoint ones from y1,
    which lead back to y0: the method is its own adjoint.
    """
    system, h = scheme.system, scheme.h
    z = list(scheme.unknowns)
    y = list(system.y)
    y1 = [a + b for a, b in zip(y, z)]
    R = scheme.residual
    back = R.subs({h: -h, **dict(zip(z, [-v for v in z])), **dict(zip(y, y1))}, simultaneous=True)
    return certify(f"{scheme.method}: symmetric, R(-Δ; y0 + Δ, -h) = -R(Δ; y0, h) for the "
                   "generated equations (the adjoint step solves the same system)",
                   back + R, system_domain(system), "symmetry (claim 9)")
