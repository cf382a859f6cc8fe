"""Wisdom–Holman splittings for ``[nbody]`` problems, certified: Kepler flows plus kicks, with correctors.

For N bodies with one dominant mass (a star and its planets) the Hamiltonian splits as

    H = H_K + H_I,
    H_K = |P|²/(2M) + Σ_{i≥1} ( |p'_i|²/(2 m'_i) − G m_i M_{i−1}/|q'_i| ),
    H_I = Σ_{i≥1} G m_i M_{i−1}/|q'_i| − Σ_{a<b} G m_a m_b/|q_a − q_b|,

in Jacobi coordinates ``q' = A q``, ``p' = A⁻ᵀ p`` (body i relative to the centre of mass
of bodies 0…i−1; ``M_i = m_0 + … + m_i``, ``m'_i = m_i M_{i−1}/M_i``) [WH91]_.  ``H_K`` is
a sum of Kepler problems (``μ_i = G M_i``), solved exactly; ``H_I`` depends on positions
only and is of the size of the planets' masses, ``ε = max m_i/m_0``.  About a fixed centre
(``[nbody] centre_mass``) the splitting is the same with ``A = I``: the body's Kepler
problem about the centre, ``H_I = 0`` for one body.

A splitting ``Φ_h = e^{c_1 h A} e^{d_1 h B} … `` of such a near-integrable ``A + εB`` has
error ``O(ε h^{p} + ε² h^{2})``: its ``ε`` terms vanish to order p when the kicks are a
quadrature rule exact for polynomials of degree p − 1 on the step.  The families of
Laskar & Robutel [LR01]_: ``saba<n>`` (kicks at the n Gauss–Legendre nodes, drifts at both
ends), ``sbab<n>`` (kicks at the n+1 Gauss–Lobatto nodes), both ``p = 2n``;
``"wisdom-holman"`` is ``saba1`` (drift, kick, drift).  With the corrector
``C_h = exp(−(g/2) h³ ε² {{A,B},B})`` on both sides, ``C_h Φ_h C_h`` has error
``O(ε h^{2n} + ε² h⁴)``; ``g`` is the coefficient of ``[B,[A,B]]`` in ``log Φ_h``.

Certificates (:func:`certify`):

* **exact** (SymPy, no floating point): the Jacobi map is canonical (``A_p A_qᵀ = I``), the
  kinetic energy is ``|P|²/(2M) + Σ|p'_i|²/(2m'_i)`` for symbolic masses (so ``H_I`` depends
  on positions only), ``μ_i m'_i = G m_i M_{i−1}``; and the scene's H equals the ``[nbody]``
  H, symbolically or, failing that, at the scene's parameter values (as exact rationals).
* **numerical** (50 digits): the kicks' quadrature conditions ``Σ d_j τ_j^k = 1/(k+1)`` for
  ``k < 2n`` (and that ``k = 2n`` fails: the ε-order is exactly 2n), ``g`` from the truncated
  BCH series, and that the ``ε h²`` term (``[A,[A,B]]``) vanishes for n ≥ 2.

What is kept: symplecticity (exact flows and kicks, a linear canonical change of
variables), symmetry (a palindromic splitting, the corrector on both sides with an odd
power of h), total linear and angular momentum to round-off.  Not kept: the energy (bounded
error of the size above).

References
----------
.. [WH91] J. Wisdom, M. Holman, Symplectic maps for the N-body problem, Astron. J. 102
   (1991) 1528–1538.
.. [LR01] J. Laskar, P. Robutel, High order symplectic integrators for perturbed
   Hamiltonian systems, Celest. Mech. Dyn. Astron. 80 (2001) 39–62.
.. [WHT96] J. Wisdom, M. Holman, J. Touma, Symplectic correctors, Fields Inst. Commun. 10
   (1996) 217–244.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import mpmath as mp
import numpy as np

from ..errors import InputError

__all__ = ["DPS", "FAMILIES", "JACOBI_PROOF", "Splitting", "splitting", "numerical_certificate", "certify"]

#: Working precision (decimal digits) of the coefficients and their conditions.
DPS = 50

#: Splitting names: "wisdom-holman" and saba1 … saba6, sbab1 … sbab6.
FAMILIES = ("wisdom-holman",) + tuple(f"saba{n}" for n in range(1, 7)) + tuple(f"sbab{n}" for n in range(1, 7))


# --- coefficients ------------------------------------------------------------------------

def _dlegendre(n, x):
    """P'_n(x) = n (x P_n(x) − P_{n−1}(x)) / (x² − 1) (x ≠ ±1)."""
    return n * (x * mp.legendre(n, x) - mp.legendre(n - 1, x)) / (x * x - 1)


