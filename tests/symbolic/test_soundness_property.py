"""Soundness of the discrete gradients, as a property: "proved" must mean true.

For random smooth potentials built from the grammar's functions,
H = Σ p_i²/2 + U(q), and every discrete-gradient method that applies, the
scheme's own ∇̄H (``scheme.discrete_gradient``) is evaluated at 50 digits **as
the generated code evaluates it** — a ``Piecewise`` on the branch it takes at
that point (a truncated series branch near the diagonal is used there, and must
be exact too), ``safe_div(n, 0)`` as 0, each helper of :mod:`methodgen.problem.special`
by the formula its generated helper computes (``stable_form``, the ``atan``
addition-formula branch, ``sinh(x)/x`` …) — and the discrete-gradient identity

    (y1 - y0)ᵀ ∇̄H(y0, y1) = H(y1) - H(y0)

is checked at exact rational points y1 = y0 + gap·d for gaps 1/10 … 1e-12 to a
relative 1e-30.  Where the identity fails, the verifier's certificate for it is
computed and named in the failure: a "proved" certificate for an identity that fails
numerically is a soundness bug of the verification layer (it proved a different
expression than the code runs).  (The slow variant runs the whole ``verify`` on every
example; the default one asks for the certificate only on a failure: its exact
reduction of a large random H ran unbounded once under xdist, past its 20 s alarm.)

A negative control shows that the check catches a two-term Taylor branch of
atan's divided difference, and a smaller property runs the generated modules
over a step-size ladder and checks the energy to round-off.
"""

from __future__ import annotations

import contextlib
import signal

import numpy as np
import pytest
import sympy as sp
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

import methodgen as mg
from methodgen.problem import special
from methodgen.errors import InputError, MethodNotApplicable
from methodgen.symbolic.verify.common import y1_symbols
from methodgen.symbolic.verify.discrete_gradients import dg_identity

METHODS = ["energy-momentum", "avf", "gonzalez", "itoh-abe"]
GAPS = [sp.Rational(1, 10), sp.Rational(1, 10**3), sp.Rational(1, 10**6), sp.Rational(1, 10**9),
        sp.Rational(1, 10**12)]
DIGITS = 50
REL_TOL = sp.Float("1e-30", DIGITS)
MAX_OPS = 40
CERTIFY_SECONDS = 20

NAMES = {1: (["q"], ["p"]), 2: (["x", "y"], ["px", "py"])}


# --- random smooth potentials ------------------------------------------------------------

def _unary(name: str, u: sp.Expr) -> sp.Expr:
    """The grammar's functions, arguments scaled or guarded so the real domain is all of R."""
    return {
        "atan": lambda: sp.atan(u),
        "tan": lambda: sp.tan(sp.sin(u) / 2),        # |argument| <= 1/2 < pi/2: no pole
        "exp": lambda: sp.exp(u / 2),
        "sin": lambda: sp.sin(u),
        "cos": lambda: sp.cos(u),
        "sinh": lambda: sp.sinh(u / 2),
        "cosh": lambda: sp.cosh(u / 2),
        "tanh": lambda: sp.tanh(u),
        "log": lambda: sp.log(1 + u**2),
        "sqrt": lambda: sp.sqrt(1 + u**2),
    }[name]()


UNARY = ["atan", "tan", "exp", "sin", "cos", "sinh", "cosh", "tanh", "log", "sqrt"]


@st.composite
def terms(draw, qs, depth, root=False):
    """A random expression of depth <= ``depth`` in the coordinates ``qs`` (not a leaf if ``root``)."""
    if depth == 0 or (not root and draw(st.integers(0, 3)) == 0):
        if draw(st.integers(0, 3)) > 0:
            return draw(st.sampled_from(qs))
        return sp.Rational(draw(st.integers(-3, 3)), draw(st.integers(1, 3)))
    kind = "fn" if root == "fn" else draw(st.sampled_from(["fn", "fn", "add", "mul", "pow"]))
    if kind == "fn":
        return _unary(draw(st.sampled_from(UNARY)), draw(terms(qs, depth - 1)))
    if kind == "pow":
        return draw(terms(qs, depth - 1)) ** draw(st.integers(2, 3))
    a, b = draw(terms(qs, depth - 1)), draw(terms(qs, depth - 1))
    return a + b if kind == "add" else a * b


