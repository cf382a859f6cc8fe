"""Claim 8: RATTLE (and SHAKE) on T*Q.

* ``g(q1) = 0``: the scheme's residual *is* ``g(q0 + Δq(ν))``; checked as an
  identity, so every solution of the Newton system lies on ``g = 0``.
* ``G(q1) M⁻¹ p1 = 0`` (RATTLE only): reduced with ``cancel`` for symbolic ν.
* Symmetry: RATTLE's defining equations E1..E4 with generic multipliers λ, μ
  map into combinations of themselves under (y0 ↔ y1, h → -h, λ ↔ μ), modulo
  the constraints at y0 (proved); the generated step is additionally run
  forward and back in 60-digit arithmetic (numerical).
* Symplecticity on T*Q: 60-digit numerical check of ``Bᵀ Φ'ᵀ J Φ' B = Bᵀ J B``
  on a basis B of the tangent space of the constraint manifold (labelled numerical).
"""

from __future__ import annotations

import random
import time

import mpmath as mp
import sympy as sp

from ..derive import constraint_jacobian, separable_split
from .common import REF_NOTES, at, system_domain
from .exact import certify, fmt_point
from .maps import NUM_TOL, symplectic_matrix
from .numeric import DPS, Stepper, param_point
from .report import NUMERICAL, PROVED, Certificate

__all__ = ["position_constraint", "velocity_constraint", "velocity_structural", "rattle_equations_symmetric",
           "numerical_symmetry", "manifold_point", "symplectic_on_manifold", "constrained_certificates",
           "constrained_items"]

REF = f"{REF_NOTES}, section 1.3 (RATTLE)"


def position_constraint(scheme) -> Certificate:
    system = scheme.system
    d = system.dim
    q1 = [a + b for a, b in zip(system.q, scheme.increment[:d])]
    g1 = sp.Matrix([at(g, system.q, q1) for g in system.constraints])
    return certify(f"{scheme.method}: g(q1) = 0 — the Newton residual is exactly g(q0 + Δq(ν))",
                   g1 - scheme.residual, system_domain(system), REF)


def _lusolve_lemma(m: int) -> bool:
    """``A·LUsolve(A, b) = b`` for a generic symmetric m×m matrix A and vector b.

    Decided in the rational-function field QQ(A_ij, b_i), where the nested
    quotients of the LU solution normalise at once (``cancel`` needs seconds
    already for m = 3).  Cached per m.
    """
    if m not in _LU_LEMMA:
        A, b = _generic_system(m)
        _LU_LEMMA[m] = field_zero(A * A.LUsolve(b) - b)
    return _LU_LEMMA[m]


def field_zero(exprs) -> bool:
    """Every entry of ``exprs`` (rational functions with rational coefficients) is 0 in QQ(symbols)."""
    exprs = list(exprs)
    gens = sorted(set().union(*(e.free_symbols for e in exprs)), key=str)
    if not gens:
        return all(e == 0 for e in exprs)
    K = sp.QQ.frac_field(*gens)
    return all(K.from_sympy(e) == K.zero for e in exprs)


_LU_LEMMA: dict[int, bool] = {}


def _generic_system(m: int):
    A = sp.Matrix(m, m, lambda i, j: sp.Symbol(f"_A{min(i, j) + 1}_{max(i, j) + 1}", real=True))
    b = sp.Matrix(sp.symbols(f"_b1:{m + 1}", real=True))
    return A, b


def _same(a, b) -> bool:
    from .structural import _same as same
    return same(a, b)


