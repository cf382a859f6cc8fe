"""The scalar removable-singularity helpers: the one source of the ``_f_<name>`` functions.

SymPy's side of these functions is :mod:`methodgen.problem.special` (``sinc_u``, ``exp_dd`` …,
each printed as a call ``_f_<name>(…)``).  This file holds their floating-point forms, plain
Python on floats with :mod:`math`:

* a generated module holds a copy of the ones it calls (:func:`source`: this file's text of the
  definition and the constants it reads), so a numpy module runs without methodgen;
* the compiled route translates *these* functions (package source, whose text is verified
  against the code that runs: :mod:`methodgen.codegen.kernelsource`) into every kernel of the
  kernel IR that calls one, never a module's copy of them.

Each g(x)/x is evaluated as the libm function over x, its exact value at x = 0 substituted
without a threshold; derivatives that cancel near 0 sum their Taylor series below a threshold;
divided differences g[a, b] are written in cancellation-free forms, each proved equal to the
quotient by :mod:`methodgen.symbolic.verify` and tested against mpmath.
"""

from __future__ import annotations

import ast
import math
import os

__all__ = ["HELPERS", "source"]


#: (a marker: the helpers start below it, each with the comments and constants above it)
_HELPERS_BELOW = True


def _f_sinc(x):
    return math.sin(x) / x if x != 0.0 else 1.0


# Taylor coefficients of dsinc(x)/x in x², highest first: (-1)^k 2k/(2k+1)!, k = 10 … 1.
_DSINC_C = (3.9145882126782523e-19, -1.4797143443923793e-16, 4.498331606952833e-14, -1.0706029224547743e-11,
            1.9270852604185937e-09, -2.505210838544172e-07, 2.2045855379188714e-05, -0.0011904761904761906,
            0.03333333333333333, -0.3333333333333333)


def _f_dsinc(x):
    if abs(x) < 1.0:
        x2 = x * x
        s = 0.0
        for c in _DSINC_C:
            s = s * x2 + c
        return x * s
    return (x * math.cos(x) - math.sin(x)) / (x * x)


def _f_sinhc(x):
    return math.sinh(x) / x if x != 0.0 else 1.0


# Taylor coefficients of dsinhc(x)/x in x², highest first: 2k/(2k+1)!, k = 10 … 1.
_DSINHC_C = (3.9145882126782523e-19, 1.4797143443923793e-16, 4.498331606952833e-14, 1.0706029224547743e-11,
             1.9270852604185937e-09, 2.505210838544172e-07, 2.2045855379188714e-05, 0.0011904761904761906,
             0.03333333333333333, 0.3333333333333333)


def _f_dsinhc(x):
    if abs(x) < 1.0:
        x2 = x * x
        s = 0.0
        for c in _DSINHC_C:
            s = s * x2 + c
        return x * s
    return (x * math.cosh(x) - math.sinh(x)) / (x * x)


def _f_atanhc(x):
    return math.atanh(x) / x if x != 0.0 else 1.0


# Taylor coefficients of datanhc(x)/x in x², highest first: 2k/(2k+1), k = 30 … 1.
_DATANHC_C = (0.9836065573770492, 0.9830508474576272, 0.9824561403508771, 0.9818181818181818,
             0.9811320754716981, 0.9803921568627451, 0.9795918367346939, 0.9787234042553191,
             0.9777777777777777, 0.9767441860465116, 0.975609756097561, 0.9743589743589743, 0.972972972972973,
             0.9714285714285714, 0.9696969696969697, 0.967741935483871, 0.9655172413793104,
             0.9629629629629629, 0.96, 0.9565217391304348, 0.9523809523809523, 0.9473684210526315,
             0.9411764705882353, 0.9333333333333333, 0.9230769230769231, 0.9090909090909091,
             0.8888888888888888, 0.8571428571428571, 0.8, 0.6666666666666666)


def _f_datanhc(x):
    if abs(x) < 0.5:
        x2 = x * x
        s = 0.0
        for c in _DATANHC_C:
            s = s * x2 + c
        return x * s
    return (x / (1.0 - x * x) - math.atanh(x)) / (x * x)