@st.composite
def systems(draw, max_dim=2, depth=3, root=True):
    """H = Σ p²/2 + U(q) with a random U (``root="fn"``: U is a grammar function of a term)."""
    d = draw(st.integers(1, max_dim))
    qn, pn = NAMES[d]
    qs = [sp.Symbol(n, real=True) for n in qn]
    ps = [sp.Symbol(n, real=True) for n in pn]
    U = draw(terms(qs, depth, root=root))
    assume(U.free_symbols)                          # a potential that depends on q
    assume(sp.count_ops(U) <= MAX_OPS)
    H = sum(p**2 for p in ps) / 2 + U
    return mg.Hamiltonian(H, q=qn, p=pn, name="prop")


@st.composite
def points(draw, n):
    """An exact rational start point y0 (|y| <= 1) and a rational direction d (|d_i| <= 1)."""
    y0 = [sp.Rational(draw(st.integers(-20, 20)), 20) for _ in range(n)]
    d = [sp.Rational(draw(st.integers(-10, 10)), 10) for _ in range(n)]
    assume(any(d))
    return y0, d


# --- evaluation as the generated code evaluates ------------------------------------------

_REMOVABLE = getattr(special, "_RemovableFunction", ())
_SAFE_DIV = getattr(special, "safe_div", None)
_DIVDIFF = getattr(special, "DividedDifference", None)


def _n(e, digits=DIGITS + 20):
    v = sp.N(e, digits)
    if not v.is_number or v.has(sp.zoo, sp.nan, sp.oo, -sp.oo, sp.I):
        raise ValueError(f"not a finite real number: {e} -> {v}")
    return v


def _truth(cond) -> bool:
    """Decide a numeric Piecewise condition exactly (or at 70 digits when transcendental)."""
    if cond is sp.true or cond is sp.false:
        return bool(cond)
    if isinstance(cond, sp.And):
        return all(_truth(c) for c in cond.args)
    if isinstance(cond, sp.Or):
        return any(_truth(c) for c in cond.args)
    if isinstance(cond, sp.Not):
        return not _truth(cond.args[0])
    if isinstance(cond, sp.core.relational.Relational):
        return bool(cond.func(_n(cond.lhs - cond.rhs), 0))
    raise TypeError(f"cannot decide the Piecewise condition {cond}")


def _generated_value(f: sp.Expr) -> sp.Expr:
    """One special function with numeric arguments, as its generated helper computes it."""
    if isinstance(f, sp.Piecewise):
        for expr, cond in f.args:
            if _truth(cond):
                return expr
        raise ValueError(f"no Piecewise branch applies: {f}")
    if _SAFE_DIV is not None and isinstance(f, _SAFE_DIV):
        n, d = f.args
        return sp.S.Zero if (d.is_zero or _n(d) == 0) else n / d
    if _DIVDIFF is not None and isinstance(f, _DIVDIFF):
        a, b = f.args
        form = type(f).stable_form(a, b)
        if form is not None:
            return form
        if type(f).__name__ == "atan_dd" and hasattr(type(f), "branch_form"):
            # templates/_special.py.j2 _f_atandd: the addition formula where 1 + ab > 0.
            return type(f).branch_form(a, b) if _truth(1 + a * b > 0) else f.as_quotient()
        return f.as_quotient()
    if isinstance(f, _REMOVABLE):
        # x != 0 here (the functions evaluate themselves at an exact 0): the helper's
        # g(x)/x is exact mathematics, evaluated at 50 digits.
        return f.as_quotient()
    if hasattr(f, "as_quotient"):
        return f.as_quotient()
    raise TypeError(f"unknown special function {f.func}")


def _is_special(e) -> bool:
    return isinstance(e, sp.Piecewise) or (isinstance(e, sp.Function) and type(e).__module__ == special.__name__)


def evaluate(expr: sp.Expr, point: dict) -> sp.Float:
    """``expr`` at an exact rational point, at 50 digits, on the generated code's branches."""
    e = sp.sympify(expr).xreplace(point)
    for _ in range(200):
        found = [f for f in sp.preorder_traversal(e) if _is_special(f)]
        inner = [f for f in found if not any(_is_special(g) for g in sp.preorder_traversal(f) if g is not f)]
        if not inner:
            return _n(e, DIGITS)
        e = e.xreplace({f: _generated_value(f) for f in inner})
    raise RuntimeError("special functions nested too deeply")


