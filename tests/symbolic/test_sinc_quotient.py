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
import sys

import mpmath
import numpy as np
import pytest
import sympy as sp

import methodgen as mg
import methodgen.symbolic.verify  # noqa: F401  (makes mg.verify callable)
from helpers import special_helpers
from methodgen.problem.special import fold_removable_quotients, sinc_dd, sinc_u
from methodgen.symbolic.verify.helpers import _certificate, helper_certificate

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
    import methodgen.problem.problem as problem
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
    pytest.importorskip("llvmlite")
    mod = mg.build(_sinc_system(), "energy-momentum", tmp_path / "s_nb.py", backend="numba")
    for y0, h, n in STARTS:
        Y = mod.integrate(np.array(y0), h, n, check_resolution=False)
        H = mod.hamiltonian(Y)
        assert np.all(np.isfinite(H)) and np.abs(H - H[0]).max() <= 4 * EPS * abs(H[0]), (y0, H - H[0])


# --- every expression is folded (H, invariants, constraints, PoissonSystem H, g) ----------------

def _pair_system(name, invariants):
    return mg.Hamiltonian("p1**2/2 + p2**2/2 + sin(q1 - q2)/(q1 - q2)", q=["q1", "q2"], p=["p1", "p2"],
                          name=name, invariants=invariants)


def test_declared_invariant_written_like_H_is_proved():
    """Exact: E2 written as H (sin(u)/u) is folded like H, so {E2, H} = 0 cancels symbol for
    symbol; monitored, it is finite at q1 = q2 (was NaN)."""
    from methodgen.symbolic.derive import declared
    system = _pair_system("pair_e2", {"E2": "p1**2/2 + p2**2/2 + sin(q1 - q2)/(q1 - q2)"})
    assert system.declared_invariants[0].expr == system.H
    (e2,) = declared(system)
    assert e2.exact and "{E2, H} = 0 exactly" in e2.why


def test_declared_invariant_monitored_at_the_removable_point(tmp_path):
    """Numerical: from q = 0 the monitor E2 (= H) is finite and constant to round-off.
    Negative control: with the folding disabled for E2 only, the monitor is NaN at q = 0."""
    import methodgen.problem.problem as problem
    src = "p**2/2 + sin(q)/q"
    system = mg.Hamiltonian(src, q=["q"], p=["p"], name="sinc_e2", invariants={"E2": src})
    mod = mg.build(system, "energy-momentum", tmp_path / "e2.py")
    E2 = mod.invariants(mod.integrate(np.array([0.0, 0.1]), 0.1, 5, check_resolution=False))["E2"]
    assert np.all(np.isfinite(E2)) and np.abs(E2 - E2[0]).max() <= 4 * EPS * abs(E2[0])
    folded = problem.fold_removable_quotients
    calls = []

    def fold_only_H(e):        # the state before the fix: H folded, the invariant not
        calls.append(e)
        return folded(e) if len(calls) == 1 else e

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(problem, "fold_removable_quotients", fold_only_H)
        raw = mg.Hamiltonian(src, q=["q"], p=["p"], name="sinc_e2_raw", invariants={"E2": src})
    assert raw.H.has(sinc_u) and not raw.declared_invariants[0].expr.has(sinc_u)
    mod = mg.build(raw, "energy-momentum", tmp_path / "e2_raw.py")
    E2 = mod.invariants(mod.integrate(np.array([0.0, 0.1]), 0.1, 5, check_resolution=False))["E2"]
    assert np.isnan(E2[0])


def test_sinc_u_meets_its_elementary_form_in_a_bracket(monkeypatch):
    """Exact: an invariant whose sin(u)/u the fold cannot see (sin(q)(q+1)/(q²+q)) against the
    folded H: {E2, H} reduces on the elementary form (dsinc_u against cos(q)/q - sin(q)/q²).
    Negative control: without the elementary form (to_elementary the identity) it is not shown."""
    import methodgen.problem.special as special
    from methodgen.symbolic.derive import declared

    def system(name):
        return mg.Hamiltonian("p**2/2 + sin(q)/q", q=["q"], p=["p"], name=name,
                              invariants={"E2": "p**2/2 + sin(q)*(q + 1)/(q**2 + q)"})

    s = system("mixed")
    assert not s.declared_invariants[0].expr.has(sinc_u)
    assert declared(s)[0].exact
    monkeypatch.setattr(special, "to_elementary", lambda e: e)
    (e2,) = declared(system("mixed_raw"))
    assert not e2.exact and "not shown exactly" in e2.why


def test_poisson_system_from_the_removable_point(tmp_path, monkeypatch):
    """Numerical: PoissonSystem("w**2/2 + sin(x)/x") runs from x = 0 (was refused: "H is NaN"),
    H constant to round-off.  Negative control: with its folding disabled it is refused."""
    import methodgen.problem.poisson as poisson

    def make(name):
        return mg.PoissonSystem("w**2/2 + sin(x)/x", y=["x", "w"], S=[[0, 1], [-1, 0]], name=name)

    mod = mg.build(make("ps_sinc"), "avf", tmp_path / "ps.py")
    H = mod.hamiltonian(mod.integrate(np.array([0.0, 0.1]), 0.1, 10, check_resolution=False))
    assert np.all(np.isfinite(H)) and np.abs(H - H[0]).max() <= 4 * EPS * abs(H[0])
    monkeypatch.setattr(poisson, "fold_removable_quotients", lambda e: e)
    raw = mg.build(make("ps_sinc_raw"), "avf", tmp_path / "ps_raw.py")
    with pytest.raises(Exception, match="H is NaN"):
        raw.integrate(np.array([0.0, 0.1]), 0.1, 10, check_resolution=False)


