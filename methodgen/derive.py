"""Symbolic analysis of a Hamiltonian: gradients, structure, invariants.

Pure SymPy, no numerics.  Each function derives one thing and is cached on the
(immutable) :class:`~methodgen.problem.Hamiltonian`, so a scheme asks only for
what it needs ("model only what the scene requires").

References
----------
.. [1] E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*,
   2nd ed., Springer 2006, ch. IV (first integrals) and VII.1 (constraints).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import sympy as sp

from .problem import Hamiltonian

__all__ = [
    "Invariant", "Separable", "gradient", "vector_field", "separable_split", "radial_profile",
    "angular_momenta", "invariants", "poisson_bracket", "PHYSICAL_ENERGY",
]


@dataclass(frozen=True)
class Invariant:
    """A monitored quantity ``I(q, p)``; ``exact`` if ``{I, H} = 0`` was shown symbolically."""

    name: str
    expr: sp.Expr
    exact: bool = True
    why: str = ""


@dataclass(frozen=True)
class Separable:
    """``H = T(p) + U(q)``; ``Minv`` is ``M⁻¹`` when ``T = ½ pᵀ M⁻¹ p`` (else None)."""

    T: sp.Expr
    U: sp.Expr
    Minv: sp.Matrix | None

    @property
    def quadratic_kinetic(self) -> bool:
        return self.Minv is not None

    @property
    def isotropic(self) -> bool:
        """``M⁻¹`` is a multiple of the identity (rotations act symplectically on T)."""
        if self.Minv is None:
            return False
        d = self.Minv.shape[0]
        c = self.Minv[0, 0]
        return all(sp.simplify(self.Minv[i, j] - (c if i == j else 0)) == 0
                   for i in range(d) for j in range(d))


def _cache(fn):
    """Cache a derivation per system object (systems are immutable)."""
    store: dict[int, tuple[Hamiltonian, object]] = {}

    @functools.wraps(fn)
    def wrapper(system: Hamiltonian):
        hit = store.get(id(system))
        if hit is not None and hit[0] is system:
            return hit[1]
        out = fn(system)
        store[id(system)] = (system, out)
        return out

    return wrapper


@_cache
def gradient(system: Hamiltonian) -> sp.Matrix:
    """∇H as a column of length 2d: ``(∂H/∂q, ∂H/∂p)``."""
    return sp.Matrix([sp.diff(system.H, s) for s in system.y])


@_cache
def vector_field(system: Hamiltonian) -> sp.Matrix:
    """``f(y) = J ∇H(y)`` with ``J = [[0, I], [-I, 0]]`` (column of length 2d)."""
    g = gradient(system)
    d = system.dim
    return sp.Matrix(list(g[d:]) + [-v for v in g[:d]])


@_cache
def separable_split(system: Hamiltonian) -> Separable | None:
    """Split ``H = T(p) + U(q)`` if possible, with the mass matrix when T is quadratic.

    The split is by additive terms of ``H`` (after ``expand`` if needed); a term
    mixing q and p makes the system non-separable.  ``T`` is quadratic when its
    Hessian in p is constant and ``T = ½ pᵀ (∂²T/∂p²) p`` exactly.
    """
    qs, ps = set(system.q), set(system.p)
    for H in (system.H, sp.expand(system.H)):
        T, U, ok = sp.S.Zero, sp.S.Zero, True
        for term in sp.Add.make_args(H):
            fs = term.free_symbols
            if fs & qs and fs & ps:
                ok = False
                break
            if fs & ps:
                T += term
            else:
                U += term
        if ok:
            break
    else:
        return None
    p = sp.Matrix(system.p)
    hess = sp.hessian(T, system.p)
    Minv = None
    if not (hess.free_symbols & (qs | ps)):
        if sp.expand(T - (p.T * hess * p)[0, 0] / 2) == 0:
            Minv = hess
    return Separable(T=T, U=U, Minv=Minv)


@_cache
def radial_profile(system: Hamiltonian) -> tuple[sp.Symbol, sp.Expr] | None:
    """If ``U(q) = V(|q|²)`` return ``(s, V(s))``, else None.

    ``V`` is found by restricting U to the first axis, ``V(s) = U(√s, 0, …, 0)``
    with ``s > 0``, and accepted only if ``U(q) - V(qᵀq)`` simplifies to 0.
    """
    sep = separable_split(system)
    if sep is None:
        return None
    U = sep.U
    s = sp.Symbol("_s", positive=True)
    if not (U.free_symbols & set(system.q)):
        return s, U
    first = {system.q[0]: sp.sqrt(s)}
    first.update({qi: sp.S.Zero for qi in system.q[1:]})
    try:
        V = U.xreplace(first)
    except (ZeroDivisionError, TypeError):  # pragma: no cover - defensive
        return None
    if V.has(sp.zoo, sp.nan, sp.oo):
        return None
    r2 = sum(qi**2 for qi in system.q)
    if sp.simplify(U - V.xreplace({s: r2})) != 0:
        return None
    return s, V


def poisson_bracket(system: Hamiltonian, F: sp.Expr, G: sp.Expr) -> sp.Expr:
    """``{F, G} = Σ ∂F/∂q_i ∂G/∂p_i - ∂F/∂p_i ∂G/∂q_i``."""
    return sp.Add(*[sp.diff(F, qi) * sp.diff(G, pi) - sp.diff(F, pi) * sp.diff(G, qi)
                    for qi, pi in zip(system.q, system.p)])


def _angular_bracket(system: Hamiltonian, i: int, j: int, F: sp.Expr) -> sp.Expr:
    """``{q_i p_j - q_j p_i, F}`` using ∂F from the cache (gradient of H) or one diff each."""
    if F is system.H:
        g = gradient(system)
        d = system.dim
        Fq_i, Fq_j, Fp_i, Fp_j = g[i], g[j], g[d + i], g[d + j]
    else:
        Fq_i, Fq_j = sp.diff(F, system.q[i]), sp.diff(F, system.q[j])
        Fp_i, Fp_j = sp.diff(F, system.p[i]), sp.diff(F, system.p[j])
    qi, qj, pi, pj = system.q[i], system.q[j], system.p[i], system.p[j]
    return pj * Fp_i - pi * Fp_j - qi * Fq_j + qj * Fq_i


def _is_zero(expr: sp.Expr, system: Hamiltonian) -> bool:
    """Exact zero test with a cheap numerical rejection first.

    ``expr`` is evaluated at two fixed points (floats); a clearly nonzero value
    rejects at once — most candidate invariants fail here, which keeps large
    systems (N bodies) fast.  Only survivors go to the exact test: ``expand``,
    then ``cancel``, then ``simplify``; the answer "zero" is always symbolic.
    """
    syms = sorted(expr.free_symbols, key=lambda s: s.name)
    for k in (3, 7):
        point = {s: sp.Float(0.37 + 0.11 * ((i * k) % 13), 30) for i, s in enumerate(syms)}
        try:
            val = complex(expr.xreplace(point).evalf(30))
        except (TypeError, ValueError, ZeroDivisionError):
            break
        if abs(val) > 1e-20:
            return False
    for reduce in (sp.expand, sp.cancel, sp.simplify):
        if reduce(expr) == 0:
            return True
    return False


def _angular_name(system: Hamiltonian, i: int, j: int) -> str:
    d = system.dim
    if d == 2:
        return "L"
    if d == 3:
        return {(1, 2): "Lx", (0, 2): "Ly", (0, 1): "Lz"}[(i, j)]
    return f"L_{system.q[i].name}_{system.q[j].name}"


@_cache
def angular_momenta(system: Hamiltonian) -> tuple[Invariant, ...]:
    """Components of angular momentum ``q × p`` that are first integrals.

    For each coordinate plane (i, j) the component ``L_ij = q_i p_j - q_j p_i``
    (in 3D ``(Lx, Ly, Lz) = q × p``) is kept if its Poisson bracket with H
    simplifies to exactly 0, i.e. H is invariant under rotations in that plane.
    Constrained systems are skipped (the constraint forces may break it).
    """
    d = system.dim
    if d < 2:
        return ()
    out = []
    for i in range(d):
        for j in range(i + 1, d):
            qi, qj, pi, pj = system.q[i], system.q[j], system.p[i], system.p[j]
            if d == 3 and (i, j) == (0, 2):
                L = qj * pi - qi * pj  # Ly = z px - x pz
            else:
                L = qi * pj - qj * pi
            # {L_ij, F} from the cached gradient of F (L is bilinear, so only four terms).
            if not all(_is_zero(_angular_bracket(system, i, j, F), system)
                       for F in [system.H, *system.constraints]):
                continue
            out.append(Invariant(_angular_name(system, i, j), L, True,
                                 f"{{{_angular_name(system, i, j)}, H}} = 0 exactly"))
    return tuple(sorted(out, key=lambda inv: inv.name) if d == 3 else out)


@_cache
def constraint_jacobian(system: Hamiltonian) -> sp.Matrix:
    """``G(q) = ∂g/∂q``, shape (m, d)."""
    return sp.Matrix(list(system.constraints)).jacobian(sp.Matrix(system.q))


@_cache
def constraint_monitors(system: Hamiltonian) -> tuple[Invariant, ...]:
    """The position constraints ``g_i(q)`` and the hidden velocity constraints ``(G M⁻¹ p)_i``.

    Both vanish along the exact flow on ``T*Q``; they are monitored like invariants.
    """
    if not system.constraints:
        return ()
    sep = separable_split(system)
    out = [Invariant(f"g{i + 1}", g, True, "position constraint g(q) = 0")
           for i, g in enumerate(system.constraints)]
    if sep is not None and sep.Minv is not None:
        v = constraint_jacobian(system) * sep.Minv * sp.Matrix(system.p)
        out += [Invariant(f"g{i + 1}_v", sp.expand(e), True, "velocity constraint G(q) M⁻¹ p = 0")
                for i, e in enumerate(v)]
    return tuple(out)


@_cache
def invariants(system: Hamiltonian) -> tuple[Invariant, ...]:
    """All monitored quantities: H first, then exact first integrals, then constraints."""
    out = ((Invariant("H", system.H, True, "the Hamiltonian"),) + angular_momenta(system)
           + constraint_monitors(system))
    tt = system.time_transform
    if tt is not None:
        # The original energy: constant on the level set K = 0 only ({H, K} = (H + e){H, g}),
        # so monitored, never claimed exact.
        out += (Invariant(PHYSICAL_ENERGY, tt.original.H, False,
                          "the original Hamiltonian H(q, p): constant (= −e) on the level set K = 0"),)
    return out


#: Name of the original Hamiltonian among the monitored quantities of a time-transformed system.
PHYSICAL_ENERGY = "H_phys"