def identity_defect(system, dg: sp.Matrix, y0, d, gap) -> tuple[float, float]:
    """(|(y1-y0)ᵀ∇̄H - (H(y1) - H(y0))|, scale) at y1 = y0 + gap·d, 50 digits."""
    ys, y1s = system.y, y1_symbols(system)
    y1 = [a + gap * b for a, b in zip(y0, d)]
    point = {**dict(zip(ys, y0)), **dict(zip(y1s, y1))}
    params = {s: sp.Rational(repr(system.param_values[s.name])) for s in system.params}
    point.update(params)
    lhs = sum((b - a) * evaluate(g, point) for a, b, g in zip(y0, y1, dg))
    H = system.H.xreplace(params)
    dH = _n(H.xreplace(dict(zip(ys, y1))), DIGITS + 30) - _n(H.xreplace(dict(zip(ys, y0))), DIGITS + 30)
    grad = [abs(_n(sp.diff(H, s).xreplace(dict(zip(ys, y0))), 20)) for s in ys]
    step = sp.sqrt(sum(abs(b - a) ** 2 for a, b in zip(y0, y1)))
    scale = max(_n(step * sp.sqrt(sum(g**2 for g in grad)), 20), abs(dH), sp.Float("1e-60"))
    return abs(lhs - dH), scale


# --- the verifier's certificate, with a time limit ------------------------------------

class _Timeout(BaseException):
    pass


@contextlib.contextmanager
def _time_limit(seconds):
    if not hasattr(signal, "setitimer"):
        yield
        return

    def handler(signum, frame):
        raise _Timeout()

    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def certificate_status(system, dg, method) -> str:
    """The dg-identity certificate's status ("proved", "refuted", ...) or why there is none."""
    try:
        with _time_limit(CERTIFY_SECONDS):
            return dg_identity(system, dg, method).status
    except _Timeout:
        return "timeout"
    except Exception as exc:          # a crash of the verifier is not a proof
        return f"crashed ({type(exc).__name__}: {str(exc)[:80]})"


def schemes_of(system):
    """(method, scheme) for the discrete-gradient methods that apply."""
    out = []
    for method in METHODS:
        try:
            out.append((method, mg.discretize(system, method)))
        except (MethodNotApplicable, InputError):
            continue
    return out


def _failure(system, dg, method, y0, d, gap, err, scale, status):
    status = certificate_status(system, dg, method) if status is None else status
    return (f"{method} on H = {system.H}: the discrete-gradient identity fails at gap {gap} "
            f"(relative defect {float(err / scale):.3e} at y0 = {y0}, d = {d}); the verifier's "
            f"certificate says {status!r}"
            + (" — a proof of an identity the generated code does not satisfy" if status == "proved" else ""))


def check_soundness(system, y0, d, full_verify=False):
    checked = 0
    for method, scheme in schemes_of(system):
        dg = scheme.discrete_gradient
        if dg is None or any(e.has(sp.Float) for e in dg):
            continue      # AVF by Gauss-Legendre quadrature: approximate by design ("numerical")
        status = None
        if full_verify:
            with _time_limit(10 * CERTIFY_SECONDS):
                report = mg.verify(scheme)
            status = next((c.status for c in report.certificates
                           if "discrete-gradient identity" in c.claim), "none")
        for gap in GAPS:
            err, scale = identity_defect(system, dg, y0, d, gap)
            # The verifier's certificate only names the failure: it is asked for when the identity
            # fails (an assert's message is evaluated then), not for every example -- its exact
            # reduction of a large random H can run far longer than the check itself.
            assert err <= REL_TOL * scale, _failure(system, dg, method, y0, d, gap, err, scale, status)
        checked += 1
    return checked


#: No shrinking in the default run: every example costs a SymPy derivation and a
#: certificate, and a failure prints its example anyway (the slow run shrinks).
FAST = dict(phases=[Phase.explicit, Phase.reuse, Phase.generate])
SETTINGS = dict(derandomize=True, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.data_too_large, HealthCheck.function_scoped_fixture])


@settings(max_examples=10, **FAST, **SETTINGS)
@given(st.data())
def test_discrete_gradients_are_exact_where_the_code_evaluates_them(data):
    system = data.draw(systems(max_dim=2, depth=3), label="system")
    y0, d = data.draw(points(2 * system.dim), label="point")
    check_soundness(system, y0, d)


@pytest.mark.slow
@settings(max_examples=60, **SETTINGS)
@given(st.data())
def test_discrete_gradients_are_exact_where_the_code_evaluates_them_extended(data):
    system = data.draw(systems(max_dim=2, depth=3), label="system")
    y0, d = data.draw(points(2 * system.dim), label="point")
    check_soundness(system, y0, d, full_verify=True)


@pytest.mark.parametrize("U", ["atan(q)", "tan(sin(q)/2)", "atan(q)**2 + exp(q/2)", "log(1 + atan(q)**2)"])
def test_fixed_atan_and_tan_potentials(U):
    """The functions that used to fall back to a truncated series, at fixed points."""
    system = mg.Hamiltonian(f"p**2/2 + {U}", q=["q"], p=["p"])
    assert check_soundness(system, [sp.Rational(3, 10), sp.Rational(-1, 2)],
                           [sp.Rational(7, 10), sp.Rational(1, 5)]) >= 3


