"""The compiled runtime of the Wisdom–Holman splittings: exact Kepler flows and interaction kicks.

An ``[nbody]`` Hamiltonian splits as ``H = H_K + H_I`` where ``H_K`` is a sum of
independent Kepler problems in Jacobi coordinates (or, about a fixed centre, in the
coordinates themselves) and ``H_I`` depends on the positions only
(:mod:`methodgen.symbolic.nbody` derives and certifies the splitting).  This module runs
the splitting: the flow of ``H_K`` is solved exactly (universal variables), the flow of
``H_I`` is a kick, and the corrector of [LR01]_ is a kick by the gradient of
``C = Σ_i |∂H_I/∂q'_i|² / m'_i``, computed exactly as ``2 Hess(H_I) M'⁻¹ ∇H_I``.

Nothing here is generated per system: the masses are arrays, so the runtime is compiled
once per machine, the way the generated schemes' stepper is (:mod:`methodgen.runtime.fused`): each
function called from Python (:func:`run`'s loop, :func:`to_jacobi`, :func:`kick`, …) is
translated from this file's source to LLVM IR by :mod:`methodgen.codegen.llvmkernels` with every
function it calls inlined, compiled on its first call, its machine code kept on disk by
:mod:`methodgen.codegen.llvmcache` under the SHA-256 of the exact source it was translated from (this
file's, and :mod:`methodgen.runtime.stepper`'s for the compensated add it shares), and called through
its C entry (ctypes).  numba is not imported.  Without llvmlite (or with
``METHODGEN_STEPPER=python``, the reference) the same functions run as Python: the same
numbers bitwise, about 100× slower.  This module imports numpy (and llvmlite on first use)
only.

Layout: positions and momenta are ``(n, 3)`` C-contiguous arrays; Jacobi body 0 is the
centre of mass (its momentum is the total momentum).  Constants, per body ``i``:
``m`` (masses), ``M`` (cumulative masses ``M_i = m_0 + … + m_i``), ``mj`` (Jacobi masses
``m'_i = m_i M_{i-1}/M_i``, ``m'_0 = M_{n-1}``), ``mu`` (``G M_i``: the Kepler parameter of
Jacobi body i), ``KM`` (``G m_i M_{i-1}``: the Kepler term ``H_I`` subtracts back).  About a
fixed centre (``jacobi`` false) the coordinates are the bodies' own, ``mj = m``,
``mu = G M_centre`` and ``KM = 0``.

References
----------
.. [WH91] J. Wisdom, M. Holman, Symplectic maps for the N-body problem, Astron. J. 102
   (1991) 1528–1538.
.. [LR01] J. Laskar, P. Robutel, High order symplectic integrators for perturbed
   Hamiltonian systems, Celest. Mech. Dyn. Astron. 80 (2001) 39–62.
.. [Danby] J. M. A. Danby, Fundamentals of Celestial Mechanics, 2nd ed., Willmann-Bell 1988,
   §6.9 (universal variables, Stumpff functions, f and g).
.. [Conway86] B. A. Conway, An improved algorithm due to Laguerre for the solution of
   Kepler's equation, Celest. Mech. 39 (1986) 199–211.
"""

from __future__ import annotations

import importlib.util
import math
import os
import threading
import types

import numpy as np

from ..codegen import ktypes as _t
from .stepper import compensated_add

__all__ = ["COMPILED", "STATUS", "to_jacobi", "from_jacobi", "kepler_drift",
           "interaction_gradient", "corrector_gradient", "gradients", "apply_kick", "kick", "potential",
           "invariants", "project", "run", "run_projected", "compiled"]

#: Whether the runtime is compiled (llvmlite is installed); else it runs as Python.
COMPILED = importlib.util.find_spec("llvmlite") is not None

_V, _M2, _M3 = _t.float64[::1], _t.float64[:, ::1], _t.float64[:, :, ::1]
_f8, _i8 = _t.float64, _t.int64
_LOCK = threading.Lock()
#: LLVM's loop unrolling and vectorisation for this runtime's code: off (its loops run over a few
#: bodies or 3 components).  Measured on the outer solar system (sbab4): the run loop compiles in
#: 2.3–3.5 s without them, 8–9 s with unrolling, more with vectorisation too, and a step is no
#: slower (min-of-20 wall clock, interleaved)
_UNROLL = False
_VECTORIZE = False


class _Kernel:
    """A function of this module as Python calls it: compiled on its first call through LLVM IR
    (:func:`methodgen.codegen.llvmkernels.compile_kernel`, the functions it calls inlined; the machine
    code cached on disk, keyed by the source) for the signature ``sig`` and called through its
    C entry -- arrays as C-contiguous float64, the others as the signature's int64 or float64
    (a bool is an int) -- or run as Python (without llvmlite, or ``METHODGEN_STEPPER=python``).
    ``py_func`` is the Python function: what other functions of the module inline."""

    __slots__ = ("py_func", "sig", "_entry", "__name__", "__wrapped__", "__dict__")

    def __init__(self, fn, sig):
        self.py_func = fn
        self.sig = sig
        self._entry = None               # the C entry once compiled (False: runs as Python)
        self.__name__ = fn.__name__
        self.__doc__ = fn.__doc__
        self.__wrapped__ = fn

    def __repr__(self):
        return f"<methodgen.runtime.kepler_flow.{self.__name__}>"

    def entry(self):
        """The compiled C entry (ctypes), compiled or loaded from the cache on the first call;
        None where the function runs as Python."""
        got = self._entry
        if got is None:
            with _LOCK:
                got = self._entry
                if got is None:
                    got = self._entry = _compile(self.py_func, self.sig)
        return got or None

    def __call__(self, *args):
        fn = self.py_func
        if len(args) < fn.__code__.co_argcount and fn.__defaults__:
            args += fn.__defaults__[len(args) - fn.__code__.co_argcount:]
        if os.environ.get("METHODGEN_STEPPER", "").strip() == "python":
            return fn(*args)
        c = self.entry()
        if c is None:
            return fn(*args)
        from ..codegen.llvmkernels import packed_structs
        buf, addrs = packed_structs([a for a in args if isinstance(a, np.ndarray)])
        it = iter(addrs)
        out = c(*[next(it) if isinstance(a, np.ndarray) else a for a in args])
        del buf             # (the structures live until the call has returned)
        return out