def _f_sdiv(n, d):
    # n/d with the removable point d = 0 mapped to its limit 0 (no threshold).
    return n / d if d != 0.0 else 0.0


def _f_atanc(x):
    return math.atan(x) / x if x != 0.0 else 1.0


# Taylor coefficients of datanc(x)/x in x², highest first: (-1)^k 2k/(2k+1), k = 30 … 1.
_DATANC_C = (0.9836065573770492, -0.9830508474576272, 0.9824561403508771, -0.9818181818181818,
            0.9811320754716981, -0.9803921568627451, 0.9795918367346939, -0.9787234042553191,
            0.9777777777777777, -0.9767441860465116, 0.975609756097561, -0.9743589743589743,
            0.972972972972973, -0.9714285714285714, 0.9696969696969697, -0.967741935483871,
            0.9655172413793104, -0.9629629629629629, 0.96, -0.9565217391304348, 0.9523809523809523,
            -0.9473684210526315, 0.9411764705882353, -0.9333333333333333, 0.9230769230769231,
            -0.9090909090909091, 0.8888888888888888, -0.8571428571428571, 0.8, -0.6666666666666666)


def _f_datanc(x):
    if abs(x) < 0.5:
        x2 = x * x
        s = 0.0
        for c in _DATANC_C:
            s = s * x2 + c
        return x * s
    return (x / (1.0 + x * x) - math.atan(x)) / (x * x)


def _f_expdd(a, b):
    # exp(b) - exp(a) = 2 exp((a+b)/2) sinh((b-a)/2), evaluated as
    # exp(hi) (1 - exp(-d))/d with hi = max(a, b), d = |b - a| (the same function:
    # sinh written in exponentials): exp(hi) is the largest factor (exp((a+b)/2) * sinh((b-a)/2)
    # underflows to 0 times inf on a thin barrier, exp(-800) * sinh(800)).  exp(hi) itself
    # overflows above 709.78 where the value, smaller by the factor (1 - exp(-d))/d, may not
    # ((0, 712): 2.3e306): there exp(hi/2) twice, each finite, a few ulp like exp(hi).
    hi = max(a, b)
    d = abs(b - a)
    f = -math.expm1(-d) / d if d != 0.0 else 1.0
    if hi <= 709.0:
        return math.exp(hi) * f
    if hi > 1419.5:
        return math.inf      # exp(hi/2) overflows: so does the value (as numpy and numba give)
    e = math.exp(0.5 * hi)
    return e * (e * f)


def _f_sinhdd(a, b):
    # sinh(b) - sinh(a) = 2 cosh((a+b)/2) sinh((b-a)/2)
    return math.cosh(0.5 * (a + b)) * _f_sinhc(0.5 * (b - a))


def _f_coshdd(a, b):
    # cosh(b) - cosh(a) = 2 sinh((a+b)/2) sinh((b-a)/2)
    return math.sinh(0.5 * (a + b)) * _f_sinhc(0.5 * (b - a))


def _f_tanhdd(a, b):
    # tanh(b) - tanh(a) = sinh(b - a) / (cosh a cosh b)
    return _f_sinhc(b - a) / (math.cosh(a) * math.cosh(b))


def _f_sindd(a, b):
    # sin(b) - sin(a) = 2 cos((a+b)/2) sin((b-a)/2)
    return math.cos(0.5 * (a + b)) * _f_sinc(0.5 * (b - a))


def _f_cosdd(a, b):
    # cos(b) - cos(a) = -2 sin((a+b)/2) sin((b-a)/2)
    return -math.sin(0.5 * (a + b)) * _f_sinc(0.5 * (b - a))


def _f_tandd(a, b):
    # tan(b) - tan(a) = sin(b - a) / (cos a cos b)
    return _f_sinc(b - a) / (math.cos(a) * math.cos(b))


