"""Symmetric projection of a symmetric explicit method onto H = H0 (and declared invariants).

The projected step [Hairer 2000; HLW06, §V.4.1] of a base step Φ_h (Störmer–Verlet or one of
its symmetric compositions) onto the level set ``g(y) = g(y_start)`` of the invariants
``g = (H, I_2, …)``, with ``G = ∂g/∂y`` their stacked gradients and ``D = diag(w) Gᵀ``, is

    ỹ0 = y0 + D(y0) λ,    ŷ1 = Φ_h(ỹ0),    y1 = ŷ1 + D(y1) λ,    g(y1) = g(y_start),

one unknown λ per invariant.  It keeps what the construction gives and nothing else:

* the invariants projected on, to the solve's round-off at every step (``g`` is the
  level of the *run's* initial state, so the error does not accumulate);
* symmetry, when Φ_h is symmetric: the step with ``-h`` from y1 is solved by ``-λ`` and
  returns to y0 (the argument of :func:`symmetry_argument`; :mod:`methodgen.symbolic.verify.projection`
  derives the claim from the base step's symmetry certificate and measures it on the
  60-digit projected step);
* the order of Φ_h (λ = O(h^{p+1}), so the projection moves the step by O(h^{p+1}));
* NOT symplecticity (the projection is not a symplectic map), and NOT an invariant
  the base method kept exactly but that is not projected on (energy-only projection
  of Störmer–Verlet loses its exact angular momentum on Kepler: ∇H is not tangent to
  the level set of L).

The direction of the correction is ``D(y) = diag(w) G(y)ᵀ`` rather than ``G(y)ᵀ``, with the
constant mass metric of :func:`metric` (``w = 1`` for unit masses); symmetry holds for any
constant w.  The solve (in the generated module, ``templates/_projection.py.j2`` and
``templates/numba_projection.py.j2``) is a quasi-Newton iteration on λ alone, Φ_h
re-evaluated at every iterate (its first-order expansion ``Φ_h(y0) + D(y0)λ`` would leave
the symmetry defect at O(h·|λ|) instead of round-off: 1.3e-5, 5.4e-7, 4.7e-8 measured on
Hénon–Heiles for orders 2, 4, 6 at h = 0.1, 0.2, 0.3, against 4e-16 to 6e-16;
``benchmarks/projection_symmetry.py``):

* λ starts from the previous step's value; the first y1 is built with D(ŷ1) (one extra
  evaluation of g and G), so ``y1 = ŷ1 + D(y1)λ`` holds to O(|λ|²) from the start;
* the residual is taken at the consistent ``y1 = ŷ1 + D(y1)λ`` to first order in the lag
  of D, so that the iterates lie on one smooth function of λ (the returned y1 is rebuilt
  with D(y1));
* the first matrix is ``G(y1)(D(y0) + D(y1))`` (exact up to ``Φ_h' = I + O(h)``; relative
  error 1.6e-3 measured on Hénon–Heiles at h = 0.1); Broyden's update (the secant slope for
  one invariant) improves it from the second iterate on;
* it stops when every residual ``g_a(y1) - g_a(start)`` is within 4 eps of the size of
  g_a's first-order terms (``Σ_i |∂g_a/∂y_i| max(|y0_i|, |y1_i|)``: scale-free, so the
  outer solar system's 1e4 ratio between |q| and |p| does not matter), or stopped
  decreasing at or below 64 eps of it; else it raises ConvergenceError with the step and
  the residual.  (Newton's sqrt(eps) plateau would accept a stagnating iteration here.)

Measured (Hénon–Heiles, H = 1/8, energy only): 7 iterations per step with the plain
simplified matrix, 4.2 with the above at h = 0.1 (order 2), 3.6 at h = 0.2 (order 4), 3.2
at h = 0.3 (order 6); at the step sizes of high-order runs 1.2-2 (the multiplier is then
near round-off).
"""

from __future__ import annotations

import dataclasses

import sympy as sp

from ..errors import InputError, MethodNotApplicable

__all__ = ["PROJECTIONS", "MAX_PROJECTED", "project_scheme", "projected_names", "symmetry_argument"]

#: ``project=`` values: "energy" (H alone) or "invariants" (H and every declared or
#: detected first integral the module monitors), symmetrically projected; with "-standard"
#: the standard projection of the same invariants (see :func:`project_scheme`).
PROJECTIONS = ("energy", "invariants", "energy-standard", "invariants-standard")
#: At most this many invariants (the m×m matrix is solved by elimination per iterate).
MAX_PROJECTED = 8


def projected_names(scheme, project: str) -> tuple[str, ...]:
    """The names of the invariants ``project`` selects for ``scheme`` (H first)."""
    names = tuple(inv.name for inv in scheme.invariants)
    if not names or names[0] != "H":
        raise MethodNotApplicable("symmetric projection needs H among the monitored invariants")
    project = project.removesuffix("-standard")
    if project == "energy":
        return ("H",)
    exact = tuple(inv.name for inv in scheme.invariants[1:] if inv.exact)
    return ("H",) + exact


