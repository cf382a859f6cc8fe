"""Gauss–Legendre rules (issue 28.1): computed from the definition, certified as emitted.

The 64-node rule used to be wrong by 2e-5 in its weights (sum 1 − 2.3e-6) and energy
collocation on ``q**64`` still "proved" exact H.  Every rule the code can choose
(1..MAX_NODES nodes) is checked here: at 60 digits against the definition, and as the
float64 numbers a module carries.
"""

from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest

from methodgen.errors import InputError
from methodgen.symbolic.schemes.quadrature import MAX_NODES, gauss_legendre, gauss_legendre_f64
from methodgen.symbolic.verify.quadrature import TOLERANCE, rule_certificate, rule_deviation
from methodgen.symbolic.verify.report import NUMERICAL, REFUTED

FAST = list(range(1, 33)) + [48, 63, 64]


def _moment_error(rule):
    """max over p < 2m of |Σ w_k x_k^p − 1/(p+1)| at 60 digits (x^p ≤ 1, w_k > 0: no cancellation)."""
    m = len(rule)
    worst = mp.mpf(0)
    with mp.workdps(60):
        powers = [mp.mpf(1)] * m
        for p in range(2 * m):
            err = mp.fsum(w * xp for (_, w), xp in zip(rule, powers)) - mp.mpf(1) / (p + 1)
            worst = max(worst, abs(err))
            powers = [xp * x for (x, _), xp in zip(rule, powers)]
    return worst


def test_moment_check_has_teeth():
    """Negative control of the 60-digit check: one weight off by 1e-45 fails it."""
    rule = list(gauss_legendre(16))
    with mp.workdps(60):
        rule[5] = (rule[5][0], rule[5][1] + mp.mpf("1e-45"))
    assert _moment_error(rule) > mp.mpf(10) ** -50


def _check_rule(m: int) -> None:
    # the 60-digit rule: every x^p, p < 2m, integrated to < 1e-50 (exact value 1/(p+1));
    # x^p ≤ 1 and w_k > 0 on [0, 1], so the check itself loses no digits
    rule = gauss_legendre(m)
    assert _moment_error(rule) < mp.mpf(10) ** -50, m
    with mp.workdps(60):
        assert all(0 < x < 1 and w > 0 for x, w in rule)
        assert all(a[0] < b[0] for a, b in zip(rule, rule[1:]))
    # the float64 rule the module carries: certified to round-off
    x, w = gauss_legendre_f64(m)
    cert = rule_certificate(x, w, "test")
    assert cert.status == NUMERICAL and cert.details["passed"], (m, cert.details)
    assert abs(cert.details["weights_sum_minus_1"]) < 4e-16


@pytest.mark.parametrize("m", FAST)
def test_rules_certified(m):
    _check_rule(m)


@pytest.mark.slow
def test_every_rule_the_code_can_choose():
    """All of 1..MAX_NODES (energy collocation picks m from the field's degree)."""
    for m in range(1, MAX_NODES + 1):
        _check_rule(m)


@pytest.mark.parametrize("m", [8, 64])
def test_one_perturbed_weight_fails(m):
    """Negative control: one weight off by 1e-12 must fail the certificate."""
    x, w = gauss_legendre_f64(m)
    bad = list(w)
    bad[m // 2] += 1e-12
    cert = rule_certificate(x, bad, "test")
    assert cert.status == REFUTED and not cert.details["passed"]
    assert cert.details["worst_deviation"] > 5e-13
    node = list(x)                                 # and one node moved by 1e-12
    node[0] += 1e-12
    assert rule_certificate(node, w, "test").status == REFUTED


def test_old_monomial_weights_were_wrong():
    """The defect this replaces, for the record: numpy's float rule is within the
    tolerance at 8 nodes (AVF's default) but not at 64, where ours is."""
    xn, wn = np.polynomial.legendre.leggauss(64)
    assert rule_deviation(list((xn + 1) / 2), list(wn / 2))["worst"] > TOLERANCE
    assert rule_deviation(*gauss_legendre_f64(64))["worst"] < TOLERANCE / 2


@pytest.mark.parametrize("m", [0, MAX_NODES + 1, 2.0, True])
def test_bad_node_count(m):
    with pytest.raises(InputError, match=rf"number of nodes must be an integer in 1\.\.{MAX_NODES}"):
        gauss_legendre(m)


def test_avf_quadrature_uses_a_certified_rule():
    """AVF's quadrature path: the rule in its equations is the certified one, and the
    identity's claim says what is checked (not "hence H(y1) = H(y0)": H is approximate)."""
    import dataclasses

    import methodgen as mg
    from methodgen.symbolic.verify.discrete_gradients import dg_items

    kepler = mg.load_scene("kepler").system
    sc = mg.discretize(kepler, "avf")
    assert sc.traits.approximate == ("H",)
    x, w = sc.structure["rule"]
    assert (x, w) == gauss_legendre_f64(8)
    items = dict(dg_items(sc))
    assert items["quadrature"].status == NUMERICAL and items["quadrature"].details["passed"]
    ident = items["invariant:H"].claim
    assert "up to the quadrature error" in ident and "hence H(y1) = H(y0)" not in ident
    # negative control: a perturbed rule in the structure is refuted
    bad = (x, tuple(v + (1e-12 if i == 3 else 0) for i, v in enumerate(w)))
    bad_items = dict(dg_items(dataclasses.replace(sc, structure={"kind": "avf-quadrature", "rule": bad})))
    assert bad_items["quadrature"].status == REFUTED
