"""Exact, cancellation-free divided differences.

``divided_difference(f, x, a, b)`` returns an expression ``D(a, b)`` with

    D(a, b) * (b - a) == f(b) - f(a)                    (an identity)
    D(a, a) == f'(a)                                    (by substitution)

and, the point of the exercise, *no* ``0/0`` at ``a = b``: the factor
``(b - a)`` is divided out symbolically, structurally, by the rules

* sums: linear;  products: ``(uv)[a,b] = u[a,b] (v_a+v_b)/2 + (u_a+u_b)/2 v[a,b]``
  (the symmetric product rule, so symmetric methods stay symmetric);
* integer powers: ``u_b^n - u_a^n = (u_b - u_a) Σ u_b^k u_a^(n-1-k)``;
* rational powers ``u^(p/q)`` through ``w = u^(1/q)``:
  ``w[a,b] = u[a,b] / Σ w_b^k w_a^(q-1-k)``;
* elementary functions through the half-angle identities of
  :mod:`methodgen.special` (``exp[a,b] = exp(m) sinhc(δ/2)`` etc.).

A function outside these rules falls back to the symmetric Taylor series about
the midpoint when ``|δ|`` is small and the plain quotient otherwise; the switch
point is chosen where both agree to round-off (see :func:`_series_fallback`).

These are the building blocks of the energy-momentum ``κ`` (a divided
difference of ``V`` in ``r²``), Itoh–Abe (coordinate-wise divided differences)
and of the stable Gonzalez and AVF forms.
"""

from __future__ import annotations

import sympy as sp

from .special import atanhc, sinc_u, sinhc

__all__ = ["divided_difference"]

#: Relative switch point of the series fallback (see _series_fallback).
SERIES_SWITCH = sp.Rational(1, 10)


def divided_difference(f: sp.Expr, x: sp.Symbol, a: sp.Expr, b: sp.Expr) -> sp.Expr:
    """Return the cancelled divided difference ``f[a, b]`` of ``f`` in ``x``.

    Parameters
    ----------
    f : sympy.Expr
        Expression in ``x`` (other symbols are treated as constants).
    x : sympy.Symbol
        The variable.
    a, b : sympy.Expr
        The two nodes.

    Returns
    -------
    sympy.Expr
        ``(f(b) - f(a))/(b - a)`` in a form without a removable singularity.
    """
    return _DD(x, a, b).dd(f)