def project_scheme(scheme, project, record: bool = True):
    """``scheme`` (symmetric, explicit, possibly composed) with symmetric projection, or with
    the standard projection for a ``project`` ending in ``-standard``.

    The standard projection [HLW06, §IV.4.1] is the same step without the shift of the start
    point: ``ŷ1 = Φ_h(y0)``, ``y1 = ŷ1 + D(y1)λ``, ``g(y1) = g(start)`` -- the projection of
    ŷ1 onto the level set along the metric's normal at y1.  Φ_h is evaluated once per step
    (the symmetric projection evaluates it once per iterate, at least twice a step whenever λ
    is above round-off), so the step costs the base step plus a few evaluations of g and G.
    It keeps the invariants projected on and the base step's order (the correction is the
    size of the base step's error in g, O(h^{p+1})); it is neither symmetric (the reverse
    step from y1 does not return to y0: measured by :mod:`methodgen.symbolic.verify.projection`) nor
    symplectic.

    Parameters
    ----------
    scheme : Scheme
    project : {"energy", "invariants"}
    record : bool
        Add ``("project", project)`` to the scheme's options (its key names the variant);
        False for a method name that stands for the projection itself.

    Raises
    ------
    InputError
        ``project`` is not one of :data:`PROJECTIONS`.
    MethodNotApplicable
        The base method is not symmetric and explicit, the system has constraints or is a
        Poisson system, or more than :data:`MAX_PROJECTED` invariants would be projected.
    """
    if not isinstance(project, str) or project not in PROJECTIONS:
        raise InputError(f"project must be one of {', '.join(PROJECTIONS)}, got {project!r}")
    t = scheme.traits
    kind = "standard" if project.endswith("-standard") else "symmetric"
    if t.solve != "explicit" or not t.symmetric:
        raise MethodNotApplicable(
            f"{kind} projection wraps a symmetric explicit method (stormer-verlet and its "
            f"compositions); {scheme.method} is {'not symmetric' if not t.symmetric else t.solve}")
    if scheme.system.constraints or scheme.structure_matrix is not None:
        raise MethodNotApplicable(f"{kind} projection is for unconstrained canonical systems here")
    names = projected_names(scheme, project)
    if len(names) > MAX_PROJECTED:
        raise MethodNotApplicable(f"{kind} projection onto {len(names)} invariants ({', '.join(names)}): "
                                  f"at most {MAX_PROJECTED} (use project='energy')")
    kept_base = [n for n in t.preserved if n not in names]
    symmetric = not project.endswith("-standard")
    if symmetric:
        note = (f"symmetric projection onto {', '.join(names)} (one quasi-Newton solve for "
                f"{len(names)} multiplier(s) per step, Φ_h re-evaluated per iterate); symmetric because "
                f"the base step is; order {t.order} kept; not symplectic")
    else:
        note = (f"standard projection onto {', '.join(names)} (Φ_h once per step, then a quasi-Newton "
                f"solve for {len(names)} multiplier(s) on g alone); order {t.order} kept; not symmetric, "
                f"not symplectic")
    note += f"; the base method's exact {', '.join(kept_base)} is not kept" if kept_base else ""
    traits = dataclasses.replace(t, symplectic=False, energy_preserving=True, preserved=names,
                                 solve="projection", symmetric=symmetric and t.symmetric,
                                 notes=t.notes + (note,))
    return dataclasses.replace(scheme, traits=traits, projection=names, projected_from=scheme,
                               projection_symmetric=symmetric,
                               options=tuple(scheme.options) + ((("project", project),) if record else ()))


def gradients(scheme) -> tuple[list[sp.Expr], list[sp.Expr], list[sp.Expr]]:
    """``g`` (the projected invariants), ``G`` row by row (flattened) and the metric ``w``,
    in y0 symbols and parameters (see :func:`metric`)."""
    by_name = {inv.name: inv.expr for inv in scheme.invariants}
    g = [by_name[n] for n in scheme.projection]
    G = [sp.diff(e, s) for e in g for s in scheme.system.y]
    return g, G, metric(scheme.system)


def metric(system) -> list[sp.Expr]:
    """The diagonal ``w`` of the projection's direction ``D(y) = diag(w) G(y)ᵀ``.

    For ``H = ½ pᵀ M⁻¹ p + U(q)`` with a diagonal mass matrix: ``w = (M⁻¹, M)``, so that
    ``δp_i = λ m_i ∂H/∂p_i`` and ``δq_i = λ (1/m_i) ∂H/∂q_i`` -- the correction of each
    body is the same fraction of its own momentum whatever its mass (in the Euclidean
    metric ``w = 1`` it is λ/m_i of it: 1e8 times the Sun's for Pluto on the outer solar
    system, whose trajectory it then spoils: final error 0.98 AU after 2e5 days where the
    unprojected step has 5e-4).  Units: the frequency that makes q and p commensurable is
    taken as 1 in the problem's units.  Else ``w = 1``.  Constant along the run, so the
    step stays symmetric.
    """
    from .derive import separable_split

    n = len(system.y)
    sep = separable_split(system) if not system.constraints else None
    Minv = None if sep is None else sep.Minv
    if Minv is None or any(Minv[i, j] != 0 for i in range(Minv.shape[0]) for j in range(Minv.shape[1])
                           if i != j):
        return [sp.Integer(1)] * n
    d = Minv.shape[0]
    return [Minv[i, i] for i in range(d)] + [1 / Minv[i, i] for i in range(d)]


def symmetry_argument(scheme) -> dict:
    """Why the projected step is symmetric: the argument, not a check (``holds`` is the
    base step's symmetry trait; the certificate is :mod:`methodgen.symbolic.verify.projection`'s).

    The projected map with ``-h`` from y1 is solved by ``-λ``: ``ỹ1 = y1 - G(y1)ᵀλ = ŷ1``,
    ``Φ_{-h}(ŷ1) = ỹ0`` (Φ symmetric), ``ỹ0 - G(y0)ᵀλ = y0`` -- the equations of the reverse
    step hold at y0 exactly, so symmetry holds whenever Φ_h is symmetric.  This is an
    argument from the structure; what it rests on is the base step's symmetry, which
    :mod:`methodgen.symbolic.verify` proves for the base method (``base``).
    """
    return {"holds": bool(scheme.traits.symmetric), "rests_on": "symmetry of the base step Φ_h",
            "how": "the reverse step from y1 with -h is solved by -λ and ends at y0"}
