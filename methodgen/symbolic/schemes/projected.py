"""Störmer–Verlet (or its symmetric composition) symmetrically projected onto H = H0.

The method name under which :func:`methodgen.symbolic.projection.project_scheme` with
``project="energy"`` is reachable wherever a method is named (scenes, ``build``,
``run``, ``bench``, ``verify``): the base step is :mod:`.stormer_verlet`'s, composed to
``--order`` first, then projected (:mod:`methodgen.symbolic.projection`).  Symmetric, of the
order of the base step, H kept to round-off at every step, not symplectic.
"""

from __future__ import annotations

from . import stormer_verlet

NAME = "stormer-verlet-projected"
SUMMARY = ("Störmer–Verlet symmetrically projected onto H = H0 (symmetric, order kept, "
           "energy to round-off, one small solve per step, not symplectic)")
#: The projection this method name stands for (see methodgen.symbolic.schemes.discretize).
PROJECT = "energy"


def applies(system) -> str | None:
    return stormer_verlet.applies(system)


def build(system):
    return stormer_verlet.build(system)