def _kernel(sig):
    """Decorator: the function as a :class:`_Kernel` of signature ``sig``."""
    return lambda fn: _Kernel(fn, sig)


def _compile(fn, sig):
    """The C entry of ``fn`` compiled for ``sig`` (ctypes), or False where the runtime runs as
    Python (no llvmlite).  A function the translator refuses is a defect of this module: the
    error is raised (a test compiles every entry)."""
    if not COMPILED:
        return False
    from ..codegen import llvmkernels as lk

    return lk.compile_kernel(fn, sig, globals_=_kernel_globals(), c_entry=True, unroll=_UNROLL,
                             vectorize=_VECTORIZE).c_call


_GLOBALS: dict = {}


def _kernel_globals() -> dict:
    """The names the compiled functions may use -- this module's functions, modules, constant
    tables and numbers -- as the namespace they are translated in.  Every value enters the
    machine-code cache key (:func:`methodgen.codegen.llvmcache.key`): a function by the text of its
    file, so the key covers :mod:`methodgen.runtime.stepper`'s source (:func:`compensated_add`) as
    well as this file's."""
    if not _GLOBALS:
        g = {}
        for name, v in globals().items():
            if (isinstance(v, (_Kernel, types.FunctionType, types.ModuleType, np.ndarray))
                    or type(v) in (int, float, bool)) and not name.startswith("__"):
                g[name] = v
        _GLOBALS.update(g)
    return _GLOBALS


def compiled() -> bool:
    """Whether the runtime's functions run compiled here (llvmlite installed and
    ``METHODGEN_STEPPER`` is not ``python``)."""
    return COMPILED and os.environ.get("METHODGEN_STEPPER", "").strip() != "python"

#: run()'s status codes.
STATUS = {0: "ok", 1: "Kepler solve did not converge", 2: "non-finite state (or a body at its centre)",
          4: "a kick changed a Jacobi momentum by more than the limit (a close encounter)",
          5: "the energy projection did not reach round-off"}

#: Largest number of iterations of the energy projection (:func:`project`); it takes about 2 at
#: the steps of a resolved run (one correction, then the check that it reached round-off).
PROJ_MAXITER = 20
_EPS = 2.220446049250313e-16
#: The projection's residuals (relative to their first-order size) stopped decreasing at or
#: below this: their round-off floor.
_PROJ_PLATEAU = 64 * _EPS

#: Largest number of iterations of the Kepler solve (Laguerre–Conway); it takes 2–6 at the
#: steps of a converged run.
KEPLER_MAXITER = 50
_KEPLER_MAXITER = KEPLER_MAXITER        # (the compiled code's constant: a private name)


def _copy(src, dst):
    """``dst[:] = src`` for (n, 3) arrays (the identity map about a fixed centre)."""
    for i in range(src.shape[0]):
        for k in range(3):
            dst[i, k] = src[i, k]


@_kernel(_t.none(_M2, _M2, _V, _V, _i8, _M2, _M2))
def to_jacobi(q, p, m, M, jacobi, qj, pj):
    """Jacobi coordinates ``qj = A q`` and momenta ``pj = A⁻ᵀ p`` (into qj, pj; (n, 3) each).

    ``qj[i] = q[i] − R_{i−1}`` (``R_{i−1}``: centre of mass of bodies 0…i−1),
    ``pj[i] = (M_{i−1} p[i] − m_i P_{i−1})/M_i`` (``P_{i−1}``: their total momentum);
    ``qj[0]`` is the centre of mass, ``pj[0]`` the total momentum.  The identity when
    ``jacobi`` is false.
    """
    _gradient_to_jacobi(p, m, M, jacobi, pj)     # momenta map like gradients: A⁻ᵀ
    if not jacobi:
        _copy(q, qj)
        return
    n = q.shape[0]
    for k in range(3):
        R = m[0] * q[0, k]
        for i in range(1, n):
            qj[i, k] = q[i, k] - R / M[i - 1]
            R += m[i] * q[i, k]
        qj[0, k] = R / M[n - 1]


@_kernel(_t.none(_M2, _M2, _V, _V, _i8, _M2, _M2))
def from_jacobi(qj, pj, m, M, jacobi, q, p):
    """The inverse of :func:`to_jacobi` (into q, p)."""
    _positions(qj, m, M, jacobi, q)
    if not jacobi:
        _copy(pj, p)
        return
    n = qj.shape[0]
    for k in range(3):
        P = pj[0, k]            # P_i, the total momentum of bodies 0…i, from i = n-1 down
        for i in range(n - 1, 0, -1):
            p[i, k] = pj[i, k] + m[i] / M[i] * P
            P -= p[i, k]
        p[0, k] = P


def _positions(qj, m, M, jacobi, q):
    """Cartesian positions of Jacobi positions (the position half of :func:`from_jacobi`)."""
    if not jacobi:
        _copy(qj, q)
        return
    n = qj.shape[0]
    for k in range(3):
        R = qj[0, k]
        for i in range(n - 1, 0, -1):
            Rm = R - m[i] / M[i] * qj[i, k]
            q[i, k] = qj[i, k] + Rm
            R = Rm
        q[0, k] = R


def _gradient_to_jacobi(g, m, M, jacobi, gj):
    """``gj = A⁻ᵀ g``: a Cartesian gradient (or momentum) as one in Jacobi coordinates."""
    if not jacobi:
        _copy(g, gj)
        return
    n = g.shape[0]
    for k in range(3):
        P = g[0, k]
        for i in range(1, n):
            gj[i, k] = (M[i - 1] * g[i, k] - m[i] * P) / M[i]
            P += g[i, k]
        gj[0, k] = P


#: Reciprocals of the series' denominators: c3's (2k+4)(2k+5) and c2's (2k+3)(2k+4), k = 0…13.
_R3 = np.array([1.0 / ((2 * k + 4) * (2 * k + 5)) for k in range(14)])
_R2 = np.array([1.0 / ((2 * k + 3) * (2 * k + 4)) for k in range(14)])