def velocity_structural(scheme) -> Certificate | None:
    """``G(q1) M⁻¹ p1 = 0`` for RATTLE from the recorded velocity stage; None if not that form.

    The scheme records ``p1 = w - G1ᵀ c`` with ``c = LUsolve(A1, b)``, ``A1 = G1 M⁻¹ G1ᵀ``,
    ``b = G1 M⁻¹ w``.  Checked structurally: p1 is that expression, G1 is ``G`` at the
    scheme's q1, A1 and b are those products, and c is the generic LU solution with
    A1 and b substituted.  Proved: ``A·LUsolve(A, b) = b`` for generic symmetric A
    (exact, in QQ(A, b)).  Then ``G1 M⁻¹ p1 = b - A1 c = 0`` wherever A1 is invertible
    (the step is defined).
    """
    t0 = time.perf_counter()
    st = scheme.structure or {}
    if st.get("kind") != "rattle":
        return None
    system = scheme.system
    sep = separable_split(system)
    d, m = system.dim, len(system.constraints)
    q1 = [a + b for a, b in zip(system.q, scheme.increment[:d])]
    p1 = [a + b for a, b in zip(system.p, scheme.increment[d:])]
    G1, w, A1, b, c = st["G1"], st["w"], st["A1"], st["b"], st["c"]
    M = sep.Minv
    checks = [
        all(_same(x, y) for x, y in zip(q1, st["q1"])),
        all(_same(x, y) for x, y in zip(at(constraint_jacobian(system), system.q, st["q1"]), G1)),
        all(_same(x, y) for x, y in zip(G1 * M * G1.T, A1)),
        all(_same(x, y) for x, y in zip(G1 * M * w, b)),
        all(_same(x, y) for x, y in zip(p1, w - G1.T * c)),
    ]
    if not all(checks):
        return None
    Ag, bg = _generic_system(m)
    inst = {**{Ag[i, j]: A1[i, j] for i in range(m) for j in range(i, m)},
            **{bg[i]: b[i] for i in range(m)}}
    if any(A1[i, j] != A1[j, i] for i in range(m) for j in range(m)):
        return None
    cg = Ag.LUsolve(bg)
    if not all(_same(x, y.xreplace(inst)) for x, y in zip(c, cg)):
        return None
    if not _lusolve_lemma(m):
        return None
    method = ("structural: p1 = w - G1ᵀc with G1 = G(q1), c = LUsolve(A1, b), A1 = G1M⁻¹G1ᵀ, "
              "b = G1M⁻¹w (checked on the scheme's expressions); A·LUsolve(A, b) = b proved for a "
              f"generic symmetric {m}×{m} A (exact, in QQ(A, b)); so G1M⁻¹p1 = b - A1c = 0")
    return Certificate(f"{scheme.method}: G(q1) M⁻¹ p1 = 0 (hidden velocity constraint), for every ν",
                       PROVED, "G(q1) M⁻¹ p1", "", method, time.perf_counter() - t0, REF,
                       {"structural": True})


def velocity_constraint(scheme) -> Certificate:
    cert = velocity_structural(scheme)
    if cert is not None:
        return cert
    system = scheme.system
    sep = separable_split(system)
    d = system.dim
    q1 = [a + b for a, b in zip(system.q, scheme.increment[:d])]
    p1 = sp.Matrix([a + b for a, b in zip(system.p, scheme.increment[d:])])
    G1 = at(constraint_jacobian(system), system.q, q1)
    if len(system.constraints) == 1:
        return certify(f"{scheme.method}: G(q1) M⁻¹ p1 = 0 (hidden velocity constraint), for every ν",
                       G1 * sep.Minv * p1, system_domain(system), REF)
    return velocity_projection_generic(system)


def velocity_projection_generic(system) -> Certificate:
    """With m >= 2 constraints the generated p1(ν) is too large to cancel in seconds, so the
    velocity stage's formula is proved for a generic point Q and vector W instead:
    ``G(Q) M⁻¹ (W - G(Q)ᵀ (G(Q) M⁻¹ G(Q)ᵀ)⁻¹ G(Q) M⁻¹ W) = 0``."""
    sep = separable_split(system)
    d = system.dim
    Q = sp.symbols(f"Q1:{d + 1}", real=True)
    W = sp.Matrix(sp.symbols(f"W1:{d + 1}", real=True))
    G = at(constraint_jacobian(system), system.q, Q)
    A = G * sep.Minv * G.T
    p1 = W - G.T * A.LUsolve(G * sep.Minv * W)
    cert = certify("rattle: the velocity stage p1 = w - G1ᵀ(G1M⁻¹G1ᵀ)⁻¹G1M⁻¹w satisfies "
                   "G(q1) M⁻¹ p1 = 0 for every q1 and w (formula of schemes/rattle.py with "
                   "generic q1 = Q, w = W)", G * sep.Minv * p1, system_domain(system), REF,
                   details={"note": "the generated p1(ν) itself is checked numerically "
                                    "(see the 60-digit certificates)"})
    return cert