def _f_logdd(a, b):
    # log(b) - log(a) = 2 atanh((b-a)/(a+b)) for a, b > 0; outside log's domain: NaN.
    if not (a > 0.0 and b > 0.0):
        return math.nan
    s = a + b
    return 2.0 * _f_atanhc((b - a) / s) / s


def _f_atandd(a, b):
    # atan(b) - atan(a) = atan((b-a)/(1+ab)) where 1 + ab > 0; elsewhere |b - a| >= 2
    # and the quotient has no cancellation.
    c = 1.0 + a * b
    if c > 0.0:
        return _f_atanc((b - a) / c) / c
    return (math.atan(b) - math.atan(a)) / (b - a)


def _f_datandd(a, b):
    # d/db atan[a, b] (Jacobians only)
    c = 1.0 + a * b
    if c > 0.0:
        t = (b - a) / c
        return ((1.0 + a * a) * _f_datanc(t) / c - a * _f_atanc(t)) / (c * c)
    return (1.0 / (1.0 + b * b) - _f_atandd(a, b)) / (b - a)


def _f_dexpdd(a, b):
    # d/db exp[a, b] = (exp(b) - exp[a, b])/(b - a) (Jacobians only): near the diagonal
    # the derivative of exp(m) sinhc(δ), m = (a+b)/2, with exp(m) = exp(hi) exp(-|δ|),
    # hi = max(a, b); elsewhere the quotient with exp(hi) taken out: exp(hi) g/D², D = |b - a| >= 1, g = D - 1 + exp(-D) for b > a and
    # 1 - exp(-D) - D exp(-D) for b < a (no cancellation beyond a factor ~2.4 at D = 1).
    # exp(hi) (exp(m)) as in _f_expdd: exp(x/2) twice above 709, so nothing overflows where
    # the value does not (a thin barrier gives 0; (0, 712) gives 2.3e306).
    d = b - a
    x = max(a, b)     # exact, unlike m = (a+b)/2: exp(m) = exp(x) exp(-|δ|) (a + b rounds by |m| eps)
    if abs(d) < 1.0:
        h = 0.5 * d
        f = 0.5 * math.exp(-abs(h)) * (_f_sinhc(h) + _f_dsinhc(h))
    else:
        D = abs(d)
        em = math.exp(-D)
        g = (D - 1.0) + em if d > 0.0 else -math.expm1(-D) - D * em
        f = g / D / D
    if x <= 709.0:
        return math.exp(x) * f
    if x > 1419.5:
        return math.inf      # exp(x/2) overflows: so does the value (as numpy and numba give)
    e = math.exp(0.5 * x)
    return e * (e * f)


# Taylor coefficients of sinc''(x) in x², highest first: (-1)^k 2k(2k-1)/(2k+1)!, k = 16 … 1.
_DDSINC_C = (1.1424204935805774e-34, -1.0580287861515605e-31, 8.550331942154474e-29, -5.969398411467106e-26,
             3.5587165569802293e-23, -1.787094618831376e-20, 7.437717604088679e-18, -2.515514385467045e-15,
             6.74749741042925e-13, -1.3917837991912066e-10, 2.1197937864604532e-08, -2.2546897546897547e-06,
             0.00015432098765432098, -0.005952380952380952, 0.1, -0.3333333333333333)


def _f_ddsinc(x):
    # sinc'' (Jacobians only): the quotient cancels badly up to |x| ~ 2.5 (-0.16 from
    # terms of 3.6 at x = 2), so the series runs to |x| < 3.
    if abs(x) < 3.0:
        x2 = x * x
        s = 0.0
        for c in _DDSINC_C:
            s = s * x2 + c
        return s
    return (2.0 * math.sin(x) - 2.0 * x * math.cos(x) - x * x * math.sin(x)) / (x * x * x)


