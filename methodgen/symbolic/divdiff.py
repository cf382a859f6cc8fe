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
* elementary functions ``g`` of the grammar by the chain rule of divided
  differences, ``(g∘u)[a, b] = g[u(a), u(b)] · u[a, b]`` (exact), with ``g[·,·]``
  one of the functions of :mod:`methodgen.problem.special` (``exp_dd``, ``atan_dd``, …)
  whose defining relation is the quotient and whose generated helper evaluates a
  cancellation-free form (``exp[a,b] = exp(m) sinhc(δ/2)``, addition formulas for
  tan/tanh/atan, ``log[a,b] = 2 atanhc((b-a)/(a+b))/(a+b)``).

There is no fallback: a function outside these rules raises
:class:`NoDividedDifference` (the parser admits none).  So whatever the
verification layer proves about the quotients is what the generated code
evaluates, on every branch.

These are the building blocks of the energy-momentum ``κ`` (a divided
difference of ``V`` in ``r²``), Itoh–Abe (coordinate-wise divided differences)
and of the stable Gonzalez and AVF forms.
"""

from __future__ import annotations

import sympy as sp

from ..errors import InputError
from ..problem.special import DIVIDED_DIFFERENCES, exp_dd

__all__ = ["divided_difference", "NoDividedDifference"]


class NoDividedDifference(InputError):
    """The expression contains a function without an exact divided-difference rule."""


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
        rule = DIVIDED_DIFFERENCES.get(type(f))
        if rule is not None:
            # Chain rule of divided differences, exact: (g∘u)[a, b] = g[u(a), u(b)] · u[a, b].
            u = f.args[0]
            return rule(self.at_a(u), self.at_b(u)) * self.dd(u)
        raise NoDividedDifference(
            f"no exact divided difference for {f.func.__name__}({', '.join(map(str, f.args))}): "
            "the grammar's functions are " + ", ".join(sorted(g.__name__ for g in DIVIDED_DIFFERENCES)))

    def _pow(self, f: sp.Pow) -> sp.Expr:
        base, e = f.args
        x = self.x
        if x in e.free_symbols or not e.is_Rational:
            # u**e = exp(e log u) for u > 0 (the only case where it is real).  Applied
            # directly: SymPy would fold exp(e*log(u)) straight back into u**e.
            g = e * sp.log(base)
            return exp_dd(self.at_a(g), self.at_b(g)) * self.dd(g)
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