def rattle_equations_symmetric(system) -> Certificate:
    """E(y1, y0, -h, μ, λ) is a combination of E(y0, y1, h, λ, μ) and the constraints at y0."""
    sep = separable_split(system)
    d, m = system.dim, len(system.constraints)
    h = sp.Symbol("h", real=True)
    q0, p0 = sp.Matrix(system.q), sp.Matrix(system.p)
    q1 = sp.Matrix(sp.symbols(f"Q1:{d + 1}", real=True))
    p1 = sp.Matrix(sp.symbols(f"P1:{d + 1}", real=True))
    lam = sp.Matrix(sp.symbols(f"lam1:{m + 1}", real=True))
    mu = sp.Matrix(sp.symbols(f"mu1:{m + 1}", real=True))
    G = constraint_jacobian(system)
    gradU = sp.Matrix([sp.diff(sep.U, s) for s in system.q])
    g = sp.Matrix(list(system.constraints))
    M = sep.Minv

    def E(qa, pa, qb, pb, hh, l, u):
        Ga, Gb = at(G, system.q, qa), at(G, system.q, qb)
        ga, gb = at(gradU, system.q, qa), at(gradU, system.q, qb)
        phalf = pa - hh / 2 * (ga + Ga.T * l)
        return (qb - qa - hh * M * phalf, pb - phalf + hh / 2 * (gb + Gb.T * u),
                at(g, system.q, qb), Gb * M * pb)

    E1, E2, E3, E4 = E(q0, p0, q1, p1, h, lam, mu)
    F1, F2, F3, F4 = E(q1, p1, q0, p0, -h, mu, lam)
    expr = sp.Matrix(list(F1 + E1 - h * M * E2) + list(F2 + E2) + list(F3 - g)
                     + list(F4 - G * M * p0))
    return certify("RATTLE's equations are self-adjoint: under (y0 ↔ y1, h → -h, λ ↔ μ) they map to "
                   "-E1 + hM⁻¹E2, -E2 and the constraints g(q0) = 0, G(q0)M⁻¹p0 = 0 (λ, μ generic)",
                   expr, system_domain(system), REF)


def manifold_point(system, rng: random.Random):
    """A point on T*Q: q projected onto g = 0 by Newton, p projected onto G M⁻¹ p = 0 (60 digits)."""
    sep = separable_split(system)
    pv = param_point(system)
    d = system.dim
    g = [sp.lambdify([list(system.q)], e.xreplace(pv), "mpmath") for e in system.constraints]
    G = sp.lambdify([list(system.q)], constraint_jacobian(system).xreplace(pv), "mpmath")
    Minv = mp.matrix(sep.Minv.xreplace(pv).tolist())
    with mp.workdps(DPS):
        q = mp.matrix([mp.mpf(rng.randint(-10, 10)) / 10 + mp.mpf("0.05") for _ in range(d)])
        for _ in range(80):   # Gauss-Newton: q <- q - Gᵀ(GGᵀ)⁻¹ g(q)
            r = mp.matrix([gi(list(q)) for gi in g])
            if mp.norm(r) < mp.mpf(10) ** (-(DPS - 5)):
                break
            Gm = mp.matrix(G(list(q)))
            q = q - Gm.T * mp.lu_solve(Gm * Gm.T, r)
        p = mp.matrix([mp.mpf(rng.randint(-10, 10)) / 10 for _ in range(d)])
        Gm = mp.matrix(G(list(q)))
        p = p - Gm.T * mp.lu_solve(Gm * Minv * Gm.T, Gm * Minv * p)
        return list(q) + list(p)


def _tangent_basis(system, y):
    """Columns spanning the tangent space of {g = 0, G M⁻¹ p = 0} at y (null space by SVD)."""
    sep = separable_split(system)
    pv = param_point(system)
    c = list(system.constraints) + list(constraint_jacobian(system) * sep.Minv * sp.Matrix(system.p))
    C = sp.Matrix(c).jacobian(sp.Matrix(system.y)).xreplace(pv)
    Cm = mp.matrix(sp.lambdify([list(system.y)], C, "mpmath")(y))
    n = Cm.cols
    k = len(c)
    square = mp.matrix(n, n)   # pad with zero rows so the SVD returns the full V
    for i in range(k):
        for j in range(n):
            square[i, j] = Cm[i, j]
    U, S, V = mp.svd_r(square)
    return [[V[i, j] for j in range(n)] for i in range(k, n)]


