"""``sin(u)/u`` in H: smooth at u = 0, and kept exactly (to round-off) by the discrete gradients.

Issue 28.2: from q = 1e-8 the energy moved by 1.47e-9 in 5 steps of a scheme claimed to keep
H exactly, and q = 0 was refused as "outside the domain".  The Hamiltonian now folds
``sin(u)/u`` into ``sinc_u(u)`` (value 1 at 0), whose helpers (value, derivatives, divided
difference ``_sincdd`` with three branches, its Jacobian ``_dsincdd``) are accurate to a few
ulp on both sides of every branch switch.  Negative controls: the product-rule divided
difference of ``sin(q)·q⁻¹`` (what the unfolded H got) and the raw quotient lose accuracy there.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
import sympy as sp

import methodgen as mg
import methodgen.verify  # noqa: F401  (makes mg.verify callable)
from helpers import special_helpers
from methodgen.special import fold_removable_quotients, sinc_dd, sinc_u
from methodgen.verify.helpers import _certificate, helper_certificate

EPS = np.finfo(float).eps
BELOW2, ABOVE2 = float(np.nextafter(2.0, 0.0)), float(np.nextafter(2.0, 3.0))
BELOW1 = float(np.nextafter(1.0, 0.0))


def _sinc_mp(x):
    return mpmath.sin(x) / x if x else mpmath.mpf(1)


def _dd_exact(a, b):
    with mpmath.workdps(80):
        A, B = mpmath.mpf(a), mpmath.mpf(b)
        if A == B:
            return float(mpmath.diff(_sinc_mp, A))
        return float((_sinc_mp(B) - _sinc_mp(A)) / (B - A))


def _ddd_exact(a, b):
    """∂/∂b sinc[a, b]."""
    with mpmath.workdps(80):
        A, B = mpmath.mpf(a), mpmath.mpf(b)
        if A == B:
            return float(mpmath.diff(_sinc_mp, A, 2) / 2)
        return float((mpmath.diff(_sinc_mp, B) - (_sinc_mp(B) - _sinc_mp(A)) / (B - A)) / (B - A))


#: Pairs on both sides of each switch of _sincdd: |a|, |b| < 2 (series) or not, |b - a| < 1
#: (product form) or not (quotient); near 0, at 0, on the diagonal, both signs.
SWITCH_PAIRS = [
    (BELOW2, BELOW2), (ABOVE2, ABOVE2), (BELOW2, ABOVE2), (1.5, BELOW2), (1.5, ABOVE2),
    (BELOW2, 1.2), (ABOVE2, 1.2), (2.5, 2.5 - BELOW1), (2.5, 1.5), (2.5, 2.5 - 1.0000000000000002),
    (-2.5, -2.5 + BELOW1), (-ABOVE2, -1.1), (0.0, 0.0), (1e-8, 1e-8), (1e-8, 1.0000001e-8), (0.0, 1e-9),
    (1e-8, -1e-8), (-0.3, 0.31), (3.0, 3.0 + 1e-9), (-7.0, -7.2), (0.0, 5.0), (10.0, 10.5), (0.5, 2.4),
]


def _close(got, want, ulps, scale=None):
    return abs(got - want) <= ulps * EPS * (abs(want) if scale is None else scale) + 1e-300


def test_sin_over_u_is_folded():
    q, x, y, k = sp.symbols("q x y k", real=True)
    assert fold_removable_quotients(sp.sin(q) / q) == sinc_u(q)
    assert fold_removable_quotients(k * sp.sin(2 * q) / (2 * q)) == k * sinc_u(2 * q)
    assert fold_removable_quotients(sp.sin(x**2 + y**2) / (x**2 + y**2)) == sinc_u(x**2 + y**2)
    # not a removable quotient: left alone
    for e in (sp.sin(q) / q**2, q * sp.sin(q), sp.sin(q) / (q + 1)):
        assert fold_removable_quotients(e) == e
    H = mg.Hamiltonian("p**2/2 + sin(q)/q", q=["q"], p=["p"], name="sincq")
    assert H.H.has(sinc_u)


def test_sinc_divided_difference_on_both_sides_of_every_switch():
    """Numerical: _sincdd (scalar and vector) within 8 ulp of the value, or of the scale
    1/|b - a| where the value is near a zero of the difference (never above 1e-16)."""
    hs = special_helpers()
    for a, b in SWITCH_PAIRS:
        want = _dd_exact(a, b)
        scale = max(abs(want), 1e-2)
        for got in (hs["_f_sincdd"](a, b), float(hs["_v_sincdd"](np.array([a]), np.array([b]))[0])):
            assert _close(got, want, 8, scale), (a, b, got, want)


def test_sinc_divided_difference_jacobian():
    """Numerical: _dsincdd (Jacobians only) within 1e-13 relative across |b - a| = 1."""
    hs = special_helpers()
    for a, b in SWITCH_PAIRS:
        want = _ddd_exact(a, b)
        for got in (hs["_f_dsincdd"](a, b), float(hs["_v_dsincdd"](np.array([a]), np.array([b]))[0])):
            assert abs(got - want) <= 1e-13 * max(abs(want), 1e-2), (a, b, got, want)


def test_product_rule_and_quotient_fail_the_same_check():
    """Negative control: the product rule on sin(q)·q⁻¹ (the unfolded H) and the raw quotient
    near 0 are off by far more than the 8 ulp above."""
    hs = special_helpers()
    a, b = 1e-8, 1.0000001e-8
    want = _dd_exact(a, b)
    sin_ab = hs["_f_sindd"](a, b)
    product = sin_ab * (1 / a + 1 / b) / 2 + (math.sin(a) + math.sin(b)) / 2 * (-1 / (a * b))
    quotient = (math.sin(b) / b - math.sin(a) / a) / (b - a)
    assert abs(product - want) > 1e6 * EPS * abs(want)
    assert abs(quotient - want) > 1e6 * EPS * abs(want)


def test_sinc_helper_certificate():
    """The identity branch is proved, the series branch is a truncation: numerical, never 'proved'."""
    cert = helper_certificate(sinc_dd)
    assert cert.status == "numerical" and cert.method.startswith("identity branch: ")
    assert cert.details["passed"] is True


def test_a_wrong_sinc_branch_is_refuted(monkeypatch):
    """Negative control: the product form with cos δ replaced by 1 is refuted."""
    def wrong(cls, a, b):
        m, d = (a + b) / 2, (b - a) / 2
        return (m * sp.cos(m) * sinc_u(d) - sp.sin(m)) / (a * b)

    monkeypatch.setattr(sinc_dd, "branch_form", classmethod(wrong))
    _certificate.cache_clear()
    try:
        assert helper_certificate(sinc_dd).status == "refuted"
    finally:
        monkeypatch.undo()
        _certificate.cache_clear()


def _sinc_system():
    return mg.Hamiltonian("p**2/2 + sin(q)/q", q=["q"], p=["p"], name="sincq")


#: Starts: the issue's q = 1e-8, q = 0 (was refused), and across the switch |q| = 2 with steps
#: of |Δq| < 1 and > 1 (p = 3, h = 0.4).
STARTS = [((1e-8, 0.0), 0.1, 5), ((0.0, 0.1), 0.1, 20), ((1.9, 0.5), 0.05, 20), ((1.5, 3.0), 0.4, 6),
          ((-2.3, 0.8), 0.1, 20)]


@pytest.mark.parametrize("method", ["energy-momentum", "avf", "itoh-abe"])
def test_energy_kept_to_round_off_across_the_switches(method, tmp_path):
    """Numerical: H(y_n) - H(y_0) ≤ 4 eps |H| on every start (numpy backend)."""
    mod = mg.build(_sinc_system(), method, tmp_path / f"s_{method.replace('-', '_')}.py")
    for y0, h, n in STARTS:
        Y = mod.integrate(np.array(y0), h, n, check_resolution=False)
        H = mod.hamiltonian(Y)
        assert np.all(np.isfinite(H)) and np.abs(H - H[0]).max() <= 4 * EPS * abs(H[0]), (y0, H - H[0])


def test_unfolded_quotient_fails_there(tmp_path, monkeypatch):
    """Negative control: with the folding disabled (H keeps sin(q)/q), the run from q = 1e-8
    does not converge and q = 0 is refused (H is NaN)."""
    import methodgen.problem as problem
    monkeypatch.setattr(problem, "fold_removable_quotients", lambda e: e)
    system = mg.Hamiltonian("p**2/2 + sin(q)/q", q=["q"], p=["p"], name="sincq_raw")
    assert not system.H.has(sinc_u)
    mod = mg.build(system, "energy-momentum", tmp_path / "raw.py")
    for y0, why in (((1e-8, 0.0), "did not converge"), ((0.0, 0.1), "H is NaN")):
        with pytest.raises(Exception, match=why):
            mod.integrate(np.array(y0), 0.1, 5, check_resolution=False)


@pytest.mark.slow
def test_energy_kept_on_numba(tmp_path):
    """Numerical: the same on the numba backend (one compiled module, energy-momentum; ~45 s
    of compilation: slow.  The fast sibling is tests/test_helper_availability.py, which
    compiles every helper, _sincdd included, and compares it at these switch points)."""
    pytest.importorskip("numba")
    mod = mg.build(_sinc_system(), "energy-momentum", tmp_path / "s_nb.py", backend="numba")
    for y0, h, n in STARTS:
        Y = mod.integrate(np.array(y0), h, n, check_resolution=False)
        H = mod.hamiltonian(Y)
        assert np.all(np.isfinite(H)) and np.abs(H - H[0]).max() <= 4 * EPS * abs(H[0]), (y0, H - H[0])