def _refined(f, df, guesses):
    """Newton's method from float guesses to the working precision (the roots are simple)."""
    out = []
    for v in guesses:
        x = mp.mpf(float(v))
        for _ in range(200):
            dx = f(x) / df(x)
            x -= dx
            if abs(dx) < mp.mpf(10) ** (-(mp.mp.dps - 5)):
                break
        out.append(x)
    return sorted(out)


def _gauss(n):
    """Gauss–Legendre nodes and weights with n points on [0, 1] (exact for degree 2n−1)."""
    with mp.workdps(DPS + 20):
        xs = _refined(lambda x: mp.legendre(n, x), lambda x: _dlegendre(n, x),
                      np.polynomial.legendre.leggauss(n)[0])
        ws = [2 / ((1 - x ** 2) * _dlegendre(n, x) ** 2) for x in xs]
        return [(x + 1) / 2 for x in xs], [w / 2 for w in ws]


def _lobatto(n):
    """Gauss–Lobatto nodes and weights with n+1 points on [0, 1] (exact for degree 2n−1)."""
    with mp.workdps(DPS + 20):
        inner = []
        if n > 1:
            # interior nodes: roots of P'_n; (P'_n)' = (2x P'_n − n(n+1) P_n)/(1 − x²)
            guess = np.polynomial.legendre.Legendre.basis(n).deriv().roots()
            inner = _refined(lambda x: _dlegendre(n, x),
                             lambda x: (2 * x * _dlegendre(n, x) - n * (n + 1) * mp.legendre(n, x)) / (1 - x * x),
                             guess)
        xs = [mp.mpf(-1)] + inner + [mp.mpf(1)]
        ws = [mp.mpf(2) / (n * (n + 1) * mp.legendre(n, x) ** 2) for x in xs]
        return [(x + 1) / 2 for x in xs], [w / 2 for w in ws]


@dataclass(frozen=True)
class Splitting:
    """A near-integrable splitting ``K_{d_s} D_{c_{s−1}} … K_{d_1} D_{c_0} K_{d_0}`` of one step.

    Attributes
    ----------
    name : str
    n : int
        The family's index: ε-order 2n.
    drifts : tuple of mpf, length s
        ``c_j``: the Kepler flows' fractions of h (they add up to 1).
    kicks : tuple of mpf, length s + 1
        ``d_j``: the kicks' fractions of h (add up to 1); ``d_0`` before the first drift,
        ``d_s`` after the last (0 for the saba family).
    g : mpf
        The corrector coefficient: ``log Φ_h = h(A + B) − g h³ [B,[A,B]] + …`` in the ε² terms.
    source : str
    """

    name: str
    n: int
    drifts: tuple
    kicks: tuple
    g: object
    source: str

    @property
    def stages(self) -> int:
        """Kepler drifts per step (what a step costs, with one interaction evaluation per drift)."""
        return len(self.drifts)

    def kick_times(self):
        """The fractions of the step at which each nonzero kick acts, with its weight."""
        t, out = mp.mpf(0), []
        for j, d in enumerate(self.kicks):
            if d != 0:
                out.append((t, d))
            if j < len(self.drifts):
                t += self.drifts[j]
        return out

    def c(self) -> np.ndarray:
        return np.array([float(v) for v in self.drifts])

    def d(self) -> np.ndarray:
        return np.array([float(v) for v in self.kicks])


def _bch3(sequence):
    """Degree-≤3 part of ``log(Π exp(c X))`` in the free algebra of A, B (words → mpf).

    ``sequence`` is ``[(letter, coefficient), …]`` in the order of application; the
    product is formed in that order (a palindromic sequence gives the same log either way).
    """
    def mul(x, y):
        out = {}
        for u, a in x.items():
            for v, b in y.items():
                if len(u) + len(v) <= 3:
                    out[u + v] = out.get(u + v, 0) + a * b
        return out

    Z = {"": mp.mpf(1)}
    for letter, c in sequence:
        e = {"": mp.mpf(1), letter: c, letter * 2: c ** 2 / 2, letter * 3: c ** 3 / 6}
        Z = mul(Z, e)
    Y = {w: v for w, v in Z.items() if w}
    Y2 = mul(Y, Y)
    Y3 = mul(Y2, Y)
    out = {}
    for k, (T, s) in enumerate(((Y, 1), (Y2, -mp.mpf(1) / 2), (Y3, mp.mpf(1) / 3))):
        for w, v in T.items():
            out[w] = out.get(w, 0) + s * v
    return out