def _stumpff(z):
    """Stumpff functions ``c0, c1, c2, c3`` at ``z`` (series for |z| < 1, closed forms otherwise).

    The closed forms for c2 and c3 are written without the cancellation of ``1 − cos``; the
    series stops when a term no longer changes the sums (at most 14 terms: |z|¹⁴/29! < 1e-30).
    """
    if abs(z) < 1.0:
        c3 = 0.0
        c2 = 0.0
        t3 = 1.0 / 6.0
        t2 = 0.5
        for k in range(14):
            c3 += t3
            c2 += t2
            t3 *= -z * _R3[k]
            t2 *= -z * _R2[k]
            if abs(t2) < 1e-18:     # |t3| < |t2| here; c2 ≥ 0.45, c3 ≥ 0.16 for |z| < 1
                break
        return 1.0 - z * c2, 1.0 - z * c3, c2, c3
    if z > 0.0:
        x = math.sqrt(z)
        s = math.sin(x)
        h = math.sin(0.5 * x)
        return math.cos(x), s / x, 2.0 * h * h / z, (x - s) / (z * x)
    x = math.sqrt(-z)
    s = math.sinh(x)
    h = math.sinh(0.5 * x)
    return math.cosh(x), s / x, 2.0 * h * h / (-z), (s - x) / (-z * x)


def _kadd(s, c, x, comp):
    """Compensated ``s + x`` (Kahan) when ``comp``: the new sum and compensation (true sum ≈
    sum − c); else the plain sum and ``c`` unchanged.

    The stepper's compensated add (:func:`methodgen.runtime.stepper.compensated_add`, whose
    compensation has the other sign: true sum ≈ sum + c) with the sign turned at both ends,
    bit for bit the sum ``t = s + (x − c)`` and compensation ``(t − s) − (x − c)`` this module
    has always computed: ``x + (−c)`` is ``x − c`` exactly, and ``0.0 − e`` is ``−e`` except
    that a zero comes out +0.0, as ``(t − s) − y`` does (``t − s`` is never −0.0 there)."""
    if not comp:
        return s + x, c
    t, e = compensated_add(s, -c, x)
    return t, 0.0 - e


@_kernel(_i8(_M2, _M2, _M2, _M2, _i8, _f8, _f8, _f8, _i8))
def kepler_drift(qj, pj, cq, cp, i, mj, mu, dt, comp=True):
    """Advance Jacobi body ``i`` (``qj[i]``, ``pj[i]``) along its Kepler orbit ``μ = mu`` by ``dt``.

    Universal variables [Danby]_: with ``r0 = |r|``, ``η = r·v``, ``β = 2μ/r0 − v²``,
    ``ζ = μ − β r0`` and ``G_k(s) = s^k c_k(β s²)``, the universal anomaly ``s`` solves
    ``r0 G1 + η G2 + μ G3 = dt`` (solved by Laguerre–Conway [Conway86]_ to round-off; for a
    bound orbit ``dt`` is first reduced by whole periods), then
    ``r' = f r + g v``, ``v' = ḟ r + ġ v``, added as the increments ``(f − 1) r + g v`` and
    ``ḟ r + (ġ − 1) v`` (``f − 1 = −μG2/r0``, ``ġ − 1 = −μG2/r``: no cancellation) with
    compensated summation into the state, the compensations in ``cq``, ``cp`` (true value ≈
    ``qj − cq``): the state's own rounding does not accumulate over the steps.  Returns the
    number of iterations, or −1 when the solve did not reach round-off in
    :data:`KEPLER_MAXITER` iterations, −2 when the body's state is not finite or at the centre
    (nothing is written then).
    """
    x, y, z = qj[i, 0], qj[i, 1], qj[i, 2]
    vx, vy, vz = pj[i, 0] / mj, pj[i, 1] / mj, pj[i, 2] / mj
    r0 = math.sqrt(x * x + y * y + z * z)
    eta = x * vx + y * vy + z * vz
    beta = 2.0 * mu / r0 - (vx * vx + vy * vy + vz * vz)
    if not (math.isfinite(beta) and math.isfinite(eta) and r0 > 0.0):
        return -2
    zeta = mu - beta * r0
    tau = dt
    if beta > 0.0:
        # a bound orbit: whole periods (2π μ/β^{3/2}) change nothing; keep the remainder
        period = 2.0 * math.pi * mu / (beta * math.sqrt(beta))
        if abs(tau) > 0.5 * period:
            tau -= math.floor(tau / period + 0.5) * period
    # start value: the Taylor series of s(t) to third order, clipped for bound orbits; on a
    # hyperbolic orbit a long drift starts from the logarithmic estimate (Vallado, Fundamentals
    # of Astrodynamics, Alg. 8, in s = χ/√μ), from which Laguerre–Conway converges in a few
    # iterations (from the Taylor value it walks down a few units per iteration, then cosh overflows)
    s = tau / r0 * (1.0 + tau / r0 * (-eta / (2.0 * r0) + tau * (3.0 * eta * eta - r0 * zeta)
                                       / (6.0 * r0 * r0 * r0)))
    if beta > 0.0:
        lim = math.pi / math.sqrt(beta)
        if s > lim:
            s = lim
        elif s < -lim:
            s = -lim
    elif beta < 0.0 and -beta * s * s > 1.0:
        sq = math.sqrt(-beta)
        sgn = 1.0 if tau > 0.0 else -1.0
        arg = (-2.0 * beta * tau) / (eta + sgn * zeta / sq)
        if arg > 1.0:
            s = sgn * math.log(arg) / sq
    it = 0
    done = False
    c0 = G1 = G2 = G3 = ds = 0.0
    while it < _KEPLER_MAXITER:
        it += 1
        c0, c1, c2, c3 = _stumpff(beta * s * s)
        G1 = s * c1
        G2 = s * s * c2
        G3 = s * s * s * c3
        F = r0 * G1 + eta * G2 + mu * G3 - tau
        dF = r0 * c0 + eta * G1 + mu * G2           # r(s) > 0
        ddF = eta * c0 + zeta * G1                   # dr/ds
        # Laguerre–Conway step (n = 5), globally convergent for Kepler's equation
        disc = 16.0 * dF * dF - 20.0 * F * ddF
        den = dF + math.copysign(math.sqrt(abs(disc)), dF)
        ds = 5.0 * F / den if den != 0.0 else F / dF
        s -= ds
        # Laguerre–Conway converges cubically (error after a step ~ (its size)³ in units of s):
        # after a step of ≤ 1e-7 |s| the error is ~1e-21 |s|, below round-off
        if abs(ds) <= 1e-7 * abs(s) or ds == 0.0:
            done = True
            break
    if not done:
        return -1
    # the G functions at the converged s from those at s + ds: dG_k/ds = G_{k-1}, dG_0/ds = -β G_1,
    # to second order in ds (the third-order term, ~|ds|³ ≤ 1e-21 |s|³, is below round-off)
    h2 = 0.5 * ds * ds
    G0 = c0 + ds * beta * G1 - h2 * beta * c0
    G3 = G3 - ds * G2 + h2 * G1
    G2 = G2 - ds * G1 + h2 * c0
    G1 = G1 - ds * c0 - h2 * beta * G1
    c0 = G0
    r = r0 * c0 + eta * G1 + mu * G2
    fm1 = -mu * G2 / r0
    # g = τ − μG3 = r0 G1 + η G2 at the root: the latter without τ − μG3's cancellation
    # (near pericentre of an eccentric orbit the two terms nearly cancel)
    g = r0 * G1 + eta * G2
    fd = -mu * G1 / (r * r0)
    gdm1 = -mu * G2 / r
    qj[i, 0], cq[i, 0] = _kadd(qj[i, 0], cq[i, 0], fm1 * x + g * vx, comp)
    qj[i, 1], cq[i, 1] = _kadd(qj[i, 1], cq[i, 1], fm1 * y + g * vy, comp)
    qj[i, 2], cq[i, 2] = _kadd(qj[i, 2], cq[i, 2], fm1 * z + g * vz, comp)
    pj[i, 0], cp[i, 0] = _kadd(pj[i, 0], cp[i, 0], mj * (fd * x + gdm1 * vx), comp)
    pj[i, 1], cp[i, 1] = _kadd(pj[i, 1], cp[i, 1], mj * (fd * y + gdm1 * vy), comp)
    pj[i, 2], cp[i, 2] = _kadd(pj[i, 2], cp[i, 2], mj * (fd * z + gdm1 * vz), comp)
    return it


