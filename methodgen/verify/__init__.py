"""Exact verification layer: every claim of the lecture notes, for *your* Hamiltonian.

``verify(scheme)`` returns a :class:`Report` of :class:`Certificate` objects,
one per claim that applies to the scheme and its system:

=====================================  ===============================================
claim                                  module
=====================================  ===============================================
1  q × p first integral (generic V)    :mod:`.invariants`
2, 4  discrete-gradient identity,      :mod:`.discrete_gradients`
      consistency, κ of Ex. 1.1
3  invariants kept by the step         :mod:`.invariants`
5  trapezoidal ~ midpoint (Ex. 2.1)    :mod:`.conjugacy`
6  Kahan forms, modified energy/volume :mod:`.kahan`
7  quadratic H: symplectic, re-timing  :mod:`.maps`, :mod:`.quadratic`
8  RATTLE on T*Q                       :mod:`.constrained`
9  symmetry of symmetric methods       :mod:`.discrete_gradients`, :mod:`.maps`
=====================================  ===============================================

Statuses: ``proved`` (exact reduction to 0, no floats), ``refuted`` (a
counterexample point), ``numerical`` (sample points and tolerance; never a proof).

The module object is callable, so ``methodgen.verify(scheme)`` works once
``methodgen.verify`` has been imported.
"""

from __future__ import annotations

import sys
import types

from ..derive import angular_momenta, radial_profile, separable_split
from ..schemes.base import is_linear_field, is_quadratic_field
from .conjugacy import conjugacy_certificate
from .constrained import constrained_certificates
from .discrete_gradients import dg_certificates, dg_symmetry
from .invariants import angular_momentum_generic, angular_momentum_user, invariant_certificates
from .kahan import (forms_agree_generic, forms_agree_user, modified_energy, modified_energy_fast,
                    modified_volume)
from .maps import explicit_symmetry, residual_symmetry, symplectic_certificate
from .quadratic import retiming_certificate
from .report import NUMERICAL, PROVED, REFUTED, Certificate, Report

__all__ = ["verify", "Report", "Certificate", "PROVED", "REFUTED", "NUMERICAL"]


def _symmetry(scheme) -> list[Certificate]:
    if scheme.discrete_gradient is not None:
        return [dg_symmetry(scheme.system, scheme.discrete_gradient, scheme.method)]
    if not scheme.unknowns:
        return [explicit_symmetry(scheme)]
    if scheme.traits.solve == "linear":
        return [residual_symmetry(scheme)]
    return []   # constrained methods: see constrained_certificates


def verify(scheme, conjugacy_dim: int | None = None) -> Report:
    """Certify every claim that applies to ``scheme`` (and its system).

    Parameters
    ----------
    scheme : Scheme
        From :func:`methodgen.discretize`.
    conjugacy_dim : int, optional
        Phase-space dimension for the Exercise 2.1 conjugacy (trapezoidal
        rule); default ``2d`` of the system.

    Returns
    -------
    Report
        ``.ok`` is False iff some applicable claim was refuted.
    """
    system, traits = scheme.system, scheme.traits
    certs: list[Certificate] = []
    # Claim 1: first integrals of the flow (system-level).
    if system.dim >= 2 and radial_profile(system) is not None and angular_momenta(system) \
            and not system.constraints:
        sep = separable_split(system)
        if sep is not None and sep.isotropic:
            certs += angular_momentum_generic(system.dim)
        certs += angular_momentum_user(system)
    # Claims 2, 4: discrete gradients.
    if traits.discrete_gradient and scheme.discrete_gradient is not None:
        certs += dg_certificates(scheme)
    # Claim 3 and every other invariant the traits promise.
    if not system.constraints:
        certs += invariant_certificates(scheme)
    # Claim 5: Exercise 2.1.
    if scheme.method == "trapezoidal":
        certs.append(conjugacy_certificate(conjugacy_dim or 2 * system.dim))
    # Claim 6: Kahan on quadratic vector fields.
    if scheme.method == "kahan" and is_quadratic_field(system):
        certs.append(forms_agree_generic(2 * system.dim))
        certs.append(forms_agree_user(system))
        fast = modified_energy_fast(system) if system.dim == 1 else None
        certs.append(fast if fast is not None else modified_energy(system))
        certs.append(modified_volume(system))
    # Claims 7, 8: symplecticity.
    if system.constraints:
        certs += constrained_certificates(scheme)
    elif traits.symplectic:
        certs.append(symplectic_certificate(scheme))
        if is_linear_field(system):
            r = retiming_certificate(scheme)
            if r is not None:
                certs.append(r)
    # Claim 9: symmetry.
    if traits.symmetric and not system.constraints:
        certs += _symmetry(scheme)
    title = f"{scheme.method} on {system.name or 'H = ' + str(system.H)}"
    return Report(title, certs)


class _CallableModule(types.ModuleType):
    """Lets ``methodgen.verify(scheme)`` work although ``methodgen.verify`` is this package."""

    def __call__(self, scheme, **kwargs) -> Report:
        return verify(scheme, **kwargs)


sys.modules[__name__].__class__ = _CallableModule
