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

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, Geometric Numerical Integration, 2nd ed.,
   Springer 2006, §VIII.2 (Poincaré transformation).
.. [Hai97] E. Hairer, Variable time step integration with symplectic methods,
   Appl. Numer. Math. 25 (1997) 219–227.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import sympy as sp

from .errors import InputError
from .parse import check_smooth, parse_expr
from .problem import Hamiltonian

__all__ = ["TimeTransform", "time_transform"]

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

    def fingerprint(self) -> str:
        text = "\n".join([sp.srepr(self.g), self.original.fingerprint(), self.time.name, self.energy.name])
        return hashlib.sha256(text.encode()).hexdigest()


def _free_name(candidates, taken, what):
    for name in candidates:
        if name not in taken:
            return name
    raise InputError(f"no free name for the {what}: {', '.join(candidates)} are all taken")


def time_transform(system: Hamiltonian, g, *, name: str | None = None) -> Hamiltonian:
    """The Poincaré time-transformed system ``K = g(q) (H(q, p) + e)`` (module docstring).

    Parameters
    ----------
    system : Hamiltonian
        The original system (constraints are kept: they depend on q only).
    g : str or sympy.Expr
        A smooth function of the coordinates (and parameters), positive along the
        motion, e.g. ``"sqrt(x**2 + y**2 + z**2)"``.  Text is parsed with the
        whitelist parser (never evaluated).
    name : str, optional
        Name of the new system (default ``<name>-tt``).

    Returns
    -------
    Hamiltonian
        State ``(q…, t, p…, e)``: the physical time ``t`` is the last coordinate,
        its conjugate ``e`` the last momentum.  ``K.time_transform`` records g and
        the original system; generated modules offer ``initial_state(y0, t0)``.

    Raises
    ------
    InputError
        g is not a smooth expression of the declared names, depends on a momentum,
        or is constant (then there is nothing to transform; use the original system).
    """
    if not isinstance(system, Hamiltonian):
        raise InputError(f"time_transform expects a methodgen.Hamiltonian, got {type(system).__name__}")
    if system.time_transform is not None:
        raise InputError("this system is already time-transformed; transform the original once")
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
    if g_expr.free_symbols & set(system.p):
        raise InputError(f"the time transformation g = {g_source} depends on momenta; it must be a "
                         "function of the coordinates q (and parameters) only")
    if not g_expr.free_symbols & set(system.q):
        raise InputError(f"the time transformation g = {g_source} does not depend on q: a constant g "
                         "only rescales time (use a different step size instead)")
    taken = set(symbols) | {inv.name for inv in system.declared_invariants}
    t_name = _free_name(_TIME_NAMES, taken, "physical time coordinate")
    e_name = _free_name(_ENERGY_NAMES, taken | {t_name}, "energy momentum")
    t, e = sp.Symbol(t_name, real=True), sp.Symbol(e_name, real=True)
    K = g_expr * (system.H + e)
    # Declared invariants are carried over (monitored on the extended phase space).  On the
    # level set K = 0, {I, K} = g{I, H}: a first integral of H stays constant along the
    # motion, but it is *claimed* (exact) for K only where {I, K} = 0 identically.
    out = Hamiltonian(K, q=[*system.q, t], p=[*system.p, e], params=system.param_values,
                      constraints=system.constraints, name=name or f"{system.name or 'system'}-tt",
                      invariants={inv.name: inv.expr for inv in system.declared_invariants} or None)
    object.__setattr__(out, "time_transform",
                       TimeTransform(g_expr, g_source, system, out.symbol(t_name), out.symbol(e_name)))
    # the source text a user reads in generated modules and reports
    object.__setattr__(out, "source", f"({g_source})*({system.source} + {e_name})")
    return out