def drift(qj, pj, cq, cp, mj, mu, jacobi, dt, comp):
    """The exact flow of ``H_K`` over ``dt``: every Kepler body, and the centre of mass
    moving freely (Jacobi).  Returns ``(status, body)``: (0, −1), or the first failing body
    with status 1 (no convergence) or 2 (a state not finite, or at the centre)."""
    n = qj.shape[0]
    first = 1 if jacobi else 0
    if jacobi:
        for k in range(3):
            qj[0, k], cq[0, k] = _kadd(qj[0, k], cq[0, k], dt * pj[0, k] / mj[0], comp)
    for i in range(first, n):
        r = kepler_drift(qj, pj, cq, cp, i, mj[i], mu[i], dt, comp)
        if r < 0:
            return (1 if r == -1 else 2), i
    return 0, -1


@_kernel(_t.none(_M2, _V, _V, _V, _f8, _i8, _M2, _M2, _M2))
def interaction_gradient(qj, m, M, KM, G, jacobi, q, g, gj):
    """``gj = ∇_{q'} H_I`` at the Jacobi positions ``qj`` (q, g: (n, 3) work arrays).

    ``H_I = Σ_{i≥1} KM_i/|q'_i| − Σ_{a<b} G m_a m_b/|q_a − q_b|``: the pairs in Cartesian
    positions, mapped with ``A⁻ᵀ``, minus the Kepler terms the splitting moved into ``H_K``.
    """
    n = qj.shape[0]
    _positions(qj, m, M, jacobi, q)
    for i in range(n):
        for k in range(3):
            g[i, k] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            dx = q[b, 0] - q[a, 0]
            dy = q[b, 1] - q[a, 1]
            dz = q[b, 2] - q[a, 2]
            r2 = dx * dx + dy * dy + dz * dz
            w = G * m[a] * m[b] / (r2 * math.sqrt(r2))
            g[b, 0] += w * dx
            g[b, 1] += w * dy
            g[b, 2] += w * dz
            g[a, 0] -= w * dx
            g[a, 1] -= w * dy
            g[a, 2] -= w * dz
    _gradient_to_jacobi(g, m, M, jacobi, gj)
    if jacobi:
        for k in range(3):
            gj[0, k] = 0.0      # H_I is translation invariant (the sum is round-off)
        for i in range(1, n):
            x, y, z = qj[i, 0], qj[i, 1], qj[i, 2]
            r2 = x * x + y * y + z * z
            w = KM[i] / (r2 * math.sqrt(r2))
            gj[i, 0] -= w * x
            gj[i, 1] -= w * y
            gj[i, 2] -= w * z


