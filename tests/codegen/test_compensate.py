"""Compensated stage sums (methodgen.symbolic.compensate): the rewrite is the identity at c = 0 and
keeps the compensation where a stage point is formed, in floating point."""

from __future__ import annotations

import sympy as sp

from methodgen.symbolic.compensate import compensate, compensation_symbols, grouped

x, y, dx, dy, h, k = sp.symbols("x y _d_x _d_y h k", real=True)
C = compensation_symbols([x, y])


def _ungroup(e):
    return e.replace(lambda a: isinstance(a, grouped), lambda a: a.args[0])


def test_identity_at_zero_compensation():
    exprs = [2 * x + dx, x * y, x + h * x, (x + dx) ** 2 + y ** 2, y - h / 2 * k * (x + dx / 2),
             dy * h * (1 - 2 * y) / 2, 1 - 2 * x + y,
             sp.sqrt((x + dx) ** 2 + (y + dy) ** 2), sp.exp(x - y + dx)]
    for e, c in zip(exprs, compensate(exprs, C)):
        assert sp.expand(_ungroup(c).xreplace({v: 0 for v in C.values()}) - e) == 0


def test_stage_points_carry_the_compensation():
    (e,) = compensate([x + dx / 2], C)
    assert e == x + grouped(C[x] + dx / 2)
    # a state alone keeps no compensation (it would round away)
    (e,) = compensate([sp.sqrt(x ** 2 + 1)], C)
    assert not (e.free_symbols & set(C.values()))


def test_in_floating_point_the_grouping_keeps_what_plain_summation_loses():
    """x = 1, c = 2⁻⁵⁴ (below half an ulp of x), dx = 2⁻⁵²: the stage point x + c + dx/2
    is 1 + 2⁻⁵³ + 2⁻⁵⁴ exactly; grouped it rounds to 1 + 2⁻⁵² (the nearest double), plain
    left-to-right summation (x + c) + dx/2 loses c and ties to 1 (negative control)."""
    xv, cv, dv = 1.0, 2.0 ** -54, 2.0 ** -52
    (e,) = compensate([x + dx / 2], C)
    (small,) = [a.args[0] for a in e.args if isinstance(a, grouped)]
    f = sp.lambdify([x, C[x], dx], small, "math")   # the grouped small sum
    assert xv + f(xv, cv, dv) == 1.0 + 2.0 ** -52
    assert (xv + cv) + dv / 2 == 1.0
