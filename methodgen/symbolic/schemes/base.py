"""The symbolic scheme: what a method needs the generator to emit.

A :class:`Scheme` is frozen data produced by one method builder (one small
file per method family in this package).  It holds

* ``unknowns`` ``z`` and the ``residual`` ``R(z; y0, h, params) = 0`` of the
  nonlinear system solved per step (implicit methods), or nothing (explicit);
* ``increment`` ``Δy(z; y0, h, params)``, so ``y1 = y0 + Δy`` (the update is
  applied with compensated summation at run time);
* ``guess``, the Newton starting value for ``z``;
* ``traits``: order, symmetry, symplecticity, energy preservation and the
  invariants the method preserves exactly for *this* system;
* for discrete-gradient methods, the discrete gradient ``∇̄H(y0, y1)`` itself
  (used by the verification layer).

Unknowns are *increments* (``Δq`` or ``Δy``), not end states: increments are
small, so Newton's stopping test and the update lose fewer digits, which is
what keeps the round-off error of long runs small.

Internal symbol names start with an underscore (user names cannot), so they
never collide with a user's coordinates or parameters:
``_h`` the step size, ``_d_<name>`` an increment, ``_n_<name>`` an end state.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property
from typing import Callable

import sympy as sp

from ..derive import (Invariant, _cache, _partials, _zero_status, first_integrals, gradient, invariants, plain_terms,
                      separable_gradients, separable_split, vector_field)
from ...problem.poisson import is_poisson
from ...problem.problem import Hamiltonian

STEP = sp.Symbol("_h", real=True)


def method_key(method: str, composition=None, options=()) -> str:
    """The name of a method variant in file names and signatures.

    ``method``, then ``-<option><value>`` for each option that selects a different
    scheme (``gauss-stages3``), then ``-order<K>-<family>`` for a composition.
    """
    key = method + "".join(f"-{k}{v}" for k, v in options)
    if composition is None or composition.order == 2:
        return key
    return f"{key}-order{composition.order}-{composition.family}"


def increment_symbol(s: sp.Symbol) -> sp.Symbol:
    return sp.Symbol("_d_" + s.name, real=True)


def next_symbol(s: sp.Symbol) -> sp.Symbol:
    return sp.Symbol("_n_" + s.name, real=True)


def latex_names(system: Hamiltonian) -> dict[sp.Symbol, str]:
    """LaTeX names for internal symbols: ``Δx``, ``x_1``, ``h``; user symbols get index 0."""
    names: dict[sp.Symbol, str] = {STEP: "h"}
    for s in system.y:
        base = sp.latex(s)
        names[increment_symbol(s)] = rf"\Delta {base}"
        names[next_symbol(s)] = rf"{{{base}}}_{{1}}"
    return names


@dataclass(frozen=True)
class Traits:
    """What a scheme claims, for this system.

    Attributes
    ----------
    order : int
        Classical order of convergence.
    symmetric : bool
        Φ_{-h} ∘ Φ_h = id.
    symplectic : bool
        The step map is symplectic (on the constraint manifold for RATTLE).
    energy_preserving : bool
        H(y1) = H(y0) exactly (up to the solve's round-off).
    preserved : tuple of str
        Names of monitored invariants the step preserves exactly.
    solve : str
        "newton", "linear" (one linear solve) or "explicit".
    discrete_gradient : bool
        The method is ``y1 = y0 + h J ∇̄H`` with a discrete gradient ∇̄H.
    notes : tuple of str
        How the scheme was derived (e.g. which cancelled form was used).
    approximate : tuple of str
        Invariants kept only up to a stated approximation error (e.g. AVF with a
        quadrature rule: H to O(‖Δy‖^16) per step).  They are *not* in
        ``preserved``, ``energy_preserving`` is False for them, and their
        certificates are numerical.
    """

    order: int
    symmetric: bool
    symplectic: bool
    energy_preserving: bool
    preserved: tuple[str, ...] = ()
    solve: str = "newton"
    discrete_gradient: bool = False
    notes: tuple[str, ...] = ()
    approximate: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        out = {
            "order": self.order, "symmetric": self.symmetric, "symplectic": self.symplectic,
            "energy_preserving": self.energy_preserving, "preserved": list(self.preserved),
            "solve": self.solve, "discrete_gradient": self.discrete_gradient,
            "notes": list(self.notes),
        }
        if self.approximate:   # only when used, so modules without it keep their bytes
            out["approximate"] = list(self.approximate)
        return out


@dataclass(frozen=True)
class LoopFamily:
    """One family of like potential terms, as a generated module loops over it.

    Attributes
    ----------
    family : methodgen.problem.families.TermFamily
        The template, its slots ``u`` (coordinates at y0) and ``w`` (parameters), and the
        index table of the instances.
    vslots : tuple of sympy.Symbol, length k
        The slots' increments ``v`` (``Δq`` of the slot's coordinate: the end point is
        ``u + v``).
    dg : tuple of sympy.Expr, length k
        The template's discrete gradient ``∇̄U_t(u, u + v)`` per slot.
    grad : tuple of sympy.Expr, length k
        The template's gradient ``∇U_t(u)`` per slot.
    """

    family: object
    vslots: tuple[sp.Symbol, ...]
    dg: tuple[sp.Expr, ...]
    grad: tuple[sp.Expr, ...]

    @cached_property
    def jacobian(self) -> tuple[tuple[sp.Expr, ...], ...]:
        """``∂dg_a/∂v_b`` (k × k), derived once: the Newton matrix's accumulated part and
        its sparsity pattern both read it."""
        return tuple(tuple(sp.diff(g, v) for v in self.vslots) for g in self.dg)


def loop_family(fam, dg_template) -> LoopFamily:
    """:class:`LoopFamily` of ``fam`` from its discrete gradient in start slots ``u`` and
    end slots ``next_symbol(u)`` (the end slots are rewritten as ``u + v``)."""
    v = tuple(sp.Symbol(f"_v{j}", real=True) for j in range(len(fam.slots)))
    end = {next_symbol(u): u + vj for u, vj in zip(fam.slots, v)}
    return LoopFamily(fam, v, tuple(sp.sympify(e).xreplace(end) for e in dg_template),
                      tuple(sp.diff(fam.template, u) for u in fam.slots))


#: A family of like terms with at least this many instances makes the module loop over
#: the families (:attr:`LoopPlan.looped`); below it the unrolled code is as small and faster.
LOOP_MIN_INSTANCES = 3


@dataclass(frozen=True)
class LoopPlan:
    """The step's equations with the potential's sums left as sums (loops in the module).

    ``residual``, ``increment`` and ``guess`` are the scheme's, with
    ``Σ_t ∇̄U_t(q0, q0 + Δq)`` replaced by the symbols ``A`` and ``Σ_t ∇U_t(q0)`` by ``F``
    (length d each); substituting the sums over :attr:`families` gives the scheme's own
    expressions back.
    """

    families: tuple[LoopFamily, ...]
    A: tuple[sp.Symbol, ...]
    F: tuple[sp.Symbol, ...]
    residual: sp.Matrix
    increment: sp.Matrix
    guess: sp.Matrix

    @property
    def largest(self) -> int:
        """Instances of the largest family."""
        return max((lf.family.size for lf in self.families), default=0)

    @property
    def looped(self) -> bool:
        """Whether the scheme's module loops by default (a family of at least
        :data:`LOOP_MIN_INSTANCES` instances; :func:`methodgen.codegen.lower.uses_loops`)."""
        return self.largest >= LOOP_MIN_INSTANCES


@dataclass(frozen=True, eq=False)
class Scheme:
    """A discretised system (see the module docstring).

    Attributes
    ----------
    system : Hamiltonian
    method : str
    traits : Traits
    unknowns : tuple of sympy.Symbol, length n (empty for explicit methods)
    residual : sympy.Matrix, shape (n, 1)
    guess : sympy.Matrix, shape (n, 1)
    increment : sympy.Matrix, shape (2d, 1)
    discrete_gradient : sympy.Matrix or None, shape (2d, 1), in ``y0`` and ``y1`` symbols
    invariants : tuple of Invariant
    description : str
    fixed_point : bool
        The residual has the form ``R(z) = z - F(z)``, so the fixed-point
        iteration ``z ← F(z)`` is available as a solver variant.
    resolution : str or None
        How the Newton Jacobian measures the local time scale: ``"full"`` when
        ``J ≈ I - (h/2) f'`` (so ``hω ≈ 2‖J - I‖``), ``"reduced"`` when
        ``J ≈ I + (h²/4) M⁻¹∇²U`` (so ``hω ≈ 2‖J - I‖^½``), None when not
        available.  Used by the generated step-size resolution guard.
    unknown_scale : sympy.Expr or None
        A magnitude the unknowns are measured against in Newton's stopping
        test, when ``|z|`` itself is not the right scale (RATTLE's scaled
        multipliers: positions).  None: ``|z|``.
    """

    system: Hamiltonian
    method: str
    traits: Traits
    unknowns: tuple[sp.Symbol, ...]
    residual: sp.Matrix
    guess: sp.Matrix
    increment: sp.Matrix
    discrete_gradient: sp.Matrix | None = None
    invariants: tuple[Invariant, ...] = ()
    description: str = ""
    unknown_scale: sp.Expr | None = None
    resolution: str | None = None
    fixed_point: bool = False
    options: tuple[tuple[str, object], ...] = field(default=())
    #: How the discrete gradient was assembled (e.g. Gonzalez: ∇H(ȳ), the numerator N,
    #: Itoh–Abe components), in y0/y1 symbols, for structural proofs; None when not recorded.
    structure: dict | None = None
    #: For a Poisson system: the structure matrix the step applies to ∇̄H, ``S̄`` in y0/y1
    #: symbols (``S((y0 + y1)/2)`` for the midpoint rule and the discrete gradients), for the
    #: proofs of :mod:`methodgen.symbolic.verify.poisson`; None for a canonical system (J).
    structure_matrix: sp.Matrix | None = None
    #: A symmetric composition Ψ_h = Φ_{γ_s h} ∘ … ∘ Φ_{γ_1 h} of this base step
    #: (:class:`methodgen.symbolic.compositions.Composition`), or None for the base method itself.
    #: The residual, increment etc. above are always those of the base step Φ_h; ``traits``
    #: are those of the composed method (order K).
    composition: object | None = None
    #: The step's equations with the potential's sums of like terms kept as sums
    #: (:class:`LoopPlan`), for modules that loop over them; None where not built.
    loops: LoopPlan | None = None
    #: An s-stage implicit method's stage system as structure (f, the tables;
    #: :class:`methodgen.symbolic.stages.StageSystem`): the module's residual and Newton matrix
    #: loop over the stages instead of expanding ``residual`` and its ``(s·n)²`` Jacobian.
    #: None for every other method.
    stage_system: object | None = None
    #: Names of the invariants a symmetric projection keeps (``H`` first,
    #: :mod:`methodgen.symbolic.projection`); empty for the method itself.
    projection: tuple[str, ...] = ()
    #: True for the symmetric projection, False for the standard one (the base step once, then
    #: onto the level set: cheaper, not symmetric); meaningful only with ``projection``.
    projection_symmetric: bool = True
    #: The scheme before the projection (its base step's claims are verified on it).
    projected_from: object | None = None

    h = STEP

    @property
    def key(self) -> str:
        """The method's name in file names and signatures: ``method`` for the base
        method, ``method-order<K>-<family>`` for a composition."""
        return method_key(self.method, self.composition, self.options)

    @property
    def base_traits(self) -> Traits:
        """Traits of the base step Φ_h (order 2) — equal to ``traits`` when not composed."""
        if self.composition is None:
            return self.traits
        # compose() raised the order from 2 and appended one note; undo both
        return Traits(**{**self.traits.__dict__, "order": 2, "notes": self.traits.notes[:-1]})

    def compose(self, composition) -> "Scheme":
        """This (symmetric, order-2) base scheme composed with ``composition``.

        The base step's equations are kept as they are (a generated module runs
        them once per stage with the step ``γ_i h``); the traits become those of
        the composition: order K; symmetry, symplecticity and every exactly
        preserved invariant are kept, because each stage is the base map with a
        different (real, possibly negative) step and the base properties hold for
        every h [HLW06, §II.4, §V.3].
        """
        if self.composition is not None:
            raise ValueError("this scheme is already a composition")
        if composition is None or composition.order == 2:
            return self
        t = self.traits
        if getattr(composition, "kind", None) == "splitting":
            note = (f"order {composition.order}{' (RKN: T quadratic, M constant)' if composition.rkn else ''}: "
                    f"symmetric splitting of T + U, {composition.family} family "
                    f"({composition.stages} stages; {composition.source})")
        else:
            note = (f"order {composition.order}: symmetric composition, {composition.family} family "
                    f"({composition.stages} stages; {composition.source})")
        traits = Traits(**{**t.__dict__, "order": composition.order, "notes": t.notes + (note,)})
        return dataclasses.replace(self, traits=traits, composition=composition)

    @property
    def y0(self) -> tuple[sp.Symbol, ...]:
        return self.system.y

    @property
    def y1(self) -> tuple[sp.Symbol, ...]:
        """Symbols of the end state used in :attr:`discrete_gradient`."""
        return tuple(next_symbol(s) for s in self.system.y)

    @cached_property
    def jacobian(self) -> sp.Matrix:
        """``∂R/∂z``, shape (n, n)."""
        if not self.unknowns:
            return sp.zeros(0, 0)
        return self.residual.jacobian(sp.Matrix(self.unknowns))

    @property
    def implicit(self) -> bool:
        return self.traits.solve == "newton"

    def equations(self) -> list[sp.Eq]:
        """The residual equations ``R_i(z) = 0`` as SymPy equalities."""
        return [sp.Eq(r, 0) for r in self.residual]

    def latex(self) -> str:
        names = latex_names(self.system)
        rows = [sp.latex(sp.Eq(r, 0), symbol_names=names) for r in self.residual]
        upd = [rf"{sp.latex(s)}_1 = {sp.latex(s)} + {sp.latex(d, symbol_names=names)}"
               for s, d in zip(self.system.y, self.increment)]
        return r"\begin{aligned}" + r"\\ ".join(rows + upd) + r"\end{aligned}"

    def _repr_latex_(self) -> str:
        return "$" + self.latex() + "$"

    def __str__(self) -> str:
        # the user's text: H itself may hold internal names (sinc_u for sin(u)/u)
        lines = [f"{self.method} scheme for H = {getattr(self.system, 'source', self.system.H)}"]
        t = self.traits
        lines.append(f"  order {t.order}, symmetric={t.symmetric}, symplectic={t.symplectic}, "
                     f"energy_preserving={t.energy_preserving}, preserves {list(t.preserved)}")
        if self.unknowns:
            lines.append(f"  unknowns: {', '.join(s.name for s in self.unknowns)}")
            for r in self.residual:
                lines.append(f"  0 = {r}")
        for s, d in zip(self.system.y, self.increment):
            lines.append(f"  {s.name}_1 = {s.name} + {d}")
        for n in t.notes:
            lines.append(f"  note: {n}")
        return "\n".join(lines)

    __repr__ = __str__


# ---------------------------------------------------------------------------
# Discrete-gradient–type methods: y1 = y0 + h J ∇̄H(y0, y1)
# ---------------------------------------------------------------------------

def _present(expr: sp.Expr, syms) -> list:
    """The symbols of ``syms`` that occur in ``expr``, in their order.

    A polynomial's monomials in these generators are its monomials in all of ``syms`` (the
    others have exponent 0), but a :class:`sympy.Poly` costs with the number of generators,
    not of the symbols used: ``Poly(p1, *y)`` over the 400 variables of a 200-particle chain
    takes ~20 ms, so a degree test per component grew as d².  Size-independent instead.
    """
    fs = sp.sympify(expr).free_symbols
    return [s for s in syms if s in fs]


def _poly(expr: sp.Expr, syms):
    """``Poly`` of ``expr`` in the symbols of ``syms`` it contains, or None if it is not a
    polynomial in them with coefficients free of them; ``(poly, gens)``, poly None for a
    constant (no generator)."""
    gens = _present(expr, syms)
    if not gens:
        return None, []
    poly = sp.Poly(expr, *gens)
    if poly.free_symbols_in_domain & set(syms):
        raise sp.PolynomialError("coefficients depend on the generators")
    return poly, gens


def _plain_monomials(expr: sp.Expr, syms) -> list[dict] | None:
    """The exponents in ``syms`` of the monomials of ``expr`` (:func:`methodgen.symbolic.derive.plain_terms`:
    exact where ``expr`` is a plain sum of monomials), or None where it is not plain."""
    terms = plain_terms(expr, syms)
    return None if terms is None else [m for _, m in terms]


def _degree_at_most(expr: sp.Expr, syms, k: int) -> bool:
    """``expr`` is a polynomial of total degree ≤ k in ``syms`` with coefficients free of them."""
    plain = _plain_monomials(expr, syms)
    if plain is not None:
        return all(sum(m.values()) <= k for m in plain)
    try:
        poly, _ = _poly(expr, syms)
    except sp.PolynomialError:
        return False
    return poly is None or poly.total_degree() <= k


def _is_quadratic(expr: sp.Expr, syms) -> bool:
    return _degree_at_most(expr, syms, 2)


def quadratic_invariants(system: Hamiltonian) -> tuple[str, ...]:
    """Names of the first integrals (``exact`` monitored invariants) that are quadratic
    (or linear) polynomials in y.

    Symplectic Runge–Kutta methods (the midpoint rule, Gauss collocation) preserve every
    quadratic first integral exactly [HLW06, Thm IV.2.2].  Monitored quantities that are
    not shown to be first integrals (a declared invariant with {I, H} ≠ 0, ``H_phys`` of a
    time-transformed system) are never listed.
    """
    return tuple(inv.name for inv in first_integrals(system) if _is_quadratic(inv.expr, system.y))


def _is_linear(expr: sp.Expr, syms) -> bool:
    return _degree_at_most(expr, syms, 1)


def linear_invariants(system: Hamiltonian) -> tuple[str, ...]:
    """Names of the first integrals that are linear in y, ``I = cᵀy`` (total momentum).

    ``cᵀf(y) ≡ 0`` then, so every method whose increment is a combination of values of
    f (Runge–Kutta methods: trapezoidal, Kahan's two forms) keeps I [HLW06, Thm IV.1.5].
    """
    return tuple(inv.name for inv in first_integrals(system) if _is_linear(inv.expr, system.y))


#: Expressions larger than this (count_ops) are not reduced when deciding a claim of the
#: traits: a claim that cannot be shown cheaply is not made (``verify`` never sees it).
CLAIM_OPS_LIMIT = 20000
#: Seconds a scheme may spend proving one such claim (where a budget can be enforced).
CLAIM_SECONDS = 20.0


def _claim_zero(expr: sp.Expr, system: Hamiltonian) -> bool:
    """``expr ≡ 0`` shown exactly (no floats), cheaply: a numerical rejection first, then
    ``expand``/``cancel`` (``simplify`` only for small expressions), under a size limit and
    a time budget.  False when not shown — the claim is then not made."""
    if expr == 0:
        return True
    if expr.has(sp.Float):
        return False
    try:
        if sp.count_ops(expr) > CLAIM_OPS_LIMIT:
            return False
    except Exception:   # pragma: no cover - count_ops on odd objects
        return False
    from ..verify.budget import BudgetExceeded, budget

    b = budget(CLAIM_SECONDS)
    try:
        with b:
            status = _zero_status(expr, system, simplify_limit=400)
            if status == "unknown":
                from ...problem.special import to_elementary
                elementary = to_elementary(expr)
                if elementary != expr:
                    status = _zero_status(elementary, system, simplify_limit=400)
            return status == "zero"
    except BudgetExceeded as exc:
        if exc.budget is not b:
            raise
        return False
    except Exception:
        return False


def splitting_invariants(system: Hamiltonian) -> tuple[str, ...]:
    """First integrals kept by a kick–drift splitting of ``H = T(p) + U(q)`` (Störmer–Verlet).

    For I affine in q (p fixed) and affine in p (q fixed) — ``qᵀDp + aᵀq + cᵀp``, so
    angular and linear momenta — a drift ``q += τ∇T(p)`` changes I by exactly
    ``τ ∂I/∂q · ∇T`` and a kick ``p -= τ∇U(q)`` by ``-τ ∂I/∂p · ∇U``.  I is claimed when
    both vanish identically (shown exactly); for ``qᵀDp`` this is HLW06 Thm IV.2.4, for
    ``cᵀp`` it says that c annihilates ∇U.
    """
    sep = separable_split(system)
    if sep is None:
        return ()
    d = system.dim
    q, p = list(system.q), list(system.p)
    gradT, gradU = separable_gradients(system)
    out = []
    for inv in first_integrals(system):
        if not _qp_degrees_within(inv.expr, system, lambda dq, dp: dq <= 1 and dp <= 1):
            continue
        drift = sp.Add(*[sp.diff(inv.expr, s) * g for s, g in zip(q, gradT)])
        if not _claim_zero(drift, system):
            continue
        weights = [sp.diff(inv.expr, s) for s in p]
        if _kick_zero_by_families(weights, system) or \
                _claim_zero(sp.Add(*[w * g for w, g in zip(weights, gradU)]), system):
            out.append(inv.name)
    return tuple(out)


def _kick_zero_by_families(weights, system: Hamiltonian) -> bool:
    """``Σ_k w_k ∂U/∂q_k ≡ 0`` shown once per family of like terms of U and weight pattern;
    False where not shown so (the caller then reduces the whole sum, as before).

    U is the sum of its families' instances ``F∘σ`` (:func:`~methodgen.symbolic.derive.potential_families`),
    so the sum is ``Σ_instances σ(Σ_j σ⁻¹(w_{i_j}) ∂F/∂u_j)`` wherever every weight of an
    instance's coordinates is a function of that instance's coordinates (and of anything
    but the other coordinates): instances with the same weights in slot symbols share one
    expression, and a renaming of 0 is 0.  A pair potential's bracket with a total linear or
    angular momentum cancels pair by pair: the 15 pairs of 6 bodies are one test of one pair
    (the outer solar system's kicks: 2 s → a fraction), instead of reducing the whole sum.
    Only a proof (:func:`_claim_zero` of each pattern, exact) answers True.
    """
    from ..derive import potential_families

    fams = potential_families(system)
    if not fams:
        return False
    q, params = list(system.q), list(system.params)
    qset = set(q)
    for fam in fams:
        grads = None
        seen = set()
        for k, idx in enumerate(fam.index):
            back = {q[i]: u for u, i in zip(fam.slots, idx)}
            if len(back) != len(idx):
                return False           # a coordinate in two slots: ∂ is not slot by slot
            pattern = []
            for i in idx:
                if weights[i].free_symbols & (qset - back.keys()):
                    return False       # a weight reads another instance's coordinate
                pattern.append(weights[i].xreplace(back))
            pattern = tuple(pattern)
            if pattern in seen:
                continue
            seen.add(pattern)
            if grads is None:
                grads = [sp.diff(fam.template, u) for u in fam.slots]
            if not _claim_zero(sp.Add(*[w * g for w, g in zip(pattern, grads)]), system):
                return False
    # every coordinate's weight outside U's families multiplies ∂U/∂q_k = 0 there
    return True


def _matvec(M: sp.Matrix, v: sp.Matrix) -> sp.Matrix:
    """``M v``, skipping the zero entries of M: the product a Matrix ``*`` forms term by term
    (``0 * v_j`` included) costs d² operations on v's (large) entries, the products of a
    diagonal mass matrix d."""
    n, m = M.shape
    return sp.Matrix([sp.Add(*[M[i, j] * v[j] for j in range(m) if M[i, j] != 0]) for i in range(n)])


def _shown_zero(expr: sp.Expr) -> bool:
    """``expr ≡ 0`` shown exactly: as constructed, by ``expand``, else by ``simplify``
    (the cheap reductions first: ``simplify`` of each of a 200-particle chain's momentum
    components took seconds in all, where the difference is 0 as built)."""
    return expr == 0 or sp.expand(expr) == 0 or sp.simplify(expr) == 0


def dg_linear_invariants(system: Hamiltonian, grad_bar: sp.Matrix, exclude=(), loops=None) -> tuple[str, ...]:
    """Linear first integrals ``I = cᵀy`` kept by ``y1 = y0 + h J ∇̄H``: those with
    ``cᵀJ∇̄H(y0, y1) ≡ 0``, shown exactly on this discrete gradient (within
    :data:`CLAIM_OPS_LIMIT` and :data:`CLAIM_SECONDS`; otherwise not claimed).

    With ``loops`` (the q-part of ∇̄H as sums over families of like terms, :class:`LoopFamily`;
    their sum is ∇̄H's q-part) the q-part's share is shown family by family first
    (:func:`_dg_linear_by_families`), at a cost independent of the number of instances; where
    that does not show it, the whole sum is reduced as without loops.
    """
    d = system.dim
    out = []
    for inv in first_integrals(system):
        if inv.name in exclude or not _is_linear(inv.expr, system.y):
            continue
        c = _partials(inv.expr, system.y)     # one pass over I's terms, not 2d diffs of the sum
        if loops and _dg_linear_by_families(system, c, grad_bar, loops):
            out.append(inv.name)
            continue
        # cᵀJ g = c_q · g_p − c_p · g_q
        e = sp.Add(*[c[i] * grad_bar[d + i] - c[d + i] * grad_bar[i] for i in range(d)])
        if _claim_zero(e, system):
            out.append(inv.name)
    return tuple(out)


def _dg_linear_by_families(system: Hamiltonian, c, grad_bar: sp.Matrix, loops) -> bool:
    """``cᵀJ∇̄H ≡ 0`` for constant ``c``, shown once per family and coefficient *pattern*.

    ``cᵀJ∇̄H = c_q·∇̄H_p − c_p·Σ_f Σ_k ∇̄U_{f,k}``, and instance k of family f contributes
    ``Σ_j c_{p, i_j} ∇̄T_j ∘ σ_k`` over its slots j (coordinate ``i_j``, template discrete
    gradient ``∇̄T_j``): the renaming σ_k of ``E = Σ_j c_{p,i_j} ∇̄T_j``.  Instances with the
    same coefficients ``(c_{p,i_j})_j`` share E, and E ≡ 0 (exact) gives 0 for all of them;
    with ``c_q·∇̄H_p ≡ 0`` as well the whole is 0 (a sum of zeros).  True only when every
    piece is shown 0; False means "not shown this way" (the pieces may still cancel).
    """
    d = system.dim
    if any(not ci.is_Rational for ci in c):
        return False
    pieces = [sp.Add(*[c[i] * grad_bar[d + i] for i in range(d)])]
    for lf in loops:
        fam = lf.family
        seen = set()
        for idx in fam.index:
            weights = tuple(c[d + i] for i in idx)
            if weights in seen:
                continue
            seen.add(weights)
            pieces.append(sp.Add(*[w * g for w, g in zip(weights, lf.dg)]))
    return all(_claim_zero(e, system) for e in pieces)


def gradient_scheme(system: Hamiltonian, method: str, dg: Callable[[tuple, tuple], sp.Matrix],
                    traits: Traits, description: str, reduce: bool = True, loops=None) -> Scheme:
    """Build the scheme ``y1 = y0 + h J ∇̄H(y0, y1)``.

    Parameters
    ----------
    dg : callable (y0, y1) -> Matrix (2d, 1)
        The (discrete) gradient in terms of the start and end states.
    loops : tuple of LoopFamily, optional
        The q-part of ``dg`` as sums over families of like terms (their sum must be
        ``dg``'s q-part); recorded as the scheme's :class:`LoopPlan` when the momenta are
        eliminated.

    Notes
    -----
    When ``H = ½ pᵀM⁻¹p + U(q)`` and the q-part of ∇̄H depends on q only while
    its p-part is ``M⁻¹(p0+p1)/2``, the momenta are eliminated:
    ``p1 = p0 - h ∇̄U(q0, q1)`` and ``q1 - q0 = h M⁻¹(p0 - h/2 ∇̄U)``, so Newton
    works on d unknowns ``Δq`` instead of 2d (a 3×3 system for Kepler instead
    of 6×6).  The start value is the Störmer–Verlet prediction.
    """
    if is_poisson(system):
        return _poisson_gradient_scheme(system, method, dg, traits, description)
    d = system.dim
    y0 = system.y
    y1 = tuple(next_symbol(s) for s in y0)
    grad_bar = dg(y0, y1)
    h = STEP
    sep = separable_split(system)
    p0 = sp.Matrix(system.p)
    p1s = set(y1[d:]) | set(system.p)
    reducible = (
        reduce and sep is not None and sep.Minv is not None
        and not any(e.free_symbols & p1s for e in grad_bar[:d])
    )
    if reducible:
        vbar = _matvec(sep.Minv, p0 + sp.Matrix(y1[d:]))     # once, not once per component
        reducible = all(_shown_zero(grad_bar[d + i] - vbar[i] / 2) for i in range(d))
    if reducible:
        z = tuple(increment_symbol(s) for s in system.q)
        zq = sp.Matrix(z)
        sub = {y1[i]: y0[i] + z[i] for i in range(d)}
        Gq = sp.Matrix([e.xreplace(sub) for e in grad_bar[:d]])
        residual = zq - h * _matvec(sep.Minv, p0 - h / 2 * Gq)
        increment = sp.Matrix(list(zq) + list(-h * Gq))
        # ∂H/∂q = ∂U/∂q (separable): the cached gradient, derived family by family where U
        # is a sum of like terms, instead of differentiating the whole sum d times
        gradU0 = sp.Matrix(list(gradient(system)[:d]))
        guess = h * _matvec(sep.Minv, p0 - h / 2 * gradU0)
        notes = ("momenta eliminated (separable H with quadratic kinetic energy): "
                 "Newton on Δq only",)
        resolution = "reduced"
        plan = None
        if loops:
            A = sp.Matrix([sp.Symbol(f"_sA{i}", real=True) for i in range(d)])
            F = sp.Matrix([sp.Symbol(f"_sF{i}", real=True) for i in range(d)])
            plan = LoopPlan(tuple(loops), tuple(A), tuple(F),
                            zq - h * sep.Minv * (p0 - h / 2 * A), sp.Matrix(list(zq) + list(-h * A)),
                            h * sep.Minv * (p0 - h / 2 * F))
    else:
        z = tuple(increment_symbol(s) for s in y0)
        zv = sp.Matrix(z)
        sub = {y1[i]: y0[i] + z[i] for i in range(2 * d)}
        G = sp.Matrix([e.xreplace(sub) for e in grad_bar])
        JG = sp.Matrix(list(G[d:]) + [-g for g in G[:d]])
        residual = zv - h * JG
        increment = zv
        guess = h * vector_field(system)
        notes = ()
        resolution = "full"
        plan = None
    if is_linear_field(system):
        # Linear f: the symmetric methods here are exact up to a phase error for
        # every h (Figure 1 of the notes uses h·ω ≈ 5 on purpose): no guard.
        resolution = None
    preserved = traits.preserved
    if traits.discrete_gradient:
        # A discrete-gradient method keeps a linear first integral cᵀy exactly when its
        # ∇̄H respects it: cᵀ(y1 - y0) = h cᵀJ∇̄H ≡ 0 (checked on this ∇̄H).
        preserved += dg_linear_invariants(system, grad_bar, exclude=preserved,
                                          loops=loops if reducible else None)
    traits = Traits(**{**traits.__dict__, "notes": traits.notes + notes, "preserved": preserved})
    return Scheme(system=system, method=method, traits=traits, unknowns=z, residual=residual,
                  guess=guess, increment=increment, discrete_gradient=grad_bar,
                  invariants=invariants(system), description=description, resolution=resolution,
                  fixed_point=True, loops=plan)


def _poisson_gradient_scheme(system, method: str, dg: Callable[[tuple, tuple], sp.Matrix],
                             traits: Traits, description: str) -> Scheme:
    """``y1 = y0 + h S(ȳ) ∇̄H(y0, y1)``, ``ȳ = (y0 + y1)/2``, for a Poisson system ``y' = S(y)∇H``.

    With the midpoint gradient this is the implicit midpoint rule ``y1 = y0 + h f(ȳ)``; with a
    discrete gradient, H is kept exactly because S(ȳ) is skew:
    ``H(y1) - H(y0) = ∇̄Hᵀ(y1 - y0) = h ∇̄Hᵀ S(ȳ) ∇̄H = 0`` [MQR99].  Newton works on Δy.

    A first integral I that is linear or quadratic in y is claimed kept when
    ``∇I(ȳ)ᵀ S(ȳ) ∇̄H(y0, y1) ≡ 0`` is shown exactly on this ∇̄H (then
    ``I(y1) - I(y0) = ∇I(ȳ)ᵀ(y1 - y0)`` vanishes): every Casimir of degree ≤ 2, since
    ``S(ȳ)∇C(ȳ) ≡ 0``.  Symplecticity is never claimed: the structure is not canonical
    (``traits.symplectic`` is False; for constant S the midpoint rule is a Poisson map, which
    is not certified here).

    References
    ----------
    .. [MQR99] McLachlan, Quispel, Robidoux, Phil. Trans. R. Soc. A 357 (1999) 1021-1045.
    """
    y0 = system.y
    n = len(y0)
    y1 = tuple(next_symbol(s) for s in y0)
    grad_bar = dg(y0, y1)
    h = STEP
    S_bar = sp.Matrix(system.S).xreplace({a: (a + b) / 2 for a, b in zip(y0, y1)})
    z = tuple(increment_symbol(s) for s in y0)
    zv = sp.Matrix(z)
    sub = {y1[i]: y0[i] + z[i] for i in range(n)}
    G = sp.Matrix([e.xreplace(sub) for e in grad_bar])
    residual = zv - h * S_bar.xreplace(sub) * G
    preserved = tuple(traits.preserved)
    mid = [(a + b) / 2 for a, b in zip(y0, y1)]
    for inv in first_integrals(system):
        if inv.name in preserved or not _is_quadratic(inv.expr, y0):
            continue
        gI = sp.Matrix([sp.diff(inv.expr, s) for s in y0]).xreplace(dict(zip(y0, mid)))
        if _claim_zero((gI.T * S_bar * grad_bar)[0, 0], system):
            preserved += (inv.name,)
    notes = ("Poisson system: y1 = y0 + h S(ȳ) ∇̄H with ȳ = (y0 + y1)/2, Newton on Δy; "
             "first integrals of degree <= 2 claimed where ∇I(ȳ)ᵀ S(ȳ) ∇̄H ≡ 0 is shown exactly",)
    energy = traits.energy_preserving or "H" in preserved
    traits = Traits(**{**traits.__dict__, "symplectic": False, "energy_preserving": energy,
                       "notes": traits.notes + notes, "preserved": preserved})
    resolution = None if is_linear_field(system) else "full"
    return Scheme(system=system, method=method, traits=traits, unknowns=z, residual=residual,
                  guess=h * vector_field(system), increment=zv, discrete_gradient=grad_bar,
                  invariants=invariants(system), description=description.replace(" J ", " S(ȳ) "),
                  resolution=resolution, fixed_point=True, structure_matrix=S_bar)


@_cache
def bilinear_invariants(system: Hamiltonian) -> tuple[str, ...]:
    """First integrals (``exact`` monitored invariants) of the form ``qᵀ D p`` (angular momentum).

    Symplectic partitioned RK methods such as Störmer–Verlet preserve exactly
    these quadratic first integrals [HLW06, Thm IV.2.4].  Cached per system (the
    energy–momentum method asks three times).
    """
    out = []
    # p before q: H's p²/2m rejects it at the first symbol, where ∂²H/∂x0² of a pair
    # potential is a large expression (the answer is the same: some symbol or none)
    pq = list(system.p) + list(system.q)
    for inv in first_integrals(system):
        if _second_power(inv.expr, pq):
            continue   # a monomial of degree ≥ 2 in one variable: not qᵀDp (H's p²/2m, at once)
        if _qp_degrees_within(inv.expr, system, lambda dq, dp: dq == 1 and dp == 1, constant=False):
            out.append(inv.name)
    return tuple(out)


def _second_power(expr: sp.Expr, syms) -> bool:
    """Some variable of ``syms`` in ``expr`` has a nonzero second derivative: ``expr`` is not
    bilinear.  A cheap rejection before the polynomial test (building the Poly of a large H in
    all its variables, e.g. an FPU chain of 64, took half of the derivation); a derivative that
    is 0 but not reduced to 0 only sends the expression on to that test."""
    for s in _present(expr, syms):
        if sp.diff(expr, s, 2) != 0:
            return True
    return False


def _qp_degrees_within(expr: sp.Expr, system: Hamiltonian, ok, constant: bool = True) -> bool:
    """``expr`` is a polynomial in y with coefficients free of y, and ``ok(deg_q, deg_p)``
    holds for each of its monomials (degree in q, degree in p); ``constant`` is the answer
    for an expression free of y.  The polynomial is taken in the symbols it contains
    (:func:`_present`), or read off the terms where they are plain (:func:`_plain_monomials`)."""
    plain = _plain_monomials(expr, system.y)
    if plain is not None:
        qs = set(system.q)
        if not any(plain):
            return constant
        return all(ok(sum(e for s, e in m.items() if s in qs), sum(e for s, e in m.items() if s not in qs))
                   for m in plain)
    try:
        poly, gens = _poly(expr, system.y)
    except sp.PolynomialError:
        return False
    if poly is None:
        return constant
    isq = [g in set(system.q) for g in gens]
    return all(ok(sum(e for e, iq in zip(m, isq) if iq), sum(e for e, iq in zip(m, isq) if not iq))
               for m in poly.monoms())


def is_linear_field(system: Hamiltonian) -> bool:
    """``f = J∇H`` is linear in y (H quadratic)."""
    return _field_degree(system) <= 1


def _field_degree(system: Hamiltonian) -> float:
    """Total polynomial degree of ``f = J∇H`` in y, with coefficients free of y (inf otherwise)."""
    deg = 0
    for fi in vector_field(system):
        plain = _plain_monomials(fi, system.y)
        if plain is not None:
            deg = max([deg] + [sum(m.values()) for m in plain])
            continue
        gens = _present(fi, system.y)
        if not gens:
            continue
        if not fi.is_polynomial(*gens):
            return float("inf")
        try:
            poly, _ = _poly(fi, system.y)
        except sp.PolynomialError:
            return float("inf")
        deg = max(deg, poly.total_degree())
    return deg


def is_quadratic_field(system: Hamiltonian) -> bool:
    """``f = J∇H`` is a polynomial of degree ≤ 2 in y (H cubic), coefficients free of y."""
    return _field_degree(system) <= 2


def midpoint_gradient(system: Hamiltonian) -> Callable:
    """∇H at the midpoint, as a function of (y0, y1)."""
    grad = gradient(system)

    def dg(y0, y1):
        mid = {a: (a + b) / 2 for a, b in zip(y0, y1)}
        return grad.xreplace(mid)

    return dg
