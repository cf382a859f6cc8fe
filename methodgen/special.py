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

The printers of :mod:`methodgen.lower` emit them as calls of helpers defined in
the generated module (``_sinhc`` and friends in ``templates/_special.py.j2``).

References
----------
.. [1] R. I. McLachlan, G. R. W. Quispel, N. Robidoux, "Geometric integration
   using discrete gradients", Phil. Trans. R. Soc. A 357 (1999) 1021-1045.
"""

from __future__ import annotations

import sympy as sp

__all__ = ["sinc_u", "sinhc", "atanhc", "dsinc_u", "dsinhc", "datanhc", "safe_div", "SPECIAL_FUNCTIONS",
           "to_elementary"]


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


class _OddDerivative(_RemovableFunction):
    _value_at_zero = sp.S.Zero
    _even = "odd"


class dsinc_u(_OddDerivative):
    r"""Derivative of :class:`sinc_u`: ``(x cos x - sin x)/x**2``, 0 at 0."""

    def fdiff(self, argindex=1):
        x = self.args[0]
        return (-x**2 * sp.sin(x) - 2 * x * sp.cos(x) + 2 * sp.sin(x)) / x**3

    def as_quotient(self):
        x = self.args[0]
        return (x * sp.cos(x) - sp.sin(x)) / x**2


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


#: Name of the runtime helper each function prints as.
SPECIAL_FUNCTIONS: dict[type, str] = {
    sinc_u: "_sinc",
    sinhc: "_sinhc",
    atanhc: "_atanhc",
    dsinc_u: "_dsinc",
    dsinhc: "_dsinhc",
    datanhc: "_datanhc",
    safe_div: "_sdiv",
}


def to_elementary(expr: sp.Expr) -> sp.Expr:
    """Replace every removable-singularity function by its elementary quotient.

    The result is equal to ``expr`` wherever the quotients are defined; the
    verification layer uses it to reduce identities with ordinary SymPy.
    """
    return expr.replace(lambda e: isinstance(e, (_RemovableFunction, safe_div)), lambda e: e.as_quotient())