# --- negative control: a truncated series branch is caught --------------------------------

def truncated_atan_dg(system):
    """∇̄H for p²/2 + atan(q) whose near-diagonal branch is the 2-term Taylor series."""
    (q,), (p,) = system.q, system.p
    (q1, p1) = y1_symbols(system)
    m, delta = (q + q1) / 2, q1 - q
    f = sp.atan(q)
    d1 = sp.diff(f, q)
    series = d1.xreplace({q: m}) + sp.diff(d1, q, 2).xreplace({q: m}) * (delta / 2) ** 2 / 6
    quotient = (sp.atan(q1) - sp.atan(q)) / delta
    branch = sp.Piecewise((quotient, sp.Abs(delta) > sp.Rational(1, 10) * (1 + sp.Abs(m))), (series, True))
    return sp.Matrix([branch, (p + p1) / 2])


def test_negative_control_truncated_series_branch_is_detected():
    system = mg.Hamiltonian("p**2/2 + atan(q)", q=["q"], p=["p"])
    dg = truncated_atan_dg(system)
    y0, d = [sp.Rational(3, 10), sp.Rational(-1, 2)], [sp.Rational(7, 10), sp.Rational(1, 5)]
    caught = []
    for gap in (sp.Rational(1, 10), sp.Rational(1, 1000)):
        err, scale = identity_defect(system, dg, y0, d, gap)
        caught.append(err > REL_TOL * scale)
        # The series' error is O(δ⁴): far above the tolerance, far below double round-off at 1e-3.
        assert err / scale > sp.Float("1e-20")
    assert all(caught)
    # The generic (first) branch is the exact quotient, so a verifier that reduces only the
    # generic branch would "prove" this identity; the evaluation above is what catches it.
    err, scale = identity_defect(system, dg.xreplace({dg[0]: dg[0].args[0].expr}), y0, d, sp.Rational(1, 10))
    assert err <= REL_TOL * scale


# --- the generated modules ----------------------------------------------------------------

H_LADDER = [0.3, 0.1, 1e-2, 1e-3, 1e-4]


def energy_ladder(system, method, scheme, folder) -> tuple[int, int]:
    """Integrate the generated module over the step-size ladder; (runs, numerical failures)."""
    folder.mkdir(parents=True, exist_ok=True)
    mod = mg.generate(scheme, folder / "m.py")
    y0 = np.array([0.5, 0.3])
    runs, skipped = 0, 0
    for h in H_LADDER:
        runs += 1
        try:
            traj = mod.integrate(y0, h, 5)
        except (mod.ConvergenceError, mod.ResolutionError, mod.NonFiniteError):
            skipped += 1
            continue
        H = mod.hamiltonian(traj)
        H0 = float(H[0])
        err = float(np.max(np.abs(H - H0)))
        assert err <= 1e-13 * max(1.0, abs(H0)), (
            f"{method} on H = {system.H}, h = {h}: max |H - H0| = {err:.3e} (H0 = {H0})")
    return runs, skipped


@settings(max_examples=6, **FAST, **SETTINGS)
@given(st.data())
def test_generated_modules_keep_the_energy_over_a_step_size_ladder(tmp_path_factory, data):
    system = data.draw(systems(max_dim=1, depth=2, root="fn"), label="system")
    schemes = schemes_of(system)
    assume(schemes)
    method, scheme = schemes[data.draw(st.integers(0, len(schemes) - 1), label="method")]
    if any(e.has(sp.Float) for e in scheme.discrete_gradient):
        return   # quadrature: energy error O(|Δy|^16), not round-off
    runs, skipped = energy_ladder(system, method, scheme, tmp_path_factory.mktemp("prop"))
    assert skipped <= runs // 2, f"{method} on H = {system.H}: {skipped} of {runs} runs failed numerically"


@pytest.mark.parametrize("U", ["atan(q)", "tan(sin(q)/2)", "log(1 + atan(q)**2)"])
def test_generated_modules_with_atan_and_tan(tmp_path, U):
    system = mg.Hamiltonian(f"p**2/2 + {U}", q=["q"], p=["p"])
    runs, skipped = 0, 0
    for method, scheme in schemes_of(system):
        r, k = energy_ladder(system, method, scheme, tmp_path / method)
        runs, skipped = runs + r, skipped + k
    assert runs >= 15 and skipped <= runs // 2, f"{skipped} of {runs} runs failed numerically"