@_kernel(_t.none(_M2, _M2, _V, _V, _V, _V, _f8, _i8, _M2, _M2, _M2, _M2, _M2))
def corrector_gradient(qj, gj, m, M, mj, KM, G, jacobi, q, u, w, h, hj):
    """``hj = ∇C = 2 Hess(H_I) u'`` with ``u' = M'⁻¹ gj`` and ``gj = ∇H_I`` at ``qj``.

    ``C = Σ_i |∂H_I/∂q'_i|²/m'_i`` (the double bracket ``{{H_K, H_I}, H_I}``: only the
    kinetic part of ``H_K`` contributes, ``H_I`` depending on positions only).  The Hessian
    is applied, not formed: pairs in Cartesian coordinates on ``w = A⁻¹ u'`` (mapped back
    with ``A⁻ᵀ``), the Kepler terms blockwise.  ``q`` must hold the Cartesian positions of
    ``qj`` (as :func:`interaction_gradient` leaves them); u, w, h are work arrays.
    """
    n = qj.shape[0]
    first = 1 if jacobi else 0
    for k in range(3):
        u[0, k] = 0.0
    for i in range(first, n):
        for k in range(3):
            u[i, k] = gj[i, k] / mj[i]
    _positions(u, m, M, jacobi, w)      # u'_0 = 0, so w = A⁻¹ u'
    for i in range(n):
        for k in range(3):
            h[i, k] = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            dx = q[b, 0] - q[a, 0]
            dy = q[b, 1] - q[a, 1]
            dz = q[b, 2] - q[a, 2]
            ex = w[b, 0] - w[a, 0]
            ey = w[b, 1] - w[a, 1]
            ez = w[b, 2] - w[a, 2]
            r2 = dx * dx + dy * dy + dz * dz
            r3 = r2 * math.sqrt(r2)
            k1 = G * m[a] * m[b] / r3
            k3 = 3.0 * k1 * (dx * ex + dy * ey + dz * ez) / r2
            vx = k1 * ex - k3 * dx
            vy = k1 * ey - k3 * dy
            vz = k1 * ez - k3 * dz
            h[b, 0] += vx
            h[b, 1] += vy
            h[b, 2] += vz
            h[a, 0] -= vx
            h[a, 1] -= vy
            h[a, 2] -= vz
    _gradient_to_jacobi(h, m, M, jacobi, hj)
    if jacobi:
        for k in range(3):
            hj[0, k] = 0.0
        for i in range(1, n):
            x, y, z = qj[i, 0], qj[i, 1], qj[i, 2]
            r2 = x * x + y * y + z * z
            r3 = r2 * math.sqrt(r2)
            k1 = KM[i] / r3
            k3 = 3.0 * k1 * (x * u[i, 0] + y * u[i, 1] + z * u[i, 2]) / r2
            hj[i, 0] -= k1 * u[i, 0] - k3 * x
            hj[i, 1] -= k1 * u[i, 1] - k3 * y
            hj[i, 2] -= k1 * u[i, 2] - k3 * z
    for i in range(n):
        for k in range(3):
            hj[i, k] *= 2.0


@_kernel(_t.none(_M2, _f8, _V, _V, _V, _V, _f8, _i8, _M3))
def gradients(qj, b, m, M, mj, KM, G, jacobi, work):
    """``work[2] = ∇H_I`` and, when ``b != 0``, ``work[6] = ∇C`` at ``qj`` (Jacobi; ``work[0]``
    then holds the Cartesian positions): what a kick at ``qj`` adds, before it is added."""
    q, g, gj, u, w, h, hj = work[0], work[1], work[2], work[3], work[4], work[5], work[6]
    interaction_gradient(qj, m, M, KM, G, jacobi, q, g, gj)
    if b != 0.0:
        corrector_gradient(qj, gj, m, M, mj, KM, G, jacobi, q, u, w, h, hj)


@_kernel(_t.none(_M2, _M2, _f8, _f8, _M3, _i8))
def apply_kick(pj, cp, a, b, work, comp=True):
    """``p' −= a ∇H_I + b ∇C`` with the gradients :func:`gradients` left in ``work``."""
    gj, hj = work[2], work[6]
    n = pj.shape[0]
    if b != 0.0:
        for i in range(n):
            for k in range(3):
                pj[i, k], cp[i, k] = _kadd(pj[i, k], cp[i, k], -(a * gj[i, k] + b * hj[i, k]), comp)
    else:
        for i in range(n):
            for k in range(3):
                pj[i, k], cp[i, k] = _kadd(pj[i, k], cp[i, k], -(a * gj[i, k]), comp)


@_kernel(_t.none(_M2, _M2, _M2, _f8, _f8, _V, _V, _V, _V, _f8, _i8, _M3, _i8))
def kick(qj, pj, cp, a, b, m, M, mj, KM, G, jacobi, work, comp=True):
    """``p' −= a ∇H_I + b ∇C`` (positions unchanged): the flow of ``a H_I + b C`` over time 1,
    added with compensated summation (compensation ``cp``, as :func:`kepler_drift`).

    ``work`` is an (7, n, 3) array.  ``b == 0`` skips the Hessian.
    """
    gradients(qj, b, m, M, mj, KM, G, jacobi, work)
    apply_kick(pj, cp, a, b, work, comp)


def _kick_size(qj, pj, work, a, b, first, mj, mu):
    """``(max_i |Δp'_i| / p_ref,i, i)`` of the kick just made (``work`` as :func:`kick` left it).

    ``p_ref,i = max(|p'_i|, m'_i √(μ_i/|q'_i|))``: the body's momentum, or that of a circular
    orbit at its distance when larger (a body near rest, at the apocentre of an eccentric
    orbit, is not an encounter).
    """
    gj, hj = work[2], work[6]
    worst = 0.0
    body = -1
    for i in range(first, pj.shape[0]):
        d2 = 0.0
        p2 = 0.0
        r2 = 0.0
        for k in range(3):
            inc = a * gj[i, k] + (b * hj[i, k] if b != 0.0 else 0.0)
            d2 += inc * inc
            p2 += pj[i, k] * pj[i, k]
            r2 += qj[i, k] * qj[i, k]
        circ = mj[i] * mj[i] * mu[i] / math.sqrt(r2) if r2 > 0.0 else 0.0
        ref2 = max(p2, circ)
        if d2 > worst * worst * ref2:
            worst = math.sqrt(d2 / ref2) if ref2 > 0.0 else np.inf
            body = i
    return worst, body


def _finite(qj, pj):
    n = qj.shape[0]
    for i in range(n):
        for k in range(3):
            if not (math.isfinite(qj[i, k]) and math.isfinite(pj[i, k])):
                return False
    return True


def _row(tq, tp, tc, m, M, jacobi, work, row):
    """``row`` = the Cartesian state (q then p) of the Jacobi state ``tq``, ``tp − tc``."""
    n = tq.shape[0]
    for i in range(n):
        for k in range(3):
            tp[i, k] -= tc[i, k]
            tc[i, k] = 0.0
    q, p = work[3], work[4]
    from_jacobi(tq, tp, m, M, jacobi, q, p)
    for i in range(n):
        for k in range(3):
            row[3 * i + k] = q[i, k]
            row[3 * n + 3 * i + k] = p[i, k]