def _sequence(drifts, kicks):
    seq = []
    for j, d in enumerate(kicks):
        if d != 0:
            seq.append(("B", d))
        if j < len(drifts) and drifts[j] != 0:
            seq.append(("A", drifts[j]))
    return seq


@lru_cache(maxsize=None)
def splitting(name: str) -> Splitting:
    """The splitting called ``name`` (one of :data:`FAMILIES`), coefficients at :data:`DPS` digits.

    Raises
    ------
    InputError
        An unknown name (the message lists the valid ones).
    """
    if name not in FAMILIES:
        raise InputError(f"unknown Wisdom–Holman splitting {name!r}; valid: {', '.join(FAMILIES)}")
    fam, n = ("saba", 1) if name == "wisdom-holman" else (name[:4], int(name[4:]))
    with mp.workdps(DPS + 20):
        if fam == "saba":
            x, w = _gauss(n)
            drifts = [x[0]] + [x[j] - x[j - 1] for j in range(1, n)] + [1 - x[-1]]
            kicks = [mp.mpf(0)] + list(w) + [mp.mpf(0)]
            src = f"[LR01] SABA{n}: kicks at the {n} Gauss–Legendre nodes"
        else:
            x, w = _lobatto(n)
            drifts = [x[j + 1] - x[j] for j in range(n)]
            kicks = list(w)
            src = f"[LR01] SBAB{n}: kicks at the {n + 1} Gauss–Lobatto nodes"
        if name == "wisdom-holman":
            src = "[WH91] drift–kick–drift (= SABA1)"
        log = _bch3(_sequence(drifts, kicks))
        g = -log.get("BAB", 0) / 2            # [B,[A,B]] = 2BAB − BBA − ABB
        return Splitting(name, n, tuple(drifts), tuple(kicks), g, src)


def numerical_certificate(s: Splitting) -> dict:
    """The conditions of ``s`` evaluated at :data:`DPS` digits (numerical, not exact).

    Returns ``{"quadrature": [|Σ d τ^k − 1/(k+1)| for k = 0 … 2n], "epsilon_order": p,
    "eh2": |coefficient of [A,[A,B]]|, "consistency": (|Σc − 1|, |Σd − 1|), "g": g,
    "bch_check": how far the degree-3 log is from a Lie element}``.
    """
    with mp.workdps(DPS):
        times = s.kick_times()
        quad = [abs(sum(d * t ** k for t, d in times) - mp.mpf(1) / (k + 1)) for k in range(2 * s.n + 1)]
        tol = mp.mpf(10) ** (-(DPS - 10))
        order = next((k for k, e in enumerate(quad) if e > tol), len(quad))
        log = _bch3(_sequence(s.drifts, s.kicks))
        # [A,[A,B]] = AAB − 2ABA + BAA: its coefficient is −(ABA)/2
        eh2 = abs(log.get("ABA", 0) / 2)
        # a Lie element: ABB = BBA = −BAB/2 and AAB = BAA = −ABA/2
        lie = max(abs(log.get("ABB", 0) + log.get("BAB", 0) / 2), abs(log.get("BBA", 0) + log.get("BAB", 0) / 2),
                  abs(log.get("AAB", 0) + log.get("ABA", 0) / 2), abs(log.get("BAA", 0) + log.get("ABA", 0) / 2))
        return {"quadrature": [float(e) for e in quad], "epsilon_order": order, "eh2": float(eh2),
                "consistency": (float(abs(sum(s.drifts) - 1)), float(abs(sum(s.kicks) - 1))),
                "g": float(s.g), "bch_check": float(lie)}


# --- the splitting of H, certified exactly -------------------------------------------------

def _jacobi_matrices(n: int, m):
    """``(A_q, A_p)`` of the Jacobi map for masses ``m`` (SymPy, one coordinate axis).

    Row 0 is the centre of mass / total momentum; row i ≥ 1 body i relative to the centre
    of mass of bodies 0…i−1 and its momentum ``(M_{i−1} p_i − m_i P_{i−1})/M_i`` (the formulas
    :func:`methodgen.runtime.kepler_flow.to_jacobi` runs)."""
    import sympy as sp

    M = [sum(m[: i + 1]) for i in range(n)]
    Aq = sp.zeros(n, n)
    Ap = sp.zeros(n, n)
    for j in range(n):
        Aq[0, j] = m[j] / M[n - 1]
        Ap[0, j] = 1
    for i in range(1, n):
        Aq[i, i] = 1
        Ap[i, i] = M[i - 1] / M[i]
        for j in range(i):
            Aq[i, j] = -m[j] / M[i - 1]
            Ap[i, j] = -m[i] / M[i]
    return Aq, Ap, M


