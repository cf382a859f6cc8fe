"""The method library: one small module per method family, and the registry.

Each method module exposes ``NAME``, ``SUMMARY``, ``applies(system) -> str |
None`` (None when the method applies, else the reason it does not) and
``build(system) -> Scheme``.
"""

from __future__ import annotations

from types import ModuleType

from ..errors import InputError, MethodNotApplicable
from ..problem import Hamiltonian
from . import energy_momentum, kahan, midpoint, stormer_verlet, trapezoidal
from .base import Scheme, Traits
from .discrete_gradients import AVF, Gonzalez, ItohAbe
from .rattle import Rattle, Shake

__all__ = ["METHODS", "Scheme", "Traits", "discretize", "applicable_methods", "method_names"]

METHODS: dict[str, ModuleType] = {m.NAME: m for m in (
    midpoint, energy_momentum, trapezoidal, kahan, AVF, Gonzalez, ItohAbe, stormer_verlet,
    Rattle, Shake)}


def method_names() -> list[str]:
    return list(METHODS)


def applicable_methods(system: Hamiltonian) -> list[str]:
    """Names of the methods that apply to ``system``."""
    return [name for name, m in METHODS.items() if m.applies(system) is None]


def discretize(system: Hamiltonian, method: str, **options) -> Scheme:
    """Discretise ``system`` with ``method`` and return the symbolic :class:`Scheme`.

    Parameters
    ----------
    system : Hamiltonian
    method : str
        One of :data:`METHODS` (``methodgen methods`` lists them).
    **options
        Method options, e.g. ``form="rk"`` for Kahan, ``nodes=`` for AVF quadrature.

    Raises
    ------
    InputError
        Unknown method name (the message lists the known ones).
    MethodNotApplicable
        The method does not apply to this system (the message says why and lists
        the methods that do).
    """
    if not isinstance(system, Hamiltonian):
        raise InputError(f"discretize expects a methodgen.Hamiltonian, got {type(system).__name__}")
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; known methods: {', '.join(METHODS)}")
    mod = METHODS[method]
    reason = mod.applies(system)
    if reason is not None:
        ok = applicable_methods(system)
        raise MethodNotApplicable(f"{reason}. Methods that apply to this system: "
                                  f"{', '.join(ok) if ok else '(none)'}")
    try:
        return mod.build(system, **options)
    except TypeError as exc:
        if "unexpected keyword" in str(exc):
            raise InputError(f"method {method!r} does not take options {sorted(options)}") from None
        raise
