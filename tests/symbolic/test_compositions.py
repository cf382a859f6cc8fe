"""Composition coefficients: every family reaches its order — decided in the free algebra,
not assumed — and a perturbed coefficient set does not."""

from __future__ import annotations

import pytest
import sympy as sp

from methodgen.symbolic.compositions import (DEFAULT_FAMILY, FAMILIES, Composition, achieved_order, composition,
                                    efficiency, order_defects, triple_jump_exact)
from methodgen.symbolic.verify.exact import reduce_to_zero

FAST = [(f, K) for f, orders in FAMILIES.items() for K in orders if not (f == "suzuki" and K >= 8)]


@pytest.mark.parametrize("family, order", FAST, ids=[f"{f}-{K}" for f, K in FAST])
def test_family_reaches_its_order(family, order):
    comp = composition(order, family)
    assert comp.gammas == tuple(reversed(comp.gammas))          # symmetric
    assert abs(sum(comp.floats()) - 1) < 1e-14
    assert achieved_order(comp) == order                        # and not more: weight K+1 is nonzero
    assert order_defects(comp)[order + 1] > 1e-8


@pytest.mark.slow
@pytest.mark.parametrize("order", [8, 10])
def test_suzuki_high_orders(order):
    assert achieved_order(composition(order, "suzuki")) == order


@pytest.mark.parametrize("order", [4, 6, 8])
def test_a_perturbed_coefficient_set_loses_the_order(order):
    comp = composition(order)
    g = list(comp.floats())
    i = len(g) // 2 - 1
    g[i] += 1e-7
    g[-1 - i] += 1e-7
    g[len(g) // 2] -= 2e-7                                        # still symmetric, still Σ = 1
    bad = Composition(comp.family, order, tuple(repr(x) for x in g), False, "perturbed")
    assert achieved_order(bad, tol=1e-12) < order


@pytest.mark.parametrize("order", [4, 6, 8, 10])
@pytest.mark.parametrize("parts", [3, 5])
def test_recursive_families_exact_conditions(order, parts):
    assert all(reduce_to_zero(e) for e in triple_jump_exact(order, parts))


def test_a_wrong_root_fails_the_exact_condition():
    r = sp.Integer(2) ** sp.Rational(1, 4)             # order 4 needs the cube root of 2
    g1 = 1 / (2 - r)
    assert reduce_to_zero(2 * g1**3 + (-r * g1) ** 3) is None


def test_defaults_are_the_most_efficient_available():
    for K, fam in DEFAULT_FAMILY.items():
        if K == 2:
            continue
        best = efficiency(composition(K, fam))
        for other, orders in FAMILIES.items():
            if K in orders and other != fam and not (other == "suzuki" and K >= 8):
                assert best < efficiency(composition(K, other)), (K, fam, other)


def test_bad_requests_are_named():
    with pytest.raises(ValueError, match="order must be one of"):
        composition(5)
    with pytest.raises(ValueError, match="unknown composition family"):
        composition(4, "yoshida-magic")
    with pytest.raises(ValueError, match="has orders"):
        composition(4, "kahan-li")