class _DD:
    def __init__(self, x, a, b):
        self.x, self.a, self.b = x, a, b
        self.cache: dict = {}

    def at_a(self, e):
        return e.xreplace({self.x: self.a})

    def at_b(self, e):
        return e.xreplace({self.x: self.b})

    def dd(self, f: sp.Expr) -> sp.Expr:
        if f in self.cache:
            return self.cache[f]
        out = self._dd(f)
        self.cache[f] = out
        return out

    def _dd(self, f: sp.Expr) -> sp.Expr:
        x = self.x
        if x not in f.free_symbols:
            return sp.S.Zero
        if f == x:
            return sp.S.One
        if f.is_Add:
            return sp.Add(*[self.dd(t) for t in f.args])
        if f.is_Mul:
            const, rest = f.as_independent(x, as_Add=False)
            if const != 1:
                return const * self.dd(rest)
            u, v = rest.args[0], sp.Mul(*rest.args[1:])
            half = sp.Rational(1, 2)
            return (self.dd(u) * half * (self.at_a(v) + self.at_b(v))
                    + half * (self.at_a(u) + self.at_b(u)) * self.dd(v))
        if f.is_Pow:
            return self._pow(f)
        if isinstance(f, sp.exp):
            u = f.args[0]
            ua, ub = self.at_a(u), self.at_b(u)
            return sp.exp((ua + ub) / 2) * sinhc((ub - ua) / 2) * self.dd(u)
        if isinstance(f, sp.log):
            u = f.args[0]
            ua, ub = self.at_a(u), self.at_b(u)
            # log(ub/ua) = 2 atanh((ub-ua)/(ua+ub)), exact for ua, ub > 0.
            return 2 / (ua + ub) * atanhc((ub - ua) / (ua + ub)) * self.dd(u)
        if isinstance(f, (sp.sin, sp.cos, sp.sinh, sp.cosh)):
            u = f.args[0]
            ua, ub = self.at_a(u), self.at_b(u)
            m, half_delta = (ua + ub) / 2, (ub - ua) / 2
            factor = {
                sp.sin: sp.cos(m) * sinc_u(half_delta),
                sp.cos: -sp.sin(m) * sinc_u(half_delta),
                sp.sinh: sp.cosh(m) * sinhc(half_delta),
                sp.cosh: sp.sinh(m) * sinhc(half_delta),
            }[f.func]
            return factor * self.dd(u)
        if isinstance(f, sp.tan):
            u = f.args[0]
            ua, ub = self.at_a(u), self.at_b(u)
            return sinc_u(ub - ua) / (sp.cos(ua) * sp.cos(ub)) * self.dd(u)
        if isinstance(f, sp.tanh):
            u = f.args[0]
            ua, ub = self.at_a(u), self.at_b(u)
            return sinhc(ub - ua) / (sp.cosh(ua) * sp.cosh(ub)) * self.dd(u)
        return self._series_fallback(f)

    def _pow(self, f: sp.Pow) -> sp.Expr:
        base, e = f.args
        x = self.x
        if x in e.free_symbols or not e.is_Rational:
            # u**e = exp(e log u) for u > 0 (the only case where it is real).
            return self.dd(sp.exp(e * sp.log(base)))
        ba, bb = self.at_a(base), self.at_b(base)
        if e.is_Integer:
            n = int(e)
            if n > 0:
                return self.dd(base) * sp.Add(*[bb**k * ba**(n - 1 - k) for k in range(n)])
            # 1/u^n: (1/u_b^n - 1/u_a^n) = -(u_b^n - u_a^n)/(u_a^n u_b^n)
            m = -n
            return -self.dd(base**m) / (ba**m * bb**m)
        p, q = int(e.p), int(e.q)
        w = base ** sp.Rational(1, q)
        wa, wb = ba ** sp.Rational(1, q), bb ** sp.Rational(1, q)
        dw = self.dd(base) / sp.Add(*[wb**k * wa**(q - 1 - k) for k in range(q)])
        if p == 1:
            return dw
        if p > 0:
            return dw * sp.Add(*[wb**k * wa**(p - 1 - k) for k in range(p)])
        m = -p
        return -dw * sp.Add(*[wb**k * wa**(m - 1 - k) for k in range(m)]) / (wa**m * wb**m)

    def _series_fallback(self, f: sp.Expr) -> sp.Expr:
        """Quotient far from the diagonal, symmetric Taylor series near it.

        ``f[a,b] = Σ_k f^(2k+1)(m) (δ/2)^(2k) / (2k+1)!`` with four terms
        (truncation ``O(δ^8)``, coefficient ``1/(2^8 9!) ≈ 1e-8``).  At the
        switch ``|δ| = 0.1 (1 + |m|)`` the truncation is ~1e-16 relative and the
        quotient's cancellation error is ~eps/0.1, so the two branches agree to
        a few ulps: Newton sees no jump.
        """
        x, a, b = self.x, self.a, self.b
        m, delta = (a + b) / 2, b - a
        series = sp.S.Zero
        deriv = sp.diff(f, x)
        for k in range(4):
            series += deriv.xreplace({x: m}) * (delta / 2) ** (2 * k) / sp.factorial(2 * k + 1)
            deriv = sp.diff(deriv, x, 2)
        quotient = (self.at_b(f) - self.at_a(f)) / delta
        return sp.Piecewise((quotient, sp.Abs(delta) > SERIES_SWITCH * (1 + sp.Abs(m))), (series, True))
