"""Removable-singularity functions used by cancelled difference quotients.

Discrete gradients are built from divided differences ``(f(b) - f(a))/(b - a)``,
which are 0/0 at ``a = b`` and lose all accuracy to cancellation near it.  For
the elementary functions the difference can be rewritten exactly in terms of
functions of the form ``g(x)/x`` whose limit at 0 is finite, e.g.

    exp(b) - exp(a) = 2 exp((a+b)/2) sinh((b-a)/2)   =>   exp[a, b] = exp(m) sinhc(δ/2)

with ``sinhc(x) = sinh(x)/x``.  ``sinh`` is computed to full *relative*
precision by libm for every ``x``, so ``sinh(x)/x`` is accurate to round-off for
every ``x != 0`` and equals 1 at ``x = 0``: no threshold, no jump.

Each function here is a SymPy ``Function`` with

* ``eval`` giving the exact value 1 at 0 (so symbolic limits ``y1 -> y0`` are
  plain substitutions),
* ``fdiff`` returning the derivative as another function of this module (so
  Jacobians stay stable too),
* ``as_quotient()`` rewriting it into elementary functions, used by the exact
  verification layer.

The printers of :mod:`methodgen.codegen.lower` emit them as calls of helpers defined in
the generated module (``_sinhc`` and friends in ``templates/_special.py.j2``).

References
----------
.. [1] R. I. McLachlan, G. R. W. Quispel, N. Robidoux, "Geometric integration
   using discrete gradients", Phil. Trans. R. Soc. A 357 (1999) 1021-1045.
"""

from __future__ import annotations

import sympy as sp

__all__ = ["sinc_u", "sinhc", "atanhc", "atanc", "dsinc_u", "dsinhc", "datanhc", "datanc", "safe_div",
           "DividedDifference", "exp_dd", "log_dd", "sin_dd", "cos_dd", "tan_dd", "sinh_dd", "cosh_dd",
           "tanh_dd", "atan_dd", "datan_dd", "dexp_dd", "ddsinc_u", "sinc_dd", "dsinc_dd",
           "DIVIDED_DIFFERENCES", "SPECIAL_FUNCTIONS", "HELPER_DEPENDENCIES", "to_elementary",
           "fold_removable_quotients"]


class _RemovableFunction(sp.Function):
    """Common machinery: value at 0, evenness, realness."""

    nargs = 1
    _value_at_zero: sp.Expr = sp.S.One
    _even = True

    @classmethod
    def eval(cls, x):
        if x.is_zero:
            return cls._value_at_zero
        if cls._even and x.could_extract_minus_sign():
            return cls(-x) if cls._even is True else -cls(-x)
        return None

    def _eval_is_real(self):
        return self.args[0].is_real

    def as_quotient(self) -> sp.Expr:  # pragma: no cover - overridden
        raise NotImplementedError


