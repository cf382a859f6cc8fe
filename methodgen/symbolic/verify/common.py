"""Small shared helpers: the symbols of a scheme and the sampling domain."""

from __future__ import annotations

import sympy as sp

from ..derive import gradient
from ..schemes.base import STEP, next_symbol
from .exact import Domain

__all__ = ["y1_symbols", "scheme_domain", "system_domain", "at", "REF_NOTES", "REF_KAHAN"]

REF_NOTES = "Celledoni, lecture notes"
REF_KAHAN = "Celledoni, McLachlan, Owren, Quispel, J. Phys. A 46 (2013) 025201"


def y1_symbols(system) -> tuple[sp.Symbol, ...]:
    """The end-state symbols ``_n_<name>`` used in discrete gradients."""
    return tuple(next_symbol(s) for s in system.y)


def system_domain(system, extra_positive=()) -> Domain:
    """Parameters positive, h small, end states near the start states."""
    return Domain(positive=set(system.params) | set(extra_positive), small={STEP},
                  near=dict(zip(y1_symbols(system), system.y)))


scheme_domain = system_domain


def at(expr, old, new):
    """``expr`` with the symbols ``old`` replaced by the expressions ``new`` (simultaneously)."""
    return expr.xreplace(dict(zip(old, new)))


def grad_at(system, point):
    return at(gradient(system), system.y, point)