def _nbody_expression(system, nbody):
    """The ``[nbody]`` H in the system's symbols (masses and G: its parameters or numbers)."""
    import sympy as sp

    def value(v):
        if isinstance(v, str):
            return system.symbol(v)
        return sp.Rational(repr(float(v)))

    G = value(nbody.G)
    m = [value(v) for v in nbody.masses]
    q, p = system.q, system.p
    nb = len(m)
    H = sum((p[3 * b] ** 2 + p[3 * b + 1] ** 2 + p[3 * b + 2] ** 2) / (2 * m[b]) for b in range(nb))
    for a in range(nb):
        for b in range(a + 1, nb):
            H -= G * m[a] * m[b] / sp.sqrt(sum((q[3 * a + k] - q[3 * b + k]) ** 2 for k in range(3)))
    if nbody.centre_mass is not None:
        C = value(nbody.centre_mass)
        H -= sum(G * C * m[b] / sp.sqrt(sum(q[3 * b + k] ** 2 for k in range(3))) for b in range(nb))
    return H


@lru_cache(maxsize=None)
def _canonical_case_identities() -> bool:
    """The six forms of an entry (i, k) of ``A_p A_qᵀ − I`` (see :func:`_jacobi_identities`),
    each reduced to 0 by ``cancel``, for symbols: ``Sp = M_{i−1}``, ``m = m_i``
    (``M_i = Sp + m``), ``Sk = M_{k−1}``, ``M`` the total mass.

    ``Σ_j A_p[i, j] A_q[k, j]`` is, with ``a = M_{i−1}/M_i`` and ``b = m_i/M_i``,
    ``a δ_ik − a [i<k] m_i/M_{k−1} − b [k<i] + b M_{min(i,k)−1}/M_{k−1}`` for i, k ≥ 1;
    ``Σ_j m_j/M`` for (0, 0); ``1 − M_{k−1}/M_{k−1}`` for (0, k); ``(a m_i − b M_{i−1})/M``
    for (i, 0)."""
    import sympy as sp

    Sp, m, Sk, Mt = sp.symbols("Sp m Sk M", positive=True)
    a, b = Sp / (Sp + m), m / (Sp + m)
    cases = (a + b * Sp / Sp - 1,          # i = k ≥ 1
             -a * m / Sk + b * Sp / Sk,     # 1 ≤ i < k
             -b + b * Sk / Sk,              # 1 ≤ k < i
             Mt / Mt - 1,                   # (0, 0)
             1 - Sk / Sk,                   # (0, k ≥ 1)
             (a * m - b * Sp) / Mt)         # (i ≥ 1, 0)
    return all(sp.cancel(c) == 0 for c in cases)


@lru_cache(maxsize=None)
def _kinetic_step_identity() -> bool:
    """The one identity the kinetic energy's induction over bodies rests on, for symbols:

    ``P²/(2m) = (Π + P)²/(2(S + m)) − Π²/(2S) + p'²/(2m')``,
    ``p' = (S P − m Π)/(S + m)``, ``m' = m S/(S + m)``,

    where ``S`` and ``Π`` are the mass and momentum of the bodies before (``M_{i−1}``,
    ``P_0 + … + P_{i−1}``), and ``P``, ``m`` body i's.  Decided by ``cancel``."""
    import sympy as sp

    S, m = sp.symbols("S m", positive=True)
    Pi, P = sp.symbols("Pi P", real=True)
    pj = (S * P - m * Pi) / (S + m)
    mj = m * S / (S + m)
    return sp.cancel(P ** 2 / (2 * m) - (Pi + P) ** 2 / (2 * (S + m)) + Pi ** 2 / (2 * S)
                     - pj ** 2 / (2 * mj)) == 0


