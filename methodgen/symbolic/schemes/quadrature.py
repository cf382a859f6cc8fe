"""Gauss–Legendre rules on [0, 1], computed from their definition at high precision.

The m-node rule has the roots ``x_k`` of the Legendre polynomial ``P_m`` as nodes
and the weights ``w_k = 2 / ((1 − x_k²) P_m'(x_k)²)`` on [−1, 1] (mapped to [0, 1]:
``(1 − x_k)/2`` and ``w_k/2``).  Each root is found by Newton's method on the
three-term recurrence at :data:`DPS` digits, started from the asymptotic estimate
``cos(π(k − 1/4)/(m + 1/2))``; the values are rounded to float64 *once*
(:func:`gauss_legendre_f64`).

Why not the Lagrange-weight formula ``w_k = ∫ ℓ_k`` in monomial form: its coefficients
grow like 2^m and cancel, so at 50 digits the 64-node weights came out wrong by 2e-5
(sum 1 − 2.3e-6) — and computing the exact roots symbolically took minutes.  The rules
actually used are certified by :func:`methodgen.symbolic.verify.quadrature.rule_certificate`:
in 60-digit arithmetic on the float64 values, every shifted Legendre polynomial of
degree < 2m is integrated to within a few units of round-off.
"""

from __future__ import annotations

from functools import lru_cache

import mpmath as mp

from ...errors import InputError

__all__ = ["DPS", "MAX_NODES", "gauss_legendre", "gauss_legendre_f64"]

#: Working precision (decimal digits) of the nodes and weights.
DPS = 60
#: The largest rule offered (energy collocation of degree-63 fields with s = 4 needs 128).
MAX_NODES = 128


def _check(m) -> int:
    if isinstance(m, bool) or not isinstance(m, int) or not 1 <= m <= MAX_NODES:
        raise InputError(f"Gauss–Legendre rule: the number of nodes must be an integer in 1..{MAX_NODES}, "
                         f"got {m!r}")
    return m


def _legendre_and_derivative(m: int, x):
    """``(P_m(x), P_m'(x))`` by the three-term recurrence (current mpmath precision)."""
    p0, p1 = mp.mpf(1), x
    if m == 0:
        return p0, mp.mpf(0)
    for k in range(1, m):
        p0, p1 = p1, ((2 * k + 1) * x * p1 - k * p0) / (k + 1)
    return p1, m * (x * p1 - p0) / (x * x - 1)


@lru_cache(maxsize=None)
def gauss_legendre(m: int) -> tuple:
    """The m-node Gauss–Legendre rule on [0, 1], ``((x_k, w_k), …)`` in increasing x.

    Returns
    -------
    tuple of (mpmath.mpf, mpmath.mpf)
        Nodes and weights correct to about :data:`DPS` − 5 digits.
    """
    _check(m)
    out = []
    with mp.workdps(DPS + 10):
        tol = mp.mpf(10) ** -(DPS + 5)
        for k in range(1, m + 1):
            x = mp.cos(mp.pi * (k - mp.mpf(1) / 4) / (m + mp.mpf(1) / 2))
            for _ in range(100):
                p, dp = _legendre_and_derivative(m, x)
                dx = p / dp
                x -= dx
                if abs(dx) < tol:
                    break
            else:   # pragma: no cover - Newton from the asymptotic guess converges in < 10 steps
                raise ArithmeticError(f"Gauss–Legendre node {k} of {m} did not converge (last step {dx})")
            _, dp = _legendre_and_derivative(m, x)
            w = 2 / ((1 - x * x) * dp * dp)
            out.append(((1 - x) / 2, w / 2))
    with mp.workdps(DPS):
        return tuple((+x, +w) for x, w in out)   # x_k = (1 − cos …)/2 increases with k


@lru_cache(maxsize=None)
def gauss_legendre_f64(m: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The m-node rule on [0, 1] rounded to float64 once: ``(nodes, weights)``."""
    rule = gauss_legendre(m)
    return tuple(float(x) for x, _ in rule), tuple(float(w) for _, w in rule)
