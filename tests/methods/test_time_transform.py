"""Poincaré time transformation (issue 14, item 4): Kepler at e = 0.99 at a fixed fictive
step through every pericentre, checked against the exact Kepler solution at the computed
physical time; invariants; certificates and their negative controls; bad input."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import methodgen as mg
from methodgen.errors import InputError, ParseError
from methodgen.symbolic.verify.report import PROVED, REFUTED
from methodgen.symbolic.verify.timetransform import time_transform_certificates

E = 0.99
Y0 = np.array([-(1 + E), 0.0, 0.0, 0.0, -np.sqrt((1 - E) / (1 + E)), 0.0])   # apocentre, a = 1
R = "sqrt(x**2 + y**2 + z**2)"


def kepler_exact(t):
    """The exact orbit through Y0 (k = m = 1, a = 1, period 2π) at time t, by Kepler's equation."""
    M = np.pi + t                                   # mean anomaly; apocentre at M = π
    Ea = M
    for _ in range(60):
        Ea = Ea - (Ea - E * np.sin(Ea) - M) / (1 - E * np.cos(Ea))
    Edot = 1 / (1 - E * np.cos(Ea))
    b = np.sqrt(1 - E * E)
    return np.array([np.cos(Ea) - E, b * np.sin(Ea), 0.0, -np.sin(Ea) * Edot, b * np.cos(Ea) * Edot, 0.0])


@pytest.fixture(scope="module")
def transformed():
    return mg.time_transform(mg.load_scene("kepler").system, R)


@pytest.fixture(scope="module")
def modules(transformed, tmp_path_factory):
    root = tmp_path_factory.mktemp("tt")
    cache = {}

    def get(method, order=2, backend="numpy"):
        if (method, order, backend) not in cache:
            scheme = mg.discretize(transformed, method, order=order)
            cache[method, order, backend] = mg.generate(
                scheme, root / f"ktt_{scheme.key}_{backend}.py".replace("-", "_"), backend=backend)
        return cache[method, order, backend]

    return get


def test_extended_system(transformed):
    assert transformed.state_names == ("x", "y", "z", "t", "px", "py", "pz", "e")
    assert transformed.time_transform.original.name == "kepler"
    assert "energy-momentum" not in mg.applicable_methods(transformed)   # K is not separable
    assert {"avf", "midpoint", "gauss"} <= set(mg.applicable_methods(transformed))


def test_initial_state_is_on_K_zero(modules):
    mod = modules("avf")
    Y = mod.initial_state(Y0, t0=2.5)
    assert Y.shape == (8,) and Y[3] == 2.5 and Y[7] == pytest.approx(0.5)    # e = -H = 1/(2a)
    assert abs(mod.hamiltonian(Y)) < 1e-15                                    # K = 0
    y, t = mod.physical_state(Y)
    assert np.array_equal(y, Y0) and t == 2.5
    with pytest.raises(ValueError, match=r"y0 must have shape \(\.\.\., 6\)"):
        mod.initial_state(np.zeros(8))


def test_kepler_099_through_pericentres(modules):
    """Ten orbits at e = 0.99 with one fixed fictive step (h = 0.02, 314 steps per orbit):
    the physical state at the computed time agrees with Kepler's equation, H exactly."""
    mod = modules("avf")
    tr = mod.integrate(mod.initial_state(Y0), 0.02, 3142)
    y, t = mod.physical_state(tr)
    r = np.linalg.norm(y[:, :3], axis=1)
    assert r.min() < 0.0101 and t[-1] > 62.8                   # ten pericentre passages
    # at every apocentre (τ-period 2π for g = r: every 314 steps), after each pericentre
    # passage: state against Kepler's equation at the computed time
    err = max(np.abs(y[i] - kepler_exact(t[i])).max() for i in range(314, len(t), 314))
    assert err < 5e-3, err
    # every pericentre is resolved: the closest approach of each orbit is a(1 - e) = 0.01
    # (the untransformed method at e = 0.999 reported 0.144 for 0.001; issue 13)
    rmin = [r[k:k + 314].min() for k in range(0, 3142 - 313, 314)]
    assert len(rmin) == 10 and np.allclose(rmin, 0.01, rtol=0.03), rmin
    inv = mod.invariants(tr)
    assert np.abs(inv["H_phys"] - inv["H_phys"][0]).max() < 1e-12              # AVF: e const, K = 0
    # negative control: the same number of equal *physical* steps misses the pericentres badly
    plain = mg.generate(mg.discretize(mg.load_scene("kepler").system, "avf"),
                        mod.__file__.replace(".py", "_plain.py"))
    with pytest.raises(plain.ResolutionError):
        plain.integrate(Y0, t[-1] / 3142, 3142)


def test_high_order_composition_of_the_transformed_system(modules):
    """Order 4 (Suzuki) of AVF on K: the error against Kepler's equation falls ~16x per halving."""
    mod = modules("avf", 4)
    errs = []
    for h, n in ((0.04, 157), (0.02, 314)):
        tr = mod.integrate(mod.initial_state(Y0), h, n)
        y, t = mod.physical_state(tr[-1])
        errs.append(np.abs(y - kepler_exact(t)).max())
    assert errs[0] / errs[1] > 2 ** 3.3, errs


def test_certificates_prove_the_reduction(transformed):
    certs = time_transform_certificates(transformed)
    assert [c.status for c in certs] == [PROVED, PROVED, PROVED]


def test_certificates_refute_a_wrong_transformation(transformed):
    """Negative control: a K that is not g(H + e) (an extra t-dependence) is refuted."""
    t, e = transformed.time_transform.time, transformed.time_transform.energy
    bad = mg.Hamiltonian(transformed.H + sp.Rational(1, 100) * t * e, q=list(transformed.q),
                         p=list(transformed.p), params=transformed.param_values, name="bad")
    object.__setattr__(bad, "time_transform", transformed.time_transform)
    statuses = [c.status for c in time_transform_certificates(bad)]
    assert statuses == [REFUTED, REFUTED, REFUTED]


@pytest.mark.parametrize("g, match", [
    ("px**2 + 1", "depends on momenta"),
    ("2", "does not depend on q"),
    ("w*x", "w"),
    ("sqrt(x**2)", "Abs|absolute"),
])
def test_bad_g(g, match):
    with pytest.raises((InputError, ParseError), match=match):
        mg.time_transform(mg.load_scene("kepler").system, g)


def test_twice_is_refused(transformed):
    with pytest.raises(InputError, match="already time-transformed"):
        mg.time_transform(transformed, R)