def numerical_symmetry(scheme, points: int = 2, seed: int = 5) -> Certificate:
    """Φ_{-h}(Φ_h(y0)) = y0 for the generated step, in 60 digits, at points on T*Q."""
    t0 = time.perf_counter()
    h = sp.Rational(1, 10)
    fwd, bwd = Stepper(scheme, h), Stepper(scheme, -h)
    rng = random.Random(seed)
    worst, pts = mp.mpf(0), []
    with mp.workdps(DPS):
        for _ in range(points):
            y0 = manifold_point(scheme.system, rng)
            y2 = bwd(fwd(y0))
            err = max(abs(a - b) for a, b in zip(y0, y2))
            worst = max(worst, err)
            pts.append({"y0": [mp.nstr(v, 20) for v in y0], "error": mp.nstr(err, 5)})
    return Certificate(f"{scheme.method}: the generated step is symmetric, Φ_(-h)(Φ_h(y0)) = y0 on T*Q",
                       NUMERICAL, "max |Φ_(-h)(Φ_h(y0)) - y0|", "", "60-digit evaluation on T*Q",
                       time.perf_counter() - t0, REF,
                       {"passed": bool(worst <= NUM_TOL), "tolerance": NUM_TOL, "h": str(h),
                        "params": fmt_point(param_point(scheme.system)), "sample_points": pts,
                        "digits": DPS})


def symplectic_on_manifold(scheme, points: int = 2, seed: int = 11) -> Certificate:
    """``ξᵀ Φ'ᵀ J Φ' η = ξᵀ J η`` for ξ, η tangent to T*Q (60-digit central differences)."""
    t0 = time.perf_counter()
    system = scheme.system
    n = 2 * system.dim
    Jm = mp.matrix(symplectic_matrix(n).tolist())
    h = sp.Rational(1, 10)
    step = Stepper(scheme, h)
    rng = random.Random(seed)
    worst, pts = mp.mpf(0), []
    with mp.workdps(DPS):
        for _ in range(points):
            y0 = manifold_point(system, rng)
            B = _tangent_basis(system, y0)
            images = [step.derivative(y0, b) for b in B]
            k = len(B)
            defect = mp.mpf(0)
            for i in range(k):
                for j in range(k):
                    before = (mp.matrix(B[i]).T * Jm * mp.matrix(B[j]))[0]
                    after = (mp.matrix(images[i]).T * Jm * mp.matrix(images[j]))[0]
                    defect = max(defect, abs(after - before))
            worst = max(worst, defect)
            pts.append({"y0": [mp.nstr(v, 20) for v in y0], "defect": mp.nstr(defect, 5)})
    return Certificate(f"{scheme.method}: symplectic on T*Q (the symplectic form restricted to the "
                       "constraint manifold is preserved)", NUMERICAL,
                       "max |ξᵀΦ'ᵀJΦ'η - ξᵀJη| over a tangent basis", "", "60-digit evaluation on T*Q",
                       time.perf_counter() - t0, REF,
                       {"passed": bool(worst <= NUM_TOL), "tolerance": NUM_TOL, "h": str(h),
                        "params": fmt_point(param_point(system)), "sample_points": pts,
                        "digits": DPS,
                        "how": "Φ'ξ by central differences (ε = 1e-22) of the 60-digit Newton step; "
                               "tangent basis from the SVD null space of the constraint Jacobian"})


def constrained_items(scheme) -> list[tuple[str, Certificate]]:
    """:func:`constrained_certificates` with what each is about: ``"constraint:position"``,
    ``"constraint:velocity"``, ``"symmetry"``, ``"symplectic"``."""
    out = [("constraint:position", position_constraint(scheme))]
    if any(n.endswith("_v") for n in scheme.traits.preserved):
        out.append(("constraint:velocity", velocity_constraint(scheme)))
    if scheme.traits.symmetric:
        out.append(("symmetry", rattle_equations_symmetric(scheme.system)))
        out.append(("symmetry", numerical_symmetry(scheme)))
    if scheme.traits.symplectic:
        out.append(("symplectic", symplectic_on_manifold(scheme)))
    return out


def constrained_certificates(scheme) -> list[Certificate]:
    """Constraints, symmetry and symplecticity on T*Q (see :func:`constrained_items`)."""
    return [cert for _, cert in constrained_items(scheme)]
