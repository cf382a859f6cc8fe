"""Brent's root finder: the one source of event location's root finding.

A generated module locates an event's crossing on its own map -- the sub-step τ in (0, h] with
g(Φ_τ(y_n)) = 0 -- with :func:`_zeroin`.  Generated modules import numpy and the standard library
only, so each holds a copy of this function's text (:func:`source`, rendered by the templates);
the family modules' event location (:func:`methodgen.runtime.events.solve_family`) calls it from
here.  One algorithm, one text: the copy is the function below, byte for byte.

References
----------
R. P. Brent, *Algorithms for Minimization without Derivatives*, Prentice-Hall (1973), ch. 4.
"""

from __future__ import annotations

import ast
import os

__all__ = ["zeroin", "source"]

#: the unit roundoff of float64, as the generated modules name it
_EPS = 2.220446049250313e-16


def _zeroin(f, b, fa, fb):
    """A root of f in [0, b] with f(0) = fa and f(b) = fb of opposite signs, to adjacent
    floats (Brent's method: R. P. Brent, Algorithms for Minimization without Derivatives,
    1973, ch. 4).  Returns (x, f(x), y(x)): f returns (value, state)."""
    a = 0.0
    c, fc = a, fa
    yb = None
    d = e = b - a
    for _ in range(200):
        if (fb > 0.0) == (fc > 0.0) and fb != 0.0:
            c, fc = a, fa
            d = e = b - a
        if abs(fc) < abs(fb):
            a, b, c = b, c, b
            fa, fb, fc = fb, fc, fb
            yb = None
        tol1 = 2.0 * _EPS * abs(b)
        xm = 0.5 * (c - b)
        if abs(xm) <= tol1 or fb == 0.0:
            break
        if abs(e) >= tol1 and abs(fa) > abs(fb):
            s = fb / fa
            if a == c:
                p, q = 2.0 * xm * s, 1.0 - s
            else:
                q, r = fa / fc, fb / fc
                p = s * (2.0 * xm * q * (q - r) - (b - a) * (r - 1.0))
                q = (q - 1.0) * (r - 1.0) * (s - 1.0)
            if p > 0.0:
                q = -q
            else:
                p = -p
            if 2.0 * p < min(3.0 * xm * q - abs(tol1 * q), abs(e * q)):
                e, d = d, p / q
            else:
                d = e = xm
        else:
            d = e = xm
        a, fa = b, fb
        b = b + d if abs(d) > tol1 else b + (tol1 if xm > 0.0 else -tol1)
        fb, yb = f(b)
    if yb is None:
        fb, yb = f(b)
    return b, fb, yb


#: the name the family event location calls it by
zeroin = _zeroin

_TEXT: list = []


def source() -> str:
    """The text of :func:`_zeroin` in this file: what a generated module holds a copy of (it
    reads ``_EPS``, which every generated module defines)."""
    if not _TEXT:
        with open(os.path.abspath(__file__), encoding="utf-8") as f:
            text = f.read()
        node = next(n for n in ast.parse(text).body if isinstance(n, ast.FunctionDef) and n.name == "_zeroin")
        _TEXT.append("\n".join(text.split("\n")[node.lineno - 1:node.end_lineno]))
    return _TEXT[0]