def test_constraint_and_time_transformation_are_folded():
    system = mg.Hamiltonian("(p1**2 + p2**2)/2", q=["q1", "q2"], p=["p1", "p2"], name="c_sinc",
                            constraints=["q1 - sin(q2)/q2"])
    assert system.constraints[0] == system.q[0] - sinc_u(system.q[1])
    tt = mg.time_transform(_sinc_system(), "2 + sin(q)/q")
    assert tt.time_transform.g == 2 + sinc_u(tt.q[0])


# --- the fold is complete, and its name stays internal -------------------------------------------

def test_fold_repeats_and_takes_powers():
    """Every factor of sin(x) sin(y)/(x y) and (sin(q)/q)² is folded; sin(2)/3 (a number) is not.
    Negative control: the one-factor fold (what one pass gave) is NaN at y = 0, the full one is not."""
    x, y, q = sp.symbols("x y q", real=True)
    both = fold_removable_quotients(sp.sin(x) * sp.sin(y) / (x * y))
    assert both == sinc_u(x) * sinc_u(y)
    assert both.subs({x: 0, y: 0}) == 1
    assert (sp.sin(y) * sinc_u(x) / y).subs({x: 0, y: 0}) is sp.nan
    assert fold_removable_quotients((sp.sin(q) / q) ** 2) == sinc_u(q) ** 2
    assert fold_removable_quotients(sp.sin(q) ** 2 / q) == sp.sin(q) * sinc_u(q)
    assert fold_removable_quotients(q * sp.sin(2) / 3) == q * sp.sin(2) / 3
    for e in (sp.sin(q) / q**2, sp.sin(q) ** 2 / q**3, sp.sin(q) / (q + 1)):
        assert fold_removable_quotients(e) == e


def test_internal_name_does_not_leak():
    """str(scheme), the verify title and the LaTeX reprs show the user's text, not sinc_u.
    Negative control: str(H), what they showed, has it."""
    from methodgen.symbolic.verify import _title
    system = mg.Hamiltonian("p**2/2 + sin(q)/q", q=["q"], p=["p"])
    scheme = mg.discretize(system, "midpoint")
    assert "sinc_u" in str(system.H)
    head = str(scheme).splitlines()[0]
    assert "sin(q)/q" in head and "sinc_u" not in head
    assert "sin(q)/q" in _title(scheme) and "sinc_u" not in _title(scheme)
    assert "sinc" not in system._repr_latex_() and r"\sin" in system._repr_latex_()
    ps = mg.PoissonSystem("w**2/2 + sin(x)/x", y=["x", "w"], S=[[0, 1], [-1, 0]])
    assert "sinc" not in ps._repr_latex_() and r"\sin" in ps._repr_latex_()


def test_sinc_certificate_never_proved_through_the_fallback(monkeypatch):
    """The series branch is a truncation: even when the first reduction fails and certify's
    own reduction proves the identity branch, the verdict is numerical.  Negative control of
    the old code path: certify itself does return 'proved' on that F."""
    helpers = sys.modules["methodgen.symbolic.verify.helpers"]
    monkeypatch.setattr(helpers, "reduce_to_zero", lambda *a, **k: None)
    _certificate.cache_clear()
    try:
        cert = helper_certificate(sinc_dd)
        assert cert.status == "numerical" and cert.method.startswith("identity branch: ")
        A, B = helpers._A, helpers._B
        F = helpers.to_elementary(sinc_dd.branch_form(A, B)) * (B - A) - (sp.sin(B) / B - sp.sin(A) / A)
        assert helpers.certify("c", F, helpers.Domain(positive=set())).status == "proved"
    finally:
        monkeypatch.undo()
        _certificate.cache_clear()


# --- extended precision: _v_sincdd in long double -------------------------------------------------

LD_PAIRS = [(0.3, 0.31), (1.0, 1.2), (1.5, 1.9), (0.01, 0.02), (-0.7, 0.4), (2.5, 2.7), (3.0, 5.0)]


def _ld_to_mp(x):
    n, d = np.longdouble(x).as_integer_ratio()
    return mpmath.mpf(n) / d


def _ld_errors(fn):
    """Relative errors of fn(a, b) on long-double inputs against mpmath (80 digits)."""
    L = np.longdouble
    out = []
    with mpmath.workdps(80):
        for a, b in LD_PAIRS:
            A, B = L(a), L(b)
            got = fn(np.array([A]), np.array([B]))[0]
            assert got.dtype == np.longdouble
            ma, mb = _ld_to_mp(A), _ld_to_mp(B)
            ref = (_sinc_mp(mb) - _sinc_mp(ma)) / (mb - ma)
            out.append(float(abs((_ld_to_mp(got) - ref) / ref)))
    return out


@pytest.mark.skipif(np.finfo(np.longdouble).eps >= EPS, reason="long double is double here")
def test_sinc_divided_difference_in_long_double():
    """Numerical: _v_sincdd on long-double inputs (extended refinement) within 8 long-double
    ulp (~8.7e-19) on every branch.  Negative control: the series with the float64
    coefficients _SINCDD_C (the former helper) is off by more than 1e-17 on the series branch."""
    hs = special_helpers()
    ld_eps = float(np.finfo(np.longdouble).eps)
    errs = _ld_errors(hs["_v_sincdd"])
    assert max(errs) <= 8 * ld_eps, errs
    coeffs = hs["_v_sincdd"].__globals__["_SINCDD_C"]

    def float64_series(a, b):
        u, v = a * a, b * b
        h, uk, s = np.ones_like(u), np.ones_like(u), np.zeros_like(u)
        for c in coeffs:
            s, uk = s + c * h, uk * u
            h = v * h + uk
        return (a + b) * s

    old = _ld_errors(float64_series)[:4]      # the pairs on the series branch
    assert max(old) > 1e-17, old
