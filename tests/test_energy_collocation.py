"""Energy-preserving collocation (issue 14, item 3): order 2s measured, H exact to round-off
on polynomial H and proved exactly; quadrature (and only a numerical claim) otherwise."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from conftest import HH_T, HH_Y0
from methodgen.errors import InputError
from methodgen.verify import verify
from methodgen.verify.collocation import energy_collocation_certificates
from methodgen.verify.report import PROVED, REFUTED



@pytest.fixture(scope="module")
def hh():
    return mg.load_scene("henon-heiles-2d").system


@pytest.fixture(scope="module")
def module(tmp_path_factory):
    root = tmp_path_factory.mktemp("ec")
    cache = {}

    def get(system, stages):
        if (system.name, stages) not in cache:
            scheme = mg.discretize(system, "energy-collocation", stages=stages)
            cache[system.name, stages] = mg.generate(scheme, root / f"{system.name}_{scheme.key}.py".replace("-", "_"))
        return cache[system.name, stages]

    return get


@pytest.mark.parametrize("s, N", [(1, 20), (2, 20), (3, 20), pytest.param(4, 10, marks=pytest.mark.slow)])
def test_order_and_exact_energy(module, hh, hh_reference, s, N):
    mod = module(hh, s)
    assert mod.ORDER == 2 * s and mod.TRAITS["preserved"] == ["H"] and mod.TRAITS["energy_preserving"]
    errs = [np.abs(mod.integrate(HH_Y0, HH_T / n, n, check_resolution=False)[-1] - hh_reference).max()
            for n in (N, 2 * N)]
    assert errs[1] > 3e-14 and errs[0] / errs[1] >= 2 ** (2 * s - 0.7), errs
    H = mod.hamiltonian(mod.integrate(HH_Y0, 0.3, 1000))
    assert np.abs(H - H[0]).max() < 2e-15


@pytest.mark.parametrize("s", [1, 2])
def test_energy_proved_exactly(hh, s):
    rep = verify(mg.discretize(hh, "energy-collocation", stages=s))
    statuses = {c.claim.split(":")[0]: c.status for c in rep.certificates}
    key = f"energy-collocation (s = {s}) keeps H exactly"
    assert statuses[key] == PROVED
    assert REFUTED not in statuses.values()


def test_wrong_weights_are_refuted(hh):
    """Negative control: b_j that are not ∫ℓ_j break the identity (and the method's energy)."""
    sc = mg.discretize(hh, "energy-collocation", stages=2)
    st = dict(sc.structure)
    st["b"] = (st["b"][0] + sp.Rational(1, 1000), st["b"][1] - sp.Rational(1, 1000))
    assert [c.status for c in energy_collocation_certificates(dataclasses.replace(sc, structure=st))] == [REFUTED]


def test_non_polynomial_h_is_only_approximate(module):
    kepler = mg.load_scene("kepler").system
    sc = mg.discretize(kepler, "energy-collocation", stages=2)
    assert sc.traits.approximate == ("H",) and not sc.traits.energy_preserving and sc.traits.preserved == ()
    assert energy_collocation_certificates(sc) == []
    rep = verify(sc)
    assert all(c.status != PROVED or "H(y1) = H(y0)" not in c.claim for c in rep.certificates)
    mod = module(kepler, 2)
    e = 0.6
    y0 = np.array([1 - e, 0, 0, 0, np.sqrt((1 + e) / (1 - e)), 0])
    errs = [np.abs(mod.integrate(y0, 2 * np.pi / n, n)[-1] - y0).max() for n in (50, 100)]
    assert errs[0] / errs[1] >= 2 ** 3.3, errs


def test_bad_stages(hh):
    with pytest.raises(InputError, match=r"stages must be one of 1, 2, 3, 4, got 5"):
        mg.discretize(hh, "energy-collocation", stages=5)


def test_one_stage_composes(module, hh):
    """s = 1 is the AVF method (symmetric, order 2): it composes to order 4."""
    sc = mg.discretize(hh, "energy-collocation", stages=1, order=4)
    assert sc.traits.order == 4 and sc.key == "energy-collocation-stages1-order4-suzuki"
    with pytest.raises(mg.MethodNotApplicable, match="symmetric method of order 2"):
        mg.discretize(hh, "energy-collocation", stages=2, order=6)


def test_too_few_quadrature_nodes_are_refuted(hh):
    """Negative control: with fewer nodes than the integrand's degree needs, the rule is not
    exact and the energy claim must fail (and the method really drifts then)."""
    sc = mg.discretize(hh, "energy-collocation", stages=2)
    assert sc.structure["nodes"] == 3                     # f quadratic: degree (s - 1) + 2s = 5 needs 3 nodes
    st = dict(sc.structure, nodes=2)
    cert = energy_collocation_certificates(dataclasses.replace(sc, structure=st))[0]
    assert cert.status == REFUTED and cert.details["integrand_degree"] == 5
