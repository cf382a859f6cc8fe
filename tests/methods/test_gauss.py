"""Gauss–Legendre collocation (issue 14, item 2): order 2s measured, quadratic invariants
kept, coefficients certified exactly, and the certificates can fail."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from conftest import HH_T, HH_Y0
from methodgen.errors import InputError
from methodgen.symbolic.schemes.gauss import coefficients
from methodgen.symbolic.verify.collocation import gauss_certificates, moments
from methodgen.symbolic.verify.report import NUMERICAL, PROVED, REFUTED

E = 0.6
KEPLER_Y0 = np.array([1 - E, 0.0, 0.0, 0.0, np.sqrt((1 + E) / (1 - E)), 0.0])


@pytest.fixture(scope="module")
def gauss(tmp_path_factory):
    root = tmp_path_factory.mktemp("gauss")
    cache = {}

    def get(scene, stages, backend="numpy"):
        if (scene, stages, backend) not in cache:
            scheme = mg.discretize(mg.load_scene(scene).system, "gauss", stages=stages)
            cache[scene, stages, backend] = mg.generate(
                scheme, root / f"{scene}_{scheme.key}_{backend}.py".replace("-", "_"), backend=backend)
        return cache[scene, stages, backend]

    return get


@pytest.mark.parametrize("s, N", [(1, 200), (2, 50), (3, 25), (4, 16),
                                  pytest.param(5, 8, marks=pytest.mark.slow),
                                  pytest.param(6, 6, marks=pytest.mark.slow)])
def test_order_2s_on_henon_heiles(gauss, hh_reference, s, N):
    mod = gauss("henon-heiles-2d", s)
    assert mod.ORDER == 2 * s and mod.TRAITS["symplectic"]
    errs = [np.abs(mod.integrate(HH_Y0, HH_T / n, n, check_resolution=False)[-1] - hh_reference).max()
            for n in (N, 2 * N)]
    assert errs[1] > 3e-14, errs                         # above round-off: the ratio means something
    assert errs[0] / errs[1] >= 2 ** (2 * s - 0.7), (errs, np.log2(errs[0] / errs[1]))


def test_order_on_kepler(gauss):
    mod = gauss("kepler", 3)
    errs = [np.abs(mod.integrate(KEPLER_Y0, 2 * np.pi / n, n, check_resolution=False)[-1] - KEPLER_Y0).max()
            for n in (50, 100)]
    assert errs[0] / errs[1] >= 2 ** (6 - 0.7), errs


def test_quadratic_invariants_kept(gauss):
    """Angular momentum (quadratic) to round-off; H (not quadratic) only to the method's error."""
    mod = gauss("kepler", 3)
    assert {"Lx", "Ly", "Lz"} <= set(mod.TRAITS["preserved"]) and "H" not in mod.TRAITS["preserved"]
    tr = mod.integrate(np.array([0.4, 0.0, 0.0, 0.0, 1.6, 1.2]), 0.05, 400)
    inv = mod.invariants(tr)
    for k in ("Lx", "Ly", "Lz"):
        assert np.abs(inv[k] - inv[k][0]).max() < 1e-14
    dH = np.abs(inv["H"] - inv["H"][0]).max()
    assert 1e-12 < dH < 1e-4          # control: a non-quadratic invariant is visibly not exact


def test_quadratic_hamiltonian_exact(gauss):
    mod = gauss("harmonic", 2)
    scene = mg.load_scene("harmonic")
    # Newton's method, as calibrated: with 4 unknowns the default is "auto", whose steps
    # agree to round-off; either way H carries a linear drift of ~2e-17 per step at h = 0.7
    # from the float64 rounding of A and d (the symplecticity condition holds to ~1e-17),
    # 1e-14 after ~500 steps.
    tr = mod.integrate(np.asarray(scene.y0, float), 0.7, 500, solver="newton")
    H = mod.hamiltonian(tr)
    assert np.abs(H - H[0]).max() < 1e-14 and mod.TRAITS["energy_preserving"]


@pytest.mark.parametrize("s", [1, 2, 3, 4, 5, 6])
def test_coefficients_certified_exactly(s):
    co = coefficients(s)
    certs = gauss_certificates(s, A=[[float(a) for a in r] for r in co["A"]], b=[float(v) for v in co["b"]])
    assert [c.status for c in certs[:-1]] == [PROVED] * (len(certs) - 1)
    assert certs[-1].status == NUMERICAL and certs[-1].details["symplectic"] < 1e-15
    assert moments(co["poly"])[2 * s - 1] == sp.Rational(1, 2 * s)


def test_wrong_nodes_are_refuted():
    """Negative control: symmetric, distinct nodes 1/4, 3/4 are not Gauss nodes."""
    x = sp.Symbol("x")
    certs = {c.claim.split(":")[0]: c.status for c in gauss_certificates(2, P=sp.Poly(16 * x**2 - 16 * x + 3, x))}
    assert certs["B(4)"] == REFUTED and certs["symplectic"] == REFUTED
    assert certs["symmetric"] == PROVED          # symmetric nodes: that claim still holds
    # and float coefficients off by 1e-10 fail the numerical check
    co = coefficients(2)
    A = [[float(a) for a in r] for r in co["A"]]
    A[0][1] += 1e-10
    assert gauss_certificates(2, A=A, b=[float(v) for v in co["b"]])[-1].status == REFUTED


def test_solvers_agree(gauss):
    mod = gauss("henon-heiles-2d", 3)
    a = mod.integrate(HH_Y0, 0.2, 100)
    for solver in ("simplified", "fixed-point"):
        assert np.abs(mod.integrate(HH_Y0, 0.2, 100, solver=solver) - a).max() < 1e-13


def test_bad_stages():
    system = mg.load_scene("kepler").system
    with pytest.raises(InputError, match=r"stages must be one of 1, 2, 3, 4, 5, 6, got 7"):
        mg.discretize(system, "gauss", stages=7)


def test_keys_name_the_stages():
    system = mg.load_scene("kepler").system
    assert mg.discretize(system, "gauss").key == "gauss"                    # s = 2, the default
    assert mg.discretize(system, "gauss", stages=3).key == "gauss-stages3"


@pytest.mark.slow
def test_numba_equals_numpy(gauss):
    pytest.importorskip("llvmlite")
    a, b = gauss("henon-heiles-2d", 3), gauss("henon-heiles-2d", 3, "numba")
    assert np.abs(a.integrate(HH_Y0, 0.2, 200) - b.integrate(HH_Y0, 0.2, 200)).max() < 1e-13


def test_gauss_on_a_large_system_says_its_newton_is_dense():
    """Where Gauss is offered for many degrees of freedom (two bodies in 3-D: 2d = 12) its
    notes say the stage Newton is dense and name the cheaper choices; control: not for 2 DOF."""
    from methodgen.app.bench import nbody_system

    big = mg.discretize(nbody_system(2, 1.0, [1.0, 1e-3]), "gauss", stages=2)
    note = [n for n in big.traits.notes if "dense linear system" in n]
    assert note and "24 unknowns" in note[0] and "Störmer–Verlet" in note[0] and "Wisdom–Holman" in note[0]
    small = mg.discretize(mg.load_scene("henon-heiles-2d").system, "gauss", stages=2)
    assert not [n for n in small.traits.notes if "dense linear system" in n]
