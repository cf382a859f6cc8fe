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
from methodgen.problem.problem import Hamiltonian


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


# --- the overflow threshold: exp(hi) overflows above 709.78 where exp[a, b] does not --------

#: Pairs at the threshold: values up to 8.5e307 while exp(max(a, b)) overflows, both orders,
#: both branches of _dexpdd (|b - a| < 1 and >= 1), and values that do overflow.
THRESHOLD = [(0.0, 712.0), (712.0, 0.0), (-3.0, 712.5), (700.0, 712.0), (709.5, 710.2), (710.2, 709.5),
             (710.3, 709.4), (709.9, 709.9), (712.0, 712.3), (1000.0, 1419.0), (100.0, 1200.0)]


def _mp(kind, a, b):
    import mpmath
    with mpmath.workdps(60):
        A, B = mpmath.mpf(a), mpmath.mpf(b)
        if A == B:
            v = mpmath.exp(A) / (2 if kind == "dexpdd" else 1)
        else:
            dd = (mpmath.exp(B) - mpmath.exp(A)) / (B - A)
            v = dd if kind == "expdd" else (mpmath.exp(B) - dd) / (B - A)
        return float(v) if v < mpmath.mpf("1.7976931348623157e308") else math.inf


def _agree(got, want, ulps=4):
    if math.isinf(want):
        return got == math.inf
    return abs(got - want) <= ulps * np.finfo(float).eps * abs(want)


def test_exp_divided_differences_at_the_overflow_threshold():
    """Numerical: _expdd and _dexpdd (Python and numpy flavours) within 4 ulp of mpmath where
    exp(max(a, b)) overflows but the value does not ((0, 712): 2.318e306 and 2.315e306), and inf
    where the value overflows — the same on both flavours (Python's math raised OverflowError)."""
    from helpers import special_helpers
    hs = special_helpers()
    for kind in ("expdd", "dexpdd"):
        for a, b in THRESHOLD:
            want = _mp(kind, a, b)
            got_f = hs[f"_f_{kind}"](a, b)
            with np.errstate(over="ignore"):
                got_v = float(hs[f"_v_{kind}"](np.array([a]), np.array([b]))[0])
            assert _agree(got_f, want) and _agree(got_v, want), (kind, a, b, got_f, got_v, want)
    assert _mp("expdd", 0.0, 712.0) == pytest.approx(2.318e306, rel=1e-3)
    assert _mp("dexpdd", 0.0, 712.0) == pytest.approx(2.315e306, rel=1e-3)


def test_the_former_forms_fail_at_the_threshold():
    """Negative control: the former evaluations exp(hi)·(1 - exp(-d))/d and
    (exp(b) - exp[a, b])/(b - a) give inf / OverflowError and nan at (0, 712)."""
    a, b = 0.0, 712.0
    with pytest.raises(OverflowError):
        math.exp(max(a, b)) * (-math.expm1(-(b - a)) / (b - a))
    with np.errstate(all="ignore"):
        v = np.exp(np.float64(b)) * (-np.expm1(-(b - a)) / (b - a))
        dv = (np.exp(np.float64(b)) - v) / (b - a)
    assert v == np.inf and np.isnan(dv)
