"""Energy-momentum on a thin exp barrier: steps far from it, where the force is 0, run.

V = 10 exp(-(q/0.005)²): a step from q = -0.3 to -0.2 has exponents -3600 and -1600, so
exp[a, b] = exp(-2600)·sinhc(1000) in the sinhc form is 0·inf (math range error, "try a
smaller h") although its value is ~0 and the step is exact free flight.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import methodgen as mg
from methodgen.problem import Hamiltonian


def _barrier():
    return Hamiltonian("p**2/2 + 10*exp(-(q/0.005)**2)", q=["q"], p=["p"], name="thin_barrier")


@pytest.fixture(scope="module")
def module(tmp_path_factory):
    return mg.build(_barrier(), "energy-momentum", tmp_path_factory.mktemp("barrier") / "barrier.py")


def test_free_flight_next_to_a_thin_barrier(module):
    """Numerical: 2 steps of h = 0.1 from q = -0.3, p = 1 are free flight, H kept exactly."""
    Y = module.integrate(np.array([-0.3, 1.0]), 0.1, 2)
    assert np.allclose(Y[-1], [-0.1, 1.0], rtol=0, atol=1e-15)
    H = module.hamiltonian(Y)
    assert np.abs(H - H[0]).max() == 0.0


def test_the_sinhc_forms_fail_there(module, monkeypatch):
    """Negative control: with exp[a, b] and its Jacobian evaluated in the sinhc form (the
    former helpers), the same run stops with the math range error."""
    def old_expdd(a, b):
        return math.exp(0.5 * (a + b)) * module._f_sinhc(0.5 * (b - a))

    def old_dexpdd(a, b):
        h = 0.5 * (b - a)
        return 0.5 * math.exp(0.5 * (a + b)) * (module._f_sinhc(h) + module._f_dsinhc(h))

    monkeypatch.setattr(module, "_f_expdd", old_expdd)
    monkeypatch.setattr(module, "_f_dexpdd", old_dexpdd)
    with pytest.raises(Exception, match="math range error"):
        module.integrate(np.array([-0.3, 1.0]), 0.1, 2)