def _emit(qj, pj, cq, cp, a, b, m, M, mj, KM, G, jacobi, work, tq, tp, tc, row, comp):
    """The output row of the carried state: its compensated value with the lagged kick ``(a, b)``,
    on a copy, in Cartesian (``tq``, ``tp``, ``tc``: work arrays)."""
    n = qj.shape[0]
    for i in range(n):
        for k in range(3):
            tq[i, k] = qj[i, k] - cq[i, k]
            tp[i, k] = pj[i, k]
            tc[i, k] = cp[i, k]
    if a != 0.0 or b != 0.0:
        kick(tq, tp, tc, a, b, m, M, mj, KM, G, jacobi, work, comp)
    _row(tq, tp, tc, m, M, jacobi, work, row)


@_kernel(_f8(_M2, _V, _V, _f8, _i8))
def potential(q, m, mu, G, jacobi):
    """``U(q) = −Σ_{a<b} G m_a m_b/|q_a − q_b|`` (Cartesian positions ``q``), and about a fixed
    centre also ``− Σ_b μ_b m_b/|q_b|``."""
    n = q.shape[0]
    U = 0.0
    for a in range(n):
        for b in range(a + 1, n):
            dx = q[b, 0] - q[a, 0]
            dy = q[b, 1] - q[a, 1]
            dz = q[b, 2] - q[a, 2]
            U -= G * m[a] * m[b] / math.sqrt(dx * dx + dy * dy + dz * dz)
        if not jacobi:
            U -= mu[a] * m[a] / math.sqrt(q[a, 0] ** 2 + q[a, 1] ** 2 + q[a, 2] ** 2)
    return U


@_kernel(_t.none(_M2, _M2, _M2, _f8, _V, _V, _i8, _M2))
def invariants(tq, tp, tc, U, mj, out, first, A):
    """``out[0:4] = (H, Lx, Ly, Lz)`` of the Jacobi state ``tq``, ``tp − tc`` with potential
    ``U`` (``H = Σ_i |p'_i|²/(2m'_i) + U``, ``L = Σ_i q'_i × p'_i``: the Jacobi map is a linear
    point transformation acting on the bodies, not on the axes, so both keep their form), and
    ``out[4:8]`` their first-order sizes, round-off is relative to these: ``2T + |U|`` for H
    (``Σ |∂H/∂y_k| |y_k|``, U homogeneous of degree −1), ``Σ_i |q'_i| |p'_i|`` for every
    component of L (a rotation-invariant size: a component that is small in these axes, as
    Lx of a nearly planar problem, carries the round-off of the others).

    ``A`` (4×4) receives ∂(H, L)/∂λ of :func:`project`'s correction of the bodies ``i ≥ first``:
    ``[[2T_f, L_fᵀ], [L_f, I_f]]`` over them (``I_f`` their inertia tensor)."""
    n = tq.shape[0]
    T = 0.0
    sL = 0.0
    for k in range(8):
        out[k] = 0.0
    for a in range(4):
        for b in range(4):
            A[a, b] = 0.0
    for i in range(n):
        px = tp[i, 0] - tc[i, 0]
        py = tp[i, 1] - tc[i, 1]
        pz = tp[i, 2] - tc[i, 2]
        x, y, z = tq[i, 0], tq[i, 1], tq[i, 2]
        p2 = px * px + py * py + pz * pz
        r2 = x * x + y * y + z * z
        lx, ly, lz = y * pz - z * py, z * px - x * pz, x * py - y * px
        T += p2 / (2.0 * mj[i])
        out[1] += lx
        out[2] += ly
        out[3] += lz
        sL += math.sqrt(r2 * p2)
        if i >= first:
            A[0, 0] += p2 / mj[i]
            A[0, 1] += lx
            A[0, 2] += ly
            A[0, 3] += lz
            A[1, 1] += mj[i] * (r2 - x * x)
            A[2, 2] += mj[i] * (r2 - y * y)
            A[3, 3] += mj[i] * (r2 - z * z)
            A[1, 2] -= mj[i] * x * y
            A[1, 3] -= mj[i] * x * z
            A[2, 3] -= mj[i] * y * z
    for a in range(4):
        for b in range(a):
            A[a, b] = A[b, a]
    out[0] = T + U
    out[4] = 2.0 * T + abs(U)
    for k in range(5, 8):
        out[k] = sL


def project(tq, tp, tc, pj, cp, tgt, U, mj, jacobi, inv, comp, maxiter, feedback):
    """Project the output state onto ``(H, L) = tgt`` by moving its Jacobi momenta only.

    The correction of body ``i`` (every body about a fixed centre; the Jacobi bodies ``i ≥ 1``
    otherwise, so the total momentum ``p'_0`` is untouched) is
    ``δp'_i = λ_H p'_i + m'_i (λ_L × q'_i)``: a scaling of the velocities and a rigid rotation,
    the gradients of ``H`` and ``L`` in ``p`` in the metric ``diag(m')`` [HLW, §IV.4.1].  With
    the positions fixed, the lagged kick from the carried state to the output (a function of the
    positions alone) commutes with it: with ``feedback`` ``δ`` is added to the carried momenta
    (``pj``, ``cp``) too, and the run continues from the projected state; without, only the
    output (``tp``, ``tc``) is projected.  Newton on the four λ (the 4×4 matrix
    ``[[2T, Lᵀ], [L, I]]``, ``I`` the inertia tensor of the moved bodies, at each iterate)
    until every residual is at round-off relative to its size (:func:`invariants`) or stopped
    decreasing at :data:`_PROJ_PLATEAU` of it.

    Returns ``(status, iterations)``: status 0; 2 when H or L is not finite (``inv[8]`` NaN); 5
    when ``maxiter`` iterations did not reach round-off (``inv[8]`` then the largest relative
    residual).
    """
    n = tq.shape[0]
    first = 1 if jacobi else 0
    A = np.empty((4, 4))
    r = np.empty(4)
    lam = np.empty(4)
    prev = np.inf
    for it in range(1, maxiter + 1):
        invariants(tq, tp, tc, U, mj, inv, first, A)
        rel = 0.0
        for a in range(4):
            r[a] = inv[a] - tgt[a]
            if not (math.isfinite(r[a]) and math.isfinite(inv[4 + a])):
                inv[8] = np.nan
                return 2, it       # H or L not finite (two bodies at one place): not a state of H
            if inv[4 + a] > 0.0:
                rel = max(rel, abs(r[a]) / inv[4 + a])
            elif r[a] != 0.0:
                rel = np.inf
        inv[8] = rel
        # converged, or stopped decreasing within the round-off plateau (this iterate itself
        # within it: a worse one is not accepted)
        if rel <= _EPS or (rel >= prev and rel <= _PROJ_PLATEAU):
            return 0, it
        if not rel < np.inf:
            return 5, it
        prev = rel
        # A: ∂(H, L)/∂λ at the current momenta, from the same pass
        for a in range(4):
            lam[a] = -r[a]
        _solve_sym(A, lam)
        for i in range(first, n):
            x, y, z = tq[i, 0], tq[i, 1], tq[i, 2]
            wx = lam[2] * z - lam[3] * y
            wy = lam[3] * x - lam[1] * z
            wz = lam[1] * y - lam[2] * x
            for k in range(3):
                dk = lam[0] * (tp[i, k] - tc[i, k]) + mj[i] * (wx if k == 0 else (wy if k == 1 else wz))
                tp[i, k], tc[i, k] = _kadd(tp[i, k], tc[i, k], dk, comp)
                if feedback:
                    pj[i, k], cp[i, k] = _kadd(pj[i, k], cp[i, k], dk, comp)
    invariants(tq, tp, tc, U, mj, inv, first, A)
    return 5, maxiter