# Taylor coefficients of sinc(x) = Σ c_k x^(2k) from k = 1: (-1)^k/(2k+1)!, k = 1 … 12.
_SINCDD_C = (-0.16666666666666666, 0.008333333333333333, -0.0001984126984126984, 2.7557319223985893e-06,
             -2.505210838544172e-08, 1.6059043836821613e-10, -7.647163731819816e-13, 2.8114572543455206e-15,
             -8.22063524662433e-18, 1.9572941063391263e-20, -3.868170170630684e-23, 6.446950284384474e-26)


def _f_sincdd(a, b):
    # sinc[a, b] = (sinc(b) - sinc(a))/(b - a), three branches (methodgen.problem.special.sinc_dd):
    if abs(a) < 2.0 and abs(b) < 2.0:
        # series: (b^2k - a^2k)/(b - a) = (a + b) h_(k-1)(a², b²), h_j(u, v) = Σ u^i v^(j-i)
        # (positive terms, h_j = v h_(j-1) + u^j); the omitted tail is below 2e-20 |a + b|.
        u = a * a
        v = b * b
        h = 1.0
        uk = 1.0
        s = 0.0
        for c in _SINCDD_C:
            s += c * h
            uk *= u
            h = v * h + uk
        return (a + b) * s
    d = b - a
    if abs(d) >= 1.0:
        # |b - a| >= 1: no small divisor, but sinc(b) - sinc(a) cancels where the two are
        # close (sinc(-4) ≈ sinc(-5): 36 ulp relative there): accurate to a few eps·|sinc|
        # absolute, not to a few ulp of the value.
        return (_f_sinc(b) - _f_sinc(a)) / d
    # a, b of one sign with |ab| > 1: sin b/b - sin a/a = (2m cos m sin δ - 2δ sin m cos δ)/(ab)
    m = 0.5 * (a + b)
    hd = 0.5 * d
    return (m * math.cos(m) * _f_sinc(hd) - math.sin(m) * math.cos(hd)) / (a * b)


# 8-point Gauss–Legendre nodes and weights on [0, 1].
_GL8_T = (0.019855071751231912, 0.10166676129318664, 0.2372337950418355, 0.4082826787521751,
          0.5917173212478248, 0.7627662049581645, 0.8983332387068134, 0.9801449282487681)
_GL8_W = (0.05061426814518853, 0.11119051722668721, 0.15685332293894344, 0.18134189168918083,
          0.18134189168918083, 0.15685332293894344, 0.11119051722668721, 0.05061426814518853)


def _f_dsincdd(a, b):
    # d/db sinc[a, b] (Jacobians only): the quotient (sinc'(b) - sinc[a, b])/(b - a) where
    # |b - a| >= 1, else ∫₀¹ t sinc''(a + t (b - a)) dt by Gauss–Legendre (sinc'' entire).
    d = b - a
    if abs(d) >= 1.0:
        return (_f_dsinc(b) - _f_sincdd(a, b)) / d
    s = 0.0
    for i in range(8):
        s += _GL8_W[i] * _GL8_T[i] * _f_ddsinc(a + _GL8_T[i] * d)
    return s


#: the helpers this file defines (``_f_<name>`` for each name)
HELPERS = tuple(name[3:] for name in dir() if name.startswith("_f_"))

_CHUNKS: dict = {}


def source(name: str) -> str:
    """The text of ``_f_<name>`` in this file with the comments and constants above it (the lines
    after the previous helper's definition): what a generated module holds a copy of.

    Raises
    ------
    KeyError
        ``name`` is not a helper of this file.
    """
    if not _CHUNKS:
        with open(os.path.abspath(__file__), encoding="utf-8") as f:
            text = f.read()
        lines = text.split("\n")
        end = None      # the last line of the marker, then of the previous helper
        for node in ast.parse(text).body:
            if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "_HELPERS_BELOW" for t in node.targets):
                end = node.end_lineno
            elif end is not None and isinstance(node, ast.FunctionDef) and node.name.startswith("_f_"):
                chunk = lines[end:node.end_lineno]
                while chunk and not chunk[0].strip():
                    chunk.pop(0)
                _CHUNKS[node.name[3:]] = "\n".join(chunk)
                end = node.end_lineno
    return _CHUNKS[name]
