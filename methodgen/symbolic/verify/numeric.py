"""High-precision stepping for the numerical certificates (mpmath, 60 digits).

Properties that are not identities one can simplify — symplecticity of an
implicit nonlinear map, RATTLE on ``T*Q`` — are checked by running the scheme's
own equations in 60-digit arithmetic: Newton on ``R(z) = 0`` to a residual of
~1e-55, and directional derivatives of the step by central differences with
``ε = 1e-22`` (truncation error ~ε² = 1e-44, round-off ~1e-38).
"""

from __future__ import annotations

import random

import mpmath as mp
import sympy as sp

from ...problem.special import to_elementary
from .exact import guarded

__all__ = ["Stepper", "DPS", "param_point"]

DPS = 60
EPS = mp.mpf("1e-22")


def param_point(system) -> dict:
    """The system's default parameter values as exact rationals."""
    return {s: sp.Rational(repr(system.param_values[s.name])) for s in system.params}


class Stepper:
    """The scheme's step map ``y0 -> y1`` in mpmath arithmetic.

    Parameters
    ----------
    scheme : Scheme
    h : sympy.Rational
        The step size (exact).
    """

    def __init__(self, scheme, h):
        self.scheme = scheme
        system = scheme.system
        sub = {**param_point(system), scheme.h: h}
        z = list(scheme.unknowns)
        y = list(system.y)
        prep = lambda M: [to_elementary(guarded(e.xreplace(sub))) for e in M]
        self.n = len(z)
        self.inc = sp.lambdify([z, y], prep(scheme.increment), modules="mpmath")
        if self.n:
            self.res = sp.lambdify([z, y], prep(scheme.residual), modules="mpmath")
            self.jac = sp.lambdify([z, y], prep(scheme.jacobian), modules="mpmath")
            self.guess = sp.lambdify([y], prep(scheme.guess), modules="mpmath")

    def __call__(self, y0):
        with mp.workdps(DPS):
            y0 = [mp.mpf(v) for v in y0]
            z = []
            if self.n:
                z = [mp.mpf(v) for v in self.guess(y0)]
                for _ in range(60):
                    r = mp.matrix(self.res(z, y0))
                    if mp.norm(r) < mp.mpf(10) ** (-(DPS - 5)):
                        break
                    J = mp.matrix(_rows(self.jac(z, y0), self.n))
                    dz = mp.lu_solve(J, r)
                    z = [zi - dzi for zi, dzi in zip(z, dz)]
                else:
                    raise ArithmeticError("Newton did not converge in 60-digit arithmetic")
            d = self.inc(z, y0)
            return [a + b for a, b in zip(y0, _flat(d))]

    def derivative(self, y0, v):
        """Directional derivative Φ'(y0) v by a 60-digit central difference."""
        with mp.workdps(DPS):
            plus = self([a + EPS * b for a, b in zip(y0, v)])
            minus = self([a - EPS * b for a, b in zip(y0, v)])
            return [(a - b) / (2 * EPS) for a, b in zip(plus, minus)]


def _flat(x):
    out = []
    for v in x:
        if isinstance(v, (list, tuple)):
            out.extend(v)
        else:
            out.append(v)
    return out


def _rows(m, n):
    flat = _flat(m)
    return [flat[i * n:(i + 1) * n] for i in range(n)]


def random_state(system, rng: random.Random, scale=1):
    """A random rational state with entries in [-scale, scale] (a few digits)."""
    return [sp.Rational(rng.randint(-20 * scale, 20 * scale), 20) for _ in system.y]
