"""Poincaré time transformation: a fixed fictive step through close encounters.

For ``H(q, p)`` and a positive function ``g(q)`` the Hamiltonian

    K(q, t, p, e) = g(q) · (H(q, p) + e)

on the extended phase space (coordinates ``q, t``; momenta ``p, e``) has the
equations ``q' = g ∂H/∂p``, ``p' = −g ∂H/∂q − (H + e) ∇g``, ``t' = g``, ``e' = 0``
(' = d/dτ, τ the fictive time).  On the level set K = 0 — reached by starting
from ``e = −H(q0, p0)``, where ``g > 0`` — the second term vanishes and
``dq/dt = ∂H/∂p``, ``dp/dt = −∂H/∂q``: the original flow, with physical time
``t(τ) = ∫ g dτ`` carried along as a coordinate.  A method with a fixed step Δτ
then takes physical steps ``Δt ≈ g(q) Δτ``: with ``g = |q|`` (or ``|q|^{3/2}``)
short near a Kepler pericentre, long at apocentre.  Every method and order
applies to K like to any Hamiltonian; a method that preserves K exactly (the
discrete gradients) keeps ``H = −e`` exactly on K = 0 (``e`` is constant because
K does not depend on t).  [HLW06, §VIII.2; Hairer 1997].

A time-dependent ``H(q, p, t)`` (``Hamiltonian(..., time="t")``) is made autonomous by
the same construction with ``g = 1`` (:func:`autonomise`): ``K = H(q, p, t) + e`` on
``(q, t; p, e)`` has ``t' = 1`` (the fictive time is the physical time),
``q' = ∂H/∂p``, ``p' = −∂H/∂q`` — the flow of H(t) — and ``e' = −∂H/∂t``; K is
autonomous, so every method applies, and K = H + e is a first integral (a discrete
gradient keeps it exactly: ``H = −e`` along the run from ``e0 = −H(q0, p0, t0)``).
A time-dependent system may also be time-transformed: ``K = g(q)(H(q, p, t) + e)``
[HLW06, §VIII.2].

The *logarithmic Hamiltonian* (``time_transform(system, form="log")``) keeps a separable
``H = T(p) + U(q)`` with ``U < 0`` separable: on the same extended phase space

    Λ(q, t, p, e) = log(T(p) + e) − log(−U(q))  =  A(p, e) + B(q)

has ``q' = ∇T/(T + e)``, ``t' = 1/(T + e)``, ``p' = −∇U/(−U)``, ``e' = 0``; on the level
set Λ = 0 (``e = −H(q0, p0)``, where ``T + e = −U``) this is the original flow with
``dt/dτ = 1/(−U)`` — the Poincaré transformation with ``g = −1/U``, since
``Λ = log(1 + g (H + e))``.  Λ is a sum of a function of the momenta and a function of the
coordinates, so Störmer–Verlet, its first-same-as-last form and its compositions to order 10
apply unchanged and stay explicit (the time-transformed leapfrog).  For Kepler
(``U = −k/r``) the drift–kick–drift leapfrog on Λ follows the exact Kepler ellipse at any step
size, with an error in the phase only [MT99, PT99]; the kick–drift–kick one does not.  So the
system is ``−Λ`` on the *exchanged* state ``(p…, e; q…, t)`` (coordinates first): there
Störmer–Verlet (kick–drift–kick) is the drift–kick–drift leapfrog of Λ
(:attr:`TimeTransform.exchanged`; generated ``initial_state``/``physical_state`` follow this
layout).  [BI12] analyse explicit adaptive symplectic schemes built on Sundman and Poincaré
transformations, of which this is one.  It applies where U < 0 along the motion: where
U ≥ 0, ``log(−U)`` is not defined (the runtimes check ``−U > 0`` and ``T + e > 0`` at every
step and stop with the step and state); a bound motion (H < 0) never gets there (U ≤ H).
The time-transformed leapfrog with an arbitrary ``Ω(q)`` and an auxiliary variable W (TTL,
Mikkola & Aarseth 2002) is not a Hamiltonian splitting of a fixed extended system and is not
offered.  :func:`methodgen.runtime.physical_time.run_to_time` runs a module to a physical time.

References
----------
.. [MT99] S. Mikkola, K. Tanikawa, Explicit symplectic algorithms for time-transformed
   Hamiltonians, Celest. Mech. Dyn. Astron. 74 (1999) 287–295.
.. [PT99] M. Preto, S. Tremaine, A class of symplectic integrators with adaptive time step
   for separable Hamiltonian systems, Astron. J. 118 (1999) 2532–2541.
.. [BI12] S. Blanes, A. Iserles, Explicit adaptive symplectic integrators for solving
   Hamiltonian systems, Celest. Mech. Dyn. Astron. 114 (2012) 297–317.
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §VIII.2 (Poincaré transformation).
.. [Hai97] E. Hairer, Variable time step integration with symplectic methods,
   Appl. Numer. Math. 25 (1997) 219–227.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import sympy as sp

from ..errors import InputError
from ..problem.parse import check_smooth, parse_expr
from ..problem.special import fold_removable_quotients
from ..problem.problem import Hamiltonian

__all__ = ["TimeTransform", "time_transform", "autonomise", "FORMS"]

#: The forms of :func:`time_transform`.
FORMS = ("poincare", "log")

_TIME_NAMES = ("t", "time", "t_")
_ENERGY_NAMES = ("e", "energy", "e_")


@dataclass(frozen=True)
class TimeTransform:
    """How a time-transformed system ``K = g(q)(H + e)`` was made from its original.

    Attributes
    ----------
    g : sympy.Expr
        The time scaling, a function of the original coordinates (and parameters).
    g_source : str
    original : Hamiltonian
        The system ``H(q, p)``.
    time, energy : sympy.Symbol
        The new coordinate (physical time t) and its momentum e (on K = 0, e = −H).
    """

    g: sp.Expr
    g_source: str
    original: Hamiltonian
    time: sp.Symbol
    energy: sp.Symbol
    #: ``"poincare"``: ``K = g(q)(H + e)``; ``"log"``: the logarithmic Hamiltonian
    #: ``Λ = log(T(p) + e) − log(−U(q))`` (``g = −1/U`` is its dt/dτ on Λ = 0).
    form: str = "poincare"

    @property
    def exchanged(self) -> bool:
        """The state is ``(p…, e, q…, t)`` (the log form), not ``(q…, t, p…, e)``."""
        return self.form == "log"

    def fingerprint(self) -> str:
        parts = [sp.srepr(self.g), self.original.fingerprint(), self.time.name, self.energy.name]
        if self.form != "poincare":       # the Poincaré fingerprints stay what they were
            parts.append("form=" + self.form)
        text = "\n".join(parts)
        return hashlib.sha256(text.encode()).hexdigest()

    @property
    def autonomised(self) -> bool:
        """``g = 1``: the autonomous extension ``K = H(q, p, t) + e`` of a time-dependent H
        (:func:`autonomise`); the fictive time is the physical time."""
        return self.g == 1


def _free_name(candidates, taken, what):
    for name in candidates:
        if name not in taken:
            return name
    raise InputError(f"no free name for the {what}: {', '.join(candidates)} are all taken")


def time_transform(system: Hamiltonian, g=None, *, form: str = "poincare",
                   name: str | None = None) -> Hamiltonian:
    """The Poincaré time-transformed system ``K = g(q) (H(q, p) + e)``, or with ``form="log"``
    the logarithmic Hamiltonian ``Λ = log(T(p) + e) − log(−U(q))`` (module docstring).

    Parameters
    ----------
    system : Hamiltonian
        The original system (constraints are kept: they depend on q only).  A time-dependent
        H(q, p, t) (``time="t"``) gives ``K = g(q)(H(q, p, t) + e)`` with its declared time
        as the new coordinate (``e`` is then not constant: ``de/dτ = −g ∂H/∂t``).
    g : str or sympy.Expr
        A smooth function of the coordinates (and parameters), positive along the
        motion, e.g. ``"sqrt(x**2 + y**2 + z**2)"``.  Text is parsed with the
        whitelist parser (never evaluated).
    form : {"poincare", "log"}
        ``"poincare"`` (default) needs ``g``.  ``"log"`` takes no g (it is ``−1/U``): it
        needs an autonomous separable ``H = T(p) + U(q)`` without constraints and
        ``U < 0`` along the motion, and gives a separable Λ on which Störmer–Verlet and its
        compositions are explicit [MT99, PT99, BI12].
    name : str, optional
        Name of the new system (default ``<name>-tt``).

    Returns
    -------
    Hamiltonian
        State ``(q…, t, p…, e)``: the physical time ``t`` is the last coordinate,
        its conjugate ``e`` the last momentum.  ``K.time_transform`` records g and
        the original system; generated modules offer ``initial_state(y0, t0)``.
        With ``form="log"``: ``K = log(−U) − log(T + e)`` (= −Λ) on the exchanged state
        ``(p…, e, q…, t)``, named ``<name>-log``, ``K.time_transform.g = −1/U``.

    Examples
    --------
    >>> import methodgen as mg
    >>> kepler = mg.Hamiltonian("(px**2 + py**2)/2 - 1/sqrt(x**2 + y**2)", q=["x", "y"], p=["px", "py"])
    >>> mg.time_transform(kepler, form="log").state_names
    ('px', 'py', 'e', 'x', 'y', 't')

    Raises
    ------
    InputError
        g is not a smooth expression of the declared names, depends on a momentum,
        or is constant (then there is nothing to transform; use the original system).
        An unknown form; for ``form="log"``: a g was given, H is not separable, time-dependent
        or constrained, or U is never negative (e.g. ``U ≥ 0`` everywhere, shown by SymPy).
    """
    if form not in FORMS:
        raise InputError(f"unknown time transformation form {form!r}; valid forms: {', '.join(FORMS)}")
    if getattr(system, "kind", None) == "poisson":
        raise InputError("time_transform needs a canonical system (methodgen.Hamiltonian with q and p): "
                         "the Poincaré transformation adds the time t and its conjugate momentum e to "
                         "(q, p); for a PoissonSystem it is not implemented")
    if not isinstance(system, Hamiltonian):
        raise InputError(f"time_transform expects a methodgen.Hamiltonian, got {type(system).__name__}")
    if system.time_transform is not None:
        raise InputError("this system is already time-transformed (or the autonomous extension of a "
                         "time-dependent H); transform the original once")
    if form == "log":
        if g is not None:
            raise InputError("form='log' takes no g: its time scaling is fixed, dt/dτ = −1/U(q) "
                             "(leave g out, or use form='poincare' with your g)")
        return _log_form(system, name)
    if g is None:
        raise InputError("time_transform needs g(q), e.g. g='sqrt(x**2 + y**2)', or form='log'")
    symbols = {s.name: s for s in (*system.y, *system.params)}
    if isinstance(g, str):
        g_expr, g_source = parse_expr(g, symbols, what="the time transformation g(q)"), g.strip()
    elif isinstance(g, sp.Expr):
        unknown = sorted(s.name for s in g.free_symbols if s.name not in symbols)
        if unknown:
            raise InputError(f"the time transformation g(q) uses undeclared names {unknown}; "
                             f"declared: {', '.join(sorted(symbols))}")
        g_expr = g.xreplace({s: symbols[s.name] for s in g.free_symbols})
        check_smooth(g_expr, "the time transformation g(q)")
        g_source = str(g)
    else:
        raise InputError(f"g must be a string or a SymPy expression, got {type(g).__name__}")
    g_expr = fold_removable_quotients(g_expr)   # sin(u)/u as in H (methodgen.problem.special)
    if g_expr.free_symbols & set(system.p):
        raise InputError(f"the time transformation g = {g_source} depends on momenta; it must be a "
                         "function of the coordinates q (and parameters) only")
    if not g_expr.free_symbols & set(system.q):
        raise InputError(f"the time transformation g = {g_source} does not depend on q: a constant g "
                         "only rescales time (use a different step size instead)")
    K, t_name, e_name = _extend(system, g_expr)
    # Declared invariants are carried over (monitored on the extended phase space).  On the
    # level set K = 0, {I, K} = g{I, H}: a first integral of H stays constant along the
    # motion, but it is *claimed* (exact) for K only where {I, K} = 0 identically.
    out = Hamiltonian(K, q=[*system.q, t_name], p=[*system.p, e_name], params=system.param_values,
                      constraints=system.constraints, name=name or f"{system.name or 'system'}-tt",
                      invariants={inv.name: inv.expr for inv in system.declared_invariants} or None)
    object.__setattr__(out, "time_transform",
                       TimeTransform(g_expr, g_source, system, out.symbol(t_name), out.symbol(e_name)))
    # the source text a user reads in generated modules and reports
    object.__setattr__(out, "source", f"({g_source})*({system.source} + {e_name})")
    return out


def _log_form(system: Hamiltonian, name: str | None) -> Hamiltonian:
    """``Λ = log(T(p) + e) − log(−U(q))`` on ``(q, t; p, e)`` (module docstring)."""
    from .derive import separable_split

    if system.time is not None:
        raise InputError("form='log' needs an autonomous H = T(p) + U(q); this H depends on the time "
                         f"{system.time.name!r} (use form='poincare' with a g(q))")
    if system.constraints:
        raise InputError("form='log' is for the explicit leapfrog on H = T(p) + U(q), which does not "
                         "enforce constraints; use form='poincare' with a g(q) and rattle/shake or an "
                         "implicit method")
    sep = separable_split(system)
    if sep is None:
        raise InputError(f"form='log' needs a separable H = T(p) + U(q) (no term mixing q and p), got "
                         f"H = {system.source}; use form='poincare' with a g(q)")
    T, U = sep.T, sep.U
    if not U.free_symbols & set(system.q):
        raise InputError(f"form='log' needs a potential U(q) that depends on q, got U = {U}: "
                         "log(T + e) − log(−U) would have no time scaling")
    values = {s: sp.Float(system.param_values[s.name]) for s in system.params}
    if U.xreplace(values).is_nonnegative:
        raise InputError(f"form='log' needs U(q) < 0 along the motion (it integrates log(−U)); U = {U} is "
                         "≥ 0 everywhere for the parameter values given; use form='poincare' with a "
                         "g(q) > 0")
    taken = {s.name for s in (*system.y, *system.params)} | {inv.name for inv in system.declared_invariants}
    t_name = _free_name(_TIME_NAMES, taken, "physical time coordinate")
    e_name = _free_name(_ENERGY_NAMES, taken | {t_name}, "energy momentum")
    e = sp.Symbol(e_name, real=True)
    # −Λ with the roles of coordinates and momenta exchanged, (Q; P) = (p, e; q, t): the
    # exchange reverses the sign of the Poisson bracket and −Λ restores it, so the flow is
    # Λ's.  Störmer–Verlet (kick–drift–kick) of this system is the drift–kick–drift leapfrog
    # of Λ, the one that follows a Kepler ellipse exactly [MT99, PT99]; the kick–drift–kick
    # leapfrog of Λ does not (measured: e = 0.99, 50 steps per orbit, 10 orbits, relative
    # energy error 0.2 against 5e-13).
    K = sp.log(-U) - sp.log(T + e)
    out = Hamiltonian(K, q=[*system.p, e_name], p=[*system.q, t_name], params=system.param_values,
                      name=name or f"{system.name or 'system'}-log",
                      invariants={inv.name: inv.expr for inv in system.declared_invariants} or None)
    g = -1 / U
    object.__setattr__(out, "time_transform",
                       TimeTransform(g, sp.sstr(g), system, out.symbol(t_name), out.symbol(e_name), form="log"))
    object.__setattr__(out, "source", f"log({sp.sstr(-U)}) - log({sp.sstr(T)} + {e_name})")
    return out


def _extend(system: Hamiltonian, g: sp.Expr) -> tuple[sp.Expr, str, str]:
    """``(K, t, e)``: ``K = g (H + e)`` and the names of the new coordinate (the declared time
    of a time-dependent H, else a free name) and of its momentum (a free name)."""
    taken = {s.name for s in (*system.y, *system.params)} | {inv.name for inv in system.declared_invariants}
    if system.time is not None:
        t_name = system.time.name
    else:
        t_name = _free_name(_TIME_NAMES, taken, "physical time coordinate")
    e_name = _free_name(_ENERGY_NAMES, taken | {t_name}, "energy momentum")
    e = sp.Symbol(e_name, real=True)
    return (system.H + e if g == 1 else g * (system.H + e)), t_name, e_name


_AUTONOMISED: dict[int, tuple[Hamiltonian, Hamiltonian]] = {}


def autonomise(system: Hamiltonian) -> Hamiltonian:
    """The autonomous extension ``K = H(q, p, t) + e`` of a time-dependent system (module docstring).

    Parameters
    ----------
    system : Hamiltonian
        Declared with ``time="t"``; any other system is returned unchanged (so every
        consumer may call this unconditionally: :func:`methodgen.discretize`,
        :func:`methodgen.build`, :attr:`methodgen.Scene.run_system`).

    Returns
    -------
    Hamiltonian
        State ``(q…, t, p…, e)``: the declared time ``t`` is the last coordinate, its
        conjugate momentum ``e`` (``e``, ``energy`` or ``e_``, the first name not taken)
        the last momentum; same name, parameters, constraints and declared invariants
        (which may depend on t: on the extended phase space ``{I, K} = {I, H} + ∂I/∂t``,
        so ``verify`` proves or refutes exactly what a time-dependent first integral needs).
        ``K.time_transform`` is a :class:`TimeTransform` with ``g = 1``
        (:attr:`TimeTransform.autonomised`); generated modules offer ``initial_state(y0, t0)``
        (``e0 = −H(y0, t0)``, so K = 0) and ``physical_state(Y)``, and monitor ``H_phys``,
        the physical ``H(q, p, t)`` (not conserved: ``dH/dt = ∂H/∂t``).  The same object is
        returned for the same system.
    """
    if getattr(system, "kind", None) == "poisson":
        return system       # a PoissonSystem has no time dependence (methodgen.problem.poisson)
    if getattr(system, "time", None) is None:     # autonomous (a Poisson system has no time either)
        return system
    if not isinstance(system, Hamiltonian):
        raise InputError(f"autonomise expects a methodgen.Hamiltonian, got {type(system).__name__}")
    hit = _AUTONOMISED.get(id(system))
    if hit is not None and hit[0] is system:
        return hit[1]
    K, t_name, e_name = _extend(system, sp.S.One)
    out = Hamiltonian(K, q=[*system.q, t_name], p=[*system.p, e_name], params=system.param_values,
                      constraints=system.constraints, name=system.name,
                      invariants={inv.name: inv.expr for inv in system.declared_invariants} or None)
    object.__setattr__(out, "time_transform",
                       TimeTransform(sp.S.One, "1", system, out.symbol(t_name), out.symbol(e_name)))
    object.__setattr__(out, "source", f"{system.source} + {e_name}")
    _AUTONOMISED[id(system)] = (system, out)
    return out


def time_scale_guard(system) -> tuple[sp.Expr, ...]:
    """What the runtimes check at every step of a time-transformed system: ``(g, d, s)``.

    ``g`` must stay positive (``K = g(H + e)`` is singular where ``g ≤ 0``: physical time
    stops or runs backwards).  ``d = H + e`` is the level-set defect: on ``K = 0`` it is 0
    and the flow of K is the original one; off it, ``d = K/g`` is the error of the physical
    energy and ``d ∇g`` a spurious force.  Where the motion approaches ``g = 0`` (the
    physical trajectory reaches it in finite time, while the flow of K only approaches it)
    a K error of round-off size is divided by a vanishing g: ``|d|`` grows to the size of
    ``s = |e| + Σ|terms of H|``, the scale of the energy, and the run no longer follows the
    physical motion.  Empty for a system without a time transformation and for the
    autonomous extension (``g = 1``: nothing is singular).
    """
    tt = getattr(system, "time_transform", None)
    if tt is None or tt.autonomised:
        return ()
    e = system.symbol(tt.energy.name)
    H = tt.original.H
    scale = sp.Abs(e) + sp.Add(*(sp.Abs(t) for t in sp.Add.make_args(H)))
    return (tt.g, H + e, scale)