@_kernel(_t.none(_M2, _V))
def _solve_sym(A, x):
    """``x ← A⁻¹ x`` for the symmetric positive semi-definite 4×4 ``A`` (in place, A destroyed).

    The rows are first scaled by the square roots of the diagonal (the entries are in different
    units: ``2T`` an energy, the inertia ``m r²`` an energy times a time squared, so a cutoff
    relative to the largest entry would depend on the unit of time), then Gaussian elimination
    with diagonal pivoting; a pivot below 1e-13 of its scaled row (a direction that moves
    nothing: the rotation about the line of a single body) gets 0 in that component, the least
    correction that solves the rest.  (The work arrays are float64 of 4 entries: the pivot
    order as float indices, the flags as 0.0 / 1.0.)"""
    m = 4
    order = np.zeros(4)
    used = np.zeros(4)
    d = np.zeros(4)
    for a in range(m):
        if A[a, a] > 0.0:
            d[a] = math.sqrt(A[a, a])
        else:
            used[a] = 1.0          # moves nothing at all: component 0 (below)
    for a in range(m):
        for b in range(m):
            A[a, b] = A[a, b] / (d[a] * d[b]) if d[a] > 0.0 and d[b] > 0.0 else 0.0
        x[a] = x[a] / d[a] if d[a] > 0.0 else 0.0
    npiv = 0
    for _ in range(m):
        k = -1
        best = 1e-13
        for a in range(m):
            if not used[a] and abs(A[a, a]) > best:
                best = abs(A[a, a])
                k = a
        if k < 0:
            break
        used[k] = 1.0
        order[npiv] = k
        npiv += 1
        for a in range(m):
            if not used[a] and A[a, k] != 0.0:
                f = A[a, k] / A[k, k]
                for b in range(m):
                    A[a, b] -= f * A[k, b]
                x[a] -= f * x[k]
    solved = np.zeros(4)
    for s in range(npiv):
        solved[int(order[s])] = 1.0
    for a in range(m):
        if not solved[a]:
            x[a] = 0.0
    for s in range(npiv - 1, -1, -1):
        k = int(order[s])
        v = x[k]
        for t in range(s + 1, npiv):
            v -= A[k, int(order[t])] * x[int(order[t])]
        x[k] = v / A[k, k]
    for a in range(m):
        if d[a] > 0.0:
            x[a] = x[a] / d[a]


def _save(qj, pj, cq, cp, sq, sp, scq, scp):
    """Copy the carried state and its compensations (to restore it after a failed step)."""
    for i in range(qj.shape[0]):
        for k in range(3):
            sq[i, k] = qj[i, k]
            sp[i, k] = pj[i, k]
            scq[i, k] = cq[i, k]
            scp[i, k] = cp[i, k]


def _buffers(n):
    """The loops' work arrays for n bodies (Python's, passed to the compiled loops): the kicks'
    (7, n, 3), the output state's three (n, 3) and the saved state's (4, n, 3)."""
    return np.empty((7, n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3)), np.empty((4, n, 3))


def _step(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, a0, b0, fresh, work, fail, comp, limit, peak):
    """One step of the splitting on the carried state (in place): the fused kick ``(a0, b0)``
    (with the gradients already in ``work`` when ``fresh``), then the drifts and the inner
    kicks.  False, with ``fail = (status, body)``, when a kick exceeded ``limit``, a Kepler
    solve failed or the state is not finite (the state is then to be restored)."""
    ns = c.shape[0]
    first = 1 if jacobi else 0
    if a0 != 0.0 or b0 != 0.0:
        if not fresh:
            gradients(qj, b0, m, M, mj, KM, G, jacobi, work)
        apply_kick(pj, cp, a0, b0, work, comp)
        size, body = _kick_size(qj, pj, work, a0, b0, first, mj, mu)
        if size > peak[0]:
            peak[0] = size
            peak[1] = body
    for j in range(ns):
        if j > 0 and d[j] != 0.0:
            kick(qj, pj, cp, d[j] * h, 0.0, m, M, mj, KM, G, jacobi, work, comp)
            size, body = _kick_size(qj, pj, work, d[j] * h, 0.0, first, mj, mu)
            if size > peak[0]:
                peak[0] = size
                peak[1] = body
        if peak[0] > limit:
            fail[0] = 4
            fail[1] = int(peak[1])
            return False
        st, body = drift(qj, pj, cq, cp, mj, mu, jacobi, c[j] * h, comp)
        if st != 0:
            fail[0] = st
            fail[1] = body
            return False
    if not _finite(qj, pj):
        fail[0] = 2
        fail[1] = -1
        return False
    return True