class sinc_u(_RemovableFunction):
    r"""``sin(x)/x`` (the *unnormalised* sinc, unlike numpy.sinc), 1 at 0."""

    def fdiff(self, argindex=1):
        return dsinc_u(self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return sp.sin(x) / x


class sinhc(_RemovableFunction):
    r"""``sinh(x)/x``, 1 at 0."""

    def fdiff(self, argindex=1):
        return dsinhc(self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return sp.sinh(x) / x


class atanhc(_RemovableFunction):
    r"""``atanh(x)/x`` for ``|x| < 1``, 1 at 0."""

    def fdiff(self, argindex=1):
        return datanhc(self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return sp.atanh(x) / x


class atanc(_RemovableFunction):
    r"""``atan(x)/x``, 1 at 0 (every real x)."""

    def fdiff(self, argindex=1):
        return datanc(self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return sp.atan(x) / x


class _OddDerivative(_RemovableFunction):
    _value_at_zero = sp.S.Zero
    _even = "odd"


class dsinc_u(_OddDerivative):
    r"""Derivative of :class:`sinc_u`: ``(x cos x - sin x)/x**2``, 0 at 0."""

    def fdiff(self, argindex=1):
        return ddsinc_u(self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return (x * sp.cos(x) - sp.sin(x)) / x**2


class ddsinc_u(_RemovableFunction):
    r"""Second derivative of :class:`sinc_u`: ``(2 sin x - 2x cos x - x² sin x)/x³``, -1/3 at 0.

    Jacobians only (the Hessian of an H with ``sin(u)/u``).
    """

    _value_at_zero = sp.Rational(-1, 3)

    def fdiff(self, argindex=1):
        return sp.diff(self.as_quotient(), self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return (2 * sp.sin(x) - 2 * x * sp.cos(x) - x**2 * sp.sin(x)) / x**3


class dsinhc(_OddDerivative):
    r"""Derivative of :class:`sinhc`: ``(x cosh x - sinh x)/x**2``, 0 at 0."""

    def fdiff(self, argindex=1):
        x = self.args[0]
        return (x**2 * sp.sinh(x) - 2 * x * sp.cosh(x) + 2 * sp.sinh(x)) / x**3

    def as_quotient(self):
        x = self.args[0]
        return (x * sp.cosh(x) - sp.sinh(x)) / x**2


class datanhc(_OddDerivative):
    r"""Derivative of :class:`atanhc`: ``(x/(1-x**2) - atanh x)/x**2``, 0 at 0."""

    def fdiff(self, argindex=1):
        return sp.diff(self.as_quotient(), self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return (x / (1 - x**2) - sp.atanh(x)) / x**2


class datanc(_OddDerivative):
    r"""Derivative of :class:`atanc`: ``(x/(1+x**2) - atan x)/x**2``, 0 at 0."""

    def fdiff(self, argindex=1):
        return sp.diff(self.as_quotient(), self.args[0])

    def as_quotient(self):
        x = self.args[0]
        return (x / (1 + x**2) - sp.atan(x)) / x**2


class safe_div(sp.Function):
    r"""``n/d`` where ``d != 0`` and 0 where ``d = 0``.

    For quotients whose limit at the removable point is 0 (Gonzalez'
    correction ``N/|Δ|²`` with ``N = O(|Δ|³)``).  A Function rather than a
    Piecewise so that common-subexpression elimination cannot hoist the
    division out of the guard; its derivatives are guarded the same way.
    """

    nargs = 2

    @classmethod
    def eval(cls, n, d):
        if n.is_zero:
            return sp.S.Zero
        if d.is_number and not d.is_zero:
            return n / d
        return None

    def fdiff(self, argindex=1):
        n, d = self.args
        if argindex == 1:
            return safe_div(sp.S.One, d)
        return -safe_div(n, d**2)

    def as_quotient(self):
        n, d = self.args
        return n / d


# --- divided differences of the elementary functions --------------------------------
#
# ``f[a, b] = (f(b) - f(a))/(b - a)`` of one elementary function f is a function
# of its own: its *defining relation* is the quotient (``as_quotient``), which is
# all the verification layer needs — every discrete-gradient identity then
# reduces to a rational-function identity in the atoms ``f(a)``, ``f(b)``.  How
# the generated code evaluates it without cancellation (``stable_form``, e.g.
# ``exp(m)·sinhc(δ/2)``) is a separate, generic claim, proved once per function
# by :mod:`methodgen.symbolic.verify.helpers` and tested against mpmath.


def _fresh_pair():
    return sp.Dummy("a", real=True), sp.Dummy("b", real=True)


class DividedDifference(sp.Function):
    """``(f(b) - f(a))/(b - a)`` of an elementary ``f``, ``f'(a)`` at ``a = b`` (symmetric in a, b).

    Subclasses set ``func`` (the SymPy function) and ``_stable`` (a formula in
    the removable-singularity functions above, valid on f's whole real domain,
    or None when it needs a branch: then ``datan_dd``-style helpers give the
    derivatives).
    """

    nargs = 2
    func_elementary = None   # type: ignore[assignment]

    @classmethod
    def eval(cls, a, b):
        if a == b or (a - b).is_zero:
            x = sp.Dummy("x", real=True)
            return sp.diff(cls.func_elementary(x), x).xreplace({x: a})
        # Canonical argument order: f[a, b] = f[b, a], so equal values print equally.
        if sp.default_sort_key(b) < sp.default_sort_key(a):
            return cls(b, a)
        return None

    def _eval_is_real(self):
        a, b = self.args
        return (a.is_real and b.is_real) or None

    def as_quotient(self) -> sp.Expr:
        a, b = self.args
        f = self.func_elementary
        return (f(b) - f(a)) / (b - a)

    @classmethod
    def stable_form(cls, a, b):
        """The formula the generated code evaluates (None: branch-wise, see the template)."""
        return None

    def fdiff(self, argindex=1):
        a, b = self.args
        A, B = _fresh_pair()
        form = self.stable_form(A, B)
        if form is None:
            return self._branch_derivative(argindex)
        d = sp.diff(form, B if argindex == 2 else A)
        return d.xreplace({A: a, B: b})

    def _branch_derivative(self, argindex):  # pragma: no cover - overridden where needed
        raise NotImplementedError


def _exp(g):
    """``exp(g)``, with ``exp(c·log u)`` written ``u**c`` as SymPy writes powers (so they cancel)."""
    if g.is_Mul:
        logs = [f for f in g.args if isinstance(f, sp.log)]
        if len(logs) == 1:
            return logs[0].args[0] ** (g / logs[0])
    return sp.exp(g)


class exp_dd(DividedDifference):
    r"""``exp[a, b] = exp((a+b)/2) sinhc((b-a)/2)``."""
    func_elementary = sp.exp

    def as_quotient(self):
        a, b = self.args
        return (_exp(b) - _exp(a)) / (b - a)

    @classmethod
    def stable_form(cls, a, b):
        return sp.exp((a + b) / 2) * sinhc((b - a) / 2)

    @classmethod
    def helper_form(cls, a, b):
        """What ``_expdd`` evaluates for ``b > a``, ``exp(b)·(1 - exp(a - b))/(b - a)`` (the same
        function written with the larger exponent outside, so no factor overflows where the
        value does not; the helper swaps the arguments of ``a > b``, the quotient being
        symmetric, and takes ``exp(a)`` at ``a = b``; above hi = 709, where exp(hi) overflows
        before the factor < 1, it multiplies exp(hi/2) twice)."""
        return sp.exp(b) * (1 - sp.exp(a - b)) / (b - a)

    def fdiff(self, argindex=1):
        # Not the derivative of the stable form: exp(m)·dsinhc(d) overflows on a thin
        # barrier (d ~ 1000) where the value and the derivative are 0.
        a, b = self.args
        return dexp_dd(a, b) if argindex == 2 else dexp_dd(b, a)


class sin_dd(DividedDifference):
    r"""``sin[a, b] = cos((a+b)/2) sinc((b-a)/2)``."""
    func_elementary = sp.sin

    @classmethod
    def stable_form(cls, a, b):
        return sp.cos((a + b) / 2) * sinc_u((b - a) / 2)


class cos_dd(DividedDifference):
    r"""``cos[a, b] = -sin((a+b)/2) sinc((b-a)/2)``."""
    func_elementary = sp.cos

    @classmethod
    def stable_form(cls, a, b):
        return -sp.sin((a + b) / 2) * sinc_u((b - a) / 2)


class sinh_dd(DividedDifference):
    r"""``sinh[a, b] = cosh((a+b)/2) sinhc((b-a)/2)``."""
    func_elementary = sp.sinh

    @classmethod
    def stable_form(cls, a, b):
        return sp.cosh((a + b) / 2) * sinhc((b - a) / 2)


class cosh_dd(DividedDifference):
    r"""``cosh[a, b] = sinh((a+b)/2) sinhc((b-a)/2)``."""
    func_elementary = sp.cosh

    @classmethod
    def stable_form(cls, a, b):
        return sp.sinh((a + b) / 2) * sinhc((b - a) / 2)


class tan_dd(DividedDifference):
    r"""``tan[a, b] = sinc(b-a) / (cos a cos b)`` (addition formula)."""
    func_elementary = sp.tan

    @classmethod
    def stable_form(cls, a, b):
        return sinc_u(b - a) / (sp.cos(a) * sp.cos(b))


class tanh_dd(DividedDifference):
    r"""``tanh[a, b] = sinhc(b-a) / (cosh a cosh b)`` (addition formula)."""
    func_elementary = sp.tanh

    @classmethod
    def stable_form(cls, a, b):
        return sinhc(b - a) / (sp.cosh(a) * sp.cosh(b))


class log_dd(DividedDifference):
    r"""``log[a, b] = 2 atanhc((b-a)/(a+b)) / (a+b)`` for a, b > 0 (log's real domain).

    The generated helper returns NaN unless a > 0 and b > 0, so a state that
    leaves the domain stops the run instead of producing a real number.
    """
    func_elementary = sp.log

    @classmethod
    def stable_form(cls, a, b):
        return 2 / (a + b) * atanhc((b - a) / (a + b))


class atan_dd(DividedDifference):
    r"""``atan[a, b]``: ``atanc(t)/c`` with ``c = 1 + ab``, ``t = (b-a)/c`` where c > 0, else the quotient.

    ``atan b - atan a = atan((b-a)/(1+ab))`` holds exactly where ``1 + ab > 0``
    (the set of b containing a); elsewhere ``|b - a| >= 2`` and the plain
    quotient has no cancellation.
    """
    func_elementary = sp.atan

    @classmethod
    def branch_form(cls, a, b):
        c = 1 + a * b
        return atanc((b - a) / c) / c

    def _branch_derivative(self, argindex):
        a, b = self.args
        return datan_dd(a, b) if argindex == 2 else datan_dd(b, a)


class datan_dd(sp.Function):
    r"""``∂/∂b atan[a, b] = (1/(1+b²) - atan[a, b])/(b - a)``, ``-a/(1+a²)²`` at a = b.

    Jacobians only.  Where ``c = 1 + ab > 0`` the generated helper evaluates
    ``((1+a²) datanc(t)/c - a atanc(t))/c²`` (no cancellation), else the quotient.
    """

    nargs = 2

    @classmethod
    def eval(cls, a, b):
        if a == b or (a - b).is_zero:
            return -a / (1 + a**2) ** 2
        return None

    def _eval_is_real(self):
        a, b = self.args
        return (a.is_real and b.is_real) or None

    def as_quotient(self):
        a, b = self.args
        return (1 / (1 + b**2) - (sp.atan(b) - sp.atan(a)) / (b - a)) / (b - a)

    @classmethod
    def branch_form(cls, a, b):
        c = 1 + a * b
        t = (b - a) / c
        return ((1 + a**2) * datanc(t) / c - a * atanc(t)) / c**2

    def fdiff(self, argindex=1):
        # Second derivatives (never in generated code): from the defining quotient.
        a, b = self.args
        A, B = _fresh_pair()
        return sp.diff(datan_dd(A, B).as_quotient(), B if argindex == 2 else A).xreplace({A: a, B: b})


class sinc_dd(DividedDifference):
    r"""``sinc[a, b] = (sinc b - sinc a)/(b - a)`` with ``sinc x = sin(x)/x`` (a term ``sin(u)/u``).

    No closed form is free of cancellation at once near ``a = b`` and near ``a = 0`` or
    ``b = 0``, so the generated helper has three branches (``templates/_special.py.j2``):
    the Taylor series ``(a + b) Σ c_k h_{k-1}(a², b²)`` (positive terms h) where
    ``|a|, |b| < 2``; the quotient itself where ``|b - a| >= 1``; else (a, b of one sign,
    ``|ab| > 1``) :meth:`branch_form`.  The last two are exact identities
    (:mod:`methodgen.symbolic.verify.helpers`), the series is truncated below round-off (numerical).
    """
    func_elementary = sinc_u

    def as_quotient(self):
        a, b = self.args
        return (sp.sin(b) / b - sp.sin(a) / a) / (b - a)

    @classmethod
    def branch_form(cls, a, b):
        """``(m cos m sinc δ - sin m cos δ)/(ab)``, ``m = (a+b)/2``, ``δ = (b-a)/2``."""
        m, d = (a + b) / 2, (b - a) / 2
        return (m * sp.cos(m) * sinc_u(d) - sp.sin(m) * sp.cos(d)) / (a * b)

    def _branch_derivative(self, argindex):
        a, b = self.args
        return dsinc_dd(a, b) if argindex == 2 else dsinc_dd(b, a)


class dsinc_dd(sp.Function):
    r"""``∂/∂b sinc[a, b] = (sinc'(b) - sinc[a, b])/(b - a) = ∫₀¹ t sinc''(a + t(b - a)) dt``,
    ``sinc''(a)/2`` at a = b.

    Jacobians only.  The helper evaluates the quotient where ``|b - a| >= 1`` and the
    integral by 8-point Gauss–Legendre elsewhere (sinc'' is entire: ~1e-14 relative).
    """

    nargs = 2

    @classmethod
    def eval(cls, a, b):
        if a == b or (a - b).is_zero:
            return ddsinc_u(a) / 2
        return None

    def _eval_is_real(self):
        a, b = self.args
        return (a.is_real and b.is_real) or None

    def as_quotient(self):
        a, b = self.args
        return (dsinc_u(b).as_quotient() - sinc_dd(a, b).as_quotient()) / (b - a)

    def fdiff(self, argindex=1):
        # Second derivatives (never in generated code): from the defining quotient.
        a, b = self.args
        A, B = _fresh_pair()
        return sp.diff(dsinc_dd(A, B).as_quotient(), B if argindex == 2 else A).xreplace({A: a, B: b})


class dexp_dd(sp.Function):
    r"""``∂/∂b exp[a, b] = (exp(b) - exp[a, b])/(b - a)``, ``exp(a)/2`` at a = b.

    Jacobians only.  The generated helper evaluates ``exp(m)(sinhc(δ) + dsinhc(δ))/2``
    (``m = (a+b)/2``, ``δ = (b-a)/2``, ``exp(m) = exp(hi) exp(-|δ|)``, hi = max(a, b)) where
    ``|b - a| < 1`` and ``exp(hi) g/D²`` elsewhere (``D = |b - a|``, ``g = D - 1 + exp(-D)``
    for b > a, ``1 - exp(-D) - D exp(-D)`` for b < a: the quotient with exp(hi) taken out),
    ``exp(hi)`` as ``exp(hi/2)²`` above 709, so no factor overflows where the value does not.
    """

    nargs = 2

    @classmethod
    def eval(cls, a, b):
        if a == b or (a - b).is_zero:
            return sp.exp(a) / 2
        return None

    def _eval_is_real(self):
        a, b = self.args
        return (a.is_real and b.is_real) or None

    def as_quotient(self):
        a, b = self.args
        return (sp.exp(b) - (sp.exp(b) - sp.exp(a)) / (b - a)) / (b - a)

    def fdiff(self, argindex=1):
        # Second derivatives (never in generated code): from the defining quotient.
        a, b = self.args
        A, B = _fresh_pair()
        return sp.diff(dexp_dd(A, B).as_quotient(), B if argindex == 2 else A).xreplace({A: a, B: b})


#: The divided difference of each elementary function of the grammar.
DIVIDED_DIFFERENCES: dict = {sp.exp: exp_dd, sp.log: log_dd, sp.sin: sin_dd, sp.cos: cos_dd, sp.tan: tan_dd,
                             sp.sinh: sinh_dd, sp.cosh: cosh_dd, sp.tanh: tanh_dd, sp.atan: atan_dd,
                             sinc_u: sinc_dd}


#: Name of the runtime helper each function prints as.
SPECIAL_FUNCTIONS: dict[type, str] = {
    sinc_u: "_sinc",
    sinhc: "_sinhc",
    atanhc: "_atanhc",
    dsinc_u: "_dsinc",
    dsinhc: "_dsinhc",
    datanhc: "_datanhc",
    safe_div: "_sdiv",
    atanc: "_atanc",
    datanc: "_datanc",
    exp_dd: "_expdd",
    log_dd: "_logdd",
    sin_dd: "_sindd",
    cos_dd: "_cosdd",
    tan_dd: "_tandd",
    sinh_dd: "_sinhdd",
    cosh_dd: "_coshdd",
    tanh_dd: "_tanhdd",
    atan_dd: "_atandd",
    datan_dd: "_datandd",
    dexp_dd: "_dexpdd",
    ddsinc_u: "_ddsinc",
    sinc_dd: "_sincdd",
    dsinc_dd: "_dsincdd",
}

#: Helpers a helper calls (so the template emits them too).
HELPER_DEPENDENCIES: dict[str, tuple[str, ...]] = {
    "sinhdd": ("sinhc",), "coshdd": ("sinhc",), "tanhdd": ("sinhc",),
    "sindd": ("sinc",), "cosdd": ("sinc",), "tandd": ("sinc",),
    "logdd": ("atanhc",), "atandd": ("atanc",), "datandd": ("atanc", "datanc", "atandd"),
    "dexpdd": ("sinhc", "dsinhc"),
    "sincdd": ("sinc",), "dsincdd": ("dsinc", "ddsinc", "sincdd"),
}


def to_elementary(expr: sp.Expr) -> sp.Expr:
    """Replace every removable-singularity function by its elementary quotient.

    The result is equal to ``expr`` wherever the quotients are defined; the
    verification layer uses it to reduce identities with ordinary SymPy.
    """
    quotients = (_RemovableFunction, safe_div, DividedDifference, datan_dd, dexp_dd, dsinc_dd)
    return expr.replace(lambda e: isinstance(e, quotients),
                        lambda e: e.as_quotient())


def fold_removable_quotients(expr: sp.Expr) -> sp.Expr:
    """Write each ``sin(u)/u`` in ``expr`` as ``sinc_u(u)`` (an exact rewriting).

    ``sin(u)/u`` is smooth at ``u = 0`` but its quotient form is 0/0 there, its derivative
    ``cos(u)/u - sin(u)/u²`` cancels like 1/u², and its product-rule divided difference
    like 1/u: as ``sinc_u`` it evaluates to 1 at 0 and gets the helpers of this module
    (derivatives, divided difference) that are accurate to round-off near 0.  A product
    ``c·sin(u)ⁿ·D⁻¹`` (n ≥ 1 an integer) is folded to ``c·sinc_u(u)ᵏ·sin(u)ⁿ⁻ᵏ·(uᵏ/D)`` for
    the largest k ≤ n with ``D/uᵏ`` free of u's symbols (``sin(2q)/(2q)``, ``k sin(q)/q``,
    ``sin(x² + y²)/(x² + y²)``, ``(sin(q)/q)**2``, ``sin(q)²/q``); ``u`` must depend on a
    symbol (``sin(2)/3`` is a number).  The
    rewriting is repeated until nothing changes, so every factor of
    ``sin(x) sin(y)/(x y)`` is folded.
    """
    def sin_power(f):
        """``(u, n)`` for a factor ``sin(u)**n`` (n a positive integer) of a symbolic u, else None."""
        base, n = (f.base, f.exp) if f.is_Pow else (f, sp.S.One)
        if isinstance(base, sp.sin) and n.is_Integer and n > 0 and base.args[0].free_symbols:
            return base.args[0], n
        return None

    def fold(m):
        for f in m.args:
            found = sin_power(f)
            if found is None:
                continue
            u, n = found
            num, den = sp.fraction(m / f)
            for k in range(int(n), 0, -1):    # sin(u)²/u folds one power: sinc_u(u)·sin(u)
                ratio = sp.cancel(den / u**k)
                if ratio != 0 and not (ratio.free_symbols & u.free_symbols):
                    return sinc_u(u) ** k * sp.sin(u) ** (n - k) * num / ratio
        return m

    def foldable(e):
        return e.is_Mul and any(sin_power(f) is not None for f in e.args)

    # Each pass folds one factor per product; a product of several quotients needs more
    # (the count of sin factors bounds the passes: each one removes a sin).
    for _ in range(expr.count(sp.sin) + 1):
        folded = expr.replace(foldable, fold)
        if folded == expr:
            break
        expr = folded
    return expr
