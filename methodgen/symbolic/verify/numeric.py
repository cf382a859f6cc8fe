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
    h : sympy.Rational or sympy.Float
        The step size (exact, or a 60-digit float: a composition's stage step).

    Notes
    -----
    The scheme's equations are printed for mpmath once per scheme, with ``h`` an argument
    (:func:`_functions`): a certificate that steps at many step sizes (an order ladder, a
    composition's stages) evaluates the same functions at each.  Printing them was the cost
    of such a certificate (a Calogero order ladder: 64 of 95 s).
    """

    def __init__(self, scheme, h):
        self.scheme = scheme
        self.h = h
        self.n, self.inc, self.res, self.jac, self.guess = _functions(scheme)

    def _h(self):
        """The step size as an mpmath number at the working precision."""
        h = self.h
        if isinstance(h, sp.Rational):
            return mp.mpf(int(h.p)) / int(h.q)
        return mp.mpf(str(h))

    def __call__(self, y0):
        with mp.workdps(DPS):
            h = self._h()
            y0 = [mp.mpf(v) for v in y0]
            z = []
            if self.n:
                z = [mp.mpf(v) for v in self.guess(y0, h)]
                for _ in range(60):
                    r = mp.matrix(self.res(z, y0, h))
                    if mp.norm(r) < mp.mpf(10) ** (-(DPS - 5)):
                        break
                    J = mp.matrix(_rows(self.jac(z, y0, h), self.n))
                    dz = mp.lu_solve(J, r)
                    z = [zi - dzi for zi, dzi in zip(z, dz)]
                else:
                    raise ArithmeticError("Newton did not converge in 60-digit arithmetic")
            d = self.inc(z, y0, h)
            return [a + b for a, b in zip(y0, _flat(d))]

    def derivative(self, y0, v):
        """Directional derivative Φ'(y0) v by a 60-digit central difference."""
        with mp.workdps(DPS):
            plus = self([a + EPS * b for a, b in zip(y0, v)])
            minus = self([a - EPS * b for a, b in zip(y0, v)])
            return [(a - b) / (2 * EPS) for a, b in zip(plus, minus)]


#: The schemes whose mpmath functions were printed, the newest _KEEP: id(scheme) -> (scheme,
#: functions).  The scheme is kept with its functions, so its id is not reused while the entry
#: lives.
_PRINTED: dict = {}
_KEEP = 16


def _functions(scheme):
    """``(n, increment, residual, jacobian, guess)`` of ``scheme`` printed for mpmath, with the
    system's parameters substituted exactly and the step size ``h`` the last argument:
    ``increment(z, y, h)``, ``residual(z, y, h)``, ``jacobian(z, y, h)`` (n·n, row-major),
    ``guess(y, h)``; printed once per scheme (the newest :data:`_KEEP` schemes are kept)."""
    got = _PRINTED.get(id(scheme))
    if got is not None and got[0] is scheme:
        return got[1]
    system = scheme.system
    sub = param_point(system)
    z = list(scheme.unknowns)
    y = list(system.y)
    hs = scheme.h
    prep = lambda M: [to_elementary(guarded(e.xreplace(sub))) for e in M]
    n = len(z)
    inc = sp.lambdify([z, y, hs], prep(scheme.increment), modules="mpmath")
    res = jac = guess = None
    if n:
        res = sp.lambdify([z, y, hs], prep(scheme.residual), modules="mpmath")
        jac = sp.lambdify([z, y, hs], prep(scheme.jacobian), modules="mpmath")
        guess = sp.lambdify([y, hs], prep(scheme.guess), modules="mpmath")
    fns = (n, inc, res, jac, guess)
    _PRINTED[id(scheme)] = (scheme, fns)
    while len(_PRINTED) > _KEEP:
        del _PRINTED[next(iter(_PRINTED))]
    return fns


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