@lru_cache(maxsize=None)
def _jacobi_identities(n: int) -> dict:
    """The exact identities of the Jacobi splitting of n bodies, for symbolic positive masses.

    Returns ``{"canonical": bool, "kinetic": bool, "kepler": bool}``:

    * ``A_p A_qᵀ = I``;
    * the kinetic energy ``Σ p_b²/(2m_b) = P²/(2M) + Σ_{i≥1} p'_i²/(2m'_i)`` (one axis; the
      others are the same polynomial);
    * ``G M_i m'_i = G m_i M_{i−1}`` (the Kepler term put into ``H_K`` is the one ``H_I``
      takes back).

    Each is decided by ``sympy.cancel`` reducing a rational function to 0: no floating point.
    The cost is polynomial in n (it grew about 4.5× per body when the kinetic energy was
    reduced as one rational function of n masses: 58 s at 8 bodies):

    * ``A_p A_qᵀ = I`` from the rows' structure: every entry of ``A_q`` and ``A_p`` is shown
      to be its closed form (``A_q[i, j] = −m_j/M_{i−1}`` for j < i, 1 on the diagonal, 0
      above; row 0 ``m_j/M``; ``A_p[i, j] = −m_i/M_i`` for j < i, ``M_{i−1}/M_i`` on the
      diagonal; row 0 ones), so with ``Σ_{j<k} m_j = M_{k−1}`` an entry (i, k) is one of six
      expressions in four symbols -- i = k, i < k, i > k, and row or column 0
      (:func:`_canonical_case_identities`, proved once);
    * the kinetic energy by induction over the bodies: with ``Π_i = P_0 + … + P_i``,
      ``Σ_{b≤i} P_b²/(2m_b) = Π_i²/(2M_i) + Σ_{1≤j≤i} p'_j²/(2m'_j)`` holds at i = 0
      (``Π_0 = P_0``, ``M_0 = m_0``), and its step from i − 1 to i is
      :func:`_kinetic_step_identity` (proved once, for symbols) once row i of ``A_p`` is
      shown to be ``p'_i = (M_{i−1} P_i − m_i Π_{i−1})/M_i`` entry by entry and ``m'_i`` to be
      ``m_i M_{i−1}/M_i``; at i = n − 1 row 0 (all ones) gives ``P = Π_{n−1}``, ``m'_0 = M``.
    """
    import sympy as sp

    S = sp.symbols(f"S0:{n}", positive=True)
    m = [S[0]] + [S[i] - S[i - 1] for i in range(1, n)]
    Aq, Ap, M = _jacobi_matrices(n, m)
    sums = all(sp.expand(M[i] - S[i]) == 0 for i in range(n))
    rows_q = all(sp.cancel(Aq[0, j] - m[j] / S[n - 1]) == 0 for j in range(n)) and all(
        sp.cancel(Aq[i, j] - (1 if j == i else -m[j] / S[i - 1] if j < i else 0)) == 0
        for i in range(1, n) for j in range(n))
    mj = [M[n - 1]] + [m[i] * M[i - 1] / M[i] for i in range(1, n)]
    rows = all(Ap[0, j] == 1 for j in range(n)) and all(
        sp.cancel(Ap[i, j] - (S[i - 1] / S[i] if j == i else -m[i] / S[i] if j < i else 0)) == 0
        for i in range(1, n) for j in range(n))
    masses = all(sp.cancel(mj[i] - m[i] * S[i - 1] / S[i]) == 0 for i in range(1, n)) and \
        sp.expand(mj[0] - S[n - 1]) == 0
    canonical = sums and rows_q and rows and _canonical_case_identities()
    kinetic = sums and rows and masses and _kinetic_step_identity()
    kepler = all(sp.cancel(M[i] * mj[i] - m[i] * M[i - 1]) == 0 for i in range(1, n))
    return {"canonical": bool(canonical), "kinetic": bool(kinetic), "kepler": bool(kepler)}


#: how :func:`_jacobi_identities` decides them (the claim's detail)
JACOBI_PROOF = ("rows of A_q, A_p in closed form entry by entry, the entries of A_p A_qᵀ in six "
                "cases and the kinetic energy by induction over the bodies, each by cancel; "
                "polynomial in the number of bodies")


def certify(system, nbody, params: dict | None = None) -> dict:
    """Decide exactly that ``system``'s H is the ``[nbody]`` H and that it splits as claimed.

    Returns
    -------
    dict
        ``"splitting"``: the identities of :func:`_jacobi_identities` (all True for a Jacobi
        splitting; ``"identity map"`` about a fixed centre); ``"hamiltonian"``: ``"symbolic"``
        (H equals the declared H for every parameter value), ``"at the parameter values"``
        (equal once the parameters take ``params``' values — default the system's — as exact
        rationals), or
        ``False``; ``"numerical"``: :func:`numerical_certificate` is separate.
    """
    import sympy as sp

    Hn = _nbody_expression(system, nbody)
    diff = sp.expand(system.H - Hn)
    if diff == 0:
        same = "symbolic"
    else:
        values = system.param_values if params is None else params
        vals = {system.symbol(k): sp.Rational(repr(float(v))) for k, v in values.items()}
        same = "at the parameter values" if sp.expand(diff.subs(vals)) == 0 else False
    if nbody.centre_mass is not None:
        split = "identity map"
    else:
        split = _jacobi_identities(len(nbody.masses))
    return {"hamiltonian": same, "splitting": split}