def run(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, kappa, steps, save_every, out, fail, comp,
        limit, peak):
    """``steps`` steps of the corrected splitting from the carried state ``(qj, pj)`` (in place;
    ``cq``, ``cp``: its compensations, in place too; ``comp`` false: plain sums, the
    compensations untouched).

    One step is ``C ∘ K_{d_s} ∘ D_{c_{s−1}} ∘ … ∘ D_{c_0} ∘ K_{d_0} ∘ C`` with ``D_c`` the
    Kepler flow over ``c h``, ``K_d`` the kick by ``d h ∇H_I`` and ``C`` the corrector kick by
    ``kappa ∇C`` (``kappa`` already has its ``h³``).  The carried state lags the returned
    one by ``C ∘ K_{d_s}`` (:func:`_emit`), so consecutive steps fuse their end kicks into one
    evaluation: ``K_{d_s+d_0}`` with ``2 kappa``.  Rows ``out[1:]`` receive every
    ``save_every``-th state (Cartesian, q then p); ``out[0]`` is left to the caller.

    Returns the number of steps done.  On failure ``fail`` holds ``(status, body)``
    (:data:`STATUS`); the state is then the last good one.  ``peak[0]`` (in/out) is the largest
    relative change of a Jacobi momentum by one kick so far (``peak[1]``: that body); a kick
    above ``limit`` stops the run with status 4 (a close encounter: H_I is no longer small).
    The loop is :func:`_run`, compiled; its work arrays are allocated here.
    """
    f = np.array(fail, dtype=np.float64)
    done = _run(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, kappa, steps, save_every, out, f, comp,
                limit, peak, *_buffers(qj.shape[0]))
    fail[:] = f
    return done


@_kernel(_i8(_M2, _M2, _M2, _M2, _V, _V, _V, _V, _V, _f8, _i8, _V, _V, _f8, _f8, _i8, _i8, _M2, _V, _i8, _f8, _V,
             _M3, _M2, _M2, _M2, _M3))
def _run(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, kappa, steps, save_every, out, fail, comp,
         limit, peak, work, tq, tp, tc, saved):
    """:func:`run`'s loop (``fail`` as float64; the work arrays of :func:`_buffers`)."""
    ns = c.shape[0]
    a0 = (d[ns] + d[0]) * h
    b0 = 2.0 * kappa
    row = 1
    for step in range(steps):
        _save(qj, pj, cq, cp, saved[0], saved[1], saved[2], saved[3])
        if not _step(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, a0, b0, False, work, fail, comp,
                     limit, peak):
            _save(saved[0], saved[1], saved[2], saved[3], qj, pj, cq, cp)
            return step
        if (step + 1) % save_every == 0:
            _emit(qj, pj, cq, cp, d[ns] * h, kappa, m, M, mj, KM, G, jacobi, work, tq, tp, tc, out[row], comp)
            row += 1
    return steps


def run_projected(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, kappa, steps, save_every, out, fail,
                  comp, limit, peak, proj, tgt, pstat, pmaxiter):
    """:func:`run` with the energy projection (:func:`project`) onto ``tgt = (H, Lx, Ly, Lz)``:
    ``proj`` 1 projects every output row, the run itself continuing unprojected; 2 ends every
    step with the projection, fed back into the carried state.  A function of its own so that
    an unprojected run does not compile the projection.

    The gradients at a projected step's end serve both the output's lagged kick and the next
    step's fused kick (the positions do not change between them), so a projection costs one
    potential evaluation and a few 4×4 solves.  ``pstat`` (float, in/out) accumulates the
    projection's iterations (total, largest, -, count); on status 5 ``pstat[2]`` is the
    largest residual relative to its size.  ``pmaxiter``: the projection's iteration limit.
    The loop is :func:`_run_projected`, compiled; its work arrays are allocated here.
    """
    f = np.array(fail, dtype=np.float64)
    done = _run_projected(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, kappa, steps, save_every, out, f,
                          comp, limit, peak, proj, tgt, pstat, pmaxiter, *_buffers(qj.shape[0]))
    fail[:] = f
    return done


@_kernel(_i8(_M2, _M2, _M2, _M2, _V, _V, _V, _V, _V, _f8, _i8, _V, _V, _f8, _f8, _i8, _i8, _M2, _V, _i8, _f8, _V,
             _i8, _V, _V, _i8, _M3, _M2, _M2, _M2, _M3))
def _run_projected(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, kappa, steps, save_every, out, fail,
                   comp, limit, peak, proj, tgt, pstat, pmaxiter, work, tq, tp, tc, saved):
    """:func:`run_projected`'s loop (``fail`` as float64; the work arrays of :func:`_buffers`)."""
    ns = c.shape[0]
    a0 = (d[ns] + d[0]) * h
    b0 = 2.0 * kappa
    a1 = d[ns] * h
    inv = np.empty(9)
    fresh = False      # work holds the gradients at the current positions
    row = 1
    for step in range(steps):
        _save(qj, pj, cq, cp, saved[0], saved[1], saved[2], saved[3])
        ok = _step(qj, pj, cq, cp, m, M, mj, mu, KM, G, jacobi, c, d, h, a0, b0, fresh, work, fail, comp,
                   limit, peak)
        fresh = False
        emit = (step + 1) % save_every == 0
        if ok and (proj == 2 or emit):
            # the output state: the carried one with its lagged kick (gradients at the carried
            # positions qj, as the next fused kick takes them, and kept for it; _emit evaluates
            # them at qj - cq, a round-off apart), positions with their compensation
            if a1 != 0.0 or kappa != 0.0:
                gradients(qj, kappa, m, M, mj, KM, G, jacobi, work)
                fresh = True
            for i in range(qj.shape[0]):
                for k in range(3):
                    tq[i, k] = qj[i, k] - cq[i, k]
                    tp[i, k] = pj[i, k]
                    tc[i, k] = cp[i, k]
            if fresh:
                apply_kick(tp, tc, a1, kappa, work, comp)
            _positions(tq, m, M, jacobi, work[5])
            U = potential(work[5], m, mu, G, jacobi)
            st, its = project(tq, tp, tc, pj, cp, tgt, U, mj, jacobi, inv, comp, pmaxiter, proj == 2)
            pstat[0] += its
            pstat[1] = max(pstat[1], its)
            pstat[3] += 1
            if st != 0:
                fail[0] = st
                fail[1] = -1
                pstat[2] = inv[8]
                ok = False
        if not ok:
            _save(saved[0], saved[1], saved[2], saved[3], qj, pj, cq, cp)
            return step
        if emit:
            _row(tq, tp, tc, m, M, jacobi, work, out[row])
            row += 1
    return steps
