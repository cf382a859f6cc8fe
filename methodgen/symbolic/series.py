"""Truncated series in the free associative algebra: the product, exponential and logarithm
that the order conditions of compositions (:mod:`methodgen.symbolic.compositions`) and splittings
(:mod:`methodgen.symbolic.splittings`) are computed with.

A series is a dict ``{word: coefficient}``, a word a tuple of letters; words are kept while
their ``weight`` is at most ``wmax`` (``sum``: the sum of the letters' generator weights, the
compositions' grading; ``len``: the word's length, the splittings' degree).  Coefficients are
whatever the caller's arithmetic is (mpmath at the caller's precision).

References
----------
.. [HLW06] E. Hairer, C. Lubich, G. Wanner, *Geometric Numerical Integration*, 2nd ed.,
   Springer 2006, §III.3-III.5 (the BCH formula, order conditions of compositions).
"""

from __future__ import annotations

import mpmath as mp

__all__ = ["mul", "exp", "log"]


def mul(a: dict, b: dict, wmax: int, weight=sum) -> dict:
    """Product of two truncated series {word: coefficient}, keeping words of ``weight`` ≤
    ``wmax`` (``sum``: words of generator weights, the compositions'; ``len``: words over
    letters, the degree in :mod:`methodgen.symbolic.splittings`)."""
    out: dict = {}
    for u, x in a.items():
        wu = weight(u)
        for v, y in b.items():
            if wu + weight(v) <= wmax:
                w = u + v
                out[w] = out.get(w, 0) + x * y
    return out


def exp(Y: dict, wmax: int) -> dict:
    """``exp Y`` of a truncated series without constant term (generator weights)."""
    out, term = {(): mp.mpf(1)}, {(): mp.mpf(1)}
    for n in range(1, wmax + 1):
        term = {k: v / n for k, v in mul(term, Y, wmax).items()}
        if not term:
            break
        for k, v in term.items():
            out[k] = out.get(k, 0) + v
    return out


def log(P: dict, wmax: int, weight=sum) -> dict:
    """``log P`` of a truncated series with constant term 1 (``weight``: see :func:`mul`)."""
    Z = {k: v for k, v in P.items() if k != ()}     # P - 1 (P has constant term 1)
    out: dict = {}
    power = {(): mp.mpf(1)}
    for n in range(1, wmax + 1):
        power = mul(power, Z, wmax, weight)
        if not power:
            break
        for k, v in power.items():
            out[k] = out.get(k, 0) + (v if n % 2 else -v) / n
    return out
